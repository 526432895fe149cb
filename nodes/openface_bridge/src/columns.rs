//! OpenFace's CSV header mapped onto what the bridge reads: the five per-row columns (frame,
//! face_id, timestamp, confidence, success) and the 32 features of `OpenFaceFeatures.msg`, by
//! name, never by position. OpenFace 2.2 writes `frame, face_id, ...` (a space after each
//! comma), later builds `frame,face_id,...`; the study data prefixes every name with `of_`.
//! Extra columns (landmarks, AU intensities) are ignored.

use openface::features::{FEATURE_COUNT, OPENFACE_FEATURES, canonical_index};

/// The per-row columns the bridge needs besides the features.
pub const ROW_COLUMNS: [&str; 5] = ["frame", "face_id", "timestamp", "confidence", "success"];

/// A header the bridge cannot read rows with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HeaderError {
    #[error(
        "the OpenFace CSV has no column {0:?} (run FeatureExtraction with -pose -aus -gaze, or without output selectors)"
    )]
    Missing(String),
    #[error("the OpenFace CSV names column {0:?} twice")]
    Duplicate(String),
}

/// Where each needed value is in a row.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnMap {
    /// Fields in a row.
    pub width: usize,
    /// Field index of frame, face_id, timestamp, confidence, success.
    pub row: [usize; 5],
    /// Field index of each feature, in the message's order.
    pub features: [usize; FEATURE_COUNT],
}

/// The name of a column without OpenFace's spaces or the study's `of_` prefix.
fn bare(name: &str) -> &str {
    let name = name.trim();
    name.strip_prefix("of_").unwrap_or(name)
}

/// Whether `line` is a header (its first field is `frame`), not a row.
pub fn is_header(line: &str) -> bool {
    line.split(',').next().is_some_and(|f| bare(f) == "frame")
}

impl ColumnMap {
    pub fn from_header(line: &str) -> Result<ColumnMap, HeaderError> {
        let names: Vec<&str> = line.split(',').map(bare).collect();
        let find = |wanted: &str| -> Result<usize, HeaderError> {
            let mut at = names.iter().enumerate().filter(|(_, n)| **n == wanted);
            match (at.next(), at.next()) {
                (Some((i, _)), None) => Ok(i),
                (Some(_), Some(_)) => Err(HeaderError::Duplicate(wanted.to_string())),
                (None, _) => Err(HeaderError::Missing(wanted.to_string())),
            }
        };
        let mut row = [0; 5];
        for (slot, name) in row.iter_mut().zip(ROW_COLUMNS) {
            *slot = find(name)?;
        }
        let mut features = [0; FEATURE_COUNT];
        for (k, name) in OPENFACE_FEATURES.iter().enumerate() {
            debug_assert_eq!(canonical_index(name), Some(k));
            features[k] = find(name)?;
        }
        Ok(ColumnMap {
            width: names.len(),
            row,
            features,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_csv::header;

    #[test]
    fn columns_are_found_by_name_in_either_spelling() {
        let spaced = ColumnMap::from_header(&header()).expect("maps");
        let tight = ColumnMap::from_header(&header().replace(", ", ",")).expect("maps");
        assert_eq!(spaced, tight);
        let prefixed: String = header()
            .split(", ")
            .map(|n| format!("of_{n}"))
            .collect::<Vec<_>>()
            .join(",");
        assert_eq!(ColumnMap::from_header(&prefixed).expect("maps"), spaced);
        assert_eq!(spaced.row, [0, 1, 2, 3, 4]);
        // pose_Tx is feature 0 and comes after the 8 gaze values and 5 x 56 eye landmarks.
        assert_eq!(spaced.features[0], 5 + 8 + 5 * 56);
        assert!(is_header(&header()) && !is_header("1, 0, 0.033, 0.98, 1"));
    }

    #[test]
    fn a_missing_or_doubled_column_is_named() {
        let no_gaze = header().replace("gaze_angle_y, ", "");
        assert_eq!(
            ColumnMap::from_header(&no_gaze),
            Err(HeaderError::Missing("gaze_angle_y".into()))
        );
        let no_confidence = header().replace("confidence, ", "");
        assert_eq!(
            ColumnMap::from_header(&no_confidence),
            Err(HeaderError::Missing("confidence".into()))
        );
        let twice = format!("{}, AU45_c", header());
        assert_eq!(
            ColumnMap::from_header(&twice),
            Err(HeaderError::Duplicate("AU45_c".into()))
        );
    }
}
