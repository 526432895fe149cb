//! Supervised autonomy (as SPARC does): a decision the policy is unsure of, because its state
//! is still hot (temperature above a parameter: few visits) or the user model's σ of
//! P(success) after the action is above a parameter (the rule: `user_models::supervision`),
//! is proposed to the therapist with a countdown. Accepted, or run out, it plays; an override replaces it; the session's end
//! withdraws it. Each step is published (ActionProposal) for the page and the bag, and the
//! response goes into the sequence's record with the decision's reason. The countdown stops
//! while the session is paused or held and starts again, whole, on resume.

use super::{GameManager, Phase, Plan, Timer};
use crate::protocol::{LogLevel, Output};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{ActionProposal, BehaviourState};
use sequence_game::{Feedback, Level, ModelInput, UserModelTable};
use session_tally::live_line::{level_and_feedback, proposal_answer, proposal_asked};
use user_models::supervision::{self, ProposalRule};

/// A proposal waiting for the therapist.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct OpenProposal {
    plan: Plan,
    /// As last published (PROPOSED).
    message: ActionProposal,
    proposed_ns: i64,
    /// Its countdown runs (a timer is set) until then; None while paused or held.
    deadline_ns: Option<i64>,
}

/// Why the policy is unsure of a decision.
struct Unsure {
    temperature: f64,
    success_std: Option<f64>,
    reason: String,
}

/// What became of a proposal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Settled {
    Accepted { command_id: u64 },
    Replaced { command_id: u64 },
    TimedOut,
}

/// An action in the therapist's words: `L2`, `L2 + encouraging`.
pub(super) fn action_words(level: Level, feedback: Feedback) -> String {
    level_and_feedback(level.get(), feedback as u8)
}

impl GameManager {
    /// Loads the user models' tables for the σ rule (`user_model_file`, read by the shell).
    pub fn with_user_models(mut self, tables: Vec<UserModelTable>) -> Self {
        self.user_models = tables;
        self
    }

    /// The σ of F^p for the sequence the action sets up, for the session's cluster (or the
    /// most cautious of the file's; `user_models::supervision::success_std`). What it means
    /// depends on the file's fit: with the paper's noise it is about 0 wherever the study saw
    /// the input at all (docs/game_manager.md).
    fn success_std(&self, level: Level, feedback: Feedback, previous_score: i8) -> Option<f64> {
        let input = ModelInput::new(level, feedback, previous_score).ok()?;
        let cluster = self.session.as_ref().map_or(-1, |s| s.cluster);
        supervision::success_std(&self.user_models, cluster.into(), input)
    }

    fn unsure(&self, plan: &Plan, temperature: f64) -> Option<Unsure> {
        if !self.params.supervised_autonomy {
            return None;
        }
        let previous_score = self.session.as_ref()?.state.previous_score;
        let success_std = self.success_std(plan.level, plan.feedback, previous_score);
        let rule = ProposalRule {
            above_temperature: self.params.propose_above_temperature,
            above_success_std: self.params.propose_above_success_std,
        };
        let reasons: Vec<String> = rule
            .reasons(temperature, success_std)
            .iter()
            .map(|r| r.to_string())
            .collect();
        (!reasons.is_empty()).then(|| Unsure {
            temperature,
            success_std,
            reason: reasons.join(" and "),
        })
    }

    /// The policy's plan for the current sequence: played at once when the policy is sure of
    /// it, else proposed to the therapist.
    pub(super) fn take_policy_plan(&mut self, plan: Plan, temperature: f64, now: i64) {
        match self.unsure(&plan, temperature) {
            None => {
                self.current.plan = Some(plan);
                self.maybe_present(now);
            }
            Some(unsure) => self.propose(plan, unsure, now),
        }
    }

    fn propose(&mut self, plan: Plan, unsure: Unsure, now: i64) {
        let Some(s) = self.session.as_ref() else {
            return;
        };
        let countdown_ns = self.scaled_ns(self.params.proposal_countdown_s);
        let message = ActionProposal {
            header: Header::at(Time::from_nanos(now)),
            session_id: s.id.clone(),
            // Its time of proposing: one id for every message of this proposal.
            proposal_id: u64::try_from(now).unwrap_or_default(),
            step: s.index,
            state: BehaviourState::from_state(s.state),
            action: plan.action.index() as u8,
            level: plan.level.get(),
            feedback: plan.feedback as u8,
            temperature: unsure.temperature,
            success_std: unsure.success_std.unwrap_or(-1.0),
            reason: unsure.reason,
            countdown: (countdown_ns as f64 * 1e-9) as f32,
            status: ActionProposal::PROPOSED,
            ..Default::default()
        };
        let index = s.index;
        if let Some(s) = self.session.as_mut() {
            s.proposals.proposed += 1;
        }
        self.out.push(Output::LiveLine(format!(
            "sequence {index}: the policy is unsure ({}): {} proposed to the therapist",
            message.reason,
            action_words(plan.level, plan.feedback)
        )));
        self.current.proposal = Some(OpenProposal {
            plan,
            message,
            proposed_ns: now,
            deadline_ns: None,
        });
        if self.paused() {
            // Shown when the session goes on: a countdown nobody can act on is no choice.
            self.log(
                LogLevel::INFO,
                format!("sequence {index}: the proposal waits for the session to go on"),
            );
        } else {
            self.start_countdown(now);
        }
    }

    /// Starts (or starts again, on resume) the open proposal's countdown and shows it.
    pub(super) fn start_countdown(&mut self, now: i64) {
        let countdown_ns = self.scaled_ns(self.params.proposal_countdown_s);
        let index = self.session.as_ref().map_or(0, |s| s.index);
        let Some(p) = self.current.proposal.as_mut() else {
            return;
        };
        let deadline = now + countdown_ns;
        p.deadline_ns = Some(deadline);
        p.message.header = Header::at(Time::from_nanos(now));
        p.message.deadline = Time::from_nanos(deadline);
        let message = p.message.clone();
        let words = action_words(p.plan.level, p.plan.feedback);
        self.out.push(Output::Proposal(message.clone()));
        self.set_timer(Timer::ProposalRunsOut, deadline);
        self.status = format!(
            "sequence {index}: proposing {words} to the therapist ({}); played in {:.1} s \
             unless accepted or replaced",
            message.reason, message.countdown
        );
        self.publish_state(now);
    }

    /// Stops the open proposal's countdown for a pause or a hold.
    pub(super) fn stop_countdown(&mut self) {
        if let Some(p) = self.current.proposal.as_mut() {
            p.deadline_ns = None;
        }
        self.drop_timers(|t| *t != Timer::ProposalRunsOut);
    }

    /// The countdown ran out: the proposal plays.
    pub(super) fn on_proposal_runs_out(&mut self, now: i64) {
        let running = self
            .current
            .proposal
            .as_ref()
            .is_some_and(|p| p.deadline_ns.is_some_and(|d| d <= now));
        if running && self.phase == Phase::Deciding {
            self.settle_proposal(Settled::TimedOut, None, now);
        }
    }

    /// Settles the open proposal: `played` is the plan that replaces it (None: it plays
    /// itself). Returns false when none was open.
    pub(super) fn settle_proposal(&mut self, how: Settled, played: Option<Plan>, now: i64) -> bool {
        let Some(open) = self.current.proposal.take() else {
            return false;
        };
        self.drop_timers(|t| *t != Timer::ProposalRunsOut);
        let after_s = (now - open.proposed_ns) as f64 * 1e-9;
        let (status, command_id) = match how {
            Settled::Accepted { command_id } => (ActionProposal::ACCEPTED, command_id),
            Settled::Replaced { command_id } => (ActionProposal::REPLACED, command_id),
            Settled::TimedOut => (ActionProposal::TIMED_OUT, 0),
        };
        let mut plan = played.unwrap_or_else(|| open.plan.clone());
        let asked = proposal_asked(&open.message);
        let why = open.message.reason.clone();
        let message = ActionProposal {
            header: Header::at(Time::from_nanos(now)),
            status,
            played_action: plan.action.index() as u8,
            played_level: plan.level.get(),
            played_feedback: plan.feedback as u8,
            command_id,
            response_time: after_s as f32,
            ..open.message
        };
        let index = message.step;
        let answer = proposal_answer(&message);
        plan.reason = format!(
            "{}; proposed to the therapist: {asked}, as {why}: {answer}",
            plan.reason
        );
        self.out.push(Output::Proposal(message));
        if let Some(s) = self.session.as_mut() {
            match how {
                Settled::Accepted { .. } => s.proposals.accepted += 1,
                Settled::Replaced { .. } => s.proposals.replaced += 1,
                Settled::TimedOut => s.proposals.timed_out += 1,
            }
        }
        let played_words = action_words(plan.level, plan.feedback);
        let line = format!("sequence {index}: proposal {asked} {answer}; {played_words} plays");
        self.out.push(Output::LiveLine(line.clone()));
        self.status = line;
        self.current.plan = Some(plan);
        self.publish_state(now);
        self.maybe_present(now);
        true
    }

    /// The session ends with a proposal open: nothing of it plays.
    pub(super) fn withdraw_proposal(&mut self, now: i64) {
        let Some(open) = self.current.proposal.take() else {
            return;
        };
        self.out.push(Output::Proposal(ActionProposal {
            header: Header::at(Time::from_nanos(now)),
            status: ActionProposal::WITHDRAWN,
            response_time: ((now - open.proposed_ns) as f64 * 1e-9) as f32,
            ..open.message
        }));
    }
}
