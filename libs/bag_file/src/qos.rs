//! The `offered_qos_profiles` channel metadata rosbag2 writes (its Jazzy, metadata version 9
//! form: policy names in lower case, infinite durations as 9223372036 s 854775807 ns), made
//! from the suite's QoS classes, and read back so the player offers what was recorded.

use qt_therapy_msgs::topics::QosKind;

/// `RMW_DURATION_INFINITE` as rosbag2 writes it.
const INFINITE: &str = "\n    sec: 9223372036\n    nsec: 854775807";

/// The publisher QoS of a topic class: (reliability, durability, depth).
fn policies(kind: QosKind) -> (&'static str, &'static str, u32) {
    match kind {
        QosKind::Reliable => ("reliable", "volatile", 100),
        QosKind::State => ("reliable", "transient_local", 1),
        QosKind::Durable => ("reliable", "transient_local", 100),
        QosKind::Features => ("best_effort", "volatile", 10),
    }
}

/// The YAML list rosbag2 stores under `offered_qos_profiles` for one publisher of `kind`.
pub fn offered_qos_yaml(kind: QosKind) -> String {
    let (reliability, durability, depth) = policies(kind);
    format!(
        "- history: keep_last\n  depth: {depth}\n  reliability: {reliability}\n  \
         durability: {durability}\n  deadline:{INFINITE}\n  lifespan:{INFINITE}\n  \
         liveliness: automatic\n  liveliness_lease_duration:{INFINITE}\n  \
         avoid_ros_namespace_conventions: false"
    )
}

/// The topic class of the first profile in an `offered_qos_profiles` text, in either the
/// version 9 (names) or the older integer form (reliability 1 = reliable, 2 = best effort;
/// durability 1 = transient local, 2 = volatile). None when the text names neither.
pub fn qos_kind_from_yaml(text: &str) -> Option<QosKind> {
    let mut reliability = None;
    let mut durability = None;
    let mut depth = None;
    for line in text.lines() {
        let line = line.trim().trim_start_matches("- ");
        let Some((key, value)) = line.split_once(':') else {
            continue;
        };
        let value = value.trim().trim_matches('"').to_ascii_lowercase();
        match key.trim() {
            "reliability" if reliability.is_none() => reliability = Some(value),
            "durability" if durability.is_none() => durability = Some(value),
            "depth" if depth.is_none() => depth = value.parse::<u32>().ok(),
            _ => {}
        }
    }
    let best_effort = match reliability.as_deref()? {
        "reliable" | "1" => false,
        "best_effort" | "2" => true,
        _ => return None,
    };
    let transient = matches!(durability.as_deref(), Some("transient_local" | "1"));
    // Transient-local with a history deeper than one keeps results, not just the latest state.
    Some(match (best_effort, transient, depth.unwrap_or(1) > 1) {
        (true, _, _) => QosKind::Features,
        (false, true, false) => QosKind::State,
        (false, true, true) => QosKind::Durable,
        (false, false, _) => QosKind::Reliable,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_class_reads_back() {
        for kind in [
            QosKind::Reliable,
            QosKind::State,
            QosKind::Durable,
            QosKind::Features,
        ] {
            assert_eq!(qos_kind_from_yaml(&offered_qos_yaml(kind)), Some(kind));
        }
    }

    #[test]
    fn reads_the_integer_form_of_older_rosbag2() {
        let humble = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  deadline:\n    sec: 9223372036\n    nsec: 854775807\n  liveliness: 1";
        assert_eq!(qos_kind_from_yaml(humble), Some(QosKind::Reliable));
        let latched = humble.replace("durability: 2", "durability: 1");
        assert_eq!(qos_kind_from_yaml(&latched), Some(QosKind::State));
        assert_eq!(qos_kind_from_yaml(""), None);
        assert_eq!(qos_kind_from_yaml("- reliability: sometimes"), None);
    }

    #[test]
    fn the_state_profile_is_rosbag2_shaped() {
        let text = offered_qos_yaml(QosKind::State);
        assert!(text.starts_with("- history: keep_last\n  depth: 1\n  reliability: reliable\n"));
        assert!(text.contains("durability: transient_local"));
        assert!(text.contains("liveliness_lease_duration:\n    sec: 9223372036\n"));
        assert!(text.ends_with("avoid_ros_namespace_conventions: false"));
    }
}
