//! The two ROS4HRI (REP-155) types the engagement classifier publishes, mirrored field for field
//! from `interfaces/hri_msgs/msg/` (which restates ROS4HRI's own `hri_msgs`); their DDS names
//! are ROS 2's (`hri_msgs::msg::dds_::EngagementLevel_`), so ROS4HRI tools read them.

use crate::definition::ros_message;
use crate::standard::std_msgs::Header;

const PKG: &str = "hri_msgs";

ros_message! {
    /// How engaged a person is with the robot.
    pub struct EngagementLevel(PKG, "EngagementLevel", include_str!("../../interfaces/hri_msgs/msg/EngagementLevel.msg")) {
        pub header: Header,
        pub level: u8,
    }
    constants {
        UNKNOWN: u8 = 0,
        DISENGAGED: u8 = 1,
        ENGAGING: u8 = 2,
        ENGAGED: u8 = 3,
        DISENGAGING: u8 = 4,
    }
}

ros_message! {
    /// A list of ROS4HRI ids (here: the persons tracked).
    pub struct IdsList(PKG, "IdsList", include_str!("../../interfaces/hri_msgs/msg/IdsList.msg")) {
        pub header: Header,
        pub ids: Vec<String>,
    }
}
