//! The 32 OpenFace features the suite reads, in the canonical order of our messages, and the
//! mapping from a model's or a CSV's column names (OpenFace's own, or the authors' `of_<name>`)
//! onto it. Columns are matched by name, never by position.

/// Number of features the classifier takes (paper: E: R^32 -> {-1, 1}).
pub const FEATURE_COUNT: usize = 32;

/// Canonical feature order of `OpenFaceFeatures.msg` (head pose 6, action-unit presence 18,
/// gaze 8): the message package's own list, so the two cannot differ.
pub const OPENFACE_FEATURES: [&str; FEATURE_COUNT] = qt_therapy_msgs::OPENFACE_FEATURES;

/// Prefix the authors' data and models put before each OpenFace name.
pub const MODEL_NAME_PREFIX: &str = "of_";

/// The authors' column order (their CSVs and their model): AUs, gaze, pose. We write our own
/// CSVs and models in this order so they line up with theirs column for column.
pub const AUTHORS_FEATURE_ORDER: [usize; FEATURE_COUNT] = [
    6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, // AUs
    24, 25, 26, 27, 28, 29, 30, 31, // gaze
    0, 1, 2, 3, 4, 5, // pose
];

/// Canonical index of a feature named either `of_<name>` (model/CSV style) or `<name>`.
pub fn canonical_index(name: &str) -> Option<usize> {
    let bare = name.trim();
    let bare = bare.strip_prefix(MODEL_NAME_PREFIX).unwrap_or(bare);
    OPENFACE_FEATURES.iter().position(|f| *f == bare)
}

/// The name a model or CSV column uses for canonical feature `index` (`of_<name>`).
pub fn model_feature_name(index: usize) -> String {
    format!("{MODEL_NAME_PREFIX}{}", OPENFACE_FEATURES[index])
}

/// True for the continuous columns (pose and gaze); the action units are 0/1 presence flags.
pub fn is_continuous(index: usize) -> bool {
    !(6..24).contains(&index)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_map_both_ways() {
        for (i, name) in OPENFACE_FEATURES.iter().enumerate() {
            assert_eq!(canonical_index(name), Some(i));
            assert_eq!(canonical_index(&model_feature_name(i)), Some(i));
        }
        assert_eq!(canonical_index("of_confidence"), None);
        assert_eq!(canonical_index("of_of_AU01_c"), None);
    }

    #[test]
    fn authors_order_is_a_permutation_starting_with_au01() {
        let mut seen = [false; FEATURE_COUNT];
        for &i in &AUTHORS_FEATURE_ORDER {
            assert!(!seen[i]);
            seen[i] = true;
        }
        assert_eq!(model_feature_name(AUTHORS_FEATURE_ORDER[0]), "of_AU01_c");
        assert_eq!(model_feature_name(AUTHORS_FEATURE_ORDER[31]), "of_pose_Rz");
    }
}
