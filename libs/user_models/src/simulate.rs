//! A SYNTHETIC study shaped like the paper's (no real person behind any record): 20 adults,
//! one session of 10 sequences each, every level played without and then with feedback; two
//! behaviour groups (11 and 9 users) that succeed alike per level but differ strongly in
//! engagement. Seeded, so every test and demo has the same data.

use crate::data::InteractionRecord;
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sequence_game::{Feedback, Level, Outcome};

/// Shape of the synthetic study.
#[derive(Debug, Clone, PartialEq)]
pub struct StudySpec {
    pub engaged_users: usize,
    pub disengaged_users: usize,
    pub seed: u64,
    /// P(success) per level, both groups.
    pub success: [f64; 3],
    /// Mean engagement per level of each group.
    pub engagement_high: [f64; 3],
    pub engagement_low: [f64; 3],
}

impl Default for StudySpec {
    fn default() -> Self {
        StudySpec {
            engaged_users: 11,
            disengaged_users: 9,
            seed: 7,
            success: [0.95, 0.88, 0.5],
            engagement_high: [0.5, 0.62, 0.57],
            engagement_low: [-0.6, -0.5, -0.7],
        }
    }
}

fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1 = 1.0 - rng.random::<f64>();
    let u2 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Generates the records, users `sim-01` ... in time order.
pub fn simulate_study(spec: &StudySpec) -> Vec<InteractionRecord> {
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let mut out = Vec::new();
    let users = spec.engaged_users + spec.disengaged_users;
    for u in 0..users {
        let engaged = u < spec.engaged_users;
        let user = format!("sim-{:02}", u + 1);
        let skill = 0.05 * normal(&mut rng);
        let offset = 0.12 * normal(&mut rng);
        let mut levels = Level::ALL;
        levels.shuffle(&mut rng);
        let mut lengths = [3usize, 3, 4];
        lengths.shuffle(&mut rng);
        let mut time = 1_700_000_000.0 + 3600.0 * u as f64;
        let mut previous_score = 0i8;
        for (level, count) in levels.iter().zip(lengths) {
            for k in 0..count {
                // Each stage starts without feedback and then gives some.
                let feedback = if k == 0 {
                    Feedback::None
                } else {
                    Feedback::ALL[rng.random_range(1..3)]
                };
                let bonus = match feedback {
                    Feedback::Encouraging => 0.03,
                    Feedback::Challenging => -0.02,
                    Feedback::None => 0.0,
                };
                let p = (spec.success[level.index()] + skill + bonus).clamp(0.02, 0.99);
                let outcome = Outcome::from_correct(rng.random::<f64>() < p);
                let base = if engaged {
                    spec.engagement_high
                } else {
                    spec.engagement_low
                }[level.index()]
                    + offset;
                let after_failure = if previous_score < 0 { -0.08 } else { 0.0 };
                let talking = 2 + 6 * level.get() as usize;
                let per_second: Vec<f64> = (0..talking)
                    .map(|_| (base + after_failure + 0.3 * normal(&mut rng)).clamp(-1.0, 1.0))
                    .collect();
                let e = per_second.iter().sum::<f64>() / per_second.len() as f64;
                let response_time =
                    (4.0 + 4.0 * f64::from(level.get()) + 1.5 * normal(&mut rng)).max(1.5);
                time += talking as f64 + response_time;
                out.push(InteractionRecord {
                    user_id: user.clone(),
                    session_id: format!("{user}-s1"),
                    time,
                    level: *level,
                    feedback,
                    previous_score,
                    outcome,
                    score: outcome.score(*level),
                    response_time,
                    engagement: Some(e),
                    engagement_per_second: per_second,
                });
                previous_score = outcome.score(*level);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn has_the_studys_shape_and_is_seeded() {
        let r = simulate_study(&StudySpec::default());
        assert_eq!(r.len(), 200);
        assert_eq!(r, simulate_study(&StudySpec::default()));
        for u in 1..=20 {
            let mine: Vec<_> = r
                .iter()
                .filter(|x| x.user_id == format!("sim-{u:02}"))
                .collect();
            assert_eq!(mine.len(), 10);
            for l in Level::ALL {
                assert!(
                    mine.iter()
                        .any(|x| x.level == l && x.feedback == Feedback::None)
                );
                assert!(
                    mine.iter()
                        .any(|x| x.level == l && x.feedback != Feedback::None),
                    "user {u} level {l}"
                );
            }
        }
    }
}
