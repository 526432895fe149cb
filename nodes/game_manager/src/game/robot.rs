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

/// The robot's steps and calls: the acts put out or queued, the step the game waits for and
/// the call under way. It knows nothing of the game; it says what became of a step
/// ([`Returned`]) and the game decides what follows.
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

/// What became of a step or call the robot answered.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Returned<'a> {
    /// An old step or call (one a pause or stop left behind), or a step with acts still to
    /// go: nothing follows yet.
    Nothing,
    /// The step the game waited for finished: what followed it goes on.
    StepDone(Timer),
    /// The step the game waited for did not finish (the rest of it is dropped).
    StepFailed(Timer, &'a str),
    /// A call no step waited for (the goodbye, the last reaction) failed.
    CallFailed(&'a str),
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

    /// Puts out `acts` (one at a time: queues them, unclaimed, for the step that follows).
    fn act(&mut self, acts: Vec<Output>, out: &mut Vec<Output>) {
        if self.one_at_a_time {
            self.unclaimed += acts.len();
            self.queue.extend(acts.into_iter().map(|a| (a, None)));
        } else {
            out.extend(acts);
        }
    }

    /// The acts just put out are a step, and `then` follows it once the robot has finished
    /// it. False when the robot does not answer (`topics`): the game goes on at its own
    /// estimate.
    fn wait_for(&mut self, then: Timer, out: &mut Vec<Output>) -> bool {
        if !self.waits {
            return false;
        }
        let step = self.new_id();
        self.awaited = Some((step, then));
        if self.one_at_a_time {
            let from = self.queue.len() - self.unclaimed;
            for (_, owner) in self.queue.range_mut(from..) {
                *owner = Some(step);
            }
            self.unclaimed = 0;
            self.put_out_call(out);
        } else {
            out.push(Output::AwaitRobot { step });
        }
        true
    }

    /// At the end of each input: acts no step claimed are nobody's; whatever can go out now
    /// does.
    fn settle(&mut self, out: &mut Vec<Output>) {
        self.unclaimed = 0;
        self.put_out_call(out);
    }

    /// One at a time: puts out the next act, unless a call is under way.
    fn put_out_call(&mut self, out: &mut Vec<Output>) {
        if !self.one_at_a_time || self.call.is_some() || self.queue.len() <= self.unclaimed {
            return;
        }
        if let Some((act, step)) = self.queue.pop_front() {
            let id = self.new_id();
            out.push(act);
            out.push(Output::AwaitRobot { step: id });
            self.call = Some((id, step));
        }
    }

    /// Nothing waits for the step under way any more: what of it was not put out yet never
    /// is.
    fn drop_step(&mut self) {
        if let Some((step, _)) = self.awaited.take() {
            self.queue.retain(|(_, owner)| *owner != Some(step));
        }
    }

    /// Silences the robot at once (the silence goes out before anything else, and nothing
    /// not yet put out follows it). The step the game waits for ends when the call under way
    /// returns, cut short or not; with none under way it ends now: its `then` is returned.
    fn silence(&mut self, out: &mut Vec<Output>) -> Option<Timer> {
        out.push(Output::Silence);
        if !self.one_at_a_time {
            return None;
        }
        self.queue.clear();
        self.unclaimed = 0;
        match (self.call, self.awaited) {
            (Some((id, _)), Some((step, _))) => {
                self.call = Some((id, Some(step)));
                self.call_silenced = true;
                None
            }
            (Some(_), None) => {
                self.call_silenced = true;
                None
            }
            (None, Some((_, then))) => {
                self.awaited = None;
                Some(then)
            }
            (None, None) => None,
        }
    }

    /// The robot answered step (one at a time: call) `id`: finished, or `failure`.
    fn returned<'a>(&mut self, id: u64, failure: Option<&'a str>) -> Returned<'a> {
        if self.one_at_a_time {
            return self.call_returned(id, failure);
        }
        match self.awaited {
            Some((step, then)) if step == id => {
                self.awaited = None;
                match failure {
                    None => Returned::StepDone(then),
                    Some(reason) => Returned::StepFailed(then, reason),
                }
            }
            _ => Returned::Nothing,
        }
    }

    /// One at a time: call `id` returned, finished or `failure`.
    fn call_returned<'a>(&mut self, id: u64, failure: Option<&'a str>) -> Returned<'a> {
        let Some((call, step)) = self.call else {
            return Returned::Nothing;
        };
        if call != id {
            return Returned::Nothing;
        }
        self.call = None;
        let failure = failure.filter(|_| !std::mem::take(&mut self.call_silenced));
        let awaited = self.awaited.filter(|(s, _)| Some(*s) == step);
        match (failure, awaited) {
            (Some(reason), Some((step, then))) => {
                // The rest of the step is not played.
                self.queue.retain(|(_, owner)| *owner != Some(step));
                self.awaited = None;
                Returned::StepFailed(then, reason)
            }
            (Some(reason), None) => Returned::CallFailed(reason),
            (None, Some((step, then))) => {
                if self.queue.iter().any(|(_, owner)| *owner == Some(step)) {
                    Returned::Nothing
                } else {
                    self.awaited = None;
                    Returned::StepDone(then)
                }
            }
            (None, None) => Returned::Nothing,
        }
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
        self.robot.act(acts, &mut self.out);
    }

    /// What follows the robot acts just put out: at `estimate_ns` (`topics` backend), or when
    /// the robot says it has finished them (services). `act` always comes first, so a step
    /// is never empty.
    pub(super) fn after_robot(&mut self, then: Timer, estimate_ns: i64) {
        if !self.robot.wait_for(then, &mut self.out) {
            self.set_timer(then, estimate_ns);
        }
    }

    /// At the end of each input: acts no step claimed are nobody's (the goodbye, the last
    /// reaction); whatever can go out now does.
    pub(super) fn settle_robot(&mut self) {
        self.robot.settle(&mut self.out);
    }

    /// The game no longer waits for the step under way (a pause, a stop): what of it was not
    /// put out yet never is.
    pub(super) fn drop_robot_step(&mut self) {
        self.robot.drop_step();
    }

    /// Silences the robot at once: the silence goes out before anything else, and nothing
    /// not yet put out follows it. The step the game waits for (an introduction or a
    /// reaction during a hold) ends when the call under way returns, cut short or not.
    pub(super) fn silence_robot(&mut self, now: i64) {
        if let Some(then) = self.robot.silence(&mut self.out) {
            self.set_timer(then, now);
        }
    }

    /// The robot finished the step (one at a time: the call) `id`: what waited for it goes on
    /// (an old step, one a pause or stop left behind, changes nothing).
    pub(super) fn on_robot_done(&mut self, id: u64, now: i64) {
        let returned = self.robot.returned(id, None);
        self.on_robot_returned(returned, now);
    }

    /// The robot did not finish the step (one at a time: the call) `id`: the session pauses
    /// with the reason, and the therapist's resume goes on from where it stopped (a feedback
    /// line or a sequence is said again from its start; an introduction or reaction is not
    /// repeated).
    pub(super) fn on_robot_failed(&mut self, id: u64, reason: &str, now: i64) {
        let returned = self.robot.returned(id, Some(reason));
        self.on_robot_returned(returned, now);
    }

    /// What follows a step or call the robot answered; then (one at a time) the next act
    /// goes out.
    fn on_robot_returned(&mut self, returned: Returned<'_>, now: i64) {
        match returned {
            Returned::Nothing => {}
            Returned::StepDone(then) => self.on_timer(then, now),
            Returned::StepFailed(then, reason) => self.robot_step_failed(then, reason, now),
            Returned::CallFailed(reason) => self.log(
                LogLevel::WARN,
                format!("the robot did not finish ({reason})"),
            ),
        }
        self.robot.put_out_call(&mut self.out);
    }

    /// A step the game waited for did not finish: the session pauses with the reason.
    fn robot_step_failed(&mut self, then: Timer, reason: &str, now: i64) {
        if then == Timer::SpeechDone {
            self.current.speech_done = true;
        }
        self.pause_for_robot(reason, now);
    }
}
