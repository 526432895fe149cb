//! The disk warning in `GameState.status`: the game manager puts it first, after a fixed
//! prefix, while the disk of its session files and bag is low or full; the tablet bridge
//! takes it out for the therapist page's warning. One home for the prefix, so the two agree.

use crate::GameState;

impl GameState {
    /// Starts `status` while the disk is low or full (`disk: 42.0 MB free in ...`).
    pub const DISK_WARNING_PREFIX: &'static str = "disk: ";

    /// The disk warning `status` starts with (without the prefix), if any: the text up to the
    /// next `; `.
    pub fn disk_warning(status: &str) -> Option<&str> {
        let rest = status.strip_prefix(Self::DISK_WARNING_PREFIX)?;
        Some(rest.split_once("; ").map_or(rest, |(warning, _)| warning))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_warning_is_the_first_part_of_the_status() {
        assert_eq!(
            GameState::disk_warning("disk: 4.0 MB free in /s; node lost: x; paused"),
            Some("4.0 MB free in /s")
        );
        assert_eq!(GameState::disk_warning("disk: full"), Some("full"));
        assert_eq!(GameState::disk_warning("node lost: x; disk: full"), None);
    }
}
