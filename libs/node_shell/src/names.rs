//! ROS names: the suite's full topic and service names (`/qt_therapy/x`) as ros2-client's
//! namespace and base name, with the reason when one is not a ROS name.

use ros2_client::Name;

/// A full topic or service name (`/qt_therapy/x`) as ros2-client's namespace and base name.
pub fn ros_name(full: &str) -> anyhow::Result<Name> {
    let (ns, base) = match full.rsplit_once('/') {
        Some(("", base)) => ("/", base),
        Some((ns, base)) => (ns, base),
        None => ("/", full),
    };
    Name::new(ns, base).map_err(|e| anyhow::anyhow!("{full:?} is not a ROS name: {e:?}"))
}
