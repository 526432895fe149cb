//! The robot's acts and the steps the game waits for. With `topics` the acts go out at once
//! and the game goes on at estimated times; with QTrobot's services it waits for the robot to
//! answer. A V2's services (`qtrobot`) serve calls side by side, so a step's acts go out
//! together as one `AwaitRobot`. A V3's gateway (`qtrobot_ros2`) serves one call at a time:
//! all its services share rclpy's mutually exclusive callback group, so a call asked while
//! another is served waits behind it (a face asked during speech plays after it, counting
//! against its call timeout, and whatever was asked before a pause or an emergency stop still
//! plays after it). There the acts go out one by one, each its own `AwaitRobot`, the next when
//! the last has returned, in the order the game wants them: the face, the gesture, then the
//! words. A pause, a stop or a failure drops what was not put out yet; a silence
//! (`Output::Silence`, which the shell turns into the gateway's cancel) goes out at once.

use super::{GameManager, Timer};
use crate::params::RobotBackend;
use crate::protocol::{LogLevel, Output};
use crate::utterances::RobotAct;
use std::collections::VecDeque;

/// The core's bookkeeping of the robot's steps and calls.
#[derive(Debug, Default)]
pub(super) struct RobotSteps {
    /// The robot answers when it has finished (services): the game waits for it.
    waits: bool,
    /// It serves one call at a time (`qtrobot_ros2`).
    one_at_a_time: bool,
    /// The step the game waits for, and what follows it.
    awaited: Option<(u64, Timer)>,
    next_id: u64,
    /// One at a time: the acts not put out yet, each with the step it belongs to (None:
    /// nothing waits for it, as for the goodbye).
    queue: VecDeque<(Output, Option<u64>)>,
    /// Acts at the queue's end that no step has claimed yet.
    unclaimed: usize,
    /// One at a time: the call under way (its `AwaitRobot` id) and the step it belongs to.
    call: Option<(u64, Option<u64>)>,
    /// The call under way was cut short by the game's own silence: its failure is not the
    /// robot's.
    call_silenced: bool,
}

impl RobotSteps {
    pub(super) fn new(backend: RobotBackend) -> Self {
        RobotSteps {
            waits: backend.answers_when_done(),
            one_at_a_time: backend.serves_one_call_at_a_time(),
            next_id: 1,
            ..RobotSteps::default()
        }
    }

    fn new_id(&mut self) -> u64 {
        let id = self.next_id;
        self.next_id += 1;
        id
    }
}

impl GameManager {
    /// Puts out `act`: its face, its gesture, then its words. One at a time, they wait in the
    /// queue for the step that follows them (`after_robot`) or, if none does, go out as
    /// nobody's.
    pub(super) fn act(&mut self, act: RobotAct) {
        let mut acts = Vec::with_capacity(3);
        if let Some(e) = act.emotion {
            acts.push(Output::ShowEmotion(e));
        }
        if let Some(g) = act.gesture {
            acts.push(Output::PlayGesture(g));
        }
        acts.push(Output::Say(act.speech));
        if self.robot.one_at_a_time {
            self.robot.unclaimed += acts.len();
            self.robot.queue.extend(acts.into_iter().map(|a| (a, None)));
        } else {
            self.out.extend(acts);
        }
    }

    /// What follows the robot acts just put out: at `estimate_ns` (`topics` backend), or when
    /// the robot says it has finished them (services). `act` always comes first, so a step
    /// is never empty.
    pub(super) fn after_robot(&mut self, then: Timer, estimate_ns: i64) {
        if !self.robot.waits {
            self.set_timer(then, estimate_ns);
            return;
        }
        let step = self.robot.new_id();
        self.robot.awaited = Some((step, then));
        if self.robot.one_at_a_time {
            let from = self.robot.queue.len() - self.robot.unclaimed;
            for (_, owner) in self.robot.queue.range_mut(from..) {
                *owner = Some(step);
            }
            self.robot.unclaimed = 0;
            self.put_out_robot_call();
        } else {
            self.out.push(Output::AwaitRobot { step });
        }
    }

    /// At the end of each input: acts no step claimed are nobody's (the goodbye, the last
    /// reaction); whatever can go out now does.
    pub(super) fn settle_robot(&mut self) {
        self.robot.unclaimed = 0;
        self.put_out_robot_call();
    }

    /// One at a time: puts out the next act, unless a call is under way.
    fn put_out_robot_call(&mut self) {
        if !self.robot.one_at_a_time
            || self.robot.call.is_some()
            || self.robot.queue.len() <= self.robot.unclaimed
        {
            return;
        }
        if let Some((act, step)) = self.robot.queue.pop_front() {
            let id = self.robot.new_id();
            self.out.push(act);
            self.out.push(Output::AwaitRobot { step: id });
            self.robot.call = Some((id, step));
        }
    }

    /// The game no longer waits for the step under way (a pause, a stop): what of it was not
    /// put out yet never is.
    pub(super) fn drop_robot_step(&mut self) {
        if let Some((step, _)) = self.robot.awaited.take() {
            self.robot.queue.retain(|(_, owner)| *owner != Some(step));
        }
    }

    /// Silences the robot at once: the silence goes out before anything else, and
    /// nothing not yet put out follows it. The step the game waits for (an introduction or a
    /// reaction during a hold) ends when the call under way returns, cut short or not.
    pub(super) fn silence_robot(&mut self, now: i64) {
        self.out.push(Output::Silence);
        if !self.robot.one_at_a_time {
            return;
        }
        self.robot.queue.clear();
        self.robot.unclaimed = 0;
        match (self.robot.call, self.robot.awaited) {
            (Some((id, _)), Some((step, _))) => {
                self.robot.call = Some((id, Some(step)));
                self.robot.call_silenced = true;
            }
            (Some(_), None) => self.robot.call_silenced = true,
            (None, Some((_, then))) => {
                self.robot.awaited = None;
                self.set_timer(then, now);
            }
            (None, None) => {}
        }
    }

    /// The robot finished the step (one at a time: the call) `id`: what waited for it goes on
    /// (an old step, one a pause or stop left behind, changes nothing).
    pub(super) fn on_robot_done(&mut self, id: u64, now: i64) {
        if self.robot.one_at_a_time {
            self.on_robot_call_returned(id, None, now);
            return;
        }
        match self.robot.awaited {
            Some((step, then)) if step == id => {
                self.robot.awaited = None;
                self.on_timer(then, now);
            }
            _ => {}
        }
    }

    /// The robot did not finish the step (one at a time: the call) `id`: the session pauses
    /// with the reason, and the therapist's resume goes on from where it stopped (a feedback
    /// line or a sequence is said again from its start; an introduction or reaction is not
    /// repeated).
    pub(super) fn on_robot_failed(&mut self, id: u64, reason: &str, now: i64) {
        if self.robot.one_at_a_time {
            self.on_robot_call_returned(id, Some(reason), now);
            return;
        }
        match self.robot.awaited {
            Some((step, then)) if step == id => {
                self.robot.awaited = None;
                self.robot_step_failed(then, reason, now);
            }
            _ => {}
        }
    }

    /// One at a time: call `id` returned, finished or `failure`; the next act goes out.
    fn on_robot_call_returned(&mut self, id: u64, failure: Option<&str>, now: i64) {
        let Some((call, step)) = self.robot.call else {
            return;
        };
        if call != id {
            return;
        }
        self.robot.call = None;
        let failure = failure.filter(|_| !std::mem::take(&mut self.robot.call_silenced));
        let awaited = self.robot.awaited.filter(|(s, _)| Some(*s) == step);
        match (failure, awaited) {
            (Some(reason), Some((step, then))) => {
                // The rest of the step is not played.
                self.robot.queue.retain(|(_, owner)| *owner != Some(step));
                self.robot.awaited = None;
                self.robot_step_failed(then, reason, now);
            }
            (Some(reason), None) => {
                self.log(
                    LogLevel::WARN,
                    format!("the robot did not finish ({reason})"),
                );
            }
            (None, Some((step, then))) => {
                if !self
                    .robot
                    .queue
                    .iter()
                    .any(|(_, owner)| *owner == Some(step))
                {
                    self.robot.awaited = None;
                    self.on_timer(then, now);
                }
            }
            (None, None) => {}
        }
        self.put_out_robot_call();
    }

    /// A step the game waited for did not finish: the session pauses with the reason.
    fn robot_step_failed(&mut self, then: Timer, reason: &str, now: i64) {
        if then == Timer::SpeechDone {
            self.current.speech_done = true;
        }
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
}
