//! One sequence played: the feedback line with its face and gesture, then the emotions one
//! word (and face) at a time, then the task on the tablet; the answer (or the timeout); the
//! wait for the period's last engagement windows; the score and the record; then the next
//! sequence's decision, or the session's end after the last. Each step is a phase of the
//! game, and this is where it changes.

use super::{Current, GameManager, Phase, Timer};
use crate::protocol::{LogLevel, Output};
use crate::session_file::{JournalEntry, SequenceRecord, SessionEnd};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{BehaviourState, SequenceResult, TabletAnswer, TabletTask};
use sequence_game::{Emotion, Feedback, State, parse_answer, score};
use session_tally::live_line::sequence_line;

impl GameManager {
    /// The introduction or the reaction has been said: the sequence may be presented.
    pub(super) fn speech_done(&mut self, now: i64) {
        self.current.speech_done = true;
        self.maybe_present(now);
    }

    /// Starts the presentation once the action is known, the robot is quiet and not paused.
    pub(super) fn maybe_present(&mut self, now: i64) {
        if self.phase == Phase::Deciding
            && self.current.plan.is_some()
            && self.current.speech_done
            && !self.paused()
        {
            self.start_presentation(now);
        }
    }

    /// Feedback (if any), then the words; again from the start after a pause.
    pub(super) fn start_presentation(&mut self, now: i64) {
        let Some(plan) = self.current.plan.clone() else {
            return;
        };
        let max_run = self.params.session.max_identical_in_a_row as usize;
        let index = self.session.as_ref().map_or(0, |s| s.index);
        if self.current.sequence.is_empty()
            && let Some(s) = self.session.as_mut()
        {
            self.current.sequence = s.rng.sequence(plan.level, max_run);
        }
        if plan.feedback == Feedback::None {
            self.start_words(now);
            return;
        }
        let count = self.utterances.feedback_line_count(plan.feedback);
        let line = match (self.current.feedback_line, self.session.as_mut()) {
            (Some(l), _) => l,
            (None, Some(s)) => s.rng.line(count),
            (None, None) => 0,
        };
        self.current.feedback_line = Some(line);
        self.set_phase(
            Phase::GivingFeedback,
            format!("sequence {index}: {} feedback", plan.feedback.name()),
            now,
        );
        if let Some(act) = self.utterances.feedback(plan.feedback, line) {
            self.act(act);
        }
        let at = now + self.scaled_ns(self.params.timing.feedback_time_s);
        self.after_robot(Timer::FeedbackDone, at);
    }

    pub(super) fn start_words(&mut self, now: i64) {
        let index = self.session.as_ref().map_or(0, |s| s.index);
        let n = self.current.sequence.len();
        self.current.words_started_ns = now;
        self.set_phase(
            Phase::SayingSequence,
            format!("sequence {index}: saying {n} emotions"),
            now,
        );
        // Each word sits in the middle of its slot: the robot takes a breath first, and a
        // listener that follows GameState (DDS does not order messages across topics) has
        // SAYING_SEQUENCE before the first face.
        let per = self.scaled_ns(self.params.timing.speaking_time_per_emotion_s);
        self.set_timer(Timer::Word(0), now + per / 2);
    }

    pub(super) fn say_word(&mut self, i: usize) {
        let Some(emotion) = self.current.sequence.get(i).copied() else {
            return;
        };
        let act = self.utterances.emotion_word(emotion);
        self.act(act);
        let n = self.current.sequence.len();
        let per = self.scaled_ns(self.params.timing.speaking_time_per_emotion_s);
        let t0 = self.current.words_started_ns;
        let slot_middle = |k: i64| t0 + per * k + per / 2;
        if i + 1 < n {
            self.after_robot(Timer::Word(i + 1), slot_middle(i as i64 + 1));
        } else {
            let total = self.scaled_ns(self.params.timing.speaking_time_s(n));
            self.after_robot(Timer::SequenceSaid, (t0 + total).max(slot_middle(i as i64)));
        }
    }

    pub(super) fn send_task(&mut self, now: i64) {
        let Some(s) = self.session.as_mut() else {
            return;
        };
        let sequence_id = s.next_sequence_id;
        s.next_sequence_id += 1;
        let (session_id, index) = (s.id.clone(), s.index);
        let timeout = self.scaled_ns(self.params.timing.answer_timeout_s);
        // Journalled first: a restarted node must not send this id again (tablets ignore a
        // task id they already saw).
        self.out.push(Output::Journal(Box::new(JournalEntry::Task {
            session_id: session_id.clone(),
            task_id: sequence_id,
            sequence_index: index,
            at_ns: now,
        })));
        self.current.sequence_id = sequence_id;
        self.current.task_sent_ns = now;
        self.current.answer_deadline_ns = now + timeout;
        self.set_phase(
            Phase::WaitingForAnswer,
            format!("sequence {index}: waiting for the answer (task {sequence_id})"),
            now,
        );
        self.out.push(Output::Task(TabletTask {
            header: Header::at(self.stamp(now)),
            session_id,
            sequence_id,
            sequence_index: index,
            length: self.current.sequence.len() as u8,
            choices: Emotion::ALL.iter().map(|e| e.name().to_string()).collect(),
            timeout: (timeout as f64 * 1e-9) as f32,
        }));
        self.set_timer(Timer::AnswerTimeout, now + timeout);
    }

    /// No answer within the task's time: counted as wrong.
    pub(super) fn answer_timed_out(&mut self, now: i64) {
        let index = self.session.as_ref().map_or(0, |s| s.index);
        self.log(
            LogLevel::WARN,
            format!(
                "sequence {index}: no answer within {} s: counted as wrong",
                self.params.timing.answer_timeout_s * self.params.timing.time_scale
            ),
        );
        self.current.timed_out = true;
        self.current.response_time =
            (self.params.timing.answer_timeout_s * self.params.timing.time_scale) as f32;
        self.close_task(now);
    }

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
        let ready_at =
            self.current.task_sent_ns + (self.params.timing.engagement_wait_s * 1e9) as i64;
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
            header: Header::at(Time::from_nanos(self.clock.wall_of(now))),
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
            // Both ends stamped by the wall clock's offset now: one clock, whatever step came
            // between them.
            engagement_period_start: Time::from_nanos(self.clock.wall_of(s.talk_start_ns)),
            engagement_period_end: Time::from_nanos(self.clock.wall_of(c.task_sent_ns)),
            response_time: c.response_time,
            sequences_planned: self.params.session.sequences_per_session as u8,
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
        let last = s.index >= self.params.session.sequences_per_session as u8;
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
            let at = now + self.scaled_ns(self.params.timing.reaction_time_s);
            self.after_robot(Timer::SpeechDone, at);
        }
        self.request_decision(now);
    }
}
