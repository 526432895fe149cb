//! The session's phases: started by the therapist or taken over after a restart; paused by
//! the therapist or by a robot that did not finish; held while a watched node is lost; going
//! on again at the therapist's resume or when the node is back; and ended (all sequences
//! played, stop, emergency stop, shutdown). A pause or a hold stops what the robot is doing,
//! and going on picks it up where it stopped. The phases within one sequence (feedback,
//! words, task, answer, score) are `play.rs`'s.

use super::{Current, GameManager, Phase, Session, Timer};
use crate::protocol::{LogLevel, Output};
use crate::sequence::SessionRng;
use crate::session_file::{JournalEntry, SessionEnd, SessionSummary};
use qt_therapy_msgs::TherapistCommand;
use sequence_game::State;
use session_tally::Tally;

/// GameState.status of a session taken over after a restart, until the therapist acts.
pub const RECOVERED_STATUS: &str = "recovered after a game manager restart; resume to go on";

fn seconds(ns: i64) -> f64 {
    ns as f64 * 1e-9
}

impl GameManager {
    pub(super) fn start_session(&mut self, c: &TherapistCommand, now: i64) {
        self.used_sessions.insert(c.session_id.clone());
        self.out
            .push(Output::Journal(Box::new(JournalEntry::Started {
                session_id: c.session_id.clone(),
                user_id: c.user_id.clone(),
                user_model_cluster: c.user_model_cluster,
                command_id: c.command_id,
                at_ns: now,
            })));
        self.engagement.clear();
        self.timers.forget_all();
        self.proposals.new_session();
        self.current = Current::default();
        self.session = Some(Session {
            id: c.session_id.clone(),
            user_id: c.user_id.clone(),
            cluster: c.user_model_cluster,
            last_command_id: c.command_id,
            rng: SessionRng::new(self.params.session.seed, &c.session_id),
            state: State::START,
            index: 1,
            next_sequence_id: 1,
            pending_override: None,
            paused_since: None,
            held_since: None,
            talk_start_ns: now,
            started_ns: now,
            results: Vec::new(),
            closed_task: None,
            fallbacks: 0,
            overrides: 0,
            rejected_commands: 0,
            rejected_answers: 0,
        });
        self.out.push(Output::LiveLine(format!(
            "session {:?} started for user {:?} (cluster {}), command {}",
            c.session_id, c.user_id, c.user_model_cluster, c.command_id
        )));
        self.set_phase(
            Phase::Deciding,
            format!(
                "session started: introduction, deciding sequence 1/{}",
                self.sequences()
            ),
            now,
        );
        let intro = self.utterances.intro();
        self.act(intro);
        let at = now + self.scaled_ns(self.params.timing.intro_time_s);
        self.after_robot(Timer::SpeechDone, at);
        self.request_decision(now);
    }

    /// Takes over `session`, which a killed node left unfinished (`recover.rs` read it back,
    /// `damage` naming what its files lost): it waits paused, the robot silent, for the
    /// therapist's resume; one with nothing left to play ends.
    pub(super) fn take_over(&mut self, session: Session, damage: Vec<String>, now: i64) {
        let (id, next, played) = (session.id.clone(), session.index, session.results.len());
        self.used_sessions.insert(id.clone());
        self.engagement.clear();
        self.timers.forget_all();
        // Only the session file's records come back; proposals live in the bag.
        self.proposals.new_session();
        self.current = Current {
            // No reaction is due: the sequence is presented as soon as the action is known.
            speech_done: true,
            ..Current::default()
        };
        self.session = Some(session);
        let planned = self.sequences();
        if next > planned {
            // Killed between the last record and the summary: nothing is left to play.
            self.phase = Phase::Deciding;
            self.end_session(
                SessionEnd::Finished,
                "all sequences played (summary written after a game manager restart)",
                now,
            );
            return;
        }
        let damaged = if damage.is_empty() {
            String::new()
        } else {
            format!(
                "; {} damaged or doubtful line(s) in its files, see the log",
                damage.len()
            )
        };
        self.out
            .push(Output::Journal(Box::new(JournalEntry::Recovered {
                session_id: id.clone(),
                results: played as u8,
                next_sequence: next,
                damage,
                at_ns: now,
            })));
        let line = format!(
            "session {id:?} {RECOVERED_STATUS} ({played} of {planned} sequences kept, \
             sequence {next} next{damaged})"
        );
        self.out.push(Output::Alarm(line));
        self.set_phase(
            Phase::Deciding,
            format!("{RECOVERED_STATUS} (sequence {next}/{planned} next{damaged})"),
            now,
        );
    }

    pub(super) fn pause(&mut self, command_id: u64, now: i64) {
        let was_paused = self.paused();
        if let Some(s) = self.session.as_mut() {
            s.paused_since = Some(now);
        }
        if !was_paused {
            self.suspend(now);
        }
        self.status = format!("paused by the therapist (command {command_id})");
        self.publish_state(now);
    }

    pub(super) fn resume(&mut self, command_id: u64, now: i64) {
        let paused_for = self
            .session
            .as_mut()
            .and_then(|s| s.paused_since.take())
            .map_or(0, |since| now - since);
        self.log(
            LogLevel::INFO,
            format!("resumed after {:.1} s", paused_for as f64 * 1e-9),
        );
        if self.paused() {
            // publish_state names the lost nodes.
            self.status = format!(
                "resumed by the therapist (command {command_id}); still held until the node is back"
            );
            self.publish_state(now);
            return;
        }
        self.continue_play(&format!("resumed (command {command_id})"), now);
    }

    /// The robot did not finish a step the game waited for: a running session pauses with
    /// the reason (the therapist's resume goes on from where it stopped).
    pub(super) fn pause_for_robot(&mut self, reason: &str, now: i64) {
        let running = self.session_running();
        let paused = match self.session.as_mut() {
            Some(s) if running => {
                s.paused_since.get_or_insert(now);
                true
            }
            _ => false,
        };
        if paused {
            self.suspend(now);
            self.out.push(Output::Alarm(format!(
                "the robot did not finish ({reason}): session paused; resume to go on"
            )));
            self.status = format!("the robot did not finish ({reason}): paused, resume to go on");
            self.publish_state(now);
        } else {
            self.log(
                LogLevel::WARN,
                format!("the robot did not finish ({reason})"),
            );
        }
    }

    /// Watched nodes are lost (`what` names them): the robot is silenced and a running
    /// session held (a pause the therapist did not ask for); a session cannot start meanwhile.
    pub(super) fn hold(&mut self, what: &str, now: i64) {
        let running = self.session_running();
        let was_paused = self.paused();
        if running
            && let Some(s) = self.session.as_mut()
            && s.held_since.is_none()
        {
            s.held_since = Some(now);
            if !was_paused {
                // Silence first: it stops the robot mid-sentence.
                self.silence_robot(now);
                self.suspend(now);
            }
        }
        let line = if running {
            self.status = if self.params.reliability.auto_resume_after_node_loss {
                "session paused, robot silent; it resumes when the node is back".into()
            } else {
                "session paused, robot silent; resume it when the node is back".into()
            };
            format!("node lost: {what}: session paused, robot silent")
        } else {
            self.status = "a session cannot start until the node is back".into();
            format!("node lost: {what}")
        };
        self.out.push(Output::Alarm(line));
        self.publish_state(now);
    }

    /// A lost node is back (`back` says which): when none is lost any more, a held session
    /// goes on by itself (`auto_resume_after_node_loss`) or waits for the therapist's resume.
    pub(super) fn release(&mut self, back: String, now: i64) {
        if !self.lost_nodes().is_empty() {
            self.status = back;
            self.publish_state(now);
            return;
        }
        let held_since = self.session.as_mut().and_then(|s| s.held_since.take());
        let Some(held_since) = held_since.filter(|_| self.session_running()) else {
            self.status = back;
            self.publish_state(now);
            return;
        };
        let therapist_paused = self.paused();
        if !self.params.reliability.auto_resume_after_node_loss {
            if let Some(s) = self.session.as_mut()
                && s.paused_since.is_none()
            {
                s.paused_since = Some(held_since);
            }
            self.status = format!("{back}: waiting for the therapist's resume");
            self.publish_state(now);
        } else if therapist_paused {
            self.status = format!("{back}; still paused by the therapist");
            self.publish_state(now);
        } else {
            self.log(
                LogLevel::INFO,
                format!(
                    "resumed after {:.1} s held for lost nodes",
                    seconds(now - held_since)
                ),
            );
            self.continue_play(&format!("{back}: resumed"), now);
        }
    }

    /// Stops what the robot is doing for a pause or a hold.
    pub(super) fn suspend(&mut self, now: i64) {
        match self.phase {
            Phase::GivingFeedback | Phase::SayingSequence => {
                // A half-said sequence is not fair to the child: say it again on resume.
                self.drop_robot_step();
                self.drop_timers(|t| {
                    !matches!(
                        t,
                        Timer::FeedbackDone | Timer::Word(_) | Timer::SequenceSaid
                    )
                });
            }
            Phase::WaitingForAnswer => {
                self.drop_timers(|t| *t != Timer::AnswerTimeout);
                self.current.answer_left_ns = Some((self.current.answer_deadline_ns - now).max(0));
            }
            // Nobody can answer a proposal while the game stands still.
            Phase::Deciding => self.stop_countdown(),
            _ => {}
        }
    }

    /// Goes on where a pause or a hold stopped; `why` starts the status.
    pub(super) fn continue_play(&mut self, why: &str, now: i64) {
        match self.phase {
            Phase::GivingFeedback | Phase::SayingSequence => {
                // Say why first; the presentation then publishes its own status.
                self.status = why.to_string();
                self.publish_state(now);
                self.start_presentation(now)
            }
            Phase::WaitingForAnswer => {
                let left = self.current.answer_left_ns.take().unwrap_or(0);
                self.current.answer_deadline_ns = now + left;
                self.set_timer(Timer::AnswerTimeout, now + left);
                self.status = format!("{why}: waiting for the answer");
                self.publish_state(now);
            }
            _ => {
                self.status = why.to_string();
                self.publish_state(now);
                // No action for the sequence yet: a recovered session (asked now rather than
                // at recovery, when the policy may not be up), a request that ran out while
                // the session was held or paused, or one still pending, which may have gone
                // to a policy that died meanwhile (its answer, if any, is then superseded).
                if self.phase == Phase::Deciding && self.proposals.is_open() {
                    self.start_countdown(now);
                } else if self.phase == Phase::Deciding && self.current.plan.is_none() {
                    self.ask_policy_again("the session goes on", now);
                }
                self.maybe_present(now);
            }
        }
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
            sequences_planned: self.params.session.sequences_per_session as u8,
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
            seed: self.params.session.seed,
            language: self.params.lines.language.clone(),
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
