//! The child page's side of the core: an answer becomes a `TabletAnswer` only when it is for
//! the task on screen, is its first answer, came in time, and holds exactly the number of
//! emotions asked, each one offered by the task.

use crate::bridge::{Bridge, ClientId, Now, Output, log};
use crate::protocol::{Role, ServerMessage};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{GameState, TabletAnswer, Validate};
use sequence_game::parse_answer;
use std::time::Duration;
use tracing::Level;

/// Network and rendering slack past the task's timeout before an answer counts as late.
pub const ANSWER_GRACE: Duration = Duration::from_secs(2);

impl Bridge {
    pub(crate) fn answer(
        &mut self,
        id: ClientId,
        sequence_id: u32,
        answer: Vec<String>,
        response_time: f64,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        match self.check_answer(sequence_id, &answer, response_time, now) {
            Err(reason) => self.reject(id, reason, out),
            Ok(message) => {
                if let Some(t) = self.task.as_mut() {
                    t.answered = true;
                }
                out.push(log(
                    Level::INFO,
                    format!(
                        "page {id}: answer to sequence {sequence_id} of session {:?} sent: {:?}",
                        message.session_id, message.answer
                    ),
                ));
                out.push(Output::Send(
                    id,
                    ServerMessage::Accepted {
                        what: "answer".into(),
                    },
                ));
                // Another child page showing the same task now has nothing to answer.
                let done = ServerMessage::NoTask {
                    reason: "answered".into(),
                };
                for (other, c) in &self.clients {
                    if c.role == Role::Child && *other != id {
                        out.push(Output::Send(*other, done.clone()));
                    }
                }
                out.push(Output::Answer(message));
            }
        }
    }

    fn check_answer(
        &self,
        sequence_id: u32,
        answer: &[String],
        response_time: f64,
        now: Now,
    ) -> Result<TabletAnswer, String> {
        let Some(open) = &self.task else {
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
        if self.gm_watch.lost() {
            return Err("the game manager is lost: the answer could not be scored".into());
        }
        if let Some(g) = &self.game
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
        Ok(message)
    }
}
