//! OpenFace CSV text for the unit tests: OpenFace 2.2's header with -pose -aus -gaze (the eye
//! landmarks included, so rows are as wide as the real ones) and rows to match.

use crate::columns::ROW_COLUMNS;

const AUS_R: [&str; 17] = [
    "01", "02", "04", "05", "06", "07", "09", "10", "12", "14", "15", "17", "20", "23", "25", "26",
    "45",
];
const AUS_C: [&str; 18] = [
    "01", "02", "04", "05", "06", "07", "09", "10", "12", "14", "15", "17", "20", "23", "25", "26",
    "28", "45",
];

fn names() -> Vec<String> {
    let mut names: Vec<String> = ROW_COLUMNS.iter().map(|s| s.to_string()).collect();
    for eye in 0..2 {
        for axis in ["x", "y", "z"] {
            names.push(format!("gaze_{eye}_{axis}"));
        }
    }
    names.extend(["gaze_angle_x", "gaze_angle_y"].map(String::from));
    for axis in ["x", "y", "X", "Y", "Z"] {
        names.extend((0..56).map(|i| format!("eye_lmk_{axis}_{i}")));
    }
    names.extend(
        [
            "pose_Tx", "pose_Ty", "pose_Tz", "pose_Rx", "pose_Ry", "pose_Rz",
        ]
        .map(String::from),
    );
    names.extend(AUS_R.iter().map(|au| format!("AU{au}_r")));
    names.extend(AUS_C.iter().map(|au| format!("AU{au}_c")));
    names
}

/// The header, ", "-separated as OpenFace 2.2 writes it.
pub fn header() -> String {
    names().join(", ")
}

/// A row: `frame`, face 0, its timestamp, confidence, success, and feature values that tell
/// rows apart (every value is `frame / 1000`, the AU flags 1).
pub fn row(frame: u32, timestamp: f64, confidence: f64, success: bool) -> String {
    let names = names();
    let mut fields = vec![
        frame.to_string(),
        "0".to_string(),
        format!("{timestamp:.3}"),
        format!("{confidence:.2}"),
        if success { "1" } else { "0" }.to_string(),
    ];
    for name in &names[5..] {
        fields.push(if name.ends_with("_c") {
            "1.00".to_string()
        } else {
            format!("{:.3}", f64::from(frame) / 1000.0)
        });
    }
    fields.join(", ")
}
