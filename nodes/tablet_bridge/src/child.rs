//! The child page's side of the core: an answer becomes a `TabletAnswer` only when it is for
//! the task on screen, is its first answer, came in time, and holds exactly the number of
//! emotions asked, each one offered by the task.

use crate::bridge::{Bridge, ClientId, Now, Output};
use crate::protocol::{Role, ServerMessage};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{GameState, TabletAnswer, Validate};
use sequence_game::Emotion;
use std::time::Duration;

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
                tracing::info!(
                    client = id,
                    session = %message.session_id,
                    sequence_id,
                    answer = ?message.answer,
                    "answer sent"
                );
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
        if answer.len() != usize::from(task.length) {
            return Err(format!(
                "the answer has {} emotions, the task asks for {}",
                answer.len(),
                task.length
            ));
        }
        for (i, word) in answer.iter().enumerate() {
            let shown: String = word.chars().take(20).collect();
            let emotion: Emotion = word.parse().map_err(|_| {
                format!("answer[{i}] = {shown:?} is not one of happy, disgusted, sad, angry")
            })?;
            if !task.choices.iter().any(|c| c == emotion.name()) {
                return Err(format!(
                    "answer[{i}] = {shown:?} is not offered by this task"
                ));
            }
        }
        if !(response_time.is_finite() && (0.0..=3600.0).contains(&response_time)) {
            return Err(format!(
                "response_time = {response_time} is not a number of seconds in 0..=3600"
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
