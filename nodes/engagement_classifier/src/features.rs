//! The 32 OpenFace features the engagement classifier reads, in the canonical order of our
//! messages, and the mapping from a model's `feature_names` (the authors' `of_<name>`) onto it.
//! Models are matched by name, never by position.

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
        assert!(is_continuous(idx("pose_Rx")) && !is_continuous(idx("AU01_c")));
    }
}
