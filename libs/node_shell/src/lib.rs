//! The shared DDS shell of every node in the suite: the only crate that touches ros2-client.
//! It reads `params/<node>.yaml` (ROS 2 parameter-file form), joins the ROS 2 graph with the
//! QoS each topic class needs, delivers validated messages on channels, logs to stderr and
//! `/rosout`, publishes a heartbeat, exits cleanly on SIGINT/SIGTERM, and exits non-zero if
//! RustDDS's threads end (so that it is started again). Node cores stay
//! sans-IO: their binaries only move messages between these channels and the core.

pub mod dds_watch;
pub mod drops;
pub mod instance_lock;
pub mod logging;
pub mod params;
pub mod security;
mod shell;
pub mod tap;

pub use shell::{
    CallError, NoParameters, NodeShell, Outbox, ServiceCall, ServiceClient, ShellOptions,
    domain_id_from_env, localhost_only_from_env, qos_profile, ros_name, service_qos,
};

use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;

/// Wall-clock time in nanoseconds since the epoch.
pub fn now_nanos() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as i64)
        .unwrap_or(0)
}

/// A header stamped now.
pub fn header_now() -> Header {
    Header::at(Time::from_nanos(now_nanos()))
}
