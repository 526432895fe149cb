//! The bridge's parameters (`params/openface_bridge.yaml`) and their checks.

use node_shell::parameters::DescribedParameters;
use serde::{Deserialize, Serialize};

/// Where a frame's stamp comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StampSource {
    /// OpenFace's own `timestamp` (seconds since its capture started) on the wall clock (the
    /// run's smallest lag from OpenFace's clock to the read): frames keep their spacing
    /// whatever the file's delays, and no stamp is ahead of the clock.
    OpenFace,
    /// The wall clock when the bridge read the row.
    Receipt,
}

/// The OpenFace bridge node's parameters.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, DescribedParameters)]
#[serde(deny_unknown_fields, default)]
pub struct OpenFaceBridgeParams {
    /// The CSV OpenFace writes (`-out_dir DIR -of NAME` gives `DIR/NAME.csv`), or `-` for
    /// standard input.
    pub csv_path: String,
    /// The camera's frame id, put in every message's header.
    pub frame_id: String,
    /// `openface` or `receipt` (see [`StampSource`]).
    pub stamp: String,
    /// Rows whose OpenFace confidence is below this are skipped (counted).
    pub min_confidence: f64,
    /// How often the file is checked for new rows, in seconds.
    pub poll_interval_s: f64,
    /// Of the rows a file already holds when the bridge finds it (a run going on: the bridge
    /// was restarted), only those within this many seconds of the newest are published.
    pub max_backlog_s: f64,
    /// 0: follow OpenFace live. Above 0: the CSV (or standard input) is a finished recording,
    /// published on OpenFace's own clock at this multiple of it; the bridge ends at its end.
    pub replay_rate: f64,
    /// The most messages a second the bridge publishes; a burst (a backlog, a stall, a
    /// fast replay) is spread out so a best-effort reader's queue (keep last 10) keeps up.
    pub max_publish_hz: f64,
    /// Longest line accepted, in bytes; a longer one is a bad row.
    pub max_line_bytes: usize,
    /// How often the counts are logged while rows flow, in seconds (0: never).
    pub report_interval_s: f64,
}

impl Default for OpenFaceBridgeParams {
    fn default() -> Self {
        OpenFaceBridgeParams {
            csv_path: String::new(),
            frame_id: "camera".into(),
            stamp: "openface".into(),
            min_confidence: 0.0,
            poll_interval_s: 0.02,
            max_backlog_s: 1.0,
            replay_rate: 0.0,
            max_publish_hz: 300.0,
            max_line_bytes: 65_536,
            report_interval_s: 60.0,
        }
    }
}

/// A parameter value the bridge cannot run with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("openface_bridge parameter {key}: {reason}")]
pub struct ParamError {
    pub key: &'static str,
    pub reason: String,
}

impl OpenFaceBridgeParams {
    /// Checks every value; returns where stamps come from.
    pub fn validate(&self) -> Result<StampSource, ParamError> {
        let bad = |key, reason: String| Err(ParamError { key, reason });
        if self.csv_path.trim().is_empty() {
            return bad(
                "csv_path",
                "is empty: give OpenFace's CSV (--csv PATH) or - for standard input".into(),
            );
        }
        if self.frame_id.is_empty() || self.frame_id.chars().any(char::is_control) {
            return bad("frame_id", format!("{:?} is not a frame id", self.frame_id));
        }
        if !(self.min_confidence.is_finite() && (0.0..=1.0).contains(&self.min_confidence)) {
            return bad(
                "min_confidence",
                format!("{} is not in [0, 1]", self.min_confidence),
            );
        }
        if !(self.poll_interval_s.is_finite() && (0.001..=10.0).contains(&self.poll_interval_s)) {
            return bad(
                "poll_interval_s",
                format!("{} is not in [0.001, 10] s", self.poll_interval_s),
            );
        }
        if !(self.max_backlog_s.is_finite() && self.max_backlog_s >= 0.0) {
            return bad(
                "max_backlog_s",
                format!("{} is not a number of seconds", self.max_backlog_s),
            );
        }
        if !(self.replay_rate.is_finite() && (0.0..=1000.0).contains(&self.replay_rate)) {
            return bad(
                "replay_rate",
                format!(
                    "{} is not in [0, 1000] (0: follow live; 1: a recording in real time)",
                    self.replay_rate
                ),
            );
        }
        if !(self.max_publish_hz.is_finite() && (1.0..=100_000.0).contains(&self.max_publish_hz)) {
            return bad(
                "max_publish_hz",
                format!("{} is not in [1, 100000] messages/s", self.max_publish_hz),
            );
        }
        if !(1024..=16 << 20).contains(&self.max_line_bytes) {
            return bad(
                "max_line_bytes",
                format!("{} is not in 1024..=16777216", self.max_line_bytes),
            );
        }
        if !(self.report_interval_s.is_finite() && self.report_interval_s >= 0.0) {
            return bad(
                "report_interval_s",
                format!("{} is not a number of seconds", self.report_interval_s),
            );
        }
        match self.stamp.as_str() {
            "openface" => Ok(StampSource::OpenFace),
            "receipt" => Ok(StampSource::Receipt),
            other => bad("stamp", format!("{other:?} is not openface or receipt")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_file_holds_the_defaults_but_the_path() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../params/openface_bridge.yaml");
        let p: OpenFaceBridgeParams =
            node_shell::params::load_parameters(&path, "openface_bridge").expect("loads");
        assert_eq!(p, OpenFaceBridgeParams::default());
        assert!(
            p.validate().is_err(),
            "no CSV given: the node refuses to start"
        );
    }

    #[test]
    fn bad_values_are_named() {
        let good = OpenFaceBridgeParams {
            csv_path: "-".into(),
            ..Default::default()
        };
        assert_eq!(good.validate(), Ok(StampSource::OpenFace));
        let cases = [
            (
                "stamp",
                OpenFaceBridgeParams {
                    stamp: "camera".into(),
                    ..good.clone()
                },
            ),
            (
                "min_confidence",
                OpenFaceBridgeParams {
                    min_confidence: 1.5,
                    ..good.clone()
                },
            ),
            (
                "poll_interval_s",
                OpenFaceBridgeParams {
                    poll_interval_s: 0.0,
                    ..good.clone()
                },
            ),
            (
                "frame_id",
                OpenFaceBridgeParams {
                    frame_id: String::new(),
                    ..good.clone()
                },
            ),
            (
                "replay_rate",
                OpenFaceBridgeParams {
                    replay_rate: -1.0,
                    ..good.clone()
                },
            ),
            (
                "max_publish_hz",
                OpenFaceBridgeParams {
                    max_publish_hz: 0.0,
                    ..good.clone()
                },
            ),
            (
                "max_backlog_s",
                OpenFaceBridgeParams {
                    max_backlog_s: f64::NAN,
                    ..good.clone()
                },
            ),
            (
                "max_line_bytes",
                OpenFaceBridgeParams {
                    max_line_bytes: 10,
                    ..good.clone()
                },
            ),
        ];
        for (key, p) in cases {
            assert_eq!(p.validate().map_err(|e| e.key), Err(key));
        }
    }
}
