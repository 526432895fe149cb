//! The robot side of the game manager's DDS shell: the core's robot acts go to QTrobot's
//! std_msgs/String topics (`robot_backend: topics`) or to its services (`qtrobot`), where the
//! calls of one step run together and the step is answered with `Input::RobotDone` once every
//! call returned (or `Input::RobotFailed` with the reason: an error, a `false` status, no
//! answer within `robot_call_timeout_s`).

use game_manager::{GameManagerParams, Input};
use node_shell::{NodeShell, Outbox, ServiceClient};
use qt_therapy_msgs::qt_robot_interface::{
    EMOTION_SHOW, EmotionShow, EmotionShowRequest, GESTURE_PLAY, GesturePlay, GesturePlayRequest,
    SPEECH_SAY, SPEECH_STOP, SpeechSay, SpeechSayRequest, SpeechStop, SpeechStopRequest,
};
use qt_therapy_msgs::std_msgs::StringMsg;
use qt_therapy_msgs::topics::{ROBOT_EMOTION, ROBOT_GESTURE, ROBOT_SPEECH};
use std::time::Duration;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

/// One robot act of the core.
pub enum Act {
    /// Speech; empty silences the robot.
    Say(String),
    Emotion(String),
    Gesture(String),
}

/// A call's outcome: Err names what went wrong.
type Call = JoinHandle<Result<(), String>>;

// One per node, made once: the size difference between the backends costs nothing.
#[allow(clippy::large_enum_variant)]
pub enum Robot {
    Topics {
        speech: Outbox<StringMsg>,
        emotion: Outbox<StringMsg>,
        gesture: Outbox<StringMsg>,
    },
    QtRobot {
        say: ServiceClient<SpeechSay>,
        stop: ServiceClient<SpeechStop>,
        emotion: ServiceClient<EmotionShow>,
        gesture: ServiceClient<GesturePlay>,
        timeout: Duration,
        gesture_speed: f32,
        /// The calls of the step being put out.
        calls: Vec<Call>,
        inputs: mpsc::Sender<Input>,
    },
}

impl Robot {
    pub fn new(
        shell: &mut NodeShell,
        params: &GameManagerParams,
        inputs: mpsc::Sender<Input>,
    ) -> anyhow::Result<Robot> {
        Ok(match params.robot_backend()? {
            game_manager::params::RobotBackend::Topics => Robot::Topics {
                speech: shell.publisher(ROBOT_SPEECH)?,
                emotion: shell.publisher(ROBOT_EMOTION)?,
                gesture: shell.publisher(ROBOT_GESTURE)?,
            },
            game_manager::params::RobotBackend::QtRobot => Robot::QtRobot {
                say: shell.client(SPEECH_SAY)?,
                stop: shell.client(SPEECH_STOP)?,
                emotion: shell.client(EMOTION_SHOW)?,
                gesture: shell.client(GESTURE_PLAY)?,
                timeout: Duration::from_secs_f64(params.robot_call_timeout_s),
                gesture_speed: params.robot_gesture_speed as f32,
                calls: Vec::new(),
                inputs,
            },
        })
    }

    /// Whether QTrobot's services answer (logged at start-up; calls fail later if not).
    pub async fn check(&self, shell: &NodeShell, wait: Duration) {
        if let Robot::QtRobot { say, .. } = self {
            if shell.wait_for_service(say, wait).await {
                tracing::info!("QTrobot's services reachable ({})", SPEECH_SAY.name);
            } else {
                tracing::warn!(
                    "no {} server within {wait:?}: sessions pause at the robot's first act \
                     until QTrobot's services answer (ros1_bridge running?)",
                    SPEECH_SAY.name
                );
            }
        }
    }

    pub fn act(&mut self, act: Act) {
        match self {
            Robot::Topics {
                speech,
                emotion,
                gesture,
            } => {
                let (outbox, data) = match act {
                    Act::Say(s) => (speech, s),
                    Act::Emotion(s) => (emotion, s),
                    Act::Gesture(s) => (gesture, s),
                };
                outbox.send(StringMsg { data });
            }
            Robot::QtRobot {
                say,
                stop,
                emotion,
                gesture,
                timeout,
                gesture_speed,
                calls,
                ..
            } => {
                let timeout = *timeout;
                let call: Call = match act {
                    Act::Say(message) if message.is_empty() => {
                        spawn_call(stop, SpeechStopRequest::default(), timeout, |r| r.status)
                    }
                    Act::Say(message) => {
                        spawn_call(say, SpeechSayRequest { message }, timeout, |r| r.status)
                    }
                    Act::Emotion(name) => {
                        spawn_call(emotion, EmotionShowRequest { name }, timeout, |r| r.status)
                    }
                    Act::Gesture(name) => {
                        let request = GesturePlayRequest {
                            name,
                            speed: *gesture_speed,
                        };
                        spawn_call(gesture, request, timeout, |r| r.status)
                    }
                };
                calls.push(call);
            }
        }
    }

    /// The calls put out since the last step are step `step`: answered when all returned.
    pub fn await_step(&mut self, step: u64) {
        let Robot::QtRobot { calls, inputs, .. } = self else {
            return;
        };
        let calls = std::mem::take(calls);
        let inputs = inputs.clone();
        tokio::spawn(async move {
            let mut failure = None;
            for call in calls {
                let outcome = call
                    .await
                    .unwrap_or_else(|e| Err(format!("the call task ended: {e}")));
                if let Err(reason) = outcome {
                    failure.get_or_insert(reason);
                }
            }
            let input = match failure {
                None => Input::RobotDone { step },
                Some(reason) => Input::RobotFailed { step, reason },
            };
            let _ = inputs.send(input).await;
        });
    }

    /// Calls no step waits for (the goodbye, the emergency stop's silence) go on by
    /// themselves; a failure is logged.
    pub fn detach(&mut self) {
        let Robot::QtRobot { calls, .. } = self else {
            return;
        };
        for call in calls.drain(..) {
            tokio::spawn(async move {
                if let Ok(Err(reason)) = call.await {
                    tracing::warn!("a robot call failed: {reason}");
                }
            });
        }
    }
}

/// Calls `client` on a task of its own; the outcome is Ok when the robot answered `status`
/// true, else the reason.
fn spawn_call<S>(
    client: &ServiceClient<S>,
    request: S::Request,
    timeout: Duration,
    status: fn(&S::Response) -> bool,
) -> Call
where
    S: qt_therapy_msgs::ServiceDefinition + 'static,
{
    let client = client.clone();
    tokio::spawn(async move {
        match client.call(request, timeout).await {
            Ok(response) if status(&response) => Ok(()),
            Ok(_) => Err(format!("{} answered status false", client.name())),
            Err(e) => Err(e.to_string()),
        }
    })
}
