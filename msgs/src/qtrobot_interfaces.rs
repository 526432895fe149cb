//! QTrobot V3's speech, face and gesture services over ROS 2 (LuxAI's gateway, package
//! `qtrobot_interfaces`), as the game manager calls them with `robot_backend: qtrobot_ros2`,
//! mirrored from `interfaces/qtrobot_interfaces/srv/`. Each call returns when the robot has
//! finished; `status` says the call reached the robot, `result` what the robot answered.

use crate::definition::ros_message;
use crate::services::{ServiceDefinition, ros_service, srv_half};

const PKG: &str = "qtrobot_interfaces";

ros_message! {
    pub struct TtsEngineSayTextRequest(PKG, "TtsEngineSayText_Request", srv_half(include_str!("../../interfaces/qtrobot_interfaces/srv/TtsEngineSayText.srv"), 0)) {
        pub text: String,
        pub engine: String,
        pub lang: String,
        pub pitch: f32,
        pub rate: f32,
        pub style: String,
        pub voice: String,
        pub volume: f32,
    }
}

ros_message! {
    pub struct TtsEngineSayTextResponse(PKG, "TtsEngineSayText_Response", srv_half(include_str!("../../interfaces/qtrobot_interfaces/srv/TtsEngineSayText.srv"), 1)) {
        pub status: bool,
        pub result: bool,
    }
}

ros_service! {
    /// Says a text with the default engine; returns when the robot has finished speaking.
    pub struct TtsEngineSayText("TtsEngineSayText", "../../interfaces/qtrobot_interfaces/srv/TtsEngineSayText.srv", TtsEngineSayTextRequest, TtsEngineSayTextResponse)
}

ros_message! {
    pub struct FaceEmotionShowRequest(PKG, "FaceEmotionShow_Request", srv_half(include_str!("../../interfaces/qtrobot_interfaces/srv/FaceEmotionShow.srv"), 0)) {
        pub emotion: String,
        pub speed: f32,
    }
}

ros_message! {
    pub struct FaceEmotionShowResponse(PKG, "FaceEmotionShow_Response", srv_half(include_str!("../../interfaces/qtrobot_interfaces/srv/FaceEmotionShow.srv"), 1)) {
        pub status: bool,
        pub result: bool,
    }
}

ros_service! {
    /// Shows an emotion on the face; returns when it has played.
    pub struct FaceEmotionShow("FaceEmotionShow", "../../interfaces/qtrobot_interfaces/srv/FaceEmotionShow.srv", FaceEmotionShowRequest, FaceEmotionShowResponse)
}

ros_message! {
    pub struct GestureFilePlayRequest(PKG, "GestureFilePlay_Request", srv_half(include_str!("../../interfaces/qtrobot_interfaces/srv/GestureFilePlay.srv"), 0)) {
        pub gesture: String,
        pub speed_factor: f32,
    }
}

ros_message! {
    pub struct GestureFilePlayResponse(PKG, "GestureFilePlay_Response", srv_half(include_str!("../../interfaces/qtrobot_interfaces/srv/GestureFilePlay.srv"), 1)) {
        pub status: bool,
        pub result: bool,
    }
}

ros_service! {
    /// Plays a recorded gesture; returns when it has played.
    pub struct GestureFilePlay("GestureFilePlay", "../../interfaces/qtrobot_interfaces/srv/GestureFilePlay.srv", GestureFilePlayRequest, GestureFilePlayResponse)
}

ros_message! {
    pub struct TtsEngineCancelRequest(PKG, "TtsEngineCancel_Request", srv_half(include_str!("../../interfaces/qtrobot_interfaces/srv/TtsEngineCancel.srv"), 0)) {
        pub engine: String,
    }
}

ros_message! {
    pub struct TtsEngineCancelResponse(PKG, "TtsEngineCancel_Response", srv_half(include_str!("../../interfaces/qtrobot_interfaces/srv/TtsEngineCancel.srv"), 1)) {
        pub status: bool,
        pub result: bool,
    }
}

ros_service! {
    /// Stops the speech under way (the emergency stop's silence).
    pub struct TtsEngineCancel("TtsEngineCancel", "../../interfaces/qtrobot_interfaces/srv/TtsEngineCancel.srv", TtsEngineCancelRequest, TtsEngineCancelResponse)
}

/// The gateway's service names.
pub const SAY_TEXT: crate::topics::Service<TtsEngineSayText> =
    crate::topics::Service::new("/qtrobot/tts/engine/say/text");
pub const TTS_CANCEL: crate::topics::Service<TtsEngineCancel> =
    crate::topics::Service::new("/qtrobot/tts/engine/cancel");
pub const EMOTION_SHOW: crate::topics::Service<FaceEmotionShow> =
    crate::topics::Service::new("/qtrobot/face/emotion/show");
pub const GESTURE_FILE_PLAY: crate::topics::Service<GestureFilePlay> =
    crate::topics::Service::new("/qtrobot/gesture/file/play");
