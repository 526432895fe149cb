//! The suite's own messages, one Rust struct per `msg/*.msg` file, field for field.

use crate::definition::ros_message;
use crate::standard::builtin_interfaces::Time;
use crate::standard::std_msgs::Header;

const PKG: &str = "qt_therapy_msgs";

ros_message! {
    /// The MDP state s = (L, F, PS); (0, 0, 0) is the session start.
    pub struct BehaviourState(PKG, "BehaviourState", include_str!("../msg/BehaviourState.msg")) {
        pub level: u8,
        pub feedback: u8,
        pub previous_score: i8,
    }
}

ros_message! {
    /// One frame's face: 32 OpenFace features in [`crate::OPENFACE_FEATURES`] order.
    pub struct OpenFaceFeatures(PKG, "OpenFaceFeatures", include_str!("../msg/OpenFaceFeatures.msg")) {
        pub header: Header,
        pub face_id: String,
        pub confidence: f32,
        pub success: bool,
        pub features: Vec<f32>,
    }
    constants {
        FEATURE_COUNT: u8 = 32,
    }
}

ros_message! {
    /// The classifier's label for one frame.
    pub struct EngagementEstimate(PKG, "EngagementEstimate", include_str!("../msg/EngagementEstimate.msg")) {
        pub header: Header,
        pub face_id: String,
        pub label: i8,
        pub probability: f32,
    }
    constants {
        ENGAGED: i8 = 1,
        DISENGAGED: i8 = -1,
        MISSING: i8 = 0,
    }
}

ros_message! {
    /// Expected engagement over one second.
    pub struct ExpectedEngagement(PKG, "ExpectedEngagement", include_str!("../msg/ExpectedEngagement.msg")) {
        pub header: Header,
        pub source: String,
        pub window_start: Time,
        pub window_end: Time,
        pub has_faces: bool,
        pub mean: f32,
        pub smoothed: f32,
        pub frame_count: u32,
        pub missing_count: u32,
    }
}

ros_message! {
    /// A therapist tablet command.
    pub struct TherapistCommand(PKG, "TherapistCommand", include_str!("../msg/TherapistCommand.msg")) {
        pub header: Header,
        pub command: u8,
        pub session_id: String,
        pub command_id: u64,
        pub user_id: String,
        pub user_model_cluster: i32,
        pub level: u8,
    }
    constants {
        START: u8 = 0,
        PAUSE: u8 = 1,
        RESUME: u8 = 2,
        STOP: u8 = 3,
        OVERRIDE_LEVEL: u8 = 4,
        EMERGENCY_STOP: u8 = 5,
        OVERRIDE_ENCOURAGING: u8 = 6,
        OVERRIDE_CHALLENGING: u8 = 7,
        ACCEPT_PROPOSAL: u8 = 8,
    }
}

ros_message! {
    /// Where the game is.
    pub struct GameState(PKG, "GameState", include_str!("../msg/GameState.msg")) {
        pub header: Header,
        pub phase: u8,
        pub session_id: String,
        pub user_id: String,
        pub user_model_cluster: i32,
        pub sequence_index: u8,
        pub level: u8,
        pub feedback: u8,
        pub last_score: i8,
        pub policy_fallback: bool,
        pub status: String,
        pub sequences_planned: u8,
        pub command_session_id: String,
        pub command_id: u64,
        pub command_outcome: u8,
        pub command_refusal: String,
    }
    constants {
        IDLE: u8 = 0,
        DECIDING: u8 = 1,
        GIVING_FEEDBACK: u8 = 2,
        SAYING_SEQUENCE: u8 = 3,
        WAITING_FOR_ANSWER: u8 = 4,
        PAUSED: u8 = 5,
        FINISHED: u8 = 6,
        STOPPED: u8 = 7,
        EMERGENCY_STOPPED: u8 = 8,
        COMMAND_NONE: u8 = 0,
        COMMAND_CARRIED_OUT: u8 = 1,
        COMMAND_REFUSED: u8 = 2,
        COMMAND_ALREADY_CARRIED_OUT: u8 = 3,
    }
}

ros_message! {
    /// One solved sequence.
    pub struct SequenceResult(PKG, "SequenceResult", include_str!("../msg/SequenceResult.msg")) {
        pub header: Header,
        pub session_id: String,
        pub user_id: String,
        pub user_model_cluster: i32,
        pub sequence_index: u8,
        pub state: BehaviourState,
        pub action: u8,
        pub level: u8,
        pub feedback: u8,
        pub overridden: bool,
        pub sequence: Vec<String>,
        pub answer: Vec<String>,
        pub outcome: i8,
        pub timed_out: bool,
        pub activity_result: f32,
        pub engagement: f32,
        pub engagement_per_second: Vec<f32>,
        pub engagement_period_start: Time,
        pub engagement_period_end: Time,
        pub response_time: f32,
        pub sequences_planned: u8,
    }
}

ros_message! {
    /// A task for the child tablet.
    pub struct TabletTask(PKG, "TabletTask", include_str!("../msg/TabletTask.msg")) {
        pub header: Header,
        pub session_id: String,
        pub sequence_id: u32,
        pub sequence_index: u8,
        pub length: u8,
        pub choices: Vec<String>,
        pub timeout: f32,
    }
}

ros_message! {
    /// The child's answer.
    pub struct TabletAnswer(PKG, "TabletAnswer", include_str!("../msg/TabletAnswer.msg")) {
        pub header: Header,
        pub session_id: String,
        pub sequence_id: u32,
        pub answer: Vec<String>,
        pub response_time: f32,
    }
}

ros_message! {
    /// One explained policy decision.
    pub struct Decision(PKG, "Decision", include_str!("../msg/Decision.msg")) {
        pub header: Header,
        pub session_id: String,
        pub step: u8,
        pub state: BehaviourState,
        pub action: u8,
        pub level: u8,
        pub feedback: u8,
        pub q_values: Vec<f64>,
        pub probabilities: Vec<f64>,
        pub temperature: f64,
        pub explored: bool,
        pub exploitation_only: bool,
        pub model_used: String,
        pub planned_on_belief: bool,
        pub belief_observations: u32,
        pub belief_success: Vec<f64>,
        pub belief_success_sd: Vec<f64>,
        pub belief_engagement: Vec<f64>,
        pub belief_engagement_sd: Vec<f64>,
        pub baseline_action: u8,
    }
}

ros_message! {
    /// The user models a user-model node holds.
    pub struct UserModelInfo(PKG, "UserModelInfo", include_str!("../msg/UserModelInfo.msg")) {
        pub header: Header,
        pub model_file: String,
        pub format_version: u32,
        pub clusters: Vec<i32>,
        pub cluster_sizes: Vec<u32>,
        pub kernel: String,
    }
}

ros_message! {
    /// A node's heartbeat.
    pub struct Heartbeat(PKG, "Heartbeat", include_str!("../msg/Heartbeat.msg")) {
        pub header: Header,
        pub node_name: String,
        pub pid: u32,
        pub sequence: u64,
    }
}

ros_message! {
    /// The policy's action offered to the therapist (supervised autonomy), and what became of it.
    pub struct ActionProposal(PKG, "ActionProposal", include_str!("../msg/ActionProposal.msg")) {
        pub header: Header,
        pub session_id: String,
        pub proposal_id: u64,
        pub step: u8,
        pub state: BehaviourState,
        pub action: u8,
        pub level: u8,
        pub feedback: u8,
        pub temperature: f64,
        pub success_std: f64,
        pub reason: String,
        pub countdown: f32,
        pub deadline: Time,
        pub status: u8,
        pub played_action: u8,
        pub played_level: u8,
        pub played_feedback: u8,
        pub command_id: u64,
        pub response_time: f32,
    }
    constants {
        PROPOSED: u8 = 0,
        ACCEPTED: u8 = 1,
        REPLACED: u8 = 2,
        TIMED_OUT: u8 = 3,
        WITHDRAWN: u8 = 4,
    }
}
