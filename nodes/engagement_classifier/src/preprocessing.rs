//! The authors' input preprocessing, carried inside the model file: each feature is
//! standardised with the training mean and (population) std, and a missing value is replaced
//! by a stored per-column fill before the trees see it.
//!
//! It travels as a JSON string in the XGBoost model's `learner.attributes` under
//! [`PREPROCESSING_ATTRIBUTE`], so the file stays a plain XGBoost model that Python loads.

use crate::features::{FEATURE_COUNT, canonical_index, model_feature_name};
use serde::{Deserialize, Serialize};

/// Attribute key of the preprocessing block in `learner.attributes`.
pub const PREPROCESSING_ATTRIBUTE: &str = "engagement_preprocessing";
/// Value of the block's `format` field; a reader refuses other formats.
pub const PREPROCESSING_FORMAT: &str = "standardize-then-fill/1";

/// Below this |std| the authors only centre the column (their `standardize_data`).
const MIN_STD: f64 = 1e-10;

/// What the preprocessing block says, per feature name (in the model's column order).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PreprocessingBlock {
    pub format: String,
    pub features: Vec<String>,
    pub mean: Vec<f64>,
    pub std: Vec<f64>,
    /// Standardised value that replaces a missing input; `null` leaves it missing, so the
    /// trees' default directions decide.
    pub nan_fill: Vec<Option<f64>>,
}

/// The same, resolved to the canonical feature order for the hot path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Preprocessing {
    pub mean: [f64; FEATURE_COUNT],
    pub std: [f64; FEATURE_COUNT],
    pub nan_fill: [f64; FEATURE_COUNT],
}

/// Why a preprocessing block cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PreprocessingError {
    #[error("not a preprocessing block: {0}")]
    Parse(String),
    #[error("format is {0:?}, expected {PREPROCESSING_FORMAT:?}")]
    Format(String),
    #[error("field {field} has {got} values for {expected} features")]
    Length {
        field: &'static str,
        got: usize,
        expected: usize,
    },
    #[error("feature {0:?} is not one of the 32 OpenFace features")]
    UnknownFeature(String),
    #[error("feature {0:?} appears twice")]
    DuplicateFeature(String),
    #[error("feature {0:?} is missing")]
    MissingFeature(String),
    #[error("{field} of feature {feature:?} is not finite")]
    NotFinite {
        field: &'static str,
        feature: String,
    },
}

impl Preprocessing {
    /// Identity: no centring, no scaling, missing stays missing.
    pub const IDENTITY: Preprocessing = Preprocessing {
        mean: [0.0; FEATURE_COUNT],
        std: [1.0; FEATURE_COUNT],
        nan_fill: [f64::NAN; FEATURE_COUNT],
    };

    /// Fits the authors' rule on training rows (canonical order): NaN-ignoring mean and
    /// population std; the fill is the standardised column minimum, or maximum for the gaze
    /// and pose columns of their list.
    pub fn fit(rows: &[[f64; FEATURE_COUNT]]) -> Preprocessing {
        let mut out = Preprocessing::IDENTITY;
        for c in 0..FEATURE_COUNT {
            let values = || rows.iter().map(|r| r[c]).filter(|v| !v.is_nan());
            let n = values().count();
            if n == 0 {
                continue;
            }
            let mean = values().sum::<f64>() / n as f64;
            let var = values().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n as f64;
            out.mean[c] = mean;
            out.std[c] = var.sqrt();
            let standardised = values().map(|v| out.standardise(c, v));
            out.nan_fill[c] = if nan_fill_uses_max(c) {
                standardised.fold(f64::NEG_INFINITY, f64::max)
            } else {
                standardised.fold(f64::INFINITY, f64::min)
            };
        }
        out
    }

    /// Standardises one raw value of canonical feature `c` (NaN stays NaN).
    #[inline]
    pub fn standardise(&self, c: usize, raw: f64) -> f64 {
        let std = self.std[c];
        if std.abs() < MIN_STD {
            raw - self.mean[c]
        } else {
            (raw - self.mean[c]) / std
        }
    }

    /// Standardises and fills a whole canonical row, then rounds to f32 as xgboost does.
    #[inline]
    pub fn apply(&self, raw: &[f64; FEATURE_COUNT], out: &mut [f32; FEATURE_COUNT]) {
        for c in 0..FEATURE_COUNT {
            let z = self.standardise(c, raw[c]);
            let z = if z.is_nan() { self.nan_fill[c] } else { z };
            out[c] = z as f32;
        }
    }

    /// The block to store in a model whose columns are `model_features` (canonical indices).
    pub fn to_block(&self, model_features: &[usize]) -> PreprocessingBlock {
        PreprocessingBlock {
            format: PREPROCESSING_FORMAT.to_string(),
            features: model_features
                .iter()
                .map(|&c| model_feature_name(c))
                .collect(),
            mean: model_features.iter().map(|&c| self.mean[c]).collect(),
            std: model_features.iter().map(|&c| self.std[c]).collect(),
            nan_fill: model_features
                .iter()
                .map(|&c| Some(self.nan_fill[c]).filter(|v| v.is_finite()))
                .collect(),
        }
    }

    /// Resolves a block by feature name; all 32 features must be present exactly once.
    pub fn from_block(block: &PreprocessingBlock) -> Result<Preprocessing, PreprocessingError> {
        if block.format != PREPROCESSING_FORMAT {
            return Err(PreprocessingError::Format(block.format.clone()));
        }
        let n = block.features.len();
        for (field, got) in [
            ("mean", block.mean.len()),
            ("std", block.std.len()),
            ("nan_fill", block.nan_fill.len()),
        ] {
            if got != n {
                return Err(PreprocessingError::Length {
                    field,
                    got,
                    expected: n,
                });
            }
        }
        let mut out = Preprocessing::IDENTITY;
        let mut seen = [false; FEATURE_COUNT];
        for (i, name) in block.features.iter().enumerate() {
            let c = canonical_index(name)
                .ok_or_else(|| PreprocessingError::UnknownFeature(name.clone()))?;
            if std::mem::replace(&mut seen[c], true) {
                return Err(PreprocessingError::DuplicateFeature(name.clone()));
            }
            for (field, v) in [("mean", block.mean[i]), ("std", block.std[i])] {
                if !v.is_finite() {
                    return Err(PreprocessingError::NotFinite {
                        field,
                        feature: name.clone(),
                    });
                }
            }
            out.mean[c] = block.mean[i];
            out.std[c] = block.std[i];
            out.nan_fill[c] = block.nan_fill[i].unwrap_or(f64::NAN);
        }
        if let Some(c) = seen.iter().position(|s| !s) {
            return Err(PreprocessingError::MissingFeature(model_feature_name(c)));
        }
        Ok(out)
    }
}

/// The authors fill NaN after standardising with the column maximum for the columns whose
/// names start with one of these prefixes, and with the minimum otherwise. Their list spells
/// `of_pose_Rxv`, so `of_pose_Rx` is filled with the minimum; we follow their code.
const NAN_FILL_WITH_MAX_PREFIXES: [&str; 13] = [
    "of_gaze_0_x",
    "of_gaze_0_y",
    "of_gaze_0_z",
    "of_gaze_1_x",
    "of_gaze_1_y",
    "of_gaze_1_z",
    "of_gaze_angle_x",
    "of_gaze_angle_y",
    "of_pose_Ry",
    "of_pose_Rz",
    "of_pose_Tx",
    "of_pose_Ty",
    "of_pose_Tz",
];

/// Whether the authors' rule fills missing values of canonical feature `index` with the
/// standardised column maximum (else the minimum).
pub fn nan_fill_uses_max(index: usize) -> bool {
    let name = model_feature_name(index);
    NAN_FILL_WITH_MAX_PREFIXES
        .iter()
        .any(|p| name.starts_with(p))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::{AUTHORS_FEATURE_ORDER, canonical_index};

    fn rows() -> Vec<[f64; FEATURE_COUNT]> {
        (0..5)
            .map(|i| {
                let mut r = [1.0; FEATURE_COUNT];
                r[0] = i as f64; // pose_Tx: 0..4
                r[30] = if i == 2 { f64::NAN } else { -(i as f64) }; // gaze_angle_x
                r
            })
            .collect()
    }

    #[test]
    fn fit_matches_numpy_nanmean_nanstd_and_the_fill_rule() {
        let p = Preprocessing::fit(&rows());
        assert_eq!(p.mean[0], 2.0);
        assert!((p.std[0] - 2f64.sqrt()).abs() < 1e-15);
        // constant AU column: std 0, only centred; fill = min of the standardised column
        assert_eq!(p.std[6], 0.0);
        assert_eq!(p.standardise(6, 1.0), 0.0);
        assert_eq!(p.nan_fill[6], 0.0);
        // gaze_angle_x ignores the NaN and fills with the standardised maximum
        let vals = [0.0, -1.0, -3.0, -4.0];
        let mean = vals.iter().sum::<f64>() / 4.0;
        assert_eq!(p.mean[30], mean);
        assert_eq!(p.nan_fill[30], p.standardise(30, 0.0));
        let mut out = [0f32; FEATURE_COUNT];
        p.apply(&rows()[2], &mut out);
        assert_eq!(out[30], p.nan_fill[30] as f32);
    }

    #[test]
    fn block_round_trips_through_json_in_any_column_order() {
        let p = Preprocessing::fit(&rows());
        let block = p.to_block(&AUTHORS_FEATURE_ORDER);
        let text = serde_json::to_string(&block).expect("serialises");
        let back: PreprocessingBlock = serde_json::from_str(&text).expect("parses");
        let q = Preprocessing::from_block(&back).expect("valid");
        assert_eq!(p.mean, q.mean);
        assert_eq!(p.std, q.std);
        assert_eq!(block.features[0], "of_AU01_c");
        assert_eq!(canonical_index(&block.features[26]), Some(0));
    }

    #[test]
    fn bad_blocks_name_the_problem() {
        let mut block = Preprocessing::fit(&rows()).to_block(&AUTHORS_FEATURE_ORDER);
        block.features[3] = "of_AU99_c".into();
        let err = Preprocessing::from_block(&block).expect_err("refused");
        assert!(err.to_string().contains("of_AU99_c"), "{err}");
        block.features[3] = block.features[4].clone();
        let err = Preprocessing::from_block(&block).expect_err("refused");
        assert!(
            matches!(err, PreprocessingError::DuplicateFeature(_)),
            "{err}"
        );
        block.features.pop();
        let err = Preprocessing::from_block(&block).expect_err("refused");
        assert!(err.to_string().contains("31 features"), "{err}");
    }

    #[test]
    fn nan_fill_rule_follows_the_authors_list() {
        let idx = |n: &str| canonical_index(n).expect("known");
        assert!(nan_fill_uses_max(idx("gaze_angle_y")));
        assert!(nan_fill_uses_max(idx("pose_Tz")));
        assert!(
            !nan_fill_uses_max(idx("pose_Rx")),
            "their list says of_pose_Rxv"
        );
        assert!(!nan_fill_uses_max(idx("AU45_c")));
        assert!(
            crate::features::is_continuous(idx("pose_Rx"))
                && !crate::features::is_continuous(idx("AU01_c"))
        );
    }
}
