//! Supervised autonomy on the therapist page: the game manager's proposals (`ActionProposal`)
//! are kept for the game's session and shown to logged-in therapist pages only (never the
//! child's), with the seconds left counted on the bridge's own clock from the proposal's
//! arrival; commands that answer a proposal are refused once it is no longer open.

use crate::io::{Output, log};
use crate::protocol::{CommandKind, ProposalView, proposal_choices};
use qt_therapy_msgs::topics::ACTION_PROPOSAL;
use qt_therapy_msgs::{ActionProposal, GameState};
use session_log::{Arrival, Once};
use session_tally::live_line::proposal_status_name;
use std::time::Duration;
use tracing::Level;

/// The newest proposal of the game's session and when the bridge got it.
#[derive(Debug, Clone)]
struct KeptProposal {
    proposal: ActionProposal,
    /// Arrival on the bridge's monotonic clock (moved on by a pause, while the countdown waits).
    received: Duration,
    /// The game paused during the countdown: the game manager's countdown waits, and so does
    /// this one (the game manager proposes again, with a new countdown, on resume).
    paused_at: Option<Duration>,
}

impl KeptProposal {
    fn is_open(&self) -> bool {
        self.proposal.status == ActionProposal::PROPOSED
    }

    /// Seconds of its countdown left at `now` (negative once it ran out).
    fn remaining(&self, now: Duration) -> f64 {
        let until = self.paused_at.unwrap_or(now);
        f64::from(self.proposal.countdown) - until.saturating_sub(self.received).as_secs_f64()
    }

    fn view(&self, now: Duration) -> ProposalView {
        ProposalView::of(&self.proposal, self.remaining(now))
    }
}

/// `a` was published before `b` (both stamped by the game manager's clock).
fn older(a: &ActionProposal, b: &GameState) -> bool {
    a.header.stamp.to_nanos() < b.header.stamp.to_nanos()
}

/// The proposals the bridge has taken: the newest of the game's session, kept.
#[derive(Debug, Default)]
pub(crate) struct Proposals {
    kept: Option<KeptProposal>,
    /// Every proposal message taken, by the suite's rule for what arrives twice
    /// (`session_log`): one delivered again must not start its countdown again.
    taken: Once<ActionProposal>,
}

impl Proposals {
    /// A proposal from the game manager, with the game's state as last heard (`game`): its
    /// view for the therapist pages when it is kept.
    pub(crate) fn arrive(
        &mut self,
        p: ActionProposal,
        game: Option<&GameState>,
        now: Duration,
        out: &mut Vec<Output>,
    ) -> Option<ProposalView> {
        match self.taken.arrive(&p, ACTION_PROPOSAL.name) {
            Ok(Arrival::New) => {}
            Ok(Arrival::Repeat) => {
                out.push(log(
                    Level::DEBUG,
                    format!(
                        "proposal {} for sequence {} delivered again; taken once",
                        p.proposal_id, p.step
                    ),
                ));
                return None;
            }
            Err(conflict) => {
                out.push(log(Level::WARN, format!("{conflict}; the first is kept")));
                return None;
            }
        }
        // The topic keeps its history: a bridge (re)started mid-session gets the proposals of
        // earlier sessions too, after or before the game's state. Those older than the state
        // of another session are history; a newer one opens the next session.
        if let Some(g) = game
            && g.session_id != p.session_id
            && older(&p, g)
        {
            out.push(log(
                Level::DEBUG,
                format!(
                    "proposal for sequence {} of the earlier session {:?}; ignored",
                    p.step, p.session_id
                ),
            ));
            return None;
        }
        if let Some(k) = &self.kept
            && k.proposal.session_id == p.session_id
            && p.header.stamp.to_nanos() < k.proposal.header.stamp.to_nanos()
        {
            out.push(log(
                Level::DEBUG,
                format!("an older proposal for sequence {}; ignored", p.step),
            ));
            return None;
        }
        let paused =
            game.is_some_and(|g| g.session_id == p.session_id && g.phase == GameState::PAUSED);
        let kept = KeptProposal {
            received: now,
            paused_at: (paused && p.status == ActionProposal::PROPOSED).then_some(now),
            proposal: p,
        };
        let p = &kept.proposal;
        out.push(log(
            Level::INFO,
            format!(
                "proposal for sequence {} of session {:?}: {} (action {}, {} s)",
                p.step,
                p.session_id,
                proposal_status_name(p.status),
                p.action,
                p.countdown
            ),
        ));
        let view = kept.view(now);
        self.kept = Some(kept);
        Some(view)
    }

    /// The game's state moved on: a proposal of another session is dropped, and a pause
    /// stops the countdown until the game goes on.
    pub(crate) fn follow_game(&mut self, g: &GameState, now: Duration) {
        let Some(k) = self.kept.as_mut() else {
            return;
        };
        if k.proposal.session_id != g.session_id {
            if !g.session_id.is_empty() && !older(&k.proposal, g) {
                // A new session's first proposal before its first state: keep it.
                return;
            }
            self.kept = None;
            return;
        }
        if !k.is_open() {
            return;
        }
        match (g.phase == GameState::PAUSED, k.paused_at) {
            (true, None) => k.paused_at = Some(now),
            (false, Some(at)) => {
                k.received += now.saturating_sub(at);
                k.paused_at = None;
            }
            _ => {}
        }
    }

    /// The open proposal of the game's session (`game`) as a page sees it now, if there is
    /// one.
    pub(crate) fn open_view(
        &self,
        game: Option<&GameState>,
        now: Duration,
    ) -> Option<ProposalView> {
        let k = self.kept.as_ref().filter(|k| k.is_open())?;
        if let Some(g) = game
            && (g.session_id != k.proposal.session_id
                || GameState::is_ended(g.phase)
                || g.phase == GameState::IDLE)
        {
            return None;
        }
        Some(k.view(now))
    }

    /// Whether `kind`, for `session`, may go out as an answer to the proposal of step
    /// `answering` (the proposal card names it; plain overrides name none).
    pub(crate) fn check_answer(
        &self,
        kind: CommandKind,
        answering: Option<u8>,
        session: &str,
    ) -> Result<(), String> {
        if kind != CommandKind::AcceptProposal && answering.is_none() {
            return Ok(());
        }
        let Some(k) = self
            .kept
            .as_ref()
            .filter(|k| k.proposal.session_id == session)
        else {
            return Err(format!("no proposal is open in session {session}"));
        };
        let p = &k.proposal;
        if let Some(step) = answering
            && step != p.step
        {
            return Err(format!(
                "the proposal for sequence {step} is not open (the newest is for sequence {}, {})",
                p.step,
                proposal_status_name(p.status)
            ));
        }
        if !k.is_open() {
            return Err(format!(
                "the proposal for sequence {} is already settled ({})",
                p.step,
                proposal_status_name(p.status)
            ));
        }
        let feedback = match kind {
            CommandKind::OverrideEncouraging => "encourage",
            CommandKind::OverrideChallenging => "challenge",
            _ => return Ok(()),
        };
        if proposal_choices(p).contains(&feedback) {
            Ok(())
        } else {
            Err(format!(
                "sequence {} has no level to repeat: {feedback} is not offered",
                p.step
            ))
        }
    }
}
