//! The game side of the core: game states, tasks, decisions, results and engagement from DDS
//! become what each page shows (proposals: `proposal.rs`); a task stays open until it is
//! answered, replaced, or the game moves to a phase where no answer can count.

use crate::bridge::{Bridge, DdsInput, Now, OpenTask, Output, log};
use crate::protocol::{DecisionView, EngagementPoint, ResultView, Role, ServerMessage, TaskView};
use qt_therapy_msgs::{GamePhase, GameState, TabletTask};
use session_tally::Tally;
use std::collections::VecDeque;
use tracing::Level;

/// Decisions and results kept for a therapist page that logs in mid-session.
const HISTORY: usize = 50;

impl Bridge {
    /// A message from the game side.
    pub fn dds(&mut self, input: DdsInput, now: Now) -> Vec<Output> {
        let mut out = Vec::new();
        match input {
            DdsInput::GameState(g) => self.game_state(g, now, &mut out),
            DdsInput::Proposal(p) => self.proposal(p, now, &mut out),
            DdsInput::Task(t) => self.new_task(t, now, &mut out),
            DdsInput::Decision(d) => {
                let view = DecisionView::of(&d);
                push_for_session(&mut self.decisions, view.clone(), |v| &v.session_id);
                self.broadcast(Role::Therapist, &ServerMessage::Decision(view), &mut out);
            }
            DdsInput::Result(r) => {
                if self
                    .session_results
                    .last()
                    .is_some_and(|last| last.session_id != r.session_id)
                {
                    self.session_results.clear();
                }
                // A result delivered again (the topic keeps its history) counts once.
                self.session_results
                    .retain(|k| k.sequence_index != r.sequence_index);
                self.session_results.push(r.clone());
                let view = ResultView::of(&r, &Tally::of(&self.session_results));
                push_for_session(&mut self.results, view.clone(), |v| &v.session_id);
                self.broadcast(Role::Therapist, &ServerMessage::Result(view), &mut out);
            }
            DdsInput::Heartbeat(hb) => self.heartbeat(&hb, now, &mut out),
            DdsInput::Engagement(e) => {
                let point = EngagementPoint::of(&e);
                if self.engagement.len() >= self.params.engagement_history {
                    self.engagement.pop_front();
                }
                self.engagement.push_back(point.clone());
                self.broadcast(Role::Therapist, &ServerMessage::Engagement(point), &mut out);
            }
        }
        out
    }

    fn game_state(&mut self, g: GameState, now: Now, out: &mut Vec<Output>) {
        if !g.session_id.is_empty() {
            self.current_session = Some(g.session_id.clone());
        }
        let ended = matches!(
            GamePhase::try_from(g.phase),
            Ok(GamePhase::Idle
                | GamePhase::Finished
                | GamePhase::Stopped
                | GamePhase::EmergencyStopped)
        );
        let other_session = self
            .task
            .as_ref()
            .is_some_and(|t| t.task.session_id != g.session_id);
        let phase = g.phase;
        self.proposal_follows_game(&g, now);
        self.game = Some(g);
        // The game manager's own state after it came back says what it does now.
        if !self.gm_watch.lost() {
            self.gm_watch.notice = None;
        }
        self.show_game(out);
        if self.task.is_some() && (ended || other_session) {
            self.task = None;
            let reason = format!("the game is {}", GameState::phase_name(phase));
            self.broadcast(Role::Child, &ServerMessage::NoTask { reason }, out);
        }
    }

    fn new_task(&mut self, t: TabletTask, now: Now, out: &mut Vec<Output>) {
        if let Some((session, last)) = &self.last_task {
            // Transient-local topics re-deliver the last task; older ones are stale.
            if *session == t.session_id && t.sequence_id <= *last {
                out.push(log(
                    Level::DEBUG,
                    format!("task {} already seen; ignored", t.sequence_id),
                ));
                return;
            }
        }
        if let Some(g) = &self.game {
            let over = GameState::is_ended(g.phase);
            if over && g.session_id == t.session_id {
                out.push(log(
                    Level::INFO,
                    format!("task for the ended session {:?}; ignored", t.session_id),
                ));
                return;
            }
        }
        out.push(log(
            Level::INFO,
            format!(
                "new task {} of session {:?}, {} emotions",
                t.sequence_id, t.session_id, t.length
            ),
        ));
        self.last_task = Some((t.session_id.clone(), t.sequence_id));
        self.broadcast(Role::Child, &ServerMessage::Task(TaskView::of(&t)), out);
        self.task = Some(OpenTask {
            task: t,
            received: now.monotonic,
            answered: false,
        });
    }
}

/// Appends to a per-session history, starting over when the session changes.
fn push_for_session<T>(list: &mut VecDeque<T>, item: T, session: impl Fn(&T) -> &String) {
    if list
        .back()
        .is_some_and(|last| session(last) != session(&item))
    {
        list.clear();
    }
    if list.len() >= HISTORY {
        list.pop_front();
    }
    list.push_back(item);
}
