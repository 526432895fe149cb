//! What `run-session` does with the game manager's proposals (supervised autonomy): a line when
//! an action is proposed to the therapist and one when the proposal is settled; with
//! `--accept-proposals`, an ACCEPT_PROPOSAL for each open proposal, sent again until the game
//! manager answers it. Sans-IO: the caller prints the lines and publishes the commands.

use crate::console::{Answer, CONFIRM_WAIT, SENDS, answer_to};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::topics::ACTION_PROPOSAL;
use qt_therapy_msgs::{ActionProposal, GameState, TherapistCommand};
use session_log::{Arrival, Once};
use session_tally::live_line::{proposal_answer, proposal_asked};
use std::time::Instant;

/// What the caller must do.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    Print(String),
    Send(TherapistCommand),
}

/// An ACCEPT_PROPOSAL sent and not answered yet.
#[derive(Debug)]
struct PendingAccept {
    step: u8,
    command: TherapistCommand,
    sends: u32,
    next_send: Instant,
}

/// The proposals of one session as `run-session` follows it.
#[derive(Debug)]
pub struct Proposals {
    session: String,
    accept: bool,
    /// Every message taken by the suite's rule for what arrives twice (`session_log`): the
    /// durable topic may hand one over twice; a proposal shown again after a pause has a new
    /// deadline, so it is new.
    taken: Once<ActionProposal>,
    /// Ids of the proposals shown, and of those settled.
    shown: Vec<u64>,
    settled: Vec<u64>,
    pending: Vec<PendingAccept>,
    last_command_id: u64,
}

impl Proposals {
    /// `accept`: accept each proposal at once. `last_command_id`: the id of the last command
    /// this console sent (the START); the accepts' ids come after it.
    pub fn new(session: &str, accept: bool, last_command_id: u64) -> Proposals {
        Proposals {
            session: session.to_string(),
            accept,
            taken: Once::new(),
            shown: Vec::new(),
            settled: Vec::new(),
            pending: Vec::new(),
            last_command_id,
        }
    }

    /// A message on the proposal topic. `now_ms`: milliseconds since the epoch (the caller's
    /// clock), the base of a new command id and its stamp.
    pub fn on_proposal(&mut self, p: &ActionProposal, now: Instant, now_ms: u64) -> Vec<Event> {
        if p.session_id != self.session {
            return Vec::new();
        }
        let mut events = Vec::new();
        match self.taken.arrive(p, ACTION_PROPOSAL.name) {
            Ok(Arrival::New) => {}
            Ok(Arrival::Repeat) => return events,
            Err(conflict) => {
                events.push(Event::Print(format!("  {conflict}; the first is kept")));
                return events;
            }
        }
        if p.status == ActionProposal::PROPOSED {
            // A showing older than the settlement, delivered after it: history.
            if self.settled.contains(&p.proposal_id) {
                return events;
            }
            let again = self.shown.contains(&p.proposal_id);
            if !again {
                self.shown.push(p.proposal_id);
            }
            events.push(Event::Print(proposed_line(p, again)));
            if self.accept && !self.pending.iter().any(|a| a.step == p.step) {
                let command = TherapistCommand {
                    header: Header::at(Time::from_nanos((now_ms as i64).saturating_mul(1_000_000))),
                    command: TherapistCommand::ACCEPT_PROPOSAL,
                    session_id: self.session.clone(),
                    command_id: now_ms.max(self.last_command_id + 1),
                    ..Default::default()
                };
                self.last_command_id = command.command_id;
                events.push(Event::Send(command.clone()));
                self.pending.push(PendingAccept {
                    step: p.step,
                    command,
                    sends: 1,
                    next_send: now + CONFIRM_WAIT,
                });
            }
        } else {
            self.settled.push(p.proposal_id);
            events.push(Event::Print(settled_line(p)));
        }
        events
    }

    /// A game state: the game manager's answer to an accept, if it names one.
    pub fn on_state(&mut self, s: &GameState) -> Vec<Event> {
        let mut events = Vec::new();
        self.pending.retain(|a| match answer_to(&a.command, s) {
            None => true,
            Some(Answer::CarriedOut) => false,
            Some(Answer::Refused(reason)) => {
                events.push(Event::Print(format!(
                    "  accepting the proposal for seq {} refused (command {}): {reason}",
                    a.step, a.command.command_id
                )));
                false
            }
        });
        events
    }

    /// When an unanswered accept is to be sent again.
    pub fn next_send(&self) -> Option<Instant> {
        self.pending.iter().map(|a| a.next_send).min()
    }

    /// Sends again the accepts unanswered for CONFIRM_WAIT (same id: the game manager never
    /// carries one out twice); gives up on one after SENDS sends, saying so.
    pub fn on_tick(&mut self, now: Instant) -> Vec<Event> {
        let mut events = Vec::new();
        self.pending.retain_mut(|a| {
            if a.next_send > now {
                return true;
            }
            if a.sends == SENDS {
                events.push(Event::Print(format!(
                    "  the game manager did not answer command {} (accept the proposal for \
                     seq {}) after {SENDS} sends",
                    a.command.command_id, a.step
                )));
                return false;
            }
            a.sends += 1;
            a.next_send = now + CONFIRM_WAIT;
            events.push(Event::Send(a.command.clone()));
            true
        });
        events
    }
}

/// `  proposal for seq 4: L2 + encouraging (T 235, σ 0.31; <reason>), 5 s to answer`.
pub fn proposed_line(p: &ActionProposal, again: bool) -> String {
    let reason = if p.reason.is_empty() {
        String::new()
    } else {
        format!("; {}", p.reason)
    };
    let asked = proposal_asked(p);
    // The reason goes inside the brackets of the asked action.
    let asked = match asked.strip_suffix(')') {
        Some(open) => format!("{open}{reason})"),
        None => asked,
    };
    format!(
        "  proposal for seq {}{}: {asked}, {:.0} s to answer",
        p.step,
        if again { " again" } else { "" },
        p.countdown
    )
}

/// `  proposal for seq 4 accepted after 2.1 s (command 17)`, and so on for each settlement.
pub fn settled_line(p: &ActionProposal) -> String {
    let command = if p.command_id > 0 {
        format!(" (command {})", p.command_id)
    } else {
        String::new()
    };
    format!(
        "  proposal for seq {} {}{command}",
        p.step,
        proposal_answer(p)
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn proposal(step: u8, status: u8, deadline: i32) -> ActionProposal {
        ActionProposal {
            session_id: "s1".into(),
            proposal_id: 1_000 + u64::from(step),
            step,
            action: 3,
            level: 2,
            feedback: 1,
            temperature: 235.0,
            success_std: 0.31,
            reason: "state visited 3 times".into(),
            countdown: 5.0,
            deadline: Time {
                sec: deadline,
                nanosec: 0,
            },
            status,
            ..Default::default()
        }
    }

    fn settled(step: u8, status: u8, played: (u8, u8), command_id: u64) -> ActionProposal {
        ActionProposal {
            played_level: played.0,
            played_feedback: played.1,
            command_id,
            response_time: 2.125,
            ..proposal(step, status, 0)
        }
    }

    fn prints(events: &[Event]) -> Vec<&str> {
        events
            .iter()
            .filter_map(|e| match e {
                Event::Print(line) => Some(line.as_str()),
                Event::Send(_) => None,
            })
            .collect()
    }

    fn sends(events: &[Event]) -> Vec<&TherapistCommand> {
        events
            .iter()
            .filter_map(|e| match e {
                Event::Send(c) => Some(c),
                Event::Print(_) => None,
            })
            .collect()
    }

    fn answer(id: u64, outcome: u8, refusal: &str) -> GameState {
        GameState {
            command_session_id: "s1".into(),
            command_id: id,
            command_outcome: outcome,
            command_refusal: refusal.into(),
            ..Default::default()
        }
    }

    #[test]
    fn a_line_when_proposed_and_when_settled_once_each() {
        let t0 = Instant::now();
        let mut p = Proposals::new("s1", false, 10);
        let e = p.on_proposal(&proposal(2, ActionProposal::PROPOSED, 100), t0, 1_000);
        assert_eq!(
            e,
            [Event::Print(
                "  proposal for seq 2: L2 + encouraging (T 235, σ 0.31; state visited 3 times), \
                 5 s to answer"
                    .into()
            )],
            "only a line: no accept unless asked"
        );
        // Handed over again (durable topic): nothing.
        assert!(
            p.on_proposal(&proposal(2, ActionProposal::PROPOSED, 100), t0, 1_000)
                .is_empty()
        );
        // Proposed again after a pause, with a new deadline and no user model.
        let again = ActionProposal {
            success_std: -1.0,
            reason: String::new(),
            countdown: 3.6,
            ..proposal(2, ActionProposal::PROPOSED, 130)
        };
        assert_eq!(
            prints(&p.on_proposal(&again, t0, 1_000)),
            ["  proposal for seq 2 again: L2 + encouraging (T 235, no user model), 4 s to answer"]
        );
        // Another session's: nothing.
        let other = ActionProposal {
            session_id: "s0".into(),
            ..proposal(3, ActionProposal::PROPOSED, 100)
        };
        assert!(p.on_proposal(&other, t0, 1_000).is_empty());
        let cases = [
            (
                settled(2, ActionProposal::ACCEPTED, (2, 1), 17),
                "  proposal for seq 2 accepted after 2.1 s (command 17)",
            ),
            (
                settled(3, ActionProposal::REPLACED, (3, 0), 18),
                "  proposal for seq 3 replaced by L3 after 2.1 s (command 18)",
            ),
            (
                settled(4, ActionProposal::TIMED_OUT, (2, 1), 0),
                "  proposal for seq 4 ran out after 2.1 s: played",
            ),
            (
                settled(5, ActionProposal::WITHDRAWN, (0, 0), 0),
                "  proposal for seq 5 withdrawn (the session ended first)",
            ),
        ];
        for (m, line) in &cases {
            assert_eq!(prints(&p.on_proposal(m, t0, 1_000)), [*line]);
            assert!(p.on_proposal(m, t0, 1_000).is_empty(), "settled once");
        }
        // A settled step proposed again (a late copy): nothing.
        assert!(
            p.on_proposal(&proposal(2, ActionProposal::PROPOSED, 200), t0, 1_000)
                .is_empty()
        );
        assert_eq!(p.next_send(), None);
    }

    #[test]
    fn accepting_each_proposal_until_the_game_manager_answers() {
        let t0 = Instant::now();
        let mut p = Proposals::new("s1", true, 5_000);
        // The id follows the START's even when the clock says less.
        let e = p.on_proposal(&proposal(2, ActionProposal::PROPOSED, 100), t0, 4_000);
        let sent = sends(&e);
        assert_eq!(sent.len(), 1, "{e:?}");
        let first = sent[0].clone();
        assert_eq!(
            (
                first.command,
                first.session_id.as_str(),
                first.command_id,
                first.level
            ),
            (TherapistCommand::ACCEPT_PROPOSAL, "s1", 5_001, 0)
        );
        // Proposed again while the accept is unanswered: no second accept.
        let e = p.on_proposal(&proposal(2, ActionProposal::PROPOSED, 130), t0, 6_000);
        assert!(sends(&e).is_empty(), "{e:?}");
        // Unanswered: sent again with the same id after CONFIRM_WAIT, SENDS times in all.
        assert_eq!(p.next_send(), Some(t0 + CONFIRM_WAIT));
        assert!(
            p.on_tick(t0 + CONFIRM_WAIT - Duration::from_millis(1))
                .is_empty()
        );
        let mut at = t0;
        for _ in 1..SENDS {
            at += CONFIRM_WAIT;
            assert_eq!(sends(&p.on_tick(at)), [&first]);
        }
        at += CONFIRM_WAIT;
        let e = p.on_tick(at);
        assert!(sends(&e).is_empty());
        assert_eq!(
            prints(&e),
            [format!(
                "  the game manager did not answer command 5001 (accept the proposal for seq \
                 2) after {SENDS} sends"
            )]
        );
        assert_eq!(p.next_send(), None);

        // The next proposal: accepted, the answer arrives, nothing more is sent.
        let e = p.on_proposal(&proposal(3, ActionProposal::PROPOSED, 200), at, 9_000);
        let second = sends(&e)[0].clone();
        assert_eq!(second.command_id, 9_000);
        assert!(
            p.on_state(&answer(9_000, GameState::COMMAND_NONE, ""))
                .is_empty()
        );
        assert!(
            p.on_state(&answer(8_999, GameState::COMMAND_CARRIED_OUT, ""))
                .is_empty()
        );
        assert!(p.next_send().is_some(), "another command's answer");
        assert!(
            p.on_state(&answer(9_000, GameState::COMMAND_CARRIED_OUT, ""))
                .is_empty()
        );
        assert_eq!(p.next_send(), None);
        assert!(p.on_tick(at + 10 * CONFIRM_WAIT).is_empty());

        // Refused (it ran out first): the reason is printed, the proposal's steps go on.
        let e = p.on_proposal(&proposal(4, ActionProposal::PROPOSED, 300), at, 9_000);
        let third = sends(&e)[0].clone();
        assert_eq!(third.command_id, 9_001, "ids only increase");
        let e = p.on_state(&answer(
            9_001,
            GameState::COMMAND_REFUSED,
            "no proposal is open (one that ran out was played)",
        ));
        assert_eq!(
            prints(&e),
            [
                "  accepting the proposal for seq 4 refused (command 9001): no proposal is open \
                 (one that ran out was played)"
            ]
        );
        assert_eq!(p.next_send(), None);
        // Settled: a copy of its proposal arriving late is not accepted.
        p.on_proposal(&settled(4, ActionProposal::TIMED_OUT, (2, 1), 0), at, 9_500);
        let e = p.on_proposal(&proposal(4, ActionProposal::PROPOSED, 400), at, 9_500);
        assert!(e.is_empty(), "{e:?}");
    }
}
