//! A seeded generator of SYNTHETIC labelled OpenFace frames for tests and demos (no real
//! person behind any row). Engaged frames face the robot with the gaze near 0; disengaged
//! frames turn the head away or look down, with the gaze following. Each participant sits at
//! their own distance and offset, so leave-one-participant-out is not trivial.

use crate::features::{FEATURE_COUNT, canonical_index};
use crate::table::FeatureTable;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// What to generate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SyntheticSpec {
    pub participants: usize,
    pub frames_per_participant: usize,
    /// Frames per second of the simulated camera (frame times are `k / fps`).
    pub fps: f64,
    /// Share of frames whose label is flipped (annotation noise).
    pub label_noise: f64,
    pub seed: u64,
}

impl Default for SyntheticSpec {
    fn default() -> Self {
        SyntheticSpec {
            participants: 6,
            frames_per_participant: 600,
            fps: 30.0,
            label_noise: 0.03,
            seed: 7,
        }
    }
}

fn normal(rng: &mut ChaCha8Rng, mean: f64, std: f64) -> f64 {
    // Box-Muller; 1 - u keeps the logarithm finite.
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    mean + std * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A participant's fixed traits.
struct Person {
    offset: [f64; 3],
    gaze_bias: [f64; 2],
    au_rate: [f64; 18],
}

fn idx(name: &str) -> usize {
    canonical_index(name).expect("the generator only uses names from OPENFACE_FEATURES")
}

/// Generates the table; the same spec always gives the same rows.
pub fn generate(spec: &SyntheticSpec) -> FeatureTable {
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let mut table = FeatureTable::default();
    let (tx, ty, tz) = (idx("pose_Tx"), idx("pose_Ty"), idx("pose_Tz"));
    let (rx, ry, rz) = (idx("pose_Rx"), idx("pose_Ry"), idx("pose_Rz"));
    let (gax, gay) = (idx("gaze_angle_x"), idx("gaze_angle_y"));
    let (g0, g1) = (idx("gaze_0_x"), idx("gaze_1_x"));
    let (au01, au04, au12, au45) = (idx("AU01_c"), idx("AU04_c"), idx("AU12_c"), idx("AU45_c"));
    for p in 0..spec.participants {
        let person = Person {
            offset: [
                normal(&mut rng, 0.0, 60.0),
                normal(&mut rng, 0.0, 40.0),
                normal(&mut rng, 700.0, 90.0),
            ],
            gaze_bias: [normal(&mut rng, 0.0, 0.06), normal(&mut rng, 0.05, 0.06)],
            au_rate: std::array::from_fn(|_| rng.random_range(0.05..0.45)),
        };
        let mut engaged = rng.random_bool(0.5);
        let mut left_in_segment = 0usize;
        let mut turn_sign = 1.0;
        let mut looks_down = false;
        for k in 0..spec.frames_per_participant {
            if left_in_segment == 0 {
                engaged = !engaged;
                left_in_segment = rng.random_range(30..150);
                turn_sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                looks_down = rng.random_bool(0.4);
            }
            left_in_segment -= 1;
            let mut row = [0f64; FEATURE_COUNT];
            let (pitch, yaw) = match (engaged, looks_down) {
                (true, _) => (normal(&mut rng, 0.0, 0.08), normal(&mut rng, 0.0, 0.1)),
                (false, true) => (normal(&mut rng, 0.45, 0.15), normal(&mut rng, 0.0, 0.15)),
                (false, false) => (
                    normal(&mut rng, 0.05, 0.1),
                    turn_sign * normal(&mut rng, 0.65, 0.2),
                ),
            };
            row[rx] = pitch;
            row[ry] = yaw;
            row[rz] = normal(&mut rng, 0.0, 0.06);
            row[tx] = person.offset[0] + 120.0 * yaw + normal(&mut rng, 0.0, 8.0);
            row[ty] = person.offset[1] + 80.0 * pitch + normal(&mut rng, 0.0, 8.0);
            row[tz] = person.offset[2] + normal(&mut rng, 0.0, 15.0);
            // Gaze follows the head, partly; engaged eyes come back towards the robot.
            let follow = if engaged { 0.2 } else { 0.7 };
            row[gax] = person.gaze_bias[0] + follow * yaw + normal(&mut rng, 0.0, 0.07);
            row[gay] = person.gaze_bias[1] + follow * pitch + normal(&mut rng, 0.0, 0.07);
            // Pupil positions (mm, camera frame), as the authors' node filled gaze_0 / gaze_1.
            for (base, side) in [(g0, -31.0), (g1, 31.0)] {
                row[base] = row[tx] + side * yaw.cos() + normal(&mut rng, 0.0, 1.0);
                row[base + 1] = row[ty] - 30.0 + 25.0 * pitch + normal(&mut rng, 0.0, 1.0);
                row[base + 2] = row[tz] - 90.0 + side * yaw.sin() + normal(&mut rng, 0.0, 2.0);
            }
            for (a, rate) in person.au_rate.iter().enumerate() {
                let c = au01 + a;
                let shift = match (c, engaged) {
                    (c, true) if c == au12 || c == au01 => 0.2,
                    (c, false) if c == au45 || c == au04 => 0.25,
                    _ => 0.0,
                };
                row[c] = f64::from(u8::from(rng.random_bool((rate + shift).min(0.95))));
            }
            // OpenFace writes four decimals; so do we (it also gives the trees tied values).
            for v in row.iter_mut() {
                *v = (*v * 1e4).round() / 1e4;
            }
            let mut label: i8 = if engaged { 1 } else { -1 };
            if rng.random_bool(spec.label_noise) {
                label = -label;
            }
            table.participants.push(format!("S{:02}", p + 1));
            table.timestamps.push(k as f64 / spec.fps);
            table.labels.push(label);
            table.rows.push(row);
        }
    }
    table
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_rows_other_seed_other_rows() {
        let spec = SyntheticSpec {
            participants: 2,
            frames_per_participant: 50,
            ..SyntheticSpec::default()
        };
        assert_eq!(generate(&spec), generate(&spec));
        let other = generate(&SyntheticSpec { seed: 8, ..spec });
        assert_ne!(generate(&spec).rows, other.rows);
    }

    #[test]
    fn engaged_frames_face_the_robot() {
        let t = generate(&SyntheticSpec::default());
        assert_eq!(t.len(), 3600);
        assert_eq!(t.participant_ids().len(), 6);
        let ry = idx("pose_Ry");
        let mean_abs_yaw = |label: i8| {
            let v: Vec<f64> = (0..t.len())
                .filter(|&i| t.labels[i] == label)
                .map(|i| t.rows[i][ry].abs())
                .collect();
            v.iter().sum::<f64>() / v.len() as f64
        };
        assert!(mean_abs_yaw(1) < 0.2, "{}", mean_abs_yaw(1));
        assert!(mean_abs_yaw(-1) > 0.3, "{}", mean_abs_yaw(-1));
        assert!(t.rows.iter().flatten().all(|v| v.is_finite()));
        assert!(t.labels.contains(&1) && t.labels.contains(&-1));
    }
}
