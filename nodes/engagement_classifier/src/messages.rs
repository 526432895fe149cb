//! The node's messages to and from the core: an `OpenFaceFeatures` frame becomes a `FaceFrame`
//! of a numbered source ("<camera>/<face>"), and a closed second becomes the
//! `ExpectedEngagement` the node publishes. The DDS node and the bag replays share it, so a
//! replay checks the node's own conversion.

use crate::{EngagementSecond, FaceFrame, SourceId};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{ExpectedEngagement, OpenFaceFeatures};
use std::collections::HashMap;

/// The source name of a frame: its camera (header frame id) and OpenFace face id.
pub fn source_name(frame: &OpenFaceFeatures) -> String {
    format!("{}/{}", frame.header.frame_id, frame.face_id)
}

/// Maps "<camera>/<face>" to the estimator's numeric source ids and back.
#[derive(Debug, Default)]
pub struct Sources {
    ids: HashMap<String, SourceId>,
    names: Vec<String>,
}

impl Sources {
    /// The id of the frame's source, numbering new sources in the order they appear.
    pub fn id(&mut self, frame: &OpenFaceFeatures) -> SourceId {
        let name = source_name(frame);
        if let Some(id) = self.ids.get(&name) {
            return *id;
        }
        let id = self.names.len() as SourceId;
        self.names.push(name.clone());
        self.ids.insert(name, id);
        id
    }

    /// The name of a source id ("?" for one never given out).
    pub fn name(&self, id: SourceId) -> &str {
        self.names.get(id as usize).map_or("?", String::as_str)
    }

    /// The frame as the estimator takes it.
    pub fn face_frame<'a>(&mut self, frame: &'a OpenFaceFeatures) -> FaceFrame<'a> {
        FaceFrame {
            stamp_ns: frame.header.stamp.to_nanos(),
            source: self.id(frame),
            detection_success: frame.success,
            confidence: frame.confidence,
            features: &frame.features,
        }
    }

    /// The `ExpectedEngagement` the node publishes for a closed second.
    pub fn expected_engagement(&self, second: &EngagementSecond) -> ExpectedEngagement {
        ExpectedEngagement {
            header: Header::at(Time::from_nanos(second.window_end_ns)),
            source: self.name(second.source).to_string(),
            window_start: Time::from_nanos(second.window_start_ns),
            window_end: Time::from_nanos(second.window_end_ns),
            has_faces: second.engagement.is_some(),
            mean: second.engagement.unwrap_or(0.0) as f32,
            smoothed: second.smoothed_engagement.unwrap_or(0.0) as f32,
            frame_count: second.frame_count(),
            missing_count: second.missing_frames,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sources_are_numbered_in_order_of_appearance_and_named_back() {
        let frame = |camera: &str, face: &str| OpenFaceFeatures {
            header: Header {
                frame_id: camera.into(),
                ..Default::default()
            },
            face_id: face.into(),
            ..Default::default()
        };
        let mut s = Sources::default();
        assert_eq!(s.id(&frame("cam", "0")), 0);
        assert_eq!(s.id(&frame("cam", "1")), 1);
        assert_eq!(s.id(&frame("cam", "0")), 0);
        assert_eq!(s.name(1), "cam/1");
        assert_eq!(s.name(7), "?");
    }
}
