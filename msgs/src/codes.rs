//! Typed names for the `u8` codes the messages carry, one enum per code field: a therapist's
//! command (`TherapistCommand.command`), the game's phase (`GameState.phase`), what became of
//! a command (`GameState.command_outcome`) and of a proposal (`ActionProposal.status`). The
//! wire fields stay `u8` and the `.msg` constants are the source of truth (each variant is
//! defined by its constant); code that branches on a code turns it into its enum first
//! (`TryFrom<u8>`), so every match names every case and an unknown code is an error, not a
//! silent default. The level, feedback and action codes are `sequence_game`'s `Level`,
//! `Feedback` and `Action`.

use crate::{ActionProposal, GameState, TherapistCommand};

/// A code outside its field's constants.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{field} {code} is none of the message's constants")]
pub struct UnknownCode {
    /// The field, e.g. `GameState.phase`.
    pub field: &'static str,
    pub code: u8,
}

macro_rules! codes {
    (
        $(#[$meta:meta])*
        $name:ident ($field:literal) {
            $( $(#[$vmeta:meta])* $variant:ident = $constant:expr, $words:literal; )+
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum $name {
            $( $(#[$vmeta])* $variant, )+
        }

        impl $name {
            /// Every value, in the order of their codes.
            pub const ALL: &'static [$name] = &[$($name::$variant),+];

            /// The code on the wire.
            pub const fn code(self) -> u8 {
                match self {
                    $( $name::$variant => $constant, )+
                }
            }

            /// The name the suite writes for it (logs, pages, reports).
            pub const fn name(self) -> &'static str {
                match self {
                    $( $name::$variant => $words, )+
                }
            }
        }

        impl TryFrom<u8> for $name {
            type Error = UnknownCode;

            fn try_from(code: u8) -> Result<Self, UnknownCode> {
                $( if code == $constant { return Ok($name::$variant); } )+
                Err(UnknownCode { field: $field, code })
            }
        }

        impl From<$name> for u8 {
            fn from(value: $name) -> u8 {
                value.code()
            }
        }
    };
}

codes! {
    /// A therapist's command (`TherapistCommand.command`).
    Command("TherapistCommand.command") {
        Start = TherapistCommand::START, "start";
        Pause = TherapistCommand::PAUSE, "pause";
        Resume = TherapistCommand::RESUME, "resume";
        Stop = TherapistCommand::STOP, "stop";
        OverrideLevel = TherapistCommand::OVERRIDE_LEVEL, "override level";
        EmergencyStop = TherapistCommand::EMERGENCY_STOP, "emergency stop";
        /// The next sequence repeats the level with encouraging feedback.
        OverrideEncouraging = TherapistCommand::OVERRIDE_ENCOURAGING, "override: encouraging feedback";
        /// The next sequence repeats the level with challenging feedback.
        OverrideChallenging = TherapistCommand::OVERRIDE_CHALLENGING, "override: challenging feedback";
        /// Carry out the action the game manager proposes now.
        AcceptProposal = TherapistCommand::ACCEPT_PROPOSAL, "accept proposal";
    }
}

codes! {
    /// Where the game is (`GameState.phase`).
    GamePhase("GameState.phase") {
        Idle = GameState::IDLE, "idle";
        Deciding = GameState::DECIDING, "deciding";
        GivingFeedback = GameState::GIVING_FEEDBACK, "giving_feedback";
        SayingSequence = GameState::SAYING_SEQUENCE, "saying_sequence";
        WaitingForAnswer = GameState::WAITING_FOR_ANSWER, "waiting_for_answer";
        Paused = GameState::PAUSED, "paused";
        Finished = GameState::FINISHED, "finished";
        Stopped = GameState::STOPPED, "stopped";
        EmergencyStopped = GameState::EMERGENCY_STOPPED, "emergency_stopped";
    }
}

impl GamePhase {
    /// A sequence under way (not idle, paused or ended).
    pub fn is_running(self) -> bool {
        matches!(
            self,
            GamePhase::Deciding
                | GamePhase::GivingFeedback
                | GamePhase::SayingSequence
                | GamePhase::WaitingForAnswer
        )
    }

    /// The end of a session.
    pub fn is_ended(self) -> bool {
        matches!(
            self,
            GamePhase::Finished | GamePhase::Stopped | GamePhase::EmergencyStopped
        )
    }
}

codes! {
    /// What became of the command a GameState answers (`GameState.command_outcome`).
    CommandOutcome("GameState.command_outcome") {
        /// The state answers no command.
        None = GameState::COMMAND_NONE, "none";
        CarriedOut = GameState::COMMAND_CARRIED_OUT, "carried out";
        Refused = GameState::COMMAND_REFUSED, "refused";
        /// The same command came again (a resend): nothing more was done.
        AlreadyCarriedOut = GameState::COMMAND_ALREADY_CARRIED_OUT, "already carried out";
    }
}

codes! {
    /// Where a proposal to the therapist is (`ActionProposal.status`).
    ProposalStatus("ActionProposal.status") {
        /// Waiting for the therapist, the countdown running.
        Proposed = ActionProposal::PROPOSED, "proposed";
        Accepted = ActionProposal::ACCEPTED, "accepted";
        /// The therapist chose another level or feedback.
        Replaced = ActionProposal::REPLACED, "replaced";
        /// The countdown ran out: the proposed action played.
        TimedOut = ActionProposal::TIMED_OUT, "timed_out";
        /// The session ended first.
        Withdrawn = ActionProposal::WITHDRAWN, "withdrawn";
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_code_reads_back_as_its_value_and_others_are_refused() {
        fn round_trip<T: Copy + PartialEq + std::fmt::Debug + TryFrom<u8>>(
            all: &[T],
            code: fn(T) -> u8,
        ) {
            for v in all {
                assert_eq!(T::try_from(code(*v)).ok(), Some(*v));
            }
            let codes: Vec<u8> = all.iter().map(|v| code(*v)).collect();
            assert_eq!(codes, (0..all.len() as u8).collect::<Vec<_>>());
            assert!(T::try_from(all.len() as u8).is_err());
        }
        round_trip(Command::ALL, Command::code);
        round_trip(GamePhase::ALL, GamePhase::code);
        round_trip(CommandOutcome::ALL, CommandOutcome::code);
        round_trip(ProposalStatus::ALL, ProposalStatus::code);
        assert_eq!(
            GamePhase::try_from(9).unwrap_err().to_string(),
            "GameState.phase 9 is none of the message's constants"
        );
    }
}
