//! The end of a sequence and of a session: take the answer (or the timeout), wait for the
//! period's last engagement windows, score and record it, move on; and end the session with
//! its summary on finish, stop, emergency stop or shutdown.

use super::{Current, GameManager, Phase, Timer};
use crate::protocol::Output;
use crate::session_file::{SequenceRecord, SessionEnd, SessionSummary};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{BehaviourState, SequenceResult, TabletAnswer};
use sequence_game::{Emotion, State};
use sequence_game::{parse_answer, score};
use session_tally::Tally;
use session_tally::live_line::sequence_line;

impl GameManager {
    pub(super) fn on_answer(&mut self, a: TabletAnswer, now: i64) {
        match self.check_answer(&a) {
            Ok(emotions) => {
                self.current.answer = Some(emotions);
                self.current.response_time = a.response_time;
                self.close_task(now);
            }
            Err(reason) => {
                if let Some(s) = self.session.as_mut() {
                    s.rejected_answers += 1;
                }
                if self.phase == Phase::WaitingForAnswer {
                    self.current.rejected_answers += 1;
                }
                let what = format!("answer {} for session {:?}", a.sequence_id, a.session_id);
                self.reject(format!("{what}: {reason}"), now);
            }
        }
    }

    /// The tapped emotions, if this answer is the one the current task waits for.
    fn check_answer(&self, a: &TabletAnswer) -> Result<Vec<Emotion>, String> {
        let Some(s) = self.session.as_ref().filter(|_| self.session_running()) else {
            return Err("no session is running".into());
        };
        if a.session_id != s.id {
            return Err(format!("wrong session: session {:?} is running", s.id));
        }
        if let Some((id, timed_out)) = s.closed_task
            && id == a.sequence_id
        {
            return Err(if timed_out {
                "came after the task had timed out".into()
            } else {
                "duplicate: this task was already answered".into()
            });
        }
        if self.phase != Phase::WaitingForAnswer {
            return Err("no task is waiting for an answer".into());
        }
        if a.sequence_id != self.current.sequence_id {
            return Err(format!(
                "for another task: waiting for task {}",
                self.current.sequence_id
            ));
        }
        parse_answer(
            &a.answer,
            f64::from(a.response_time),
            self.current.sequence.len(),
        )
        .map_err(|e| e.to_string())
    }

    /// Answered or timed out: score once the engagement of the talking period is in.
    pub(super) fn close_task(&mut self, now: i64) {
        self.drop_timers(|t| *t != Timer::AnswerTimeout);
        self.current.answered_ns = now;
        let timed_out = self.current.timed_out;
        if let Some(s) = self.session.as_mut() {
            s.closed_task = Some((self.current.sequence_id, timed_out));
        }
        let ready_at = self.current.task_sent_ns + (self.params.engagement_wait_s * 1e9) as i64;
        if now >= ready_at {
            self.finalize(now, true);
        } else {
            self.phase = Phase::Settling;
            self.set_timer(Timer::Settled, ready_at);
        }
    }

    /// Scores and records the current sequence, then moves on (unless `go_on` is false,
    /// when the session is ending).
    pub(super) fn finalize(&mut self, now: i64, go_on: bool) {
        self.drop_timers(|t| *t != Timer::Settled);
        let (Some(plan), Some(s)) = (self.current.plan.clone(), self.session.as_mut()) else {
            return;
        };
        let c = std::mem::take(&mut self.current);
        let scored = score(plan.level, &c.sequence, c.answer.as_deref());
        let engagement = self.engagement.gather(s.talk_start_ns, c.task_sent_ns);
        let names = |v: &[Emotion]| v.iter().map(|e| e.name().to_string()).collect();
        let result = SequenceResult {
            header: Header::at(Time::from_nanos(now)),
            session_id: s.id.clone(),
            user_id: s.user_id.clone(),
            user_model_cluster: s.cluster,
            sequence_index: s.index,
            state: BehaviourState::from_state(s.state),
            action: plan.action.index() as u8,
            level: plan.level.get(),
            feedback: plan.feedback as u8,
            overridden: plan.overridden,
            sequence: names(&c.sequence),
            answer: c.answer.as_deref().map(names).unwrap_or_default(),
            outcome: scored.outcome.sign(),
            timed_out: c.timed_out,
            activity_result: scored.activity_result as f32,
            engagement: engagement.mean,
            engagement_per_second: engagement.per_second,
            engagement_period_start: Time::from_nanos(s.talk_start_ns),
            engagement_period_end: Time::from_nanos(c.task_sent_ns),
            response_time: c.response_time,
            sequences_planned: self.params.sequences_per_session as u8,
        };
        let record = SequenceRecord {
            result: result.clone(),
            policy_fallback: plan.fallback,
            decision_reason: plan.reason.clone(),
            talk_start_ns: s.talk_start_ns,
            task_sent_ns: c.task_sent_ns,
            answered_ns: c.answered_ns,
            rejected_answers: c.rejected_answers,
        };
        s.state = State::after(plan.level, plan.feedback, scored.outcome);
        s.talk_start_ns = c.answered_ns;
        s.results.push(result.clone());
        let last = s.index >= self.params.sequences_per_session as u8;
        let line = sequence_line(&result, &plan.reason);
        self.engagement.forget_before(c.answered_ns);
        self.out.push(Output::Record(Box::new(record)));
        self.out.push(Output::Result(result));
        self.out.push(Output::LiveLine(line));
        if !go_on {
            return;
        }
        let correct = scored.outcome.sign() > 0;
        if last {
            if !self.paused() {
                let act = self.utterances.reaction(correct, true);
                self.act(act);
            }
            self.end_session(SessionEnd::Finished, "all sequences played", now);
            return;
        }
        let Some(s) = self.session.as_mut() else {
            return;
        };
        s.index += 1;
        let index = s.index;
        self.current = Current::default();
        self.set_phase(
            Phase::Deciding,
            format!("deciding sequence {index}/{}", self.sequences()),
            now,
        );
        if self.paused() {
            // No robot output while paused; the reaction is skipped.
            self.current.speech_done = true;
        } else {
            let act = self.utterances.reaction(correct, false);
            self.act(act);
            let at = now + self.scaled_ns(self.params.reaction_time_s);
            self.after_robot(Timer::SpeechDone, at);
        }
        self.request_decision(now);
    }

    /// Ends the session: scores an answered sequence first, says goodbye on a stop, silences
    /// the robot at once on an emergency stop, and writes the summary.
    pub(super) fn end_session(&mut self, end: SessionEnd, reason: &str, now: i64) {
        if end == SessionEnd::EmergencyStopped {
            self.silence_robot(now);
        }
        if self.phase == Phase::Settling {
            self.finalize(now, false);
        }
        // After the last answer the phase still reads "waiting"; a finished session has no
        // interrupted sequence.
        let interrupted = end != SessionEnd::Finished
            && matches!(
                self.phase,
                Phase::GivingFeedback | Phase::SayingSequence | Phase::WaitingForAnswer
            );
        if end == SessionEnd::Stopped {
            let act = self.utterances.goodbye();
            self.act(act);
        }
        self.withdraw_proposal(now);
        self.timers.forget_all();
        self.drop_robot_step();
        self.current = Current::default();
        let proposals = self.proposals.counts();
        let Some(s) = self.session.as_mut() else {
            return;
        };
        s.paused_since = None;
        s.held_since = None;
        let tally = Tally::of(&s.results);
        let summary = SessionSummary {
            session_id: s.id.clone(),
            user_id: s.user_id.clone(),
            user_model_cluster: s.cluster,
            end,
            reason: reason.to_string(),
            sequences_planned: self.params.sequences_per_session as u8,
            sequences_played: s.results.len() as u8,
            interrupted_sequence: interrupted.then_some(s.index),
            correct: tally.correct as u32,
            timeouts: tally.timeouts as u32,
            score: tally.score,
            max_score: tally.max_score,
            mean_engagement: tally.mean_engagement,
            overrides: s.overrides,
            proposals: proposals.proposed,
            proposals_accepted: proposals.accepted,
            proposals_replaced: proposals.replaced,
            proposals_timed_out: proposals.timed_out,
            policy_fallbacks: s.fallbacks,
            rejected_commands: s.rejected_commands,
            rejected_answers: s.rejected_answers,
            seed: self.params.seed,
            language: self.params.language.clone(),
            started_ns: s.started_ns,
            ended_ns: now,
        };
        let line = format!(
            "session {:?} {reason}: {} of {} sequences, {} right, score {}/{}",
            s.id,
            summary.sequences_played,
            summary.sequences_planned,
            summary.correct,
            summary.score,
            summary.max_score
        );
        self.out.push(Output::Summary(Box::new(summary)));
        self.out.push(Output::LiveLine(line));
        self.set_phase(Phase::Ended(end), reason.to_string(), now);
    }
}
