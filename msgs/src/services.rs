//! The suite's services, one request and one response struct per `srv/*.srv` file.

use crate::definition::ros_message;
use crate::messages::{BehaviourState, Decision};

const PKG: &str = "qt_therapy_msgs";

/// A ROS 2 service: its type name and its two halves.
pub trait ServiceDefinition {
    const PACKAGE: &'static str;
    const NAME: &'static str;
    type Request: crate::MessageDefinition;
    type Response: crate::MessageDefinition;
    fn definition_text() -> &'static str;
}

/// The request (`half == 0`) or response (`half == 1`) part of a `.srv` text.
pub(crate) fn srv_half(text: &'static str, half: usize) -> &'static str {
    let mut parts = text.splitn(2, "\n---\n");
    let request = parts.next().unwrap_or("");
    match half {
        0 => request,
        _ => parts.next().unwrap_or(""),
    }
}

macro_rules! ros_service {
    ($(#[$meta:meta])* pub struct $name:ident($ros:literal, $file:literal, $req:ident, $resp:ident)) => {
        $(#[$meta])*
        pub struct $name;
        impl ServiceDefinition for $name {
            const PACKAGE: &'static str = PKG;
            const NAME: &'static str = $ros;
            type Request = $req;
            type Response = $resp;
            fn definition_text() -> &'static str {
                include_str!($file)
            }
        }
    };
}
pub(crate) use ros_service;

ros_message! {
    pub struct PredictUserRequest(PKG, "PredictUser_Request", srv_half(include_str!("../srv/PredictUser.srv"), 0)) {
        pub cluster: i32,
        pub level: u8,
        pub feedback: u8,
        pub previous_score: i8,
        pub outcome: i8,
    }
}

ros_message! {
    pub struct PredictUserResponse(PKG, "PredictUser_Response", srv_half(include_str!("../srv/PredictUser.srv"), 1)) {
        pub ok: bool,
        pub error: String,
        pub success_probability: f64,
        pub success_std: f64,
        pub engagement: f64,
        pub engagement_std: f64,
    }
}

ros_service! {
    /// F^p and F^e of one cluster's user model at one input.
    pub struct PredictUser("PredictUser", "../srv/PredictUser.srv", PredictUserRequest, PredictUserResponse)
}

ros_message! {
    pub struct AssignClusterRequest(PKG, "AssignCluster_Request", srv_half(include_str!("../srv/AssignCluster.srv"), 0)) {
        pub user_vector: Vec<f64>,
    }
}

ros_message! {
    pub struct AssignClusterResponse(PKG, "AssignCluster_Response", srv_half(include_str!("../srv/AssignCluster.srv"), 1)) {
        pub ok: bool,
        pub error: String,
        pub cluster: i32,
        pub projection: Vec<f64>,
    }
}

ros_service! {
    /// Which cluster a new user's vector belongs to.
    pub struct AssignCluster("AssignCluster", "../srv/AssignCluster.srv", AssignClusterRequest, AssignClusterResponse)
}

ros_message! {
    pub struct DecideActionRequest(PKG, "DecideAction_Request", srv_half(include_str!("../srv/DecideAction.srv"), 0)) {
        pub session_id: String,
        pub user_id: String,
        pub user_model_cluster: i32,
        pub state: BehaviourState,
        pub step: u8,
        pub after_sequence: u8,
    }
}

ros_message! {
    pub struct DecideActionResponse(PKG, "DecideAction_Response", srv_half(include_str!("../srv/DecideAction.srv"), 1)) {
        pub ok: bool,
        pub error: String,
        pub decision: Decision,
    }
}

ros_service! {
    /// The behaviour policy's next action.
    pub struct DecideAction("DecideAction", "../srv/DecideAction.srv", DecideActionRequest, DecideActionResponse)
}
