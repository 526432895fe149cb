//! Getting the action for the current sequence: a therapist override wins, else the policy's
//! decision if it comes in time and fits the state, else the safe fallback (same level, no
//! feedback; level 1 on the first sequence).

use super::propose::{Settled, action_words};
use super::{GameManager, Phase, Plan, PolicySilence, Timer};
use crate::protocol::{LogLevel, Output};
use qt_therapy_msgs::topics::BEHAVIOUR_POLICY_NODE;
use qt_therapy_msgs::{BehaviourState, DecideActionRequest, DecideActionResponse, Validate};
use sequence_game::{Action, Feedback, Level};
use session_tally::live_line::decision_reason;

/// A silence in the policy's heartbeat (10 Hz) that says it may be dead rather than slow:
/// five heartbeats missed.
const POLICY_SILENT_NS: i64 = 500_000_000;

impl GameManager {
    /// Asks the policy for the current sequence's action, unless the therapist already chose.
    pub(super) fn request_decision(&mut self, now: i64) {
        if self.apply_override(now) {
            return;
        }
        let Some(s) = self.session.as_ref() else {
            return;
        };
        if self.current.policy_silence == PolicySilence::Waiting {
            self.current.policy_silence = PolicySilence::Waited;
        }
        let request_id = self.next_request_id;
        self.next_request_id += 1;
        let request = DecideActionRequest {
            session_id: s.id.clone(),
            user_id: s.user_id.clone(),
            user_model_cluster: s.cluster,
            state: BehaviourState::from_state(s.state),
            step: s.index,
            // Algorithm 1 learns a result before the next choice: the policy waits for this
            // one (results travel on a topic, requests on a service: either may come first).
            after_sequence: s.results.last().map_or(0, |r| r.sequence_index),
        };
        let deadline_ns = now + (self.params.timing.policy_deadline_s * 1e9).round() as i64;
        self.current.request_id = Some(request_id);
        self.out.push(Output::Decide {
            request_id,
            request,
            deadline_ns,
        });
        self.set_timer(Timer::PolicyDeadline { request_id }, deadline_ns);
    }

    /// Uses a pending override for the current sequence (replacing a proposal open for it);
    /// true if there was one.
    pub(super) fn apply_override(&mut self, now: i64) -> bool {
        let Some(s) = self.session.as_mut() else {
            return false;
        };
        let Some(o) = s.pending_override else {
            return false;
        };
        if o.sequence_index != s.index {
            return false;
        }
        s.pending_override = None;
        let index = s.index;
        let Some((level, feedback)) = o.action.apply(s.state) else {
            // Checked when the command came; a recovered journal may still hold one.
            let state = s.state;
            self.log(
                LogLevel::WARN,
                format!(
                    "sequence {index}: the therapist's {} cannot be played in state {state}: \
                     the policy decides",
                    o.action
                ),
            );
            return false;
        };
        s.overrides += 1;
        // A policy answer still on its way is ignored: the override always wins.
        self.current.request_id = None;
        let plan = Plan {
            action: o.action,
            level,
            feedback,
            overridden: true,
            fallback: false,
            reason: "therapist override".into(),
        };
        let words = action_words(level, feedback);
        let replaced = Settled::Replaced {
            command_id: o.command_id,
        };
        if !self.settle_proposal(replaced, Some(plan.clone()), now) {
            self.current.plan = Some(plan);
            self.status = format!("sequence {index}: {words} set by the therapist");
            self.publish_state(now);
        }
        true
    }

    pub(super) fn on_decision(
        &mut self,
        request_id: u64,
        response: Result<DecideActionResponse, String>,
        now: i64,
    ) {
        if self.phase != Phase::Deciding || self.current.request_id != Some(request_id) {
            self.log(
                LogLevel::INFO,
                format!("ignored a late or superseded policy answer (request {request_id})"),
            );
            return;
        }
        self.current.request_id = None;
        let plan = match response {
            Err(reason) => Err(format!("policy call failed: {reason}")),
            Ok(r) => self
                .plan_from_decision(&r)
                .map(|plan| (plan, r.decision.temperature)),
        };
        match plan {
            Ok((plan, temperature)) => self.take_policy_plan(plan, temperature, now),
            Err(reason) => self.fall_back(reason, now),
        }
    }

    /// The plan a policy answer gives, or why it cannot be used.
    fn plan_from_decision(&self, r: &DecideActionResponse) -> Result<Plan, String> {
        let s = self.session.as_ref().ok_or("no session")?;
        if !r.ok {
            return Err(format!("policy refused: {}", r.error));
        }
        r.validate().map_err(|e| e.to_string())?;
        let d = &r.decision;
        if d.step != s.index {
            return Err(format!(
                "decision is for step {}, expected {}",
                d.step, s.index
            ));
        }
        let action = Action::new(d.action.into()).map_err(|e| e.to_string())?;
        let (level, feedback) = action
            .apply(s.state)
            .ok_or_else(|| format!("{action} is not allowed in state {}", s.state))?;
        if d.level != level.get() || d.feedback != feedback as u8 {
            return Err(format!(
                "decision says level {} feedback {} but {action} gives {level} feedback {}",
                d.level, d.feedback, feedback as u8
            ));
        }
        Ok(Plan {
            action,
            level,
            feedback,
            overridden: false,
            fallback: false,
            reason: decision_reason(d),
        })
    }

    /// At the policy's deadline (`second_look` false), or at the look at its heartbeat that
    /// the deadline put off (true). With the session going on, a policy whose heartbeat is
    /// silent too, as it is for a process that died shortly before or after the request and
    /// that the watch cannot call lost yet, is waited for: its next heartbeat asks it again,
    /// its loss holds the session, and its answer to the request still counts meanwhile. A
    /// policy heard less than [`POLICY_SILENT_NS`] ago may have died since, so the deadline
    /// looks again once it would count as silent: the fallback waits at most that long for
    /// a policy that beats but does not answer, and a death just before the deadline is
    /// waited for too. Else the fallback, or, paused or held, a new request on resume.
    pub(super) fn on_policy_deadline(&mut self, request_id: u64, second_look: bool, now: i64) {
        if self.phase != Phase::Deciding || self.current.request_id != Some(request_id) {
            return;
        }
        let may_wait = self.current.policy_silence == PolicySilence::NotWaited && !self.paused();
        if let Some(silent_ns) = self.watched.silent_ns(BEHAVIOUR_POLICY_NODE, now)
            && may_wait
        {
            if silent_ns >= POLICY_SILENT_NS {
                self.wait_for_silent_policy(silent_ns, now);
                return;
            }
            if !second_look {
                let look_at = now + POLICY_SILENT_NS - silent_ns;
                self.set_timer(Timer::PolicyHeartbeatLook { request_id }, look_at);
                return;
            }
        }
        self.current.request_id = None;
        let s = self.params.timing.policy_deadline_s;
        if self.paused() {
            // Nothing plays while held (a lost policy is the likely cause) or paused, so
            // waiting costs the child nothing: the policy is asked again when the session
            // goes on, rather than a fallback played.
            self.log(
                LogLevel::INFO,
                format!(
                    "the policy did not answer within {s} s while the session was paused or \
                     held; it is asked again when the session goes on"
                ),
            );
        } else {
            self.fall_back(format!("the policy did not answer within {s} s"), now);
        }
    }

    /// Waits for a policy silent at its deadline (see [`Self::on_policy_deadline`]).
    fn wait_for_silent_policy(&mut self, silent_ns: i64, now: i64) {
        self.current.policy_silence = PolicySilence::Waiting;
        let index = self.session.as_ref().map_or(0, |s| s.index);
        let silent_s = silent_ns as f64 * 1e-9;
        self.log(
            LogLevel::WARN,
            format!(
                "sequence {index}: the policy did not answer within {} s and has sent no \
                 heartbeat for {silent_s:.1} s: waiting for its next heartbeat (it is then \
                 asked again) or its loss (the session is then held) rather than playing the \
                 fallback",
                self.params.timing.policy_deadline_s
            ),
        );
        self.status =
            format!("sequence {index}: waiting for the behaviour policy (silent {silent_s:.1} s)");
        self.publish_state(now);
    }

    /// A heartbeat of the policy: asks it again if the current sequence waits for it.
    pub(super) fn on_policy_heard(&mut self, now: i64) {
        if self.current.policy_silence == PolicySilence::Waiting
            && !self.paused()
            && self.phase == Phase::Deciding
            && self.current.plan.is_none()
            && !self.proposals.is_open()
        {
            self.ask_policy_again("the policy is heard again", now);
        }
    }

    /// A new request for the current sequence. One still pending may have gone to a process
    /// that died meanwhile: its answer, if any, is superseded (ignored by its id).
    pub(super) fn ask_policy_again(&mut self, why: &str, now: i64) {
        if let Some(old) = self.current.request_id.take() {
            self.log(
                LogLevel::INFO,
                format!("{why}: asking the policy again (request {old} still unanswered)"),
            );
        }
        self.request_decision(now);
    }

    /// Same level, no feedback (level 1 on the first sequence).
    pub(super) fn fall_back(&mut self, reason: String, now: i64) {
        let Some(s) = self.session.as_mut() else {
            return;
        };
        let level = s.state.level().unwrap_or(Level::ONE);
        s.fallbacks += 1;
        let index = s.index;
        self.log(
            LogLevel::WARN,
            format!("sequence {index}: safe fallback ({level}, no feedback): {reason}"),
        );
        self.current.plan = Some(Plan {
            action: Action::SetLevel(level),
            level,
            feedback: Feedback::None,
            overridden: false,
            fallback: true,
            reason: format!("safe fallback: {reason}"),
        });
        self.status = format!("policy fallback for sequence {index}: {reason}");
        self.publish_state(now);
        self.maybe_present(now);
    }
}
