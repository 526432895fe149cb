//! QTrobot's speech, emotion and gesture services as the game manager calls them with
//! `robot_backend: qtrobot`, mirrored from `interfaces/qt_robot_interface/srv/` (the ROS 2 side
//! of QTrobot's ROS 1 `qt_robot_interface` and `qt_gesture_controller` services, which
//! ros1_bridge connects with that package's mapping rules). Each call returns when the robot has
//! finished.

use crate::definition::ros_message;
use crate::services::{ServiceDefinition, ros_service, srv_half};

const PKG: &str = "qt_robot_interface";

ros_message! {
    pub struct SpeechSayRequest(PKG, "SpeechSay_Request", srv_half(include_str!("../../interfaces/qt_robot_interface/srv/SpeechSay.srv"), 0)) {
        pub message: String,
    }
}

ros_message! {
    pub struct SpeechSayResponse(PKG, "SpeechSay_Response", srv_half(include_str!("../../interfaces/qt_robot_interface/srv/SpeechSay.srv"), 1)) {
        pub status: bool,
    }
}

ros_service! {
    /// Says a text; returns when the robot has finished speaking.
    pub struct SpeechSay("SpeechSay", "../../interfaces/qt_robot_interface/srv/SpeechSay.srv", SpeechSayRequest, SpeechSayResponse)
}

ros_message! {
    /// Empty in the `.srv`; ROS 2 gives an empty message this one byte on the wire.
    pub struct SpeechStopRequest(PKG, "SpeechStop_Request", srv_half(include_str!("../../interfaces/qt_robot_interface/srv/SpeechStop.srv"), 0)) {
        pub structure_needs_at_least_one_member: u8,
    }
}

ros_message! {
    pub struct SpeechStopResponse(PKG, "SpeechStop_Response", srv_half(include_str!("../../interfaces/qt_robot_interface/srv/SpeechStop.srv"), 1)) {
        pub status: bool,
    }
}

ros_service! {
    /// Stops speaking at once (the emergency stop).
    pub struct SpeechStop("SpeechStop", "../../interfaces/qt_robot_interface/srv/SpeechStop.srv", SpeechStopRequest, SpeechStopResponse)
}

ros_message! {
    pub struct EmotionShowRequest(PKG, "EmotionShow_Request", srv_half(include_str!("../../interfaces/qt_robot_interface/srv/EmotionShow.srv"), 0)) {
        pub name: String,
    }
}

ros_message! {
    pub struct EmotionShowResponse(PKG, "EmotionShow_Response", srv_half(include_str!("../../interfaces/qt_robot_interface/srv/EmotionShow.srv"), 1)) {
        pub status: bool,
    }
}

ros_service! {
    /// Shows an emotion animation on the face; returns when it has played.
    pub struct EmotionShow("EmotionShow", "../../interfaces/qt_robot_interface/srv/EmotionShow.srv", EmotionShowRequest, EmotionShowResponse)
}

ros_message! {
    pub struct GesturePlayRequest(PKG, "GesturePlay_Request", srv_half(include_str!("../../interfaces/qt_robot_interface/srv/GesturePlay.srv"), 0)) {
        pub name: String,
        pub speed: f32,
    }
}

ros_message! {
    pub struct GesturePlayResponse(PKG, "GesturePlay_Response", srv_half(include_str!("../../interfaces/qt_robot_interface/srv/GesturePlay.srv"), 1)) {
        pub status: bool,
    }
}

ros_service! {
    /// Plays a recorded gesture; returns when it has played.
    pub struct GesturePlay("GesturePlay", "../../interfaces/qt_robot_interface/srv/GesturePlay.srv", GesturePlayRequest, GesturePlayResponse)
}

/// QTrobot's service names (its ROS 1 names, bridged one to one).
pub const SPEECH_SAY: crate::topics::Service<SpeechSay> =
    crate::topics::Service::new("/qt_robot/speech/say");
pub const SPEECH_STOP: crate::topics::Service<SpeechStop> =
    crate::topics::Service::new("/qt_robot/speech/stop");
pub const EMOTION_SHOW: crate::topics::Service<EmotionShow> =
    crate::topics::Service::new("/qt_robot/emotion/show");
pub const GESTURE_PLAY: crate::topics::Service<GesturePlay> =
    crate::topics::Service::new("/qt_robot/gesture/play");
