//! Rust mirror of the `qt_therapy_msgs` ROS 2 interface package in this directory. The
//! `msg/*.msg` and `srv/*.srv` files are the source of truth; each struct here repeats one of
//! them field for field (the `mirror` test proves it), serialises to the same CDR as a ROS 2
//! peer, and names itself `qt_therapy_msgs::msg::dds_::<Type>_` on DDS.

pub mod codes;
pub mod definition;
pub mod disk_status;
pub mod hri_msgs;
pub mod messages;
pub mod phases;
pub mod qt_robot_interface;
pub mod qtrobot_interfaces;
pub mod results;
pub mod services;
mod standard;
pub mod topics;
pub mod type_description;
pub mod validate;

pub use codes::{Command, CommandOutcome, GamePhase, ProposalStatus, UnknownCode};
pub use definition::{MessageDefinition, RosType};
pub use messages::*;
pub use services::*;
pub use standard::{builtin_interfaces, rosgraph_msgs, std_msgs};
pub use validate::{InvalidMessage, Validate};

/// The 32 OpenFace columns of `OpenFaceFeatures.features`, in order (see the `.msg`).
pub const OPENFACE_FEATURES: [&str; 32] = [
    "pose_Tx",
    "pose_Ty",
    "pose_Tz",
    "pose_Rx",
    "pose_Ry",
    "pose_Rz",
    "AU01_c",
    "AU02_c",
    "AU04_c",
    "AU05_c",
    "AU06_c",
    "AU07_c",
    "AU09_c",
    "AU10_c",
    "AU12_c",
    "AU14_c",
    "AU15_c",
    "AU17_c",
    "AU20_c",
    "AU23_c",
    "AU25_c",
    "AU26_c",
    "AU28_c",
    "AU45_c",
    "gaze_0_x",
    "gaze_0_y",
    "gaze_0_z",
    "gaze_1_x",
    "gaze_1_y",
    "gaze_1_z",
    "gaze_angle_x",
    "gaze_angle_y",
];

#[cfg(feature = "dds")]
/// The ROS 2 DDS type name of a message, e.g. `qt_therapy_msgs::msg::dds_::GameState_`.
pub fn dds_type_name<M: MessageDefinition>() -> ros2_client::MessageTypeName {
    ros2_client::MessageTypeName::new(M::PACKAGE, M::NAME)
}
