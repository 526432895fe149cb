//! Supervised autonomy (as SPARC does): a decision the policy is unsure of, because its state
//! is still hot (temperature above a parameter: few visits) or the user model's σ of
//! P(success) after the action is above a parameter (the rule: `user_models::supervision`),
//! is proposed to the therapist with a countdown. Accepted, or run out, it plays; an override
//! replaces it; the session's end withdraws it. Each step is published (ActionProposal) for
//! the page and the bag, and the response goes into the sequence's record with the decision's
//! reason. The countdown stops while the session is paused or held and starts again, whole,
//! on resume. The proposal desk ([`ProposalDesk`]) keeps the open proposal, its countdown and
//! the session's counts; the game manager's methods here put out what it says and decide
//! what follows.

use super::{GameManager, Phase, Plan, Timer};
use crate::params::SupervisionParams;
use crate::protocol::{LogLevel, Output};
use clock_steps::ClockSteps;
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{ActionProposal, BehaviourState};
use sequence_game::{Feedback, Level, ModelInput, State, UserModelTable};
use session_tally::live_line::{level_and_feedback, proposal_answer, proposal_asked};
use user_models::supervision::{self, ProposalRule};

/// A proposal waiting for the therapist.
#[derive(Debug, Clone, PartialEq)]
struct OpenProposal {
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

/// What became of a session's proposals.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct ProposalCounts {
    pub(super) proposed: u32,
    pub(super) accepted: u32,
    pub(super) replaced: u32,
    pub(super) timed_out: u32,
}

/// An action in the therapist's words: `L2`, `L2 + encouraging`.
pub(super) fn action_words(level: Level, feedback: Feedback) -> String {
    level_and_feedback(level.get(), feedback as u8)
}

/// The proposal desk: whether a decision is proposed, the proposal open (at most one: the
/// current sequence's) with its countdown, and what became of the session's proposals.
#[derive(Debug)]
pub(super) struct ProposalDesk {
    /// Off: every decision plays at once.
    enabled: bool,
    rule: ProposalRule,
    /// The user models' tables the σ rule reads (empty: that rule is off).
    user_models: Vec<UserModelTable>,
    /// A countdown's length, on the game's time scale.
    countdown_ns: i64,
    open: Option<OpenProposal>,
    counts: ProposalCounts,
}

impl ProposalDesk {
    /// A desk with the supervision parameters, its countdowns on the game's `time_scale`.
    pub(super) fn new(params: &SupervisionParams, time_scale: f64) -> Self {
        ProposalDesk {
            enabled: params.supervised_autonomy,
            rule: ProposalRule {
                above_temperature: params.propose_above_temperature,
                above_success_std: params.propose_above_success_std,
            },
            user_models: Vec::new(),
            countdown_ns: (params.proposal_countdown_s * time_scale * 1e9).round() as i64,
            open: None,
            counts: ProposalCounts::default(),
        }
    }

    /// New supervision settings (between sessions: no proposal is open); the user models
    /// stay.
    pub(super) fn set_params(&mut self, params: &SupervisionParams, time_scale: f64) {
        let desk = ProposalDesk::new(params, time_scale);
        self.enabled = desk.enabled;
        self.rule = desk.rule;
        self.countdown_ns = desk.countdown_ns;
    }

    pub(super) fn has_user_models(&self) -> bool {
        !self.user_models.is_empty()
    }

    pub(super) fn set_user_models(&mut self, tables: Vec<UserModelTable>) {
        self.user_models = tables;
    }

    /// A new (or taken-over) session: no proposal open, none counted (a taken-over session's
    /// proposals live in the bag, not in its files).
    pub(super) fn new_session(&mut self) {
        self.open = None;
        self.counts = ProposalCounts::default();
    }

    pub(super) fn counts(&self) -> ProposalCounts {
        self.counts
    }

    pub(super) fn is_open(&self) -> bool {
        self.open.is_some()
    }

    /// The σ of F^p for the sequence the action sets up, for the session's cluster (or the
    /// most cautious of the file's; `user_models::supervision::success_std`). What it means
    /// depends on the file's fit: with the paper's noise it is about 0 wherever the study saw
    /// the input at all (docs/game_manager.md).
    fn success_std(&self, plan: &Plan, cluster: i32, previous_score: i8) -> Option<f64> {
        let input = ModelInput::new(plan.level, plan.feedback, previous_score).ok()?;
        supervision::success_std(&self.user_models, cluster.into(), input)
    }

    /// Why the policy is unsure of `plan` at `temperature`, if it is and proposals are on.
    fn unsure(&self, plan: &Plan, temperature: f64, cluster: i32, state: State) -> Option<Unsure> {
        if !self.enabled {
            return None;
        }
        let success_std = self.success_std(plan, cluster, state.previous_score);
        let reasons: Vec<String> = self
            .rule
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

    /// Opens a proposal of `plan` (its countdown not started yet); the message as proposed.
    fn open(&mut self, plan: Plan, message: ActionProposal, now: i64) -> &ActionProposal {
        self.counts.proposed += 1;
        &self
            .open
            .insert(OpenProposal {
                plan,
                message,
                proposed_ns: now,
                deadline_ns: None,
            })
            .message
    }

    /// Starts (or starts again) the open proposal's countdown: the message that shows it and
    /// its deadline.
    fn start_countdown(&mut self, now: i64, clock: &ClockSteps) -> Option<(&OpenProposal, i64)> {
        let p = self.open.as_mut()?;
        let deadline = now + self.countdown_ns;
        p.deadline_ns = Some(deadline);
        p.message.header = Header::at(Time::from_nanos(clock.wall_of(now)));
        p.message.deadline = Time::from_nanos(clock.wall_of(deadline));
        Some((p, deadline))
    }

    /// Stops the open proposal's countdown.
    fn stop_countdown(&mut self) {
        if let Some(p) = self.open.as_mut() {
            p.deadline_ns = None;
        }
    }

    /// Whether the open proposal's countdown has run out by `now`.
    fn ran_out(&self, now: i64) -> bool {
        self.open
            .as_ref()
            .is_some_and(|p| p.deadline_ns.is_some_and(|d| d <= now))
    }

    /// Settles the open proposal: `played` is the plan that replaces it (None: it plays
    /// itself). The message that says so and the plan that plays, its reason telling what
    /// the therapist was asked and answered; None when none was open.
    fn settle(
        &mut self,
        how: Settled,
        played: Option<Plan>,
        now: i64,
        clock: &ClockSteps,
    ) -> Option<(ActionProposal, Plan)> {
        let open = self.open.take()?;
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
            header: Header::at(Time::from_nanos(clock.wall_of(now))),
            status,
            played_action: plan.action.index() as u8,
            played_level: plan.level.get(),
            played_feedback: plan.feedback as u8,
            command_id,
            response_time: after_s as f32,
            ..open.message
        };
        let answer = proposal_answer(&message);
        plan.reason = format!(
            "{}; proposed to the therapist: {asked}, as {why}: {answer}",
            plan.reason
        );
        match how {
            Settled::Accepted { .. } => self.counts.accepted += 1,
            Settled::Replaced { .. } => self.counts.replaced += 1,
            Settled::TimedOut => self.counts.timed_out += 1,
        }
        Some((message, plan))
    }

    /// Withdraws the open proposal (nothing of it plays): the message that says so.
    fn withdraw(&mut self, now: i64, clock: &ClockSteps) -> Option<ActionProposal> {
        let open = self.open.take()?;
        Some(ActionProposal {
            header: Header::at(Time::from_nanos(clock.wall_of(now))),
            status: ActionProposal::WITHDRAWN,
            response_time: ((now - open.proposed_ns) as f64 * 1e-9) as f32,
            ..open.message
        })
    }
}

impl GameManager {
    /// Loads the user models' tables for the σ rule (`user_model_file`, read by the shell).
    pub fn with_user_models(mut self, tables: Vec<UserModelTable>) -> Self {
        self.proposals.user_models = tables;
        self
    }

    /// The policy's plan for the current sequence: played at once when the policy is sure of
    /// it, else proposed to the therapist.
    pub(super) fn take_policy_plan(&mut self, plan: Plan, temperature: f64, now: i64) {
        let unsure = self.session.as_ref().and_then(|s| {
            self.proposals
                .unsure(&plan, temperature, s.cluster, s.state)
        });
        match unsure {
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
        let message = ActionProposal {
            header: Header::at(Time::from_nanos(self.clock.wall_of(now))),
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
            countdown: (self.proposals.countdown_ns as f64 * 1e-9) as f32,
            status: ActionProposal::PROPOSED,
            ..Default::default()
        };
        let index = s.index;
        let words = action_words(plan.level, plan.feedback);
        let reason = &self.proposals.open(plan, message, now).reason;
        self.out.push(Output::LiveLine(format!(
            "sequence {index}: the policy is unsure ({reason}): {words} proposed to the therapist"
        )));
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
        let index = self.session.as_ref().map_or(0, |s| s.index);
        let Some((p, deadline)) = self.proposals.start_countdown(now, &self.clock) else {
            return;
        };
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
        self.proposals.stop_countdown();
        self.drop_timers(|t| *t != Timer::ProposalRunsOut);
    }

    /// The countdown ran out: the proposal plays.
    pub(super) fn on_proposal_runs_out(&mut self, now: i64) {
        if self.proposals.ran_out(now) && self.phase == Phase::Deciding {
            self.settle_proposal(Settled::TimedOut, None, now);
        }
    }

    /// Settles the open proposal: `played` is the plan that replaces it (None: it plays
    /// itself). Returns false when none was open.
    pub(super) fn settle_proposal(&mut self, how: Settled, played: Option<Plan>, now: i64) -> bool {
        let Some((message, plan)) = self.proposals.settle(how, played, now, &self.clock) else {
            return false;
        };
        self.drop_timers(|t| *t != Timer::ProposalRunsOut);
        let index = message.step;
        let asked = proposal_asked(&message);
        let answer = proposal_answer(&message);
        self.out.push(Output::Proposal(message));
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
        if let Some(message) = self.proposals.withdraw(now, &self.clock) {
            self.out.push(Output::Proposal(message));
        }
    }
}
