//! Repair of continuous values that lost their decimal point in the MigrAVE frames
//! (`-49981` between `-49.98` and `-50.06`). The digits are intact, so the value is the
//! integer divided by some power of ten; we pick the power that puts it at the order of
//! magnitude of the same participant's nearest intact values in that column (log distance,
//! which also works for angles that wrap at ±π, where a linear mean would not).

use crate::features::{FEATURE_COUNT, model_feature_name};
use crate::table::FeatureTable;
use std::collections::{BTreeMap, HashMap};

/// What to do with a continuous value written as a bare non-zero integer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DecimalRepair {
    /// Put the decimal point back where the neighbours' magnitude says (our default).
    Magnitude,
    /// Treat it as a missing value (NaN; the preprocessing fills it).
    Missing,
    /// Use it as written (what the authors' training did).
    Keep,
}

impl std::str::FromStr for DecimalRepair {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "magnitude" => Ok(DecimalRepair::Magnitude),
            "missing" => Ok(DecimalRepair::Missing),
            "keep" => Ok(DecimalRepair::Keep),
            other => Err(format!(
                "decimal_repair {other:?} is not magnitude, missing or keep"
            )),
        }
    }
}

/// What the loader did to the data.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CleaningReport {
    pub rows_read: usize,
    /// Rows labelled 0 (neutral), before the neutral-label policy applied.
    pub neutral_rows: usize,
    /// Continuous values without a decimal point, per canonical feature.
    pub dotless_values: [usize; FEATURE_COUNT],
    /// Rows with at least one such value (among the rows kept).
    pub dotless_rows: usize,
    /// Repaired values by the power of ten they were divided by.
    pub divided_by_power: BTreeMap<u32, usize>,
    /// Values set to NaN (policy `missing`, or no intact value to compare with).
    pub set_missing: usize,
}

impl CleaningReport {
    /// Human-readable summary, one line per fact.
    pub fn summary(&self) -> String {
        let total: usize = self.dotless_values.iter().sum();
        let mut s = format!(
            "read {} rows; {} labelled 0 (neutral); {} values in {} rows had lost their decimal point",
            self.rows_read, self.neutral_rows, total, self.dotless_rows
        );
        let per_column: Vec<String> = (0..FEATURE_COUNT)
            .filter(|&c| self.dotless_values[c] > 0)
            .map(|c| format!("{} {}", model_feature_name(c), self.dotless_values[c]))
            .collect();
        if !per_column.is_empty() {
            s.push_str(&format!("\n  per column: {}", per_column.join(", ")));
        }
        if !self.divided_by_power.is_empty() {
            let powers: Vec<String> = self
                .divided_by_power
                .iter()
                .map(|(k, n)| format!("10^{k}: {n}"))
                .collect();
            s.push_str(&format!(
                "\n  repaired by dividing by {}",
                powers.join(", ")
            ));
        }
        if self.set_missing > 0 {
            s.push_str(&format!("\n  set to missing: {}", self.set_missing));
        }
        s
    }
}

/// Applies `policy` to the values flagged in `dotless` (bit c of row i = feature c).
pub(crate) fn repair_dotless(
    table: &mut FeatureTable,
    dotless: &[u32],
    policy: DecimalRepair,
    report: &mut CleaningReport,
) {
    report.dotless_rows = dotless.iter().filter(|&&f| f != 0).count();
    for c in 0..FEATURE_COUNT {
        let bit = 1u32 << c;
        let flagged: Vec<usize> = (0..table.len())
            .filter(|&i| dotless[i] & bit != 0)
            .collect();
        report.dotless_values[c] = flagged.len();
        if flagged.is_empty() || policy == DecimalRepair::Keep {
            continue;
        }
        if policy == DecimalRepair::Missing {
            for &i in &flagged {
                table.rows[i][c] = f64::NAN;
            }
            report.set_missing += flagged.len();
            continue;
        }
        let magnitude = |i: usize| {
            let v = table.rows[i][c];
            (dotless[i] & bit == 0 && v.is_finite() && v != 0.0).then(|| v.abs().log10())
        };
        let before = nearest_intact(table, (0..table.len()).collect(), &magnitude);
        let after = nearest_intact(table, (0..table.len()).rev().collect(), &magnitude);
        let mut column_logs: Vec<f64> = (0..table.len()).filter_map(magnitude).collect();
        column_logs.sort_by(f64::total_cmp);
        let column_median = column_logs.get(column_logs.len() / 2).copied();
        for &i in &flagged {
            let target = match (before[i], after[i]) {
                (Some(a), Some(b)) => Some((a + b) / 2.0),
                (Some(a), None) | (None, Some(a)) => Some(a),
                (None, None) => column_median,
            };
            let Some(target) = target else {
                table.rows[i][c] = f64::NAN;
                report.set_missing += 1;
                continue;
            };
            let (value, power) = closest_magnitude(table.rows[i][c], target, physical_limit(c));
            table.rows[i][c] = value;
            *report.divided_by_power.entry(power).or_default() += 1;
        }
    }
}

/// For each row, log10 magnitude of the latest intact value of the same participant seen
/// before it when walking `order`.
fn nearest_intact(
    table: &FeatureTable,
    order: Vec<usize>,
    magnitude: &impl Fn(usize) -> Option<f64>,
) -> Vec<Option<f64>> {
    let mut last: HashMap<&str, f64> = HashMap::new();
    let mut out = vec![None; table.len()];
    for i in order {
        let who = table.participants[i].as_str();
        out[i] = last.get(who).copied();
        if let Some(m) = magnitude(i) {
            last.insert(who, m);
        }
    }
    out
}

/// Largest |value| a feature can take: head rotations are angles in radians, gaze angles lie
/// within a quarter turn; positions (mm) have no fixed bound.
fn physical_limit(c: usize) -> f64 {
    let name = crate::features::OPENFACE_FEATURES[c];
    if name.starts_with("pose_R") {
        std::f64::consts::PI
    } else if name.starts_with("gaze_angle") {
        std::f64::consts::FRAC_PI_2
    } else {
        f64::INFINITY
    }
}

/// `integer / 10^k` within `limit` whose log10 magnitude is closest to `target`. k runs past
/// the number of digits because zeros after the lost point went with it
/// (`0.018` -> `0018` -> `18`).
fn closest_magnitude(integer: f64, target: f64, limit: f64) -> (f64, u32) {
    let digits = integer.abs().log10().floor().max(0.0) as u32 + 1;
    let mut best = (integer, 0u32, f64::INFINITY);
    for k in 0..=digits + 6 {
        let candidate = integer / 10f64.powi(k as i32);
        if candidate.abs() > limit {
            continue;
        }
        let distance = (candidate.abs().log10() - target).abs();
        if distance < best.2 {
            best = (candidate, k, distance);
        }
    }
    (best.0, best.1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_magnitude_puts_the_point_back() {
        let free = f64::INFINITY;
        assert_eq!(
            closest_magnitude(-49981.0, 49.98f64.log10(), free),
            (-49.981, 3)
        );
        assert_eq!(closest_magnitude(18.0, 0.0175f64.log10(), free), (0.018, 3));
        assert_eq!(
            closest_magnitude(1239304.0, 1239.14f64.log10(), free),
            (1239.304, 3)
        );
        // an angle near -pi between neighbours near +pi and -pi keeps its magnitude
        let pi = std::f64::consts::PI;
        assert_eq!(closest_magnitude(-3065.0, 2.75f64.log10(), pi), (-3.065, 3));
        // 4.4 is nearer 1.44 in magnitude, but no angle is 4.4 rad
        assert_eq!(closest_magnitude(44.0, 1.44f64.log10(), pi), (0.44, 2));
        // a genuine integer stays as it is
        assert_eq!(
            closest_magnitude(1240.0, 1239.0f64.log10(), free),
            (1240.0, 0)
        );
    }

    fn table(values: &[(&str, f64)]) -> FeatureTable {
        let mut t = FeatureTable::default();
        for (p, v) in values {
            let mut row = [0.0; FEATURE_COUNT];
            row[0] = *v;
            t.participants.push(p.to_string());
            t.timestamps.push(0.0);
            t.labels.push(1);
            t.rows.push(row);
        }
        t
    }

    #[test]
    fn repair_uses_the_same_participants_neighbours() {
        let mut t = table(&[
            ("a", 5.59),
            ("a", 5794.0),
            ("a", 5.78),
            ("b", 6003.0),
            ("b", 600.3),
        ]);
        let dotless = [0, 1, 0, 1, 0];
        let mut report = CleaningReport::default();
        repair_dotless(&mut t, &dotless, DecimalRepair::Magnitude, &mut report);
        assert_eq!(t.rows[1][0], 5.794);
        // participant b's only intact value is 600.3, not a's 5.78
        assert_eq!(t.rows[3][0], 600.3);
        assert_eq!(report.dotless_values[0], 2);
        assert_eq!(report.divided_by_power.get(&3), Some(&1));
        assert_eq!(report.divided_by_power.get(&1), Some(&1));
    }

    #[test]
    fn missing_and_keep_policies() {
        let dotless = [0, 1];
        let mut t = table(&[("a", 5.59), ("a", 5794.0)]);
        let mut report = CleaningReport::default();
        repair_dotless(&mut t, &dotless, DecimalRepair::Missing, &mut report);
        assert!(t.rows[1][0].is_nan());
        assert_eq!(report.set_missing, 1);
        let mut t = table(&[("a", 5.59), ("a", 5794.0)]);
        repair_dotless(&mut t, &dotless, DecimalRepair::Keep, &mut report);
        assert_eq!(t.rows[1][0], 5794.0);
    }
}
