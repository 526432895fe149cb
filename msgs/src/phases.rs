//! The game manager's phases (`GameState.phase`) by name, and which of them are a session
//! under way, for a raw code: the therapist console, the tablet bridge and its pages all read
//! them from here. The rules are [`GamePhase`]'s.

use crate::{GamePhase, GameState};

impl GameState {
    /// The name of `phase` (`saying_sequence`), `unknown` outside the list.
    pub fn phase_name(phase: u8) -> &'static str {
        GamePhase::try_from(phase).map_or("unknown", GamePhase::name)
    }

    /// Whether `phase` is a sequence under way (not idle, paused or ended).
    pub fn is_running(phase: u8) -> bool {
        GamePhase::try_from(phase).is_ok_and(GamePhase::is_running)
    }

    /// Whether `phase` ends a session.
    pub fn is_ended(phase: u8) -> bool {
        GamePhase::try_from(phase).is_ok_and(GamePhase::is_ended)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_follow_the_constants() {
        assert_eq!(GameState::phase_name(GameState::IDLE), "idle");
        assert_eq!(
            GameState::phase_name(GameState::WAITING_FOR_ANSWER),
            "waiting_for_answer"
        );
        assert_eq!(
            GameState::phase_name(GameState::EMERGENCY_STOPPED),
            "emergency_stopped"
        );
        assert_eq!(GameState::phase_name(9), "unknown");
        assert!(GameState::is_running(GameState::SAYING_SEQUENCE));
        assert!(!GameState::is_running(GameState::PAUSED));
        assert!(GameState::is_ended(GameState::STOPPED) && !GameState::is_ended(GameState::IDLE));
    }
}
