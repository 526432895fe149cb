//! The ROS 2 environment a participant is built from: the domain (`ROS_DOMAIN_ID`) and whether
//! discovery stays on this machine (`ROS_LOCALHOST_ONLY`, `ROS_AUTOMATIC_DISCOVERY_RANGE`).

use anyhow::bail;

/// ROS_DOMAIN_ID, 0 when unset; values outside 0..=232 are an error.
pub fn domain_id_from_env() -> anyhow::Result<u16> {
    domain_id_from(std::env::var("ROS_DOMAIN_ID").ok().as_deref())
}

/// The domain id a `ROS_DOMAIN_ID` value names: unset or empty is 0, as in ROS 2.
fn domain_id_from(value: Option<&str>) -> anyhow::Result<u16> {
    match value.map(str::trim) {
        None | Some("") => Ok(0),
        Some(s) => match s.parse::<u16>() {
            Ok(d) if d <= 232 => Ok(d),
            _ => bail!("ROS_DOMAIN_ID={s:?} is not a domain id in 0..=232"),
        },
    }
}

/// True when ROS_LOCALHOST_ONLY=1 or ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST.
pub fn localhost_only_from_env() -> bool {
    localhost_only_from(
        std::env::var("ROS_LOCALHOST_ONLY").ok().as_deref(),
        std::env::var("ROS_AUTOMATIC_DISCOVERY_RANGE")
            .ok()
            .as_deref(),
    )
}

/// Whether `ROS_LOCALHOST_ONLY` (Humble) or `ROS_AUTOMATIC_DISCOVERY_RANGE` (Jazzy) keep
/// discovery on this machine.
fn localhost_only_from(localhost_only: Option<&str>, discovery_range: Option<&str>) -> bool {
    localhost_only.is_some_and(|v| v.trim() == "1")
        || discovery_range.is_some_and(|v| v.trim().eq_ignore_ascii_case("LOCALHOST"))
}

#[cfg(test)]
mod tests {
    use super::{domain_id_from, localhost_only_from};

    #[test]
    fn ros_domain_id_is_read_as_ros_2_does_and_nonsense_is_named() {
        assert_eq!(domain_id_from(None).ok(), Some(0));
        assert_eq!(domain_id_from(Some("")).ok(), Some(0));
        assert_eq!(domain_id_from(Some(" 42 ")).ok(), Some(42));
        assert_eq!(domain_id_from(Some("232")).ok(), Some(232));
        for bad in ["233", "-1", "seven", "1.5"] {
            let e = domain_id_from(Some(bad)).map_err(|e| e.to_string());
            assert_eq!(
                e,
                Err(format!(
                    "ROS_DOMAIN_ID={bad:?} is not a domain id in 0..=232"
                ))
            );
        }
    }

    #[test]
    fn either_localhost_setting_keeps_discovery_local() {
        assert!(!localhost_only_from(None, None));
        assert!(localhost_only_from(Some("1"), None));
        assert!(!localhost_only_from(Some("0"), None));
        assert!(localhost_only_from(None, Some("LOCALHOST")));
        assert!(localhost_only_from(Some("0"), Some("localhost")));
        assert!(!localhost_only_from(None, Some("SUBNET")));
    }
}
