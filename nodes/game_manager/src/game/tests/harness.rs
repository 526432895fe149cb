//! A test driver for the core: a simulated clock and event queue that fires the core's timers,
//! a scripted policy answering DecideAction, a scripted child that "hears" the emotions the
//! robot shows and answers each tablet task, and engagement windows every second.

use crate::game::GameManager;
use crate::params::GameManagerParams;
use crate::protocol::{Input, Now, Output};
use crate::recovery::RecoveredSession;
use crate::session_file::{JournalEntry, SequenceRecord, SessionSummary};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{
    DecideActionRequest, DecideActionResponse, Decision, ExpectedEngagement, GameState, Heartbeat,
    SequenceResult, TabletAnswer, TabletTask, TherapistCommand,
};
use sequence_game::{Action, Emotion, State};
use std::collections::BTreeMap;

pub const S: i64 = 1_000_000_000;
/// Message time at which tests start.
pub const T0: i64 = 1_000 * S;

pub fn ns(seconds: f64) -> i64 {
    (seconds * 1e9).round() as i64
}

/// What the scripted policy does with a request.
// One reply alive per request in a test: its size does not matter.
#[allow(clippy::large_enum_variant)]
pub enum PolicyReply {
    Answer {
        after_s: f64,
        response: DecideActionResponse,
    },
    Fail {
        after_s: f64,
        reason: String,
    },
    Silent,
}

/// What the scripted child does with a task.
#[derive(Debug, Clone)]
pub enum ChildReply {
    Right { after_s: f64 },
    Wrong { after_s: f64 },
    Nothing,
}

type Policy = Box<dyn FnMut(&DecideActionRequest) -> PolicyReply>;
type Child = Box<dyn FnMut(&TabletTask) -> ChildReply>;

pub struct Harness {
    pub gm: GameManager,
    pub now: i64,
    queue: BTreeMap<(i64, u64), Input>,
    seq: u64,
    pub log: Vec<(i64, Output)>,
    pub policy: Policy,
    pub child: Child,
    heard: Vec<Emotion>,
    saying: bool,
    /// How the robot answers a step (`qtrobot` backend).
    pub robot: Box<dyn FnMut(u64) -> RobotReply>,
    /// The wall clock stepped by `.1` at steady time `.0` (the clock is the steady one).
    pub wall_step: Option<(i64, i64)>,
}

/// A fixed rule in place of the learned policy: level 1 first; up a level after a success,
/// encourage after a failure without feedback, else the same level. Every third step is
/// marked "explored".
pub fn rule_decision(req: &DecideActionRequest) -> DecideActionResponse {
    let s = req.state.to_state().unwrap_or(State::START);
    let action = match s.level() {
        None => Action::SetLevel(sequence_game::Level::ONE),
        Some(l) if s.previous_score > 0 && l.get() < 3 => {
            Action::SetLevel(sequence_game::Level::ALL[l.index() + 1])
        }
        Some(_) if s.previous_score < 0 && s.feedback == sequence_game::Feedback::None => {
            Action::Encourage
        }
        Some(l) => Action::SetLevel(l),
    };
    let (level, feedback) = action
        .apply(s)
        .unwrap_or((sequence_game::Level::ONE, sequence_game::Feedback::None));
    DecideActionResponse {
        ok: true,
        error: String::new(),
        decision: Decision {
            session_id: req.session_id.clone(),
            step: req.step,
            state: req.state.clone(),
            action: action.index() as u8,
            level: level.get(),
            feedback: feedback as u8,
            q_values: vec![0.1, 0.2, 0.3, 0.4, 0.5],
            probabilities: vec![0.2; 5],
            temperature: 1.0,
            explored: req.step.is_multiple_of(3),
            model_used: "rule".into(),
            ..Default::default()
        },
    }
}

pub fn rule_policy() -> Policy {
    Box::new(|req| PolicyReply::Answer {
        after_s: 0.05,
        response: rule_decision(req),
    })
}

/// Right after 5 s, except the listed sequence indices.
pub fn scripted_child(exceptions: Vec<(u8, ChildReply)>) -> Child {
    Box::new(move |task| {
        exceptions
            .iter()
            .find(|(i, _)| *i == task.sequence_index)
            .map(|(_, r)| r.clone())
            .unwrap_or(ChildReply::Right { after_s: 5.0 })
    })
}

pub fn command(code: u8, session: &str, id: u64) -> TherapistCommand {
    TherapistCommand {
        command: code,
        session_id: session.into(),
        command_id: id,
        user_id: "child-1".into(),
        user_model_cluster: 0,
        ..Default::default()
    }
}

/// A therapist command as the core's input.
pub fn cmd(code: u8, session: &str, id: u64) -> Input {
    Input::Command(command(code, session, id))
}

/// The therapist's override of the next sequence's level.
pub fn override_to(level: u8, session: &str, id: u64) -> Input {
    let mut c = command(TherapistCommand::OVERRIDE_LEVEL, session, id);
    c.level = level;
    Input::Command(c)
}

/// How the simulated robot answers a step of calls.
pub enum RobotReply {
    Done { after_s: f64 },
    Fail { after_s: f64, reason: String },
}

impl Harness {
    pub fn new(params: GameManagerParams, policy: Policy, child: Child) -> Self {
        let mut gm = GameManager::new(params).expect("valid parameters");
        let initial = gm.initial_outputs(T0);
        Self::around(gm, T0, initial, policy, child)
    }

    /// A core started at `now` that takes over the unfinished session `r`.
    pub fn recovering(
        params: GameManagerParams,
        policy: Policy,
        child: Child,
        r: RecoveredSession,
        now: i64,
    ) -> Self {
        let mut gm = GameManager::new(params).expect("valid parameters");
        let initial = gm.recover(r, now);
        Self::around(gm, now, initial, policy, child)
    }

    fn around(
        gm: GameManager,
        now: i64,
        initial: Vec<Output>,
        policy: Policy,
        child: Child,
    ) -> Self {
        let mut h = Harness {
            gm,
            now,
            queue: BTreeMap::new(),
            seq: 0,
            log: Vec::new(),
            policy,
            child,
            heard: Vec::new(),
            saying: false,
            robot: Box::new(|_| RobotReply::Done { after_s: 0.5 }),
            wall_step: None,
        };
        h.absorb(initial);
        h
    }

    pub fn at(&mut self, t: i64, input: Input) {
        self.seq += 1;
        self.queue.insert((t, self.seq), input);
    }

    /// The wall clock's reading at steady time `t`.
    pub fn wall(&self, t: i64) -> i64 {
        match self.wall_step {
            Some((at, by)) if t >= at => t + by,
            _ => t,
        }
    }

    /// Handles `input` now.
    pub fn feed(&mut self, input: Input) -> Vec<Output> {
        let now = Now {
            steady_ns: self.now,
            wall_ns: self.wall(self.now),
        };
        let out = self.gm.handle(input, now);
        self.absorb(out.clone());
        out
    }

    /// Starts session `id` now with command id 1.
    pub fn start(&mut self, id: &str) {
        self.feed(Input::Command(command(TherapistCommand::START, id, 1)));
    }

    /// One engagement window per second in [from, to), published 0.2 s after it closes;
    /// `value(second)` None = no face. Stamped by the wall clock (set `wall_step` first).
    pub fn engagement(&mut self, from_s: i64, to_s: i64, value: impl Fn(i64) -> Option<f32>) {
        for sec in from_s..to_s {
            let v = value(sec);
            let msg = ExpectedEngagement {
                source: "camera/0".into(),
                window_start: Time::from_nanos(self.wall(sec * S)),
                window_end: Time::from_nanos(self.wall(sec * S) + S),
                has_faces: v.is_some(),
                mean: v.unwrap_or(0.0),
                smoothed: v.unwrap_or(0.0),
                frame_count: 30,
                ..Default::default()
            };
            self.at((sec + 1) * S + S / 5, Input::Engagement(msg));
        }
    }

    /// Heartbeats of `node` (process `pid`) every 100 ms in [from, to).
    pub fn heartbeats(&mut self, node: &str, pid: u32, from: i64, to: i64) {
        let mut t = from;
        let mut sequence = 0;
        while t < to {
            let hb = Heartbeat {
                header: Header::at(Time::from_nanos(t)),
                node_name: node.into(),
                pid,
                sequence,
            };
            self.at(t, Input::Heartbeat(hb));
            sequence += 1;
            t += S / 10;
        }
    }

    /// Processes queued events up to `until` (ns), then sets the clock there.
    pub fn run_until(&mut self, until: i64) {
        while let Some(entry) = self.queue.first_entry() {
            if entry.key().0 > until {
                break;
            }
            let ((t, _), input) = entry.remove_entry();
            self.now = self.now.max(t);
            self.feed(input);
        }
        self.now = self.now.max(until);
    }

    /// Runs until the queue holds nothing but engagement windows, or `limit_s` passes.
    pub fn run(&mut self, limit_s: f64) {
        let limit = self.now + ns(limit_s);
        loop {
            let next = self
                .queue
                .iter()
                .find(|(_, i)| !matches!(i, Input::Engagement(_)))
                .map(|((t, _), _)| *t);
            match next {
                Some(t) if t <= limit => self.run_until(t),
                _ => break,
            }
        }
    }

    fn absorb(&mut self, out: Vec<Output>) {
        for o in out {
            match &o {
                Output::AwaitRobot { step } => match (self.robot)(*step) {
                    RobotReply::Done { after_s } => {
                        self.at(self.now + ns(after_s), Input::RobotDone { step: *step })
                    }
                    RobotReply::Fail { after_s, reason } => self.at(
                        self.now + ns(after_s),
                        Input::RobotFailed {
                            step: *step,
                            reason,
                        },
                    ),
                },
                Output::SetTimer { id, at_ns } => {
                    self.at(*at_ns, Input::TimerFired { id: *id });
                }
                Output::Decide {
                    request_id,
                    request,
                    ..
                } => match (self.policy)(request) {
                    PolicyReply::Answer { after_s, response } => {
                        let t = self.now + ns(after_s);
                        self.at(
                            t,
                            Input::Decision {
                                request_id: *request_id,
                                response,
                            },
                        );
                    }
                    PolicyReply::Fail { after_s, reason } => {
                        let t = self.now + ns(after_s);
                        self.at(
                            t,
                            Input::DecisionFailed {
                                request_id: *request_id,
                                reason,
                            },
                        );
                    }
                    PolicyReply::Silent => {}
                },
                Output::State(s) => {
                    let saying = s.phase == GameState::SAYING_SEQUENCE;
                    if saying && !self.saying {
                        self.heard.clear();
                    }
                    self.saying = saying;
                }
                Output::ShowEmotion(e) if self.saying => {
                    if let Ok(e) = e.trim_start_matches("QT/").parse::<Emotion>() {
                        self.heard.push(e);
                    }
                }
                Output::Task(task) => {
                    let heard: Vec<String> =
                        self.heard.iter().map(|e| e.name().to_string()).collect();
                    let reply = (self.child)(task);
                    let (after_s, words) = match reply {
                        ChildReply::Right { after_s } => (after_s, heard),
                        ChildReply::Wrong { after_s } => {
                            let mut w = heard;
                            // Swap in a different first emotion.
                            let first = if w.first().map(String::as_str) == Some("happy") {
                                "sad"
                            } else {
                                "happy"
                            };
                            if let Some(x) = w.first_mut() {
                                *x = first.into();
                            }
                            (after_s, w)
                        }
                        ChildReply::Nothing => (f64::NAN, vec![]),
                    };
                    if after_s.is_finite() {
                        let answer = TabletAnswer {
                            session_id: task.session_id.clone(),
                            sequence_id: task.sequence_id,
                            answer: words,
                            response_time: after_s as f32,
                            ..Default::default()
                        };
                        self.at(self.now + ns(after_s), Input::Answer(answer));
                    }
                }
                _ => {}
            }
            self.log.push((self.now, o));
        }
    }

    // Views of the log.

    pub fn outputs(&self) -> impl Iterator<Item = &Output> {
        self.log.iter().map(|(_, o)| o)
    }

    pub fn results(&self) -> Vec<SequenceResult> {
        self.outputs()
            .filter_map(|o| match o {
                Output::Result(r) => Some(r.clone()),
                _ => None,
            })
            .collect()
    }

    pub fn records(&self) -> Vec<SequenceRecord> {
        self.outputs()
            .filter_map(|o| match o {
                Output::Record(r) => Some((**r).clone()),
                _ => None,
            })
            .collect()
    }

    pub fn journal(&self) -> Vec<JournalEntry> {
        self.outputs()
            .filter_map(|o| match o {
                Output::Journal(e) => Some((**e).clone()),
                _ => None,
            })
            .collect()
    }

    /// The session file and journal as `SessionFiles` writes them: one JSON line each.
    pub fn file_texts(&self) -> (String, String) {
        let lines = |v: Vec<String>| v.into_iter().map(|l| l + "\n").collect::<String>();
        let records = self
            .records()
            .iter()
            .map(|r| serde_json::to_string(r).expect("json"))
            .collect();
        let journal = self
            .journal()
            .iter()
            .map(|e| serde_json::to_string(e).expect("json"))
            .collect();
        (lines(records), lines(journal))
    }

    pub fn summaries(&self) -> Vec<SessionSummary> {
        self.outputs()
            .filter_map(|o| match o {
                Output::Summary(s) => Some((**s).clone()),
                _ => None,
            })
            .collect()
    }

    pub fn states(&self) -> Vec<GameState> {
        self.outputs()
            .filter_map(|o| match o {
                Output::State(s) => Some(s.clone()),
                _ => None,
            })
            .collect()
    }

    pub fn tasks(&self) -> Vec<(i64, TabletTask)> {
        self.log
            .iter()
            .filter_map(|(t, o)| match o {
                Output::Task(k) => Some((*t, k.clone())),
                _ => None,
            })
            .collect()
    }

    pub fn last_state(&self) -> GameState {
        self.states().pop().expect("a state was published")
    }

    /// Warnings logged so far.
    pub fn warnings(&self) -> Vec<String> {
        self.outputs()
            .filter_map(|o| match o {
                Output::Log {
                    level: crate::protocol::LogLevel::WARN,
                    message,
                } => Some(message.clone()),
                _ => None,
            })
            .collect()
    }

    /// The emotions the robot showed while saying the current sequence.
    pub fn heard(&self) -> Vec<String> {
        self.heard.iter().map(|e| e.name().to_string()).collect()
    }

    /// Steps the clock by 100 ms until `done(self)` or `limit_s` passes.
    pub fn run_until_true(&mut self, limit_s: f64, done: impl Fn(&Harness) -> bool) {
        let limit = self.now + ns(limit_s);
        while !done(self) && self.now < limit {
            self.run_until(self.now + S / 10);
        }
        assert!(done(self), "condition not reached within {limit_s} s");
    }

    pub fn robot_outputs_since(&self, index: usize) -> Vec<Output> {
        self.log[index..]
            .iter()
            .filter(|(_, o)| o.is_robot())
            .map(|(_, o)| o.clone())
            .collect()
    }
}
