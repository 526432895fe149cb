//! Going on with a session a killed game manager left unfinished (its files read back by
//! `crate::recovery`). The session comes back paused, the robot silent: the child may have
//! been moved, the therapist decides when to go on. Its RESUME plays the next unplayed
//! sequence from its start (an interrupted one again, as after a pause); every result, the
//! state (L, F, PS), the command ids carried out and the task ids sent carry over, so nothing
//! is played, scored or carried out twice. Here the files become a `Session`; taking it over
//! is `session.rs`'s.

use super::{GameManager, PendingOverride, Session};
use crate::protocol::{LogLevel, Now, Output};
use crate::recovery::RecoveredSession;
use crate::sequence::SessionRng;
use sequence_game::{Emotion, Feedback, Level, Outcome, State};

impl GameManager {
    /// Session ids used before this node started (their files are in the sessions
    /// directory): a START with one of them is refused, as within one run.
    pub fn remember_sessions(&mut self, ids: impl IntoIterator<Item = String>) {
        self.used_sessions.extend(ids);
    }

    /// Takes over `r` at start-up, in place of [`GameManager::initial_outputs`].
    pub fn recover(&mut self, r: RecoveredSession, now: impl Into<Now>) -> Vec<Output> {
        let now = self.read_clocks(now.into());
        // Silence first: the dead node's last line may still be playing.
        self.silence_robot(now);
        for d in &r.damage {
            self.log(
                LogLevel::WARN,
                format!("recovering {:?}: {d}", r.session_id),
            );
        }
        let session = self.recovered_session(&r, now);
        self.take_over(session, r.damage, now);
        std::mem::take(&mut self.out)
    }

    /// The session `r`'s files tell, paused since `now`.
    fn recovered_session(&mut self, r: &RecoveredSession, now: i64) -> Session {
        let last = r.records.last();
        // The state after the last result, as scoring it made it (play.rs). Validated
        // records always give one; the start state is the safe answer anyway.
        let state = last
            .and_then(|l| {
                let res = &l.result;
                Some(State::after(
                    Level::new(res.level.into()).ok()?,
                    Feedback::new(res.feedback.into()).ok()?,
                    Outcome::new(res.outcome.into()).ok()?,
                ))
            })
            .unwrap_or(State::START);
        let rng = self.replayed_rng(r);
        let pending_override = r.pending_override.map(|(i, action)| PendingOverride {
            sequence_index: i,
            action,
            command_id: 0,
        });
        let results: Vec<_> = r.records.iter().map(|x| x.result.clone()).collect();
        Session {
            id: r.session_id.clone(),
            user_id: r.user_id.clone(),
            cluster: r.user_model_cluster,
            last_command_id: r.last_command_id,
            rng,
            state,
            index: r.next_index(),
            next_sequence_id: r.last_task_id.saturating_add(1),
            pending_override,
            paused_since: Some(now),
            held_since: None,
            talk_start_ns: last.map_or(r.started_ns, |l| l.answered_ns),
            started_ns: r.started_ns,
            closed_task: None,
            fallbacks: r.records.iter().filter(|x| x.policy_fallback).count() as u32,
            overrides: results.iter().filter(|x| x.overridden).count() as u32,
            rejected_commands: 0,
            rejected_answers: r.records.iter().map(|x| x.rejected_answers).sum(),
            results,
        }
    }

    /// The session's random streams advanced past the recorded sequences, so the rest of the
    /// session draws what an uninterrupted run would have (and an interrupted sequence is
    /// said again with the same emotions).
    fn replayed_rng(&mut self, r: &RecoveredSession) -> SessionRng {
        let mut rng = SessionRng::new(self.params.session.seed, &r.session_id);
        let max_run = self.params.session.max_identical_in_a_row as usize;
        for (k, record) in r.records.iter().enumerate() {
            let res = &record.result;
            if usize::from(res.sequence_index) != k + 1 {
                self.log(
                    LogLevel::WARN,
                    format!(
                        "recovering {:?}: a sequence before {} is missing, so the sequences \
                         from here on are drawn afresh",
                        r.session_id, res.sequence_index
                    ),
                );
                break;
            }
            let (Ok(level), Ok(feedback)) = (
                Level::new(res.level.into()),
                Feedback::new(res.feedback.into()),
            ) else {
                break;
            };
            let drawn = rng.sequence(level, max_run);
            if feedback != Feedback::None {
                rng.line(self.utterances.feedback_line_count(feedback));
            }
            let said: Vec<&str> = drawn.iter().map(|e: &Emotion| e.name()).collect();
            if said != res.sequence {
                self.log(
                    LogLevel::WARN,
                    format!(
                        "recovering {:?}: sequence {} in the file is not what seed {} draws \
                         (parameters changed?); the next sequences are drawn afresh",
                        r.session_id, res.sequence_index, self.params.session.seed
                    ),
                );
                break;
            }
        }
        rng
    }
}
