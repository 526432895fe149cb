//! The child page's side of the core: the task on its screen, open from the game manager's
//! `TabletTask` until it is answered, replaced, or the game moves to a phase where no answer
//! can count; and its answer, which becomes a `TabletAnswer` only when it is for the task on
//! screen, is its first answer, came in time, and holds exactly the number of emotions asked,
//! each one offered by the task.

use crate::io::{Now, Output, log};
use crate::protocol::{ServerMessage, TaskView};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{GamePhase, GameState, TabletAnswer, TabletTask, Validate};
use sequence_game::parse_answer;
use std::time::Duration;
use tracing::Level;

/// Network and rendering slack past the task's timeout before an answer counts as late.
pub const ANSWER_GRACE: Duration = Duration::from_secs(2);

/// The task on the child's screen.
#[derive(Debug)]
struct OpenTask {
    task: TabletTask,
    received: Duration,
    answered: bool,
}

/// The child tablet's task: the one open, and the newest seen.
#[derive(Debug, Default)]
pub(crate) struct ChildTask {
    open: Option<OpenTask>,
    /// (session, sequence_id) of the newest task seen, so re-delivered tasks stay closed.
    last: Option<(String, u32)>,
}

impl ChildTask {
    /// What a child page is told about the task now.
    pub(crate) fn message(&self) -> ServerMessage {
        match &self.open {
            Some(t) if !t.answered => ServerMessage::Task(TaskView::of(&t.task)),
            Some(_) => ServerMessage::NoTask {
                reason: "answered".into(),
            },
            None => ServerMessage::NoTask {
                reason: "waiting".into(),
            },
        }
    }

    /// A task from the game manager, with the game's state as last heard (`game`): what the
    /// child pages are to show when it opens.
    pub(crate) fn arrive(
        &mut self,
        t: TabletTask,
        game: Option<&GameState>,
        now: Now,
        out: &mut Vec<Output>,
    ) -> Option<TaskView> {
        if let Some((session, last)) = &self.last {
            // Transient-local topics re-deliver the last task; older ones are stale.
            if *session == t.session_id && t.sequence_id <= *last {
                out.push(log(
                    Level::DEBUG,
                    format!("task {} already seen; ignored", t.sequence_id),
                ));
                return None;
            }
        }
        if let Some(g) = game {
            let over = GameState::is_ended(g.phase);
            if over && g.session_id == t.session_id {
                out.push(log(
                    Level::INFO,
                    format!("task for the ended session {:?}; ignored", t.session_id),
                ));
                return None;
            }
        }
        out.push(log(
            Level::INFO,
            format!(
                "new task {} of session {:?}, {} emotions",
                t.sequence_id, t.session_id, t.length
            ),
        ));
        self.last = Some((t.session_id.clone(), t.sequence_id));
        let view = TaskView::of(&t);
        self.open = Some(OpenTask {
            task: t,
            received: now.monotonic,
            answered: false,
        });
        Some(view)
    }

    /// The game's new state `g`: an open task closes when the game has ended or plays
    /// another session (the reason the child pages are given).
    pub(crate) fn follow_game(&mut self, g: &GameState) -> Option<String> {
        let ended = matches!(
            GamePhase::try_from(g.phase),
            Ok(GamePhase::Idle
                | GamePhase::Finished
                | GamePhase::Stopped
                | GamePhase::EmergencyStopped)
        );
        let open = self.open.as_ref()?;
        if !ended && open.task.session_id == g.session_id {
            return None;
        }
        self.open = None;
        Some(format!("the game is {}", GameState::phase_name(g.phase)))
    }

    /// The answer a child page sent, as the `TabletAnswer` to publish (the task is then
    /// answered), or why it cannot count: `game` is the game's state as last heard, and
    /// `game_manager_lost` whether its heartbeat has stopped.
    pub(crate) fn answer(
        &mut self,
        sequence_id: u32,
        answer: &[String],
        response_time: f64,
        game: Option<&GameState>,
        game_manager_lost: bool,
        now: Now,
    ) -> Result<TabletAnswer, String> {
        let Some(open) = self.open.as_mut() else {
            return Err("no task is waiting for an answer".into());
        };
        let task = &open.task;
        if sequence_id != task.sequence_id {
            return Err(format!(
                "this answer is for sequence {sequence_id}, but the current task is sequence {}",
                task.sequence_id
            ));
        }
        if open.answered {
            return Err(format!("sequence {sequence_id} was already answered"));
        }
        if game_manager_lost {
            return Err("the game manager is lost: the answer could not be scored".into());
        }
        if let Some(g) = game
            && g.phase == GameState::PAUSED
            && g.session_id == task.session_id
        {
            return Err("the game is paused".into());
        }
        // A timeout of 0 (or nonsense, which validation drops before it gets here) means none.
        if let Ok(timeout) = Duration::try_from_secs_f32(task.timeout)
            && task.timeout > 0.0
        {
            let limit = timeout.saturating_add(ANSWER_GRACE);
            if now.monotonic.saturating_sub(open.received) > limit {
                return Err(format!(
                    "too late: the task's time ({} s) is over",
                    task.timeout
                ));
            }
        }
        let emotions = parse_answer(answer, response_time, usize::from(task.length))
            .map_err(|e| e.to_string())?;
        if let Some((i, e)) = emotions
            .iter()
            .enumerate()
            .find(|(_, e)| !task.choices.iter().any(|c| c == e.name()))
        {
            return Err(format!(
                "answer[{i}] = {:?} is not offered by this task",
                e.name()
            ));
        }
        let message = TabletAnswer {
            header: Header::at(Time::from_nanos(now.wall_nanos)),
            session_id: task.session_id.clone(),
            sequence_id,
            answer: answer.to_vec(),
            response_time: response_time as f32,
        };
        message.validate().map_err(|e| e.reason)?;
        open.answered = true;
        Ok(message)
    }
}
