//! Presenting a sequence: the feedback line with its face and gesture, then the emotions one
//! word (and face) at a time, then the task on the tablet; and the timers that drive it all.

use super::{GameManager, Phase, Timer};
use crate::protocol::{LogLevel, Output};
use crate::session_file::JournalEntry;
use qt_therapy_msgs::TabletTask;
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use sequence_game::{Emotion, Feedback};

impl GameManager {
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
        let max_run = self.params.max_identical_in_a_row as usize;
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
        let at = now + self.scaled_ns(self.params.feedback_time_s);
        self.after_robot(Timer::FeedbackDone, at);
    }

    fn start_words(&mut self, now: i64) {
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
        let per = self.scaled_ns(self.params.speaking_time_per_emotion_s);
        self.set_timer(Timer::Word(0), now + per / 2);
    }

    fn say_word(&mut self, i: usize) {
        let Some(emotion) = self.current.sequence.get(i).copied() else {
            return;
        };
        let act = self.utterances.emotion_word(emotion);
        self.act(act);
        let n = self.current.sequence.len();
        let per = self.scaled_ns(self.params.speaking_time_per_emotion_s);
        let t0 = self.current.words_started_ns;
        let slot_middle = |k: i64| t0 + per * k + per / 2;
        if i + 1 < n {
            self.after_robot(Timer::Word(i + 1), slot_middle(i as i64 + 1));
        } else {
            let total = self.scaled_ns(self.params.speaking_time_s(n));
            self.after_robot(Timer::SequenceSaid, (t0 + total).max(slot_middle(i as i64)));
        }
    }

    fn send_task(&mut self, now: i64) {
        let Some(s) = self.session.as_mut() else {
            return;
        };
        let sequence_id = s.next_sequence_id;
        s.next_sequence_id += 1;
        let (session_id, index) = (s.id.clone(), s.index);
        let timeout = self.scaled_ns(self.params.answer_timeout_s);
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
            header: Header::at(Time::from_nanos(now)),
            session_id,
            sequence_id,
            sequence_index: index,
            length: self.current.sequence.len() as u8,
            choices: Emotion::ALL.iter().map(|e| e.name().to_string()).collect(),
            timeout: (timeout as f64 * 1e-9) as f32,
        }));
        self.set_timer(Timer::AnswerTimeout, now + timeout);
    }

    pub(super) fn on_timer(&mut self, timer: Timer, now: i64) {
        match timer {
            Timer::PolicyDeadline { request_id } => self.on_policy_deadline(request_id, false, now),
            Timer::PolicyHeartbeatLook { request_id } => {
                self.on_policy_deadline(request_id, true, now)
            }
            Timer::SpeechDone => {
                self.current.speech_done = true;
                self.maybe_present(now);
            }
            Timer::FeedbackDone => self.start_words(now),
            Timer::Word(i) => self.say_word(i),
            Timer::SequenceSaid => self.send_task(now),
            Timer::AnswerTimeout => {
                let index = self.session.as_ref().map_or(0, |s| s.index);
                self.log(
                    LogLevel::WARN,
                    format!(
                        "sequence {index}: no answer within {} s: counted as wrong",
                        self.params.answer_timeout_s * self.params.time_scale
                    ),
                );
                self.current.timed_out = true;
                self.current.response_time =
                    (self.params.answer_timeout_s * self.params.time_scale) as f32;
                self.close_task(now);
            }
            Timer::Settled => self.finalize(now, true),
            Timer::ProposalRunsOut => self.on_proposal_runs_out(now),
        }
    }
}
