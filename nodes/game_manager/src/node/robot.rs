//! The robot side of the game manager's run loop: the core's robot acts go to QTrobot's
//! std_msgs/String topics (`robot_backend: topics`) or to its services (`qtrobot`: V2's
//! qt_robot_interface; `qtrobot_ros2`: V3's gateway), where the calls of one step run together
//! and the step is answered with `Input::RobotDone` once every call returned (or
//! `Input::RobotFailed` with the reason: an error, a `false` status, no answer within
//! `robot_call_timeout_s`). For a V3 the core puts out one call per step, as its gateway
//! serves one at a time; the silence (the emergency stop's cancel) goes to the stop gateway,
//! a second gateway process under `qtrobot_ros2_stop_namespace` that nothing keeps busy.

use crate::params::RobotBackend;
use crate::{GameManagerParams, Input};
use node_shell::{Bus, Outbox, ServiceClient};
use qt_therapy_msgs::qt_robot_interface::{
    EMOTION_SHOW, EmotionShow, EmotionShowRequest, GESTURE_PLAY, GesturePlay, GesturePlayRequest,
    SPEECH_SAY, SPEECH_STOP, SpeechSay, SpeechSayRequest, SpeechStop, SpeechStopRequest,
};
use qt_therapy_msgs::qtrobot_interfaces as v3;
use qt_therapy_msgs::std_msgs::StringMsg;
use qt_therapy_msgs::topics::{ROBOT_EMOTION, ROBOT_GESTURE, ROBOT_SPEECH, Service};
use std::time::Duration;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

/// What QTrobot's speech topic (`/qt_robot/speech/say`) carries for a silence: it has no
/// stop of its own, and the empty utterance cuts short what the robot is saying.
pub const SILENCE_ON_SPEECH_TOPIC: &str = "";

/// One robot act of the core.
pub enum Act {
    Say(String),
    /// Stop speaking at once.
    Silence,
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
    Services {
        services: RobotServices,
        timeout: Duration,
        gesture_speed: f32,
        /// The calls of the step being put out.
        calls: Vec<Call>,
        inputs: mpsc::Sender<Input>,
    },
}

/// QTrobot's services, by robot generation.
pub enum RobotServices {
    /// V2: qt_robot_interface (ROS 1, through ros1_bridge).
    V2 {
        say: ServiceClient<SpeechSay>,
        stop: ServiceClient<SpeechStop>,
        emotion: ServiceClient<EmotionShow>,
        gesture: ServiceClient<GesturePlay>,
    },
    /// V3: LuxAI's ROS 2 gateway.
    V3 {
        say: ServiceClient<v3::TtsEngineSayText>,
        /// The stop gateway's cancel (or the robot's gateway's, with no stop namespace).
        cancel: ServiceClient<v3::TtsEngineCancel>,
        emotion: ServiceClient<v3::FaceEmotionShow>,
        gesture: ServiceClient<v3::GestureFilePlay>,
    },
}

/// `service`, named under the gateway's /qtrobot, under `namespace` instead.
fn under<S: qt_therapy_msgs::ServiceDefinition>(
    namespace: &str,
    service: Service<S>,
) -> Service<S> {
    let tail = service
        .name
        .strip_prefix("/qtrobot")
        .unwrap_or(service.name);
    // Once, at start-up: service names live as long as the node.
    Service::new(Box::leak(format!("{namespace}{tail}").into_boxed_str()))
}

impl Robot {
    pub fn new(
        bus: &mut impl Bus,
        params: &GameManagerParams,
        inputs: mpsc::Sender<Input>,
    ) -> anyhow::Result<Robot> {
        let services = match params.robot.backend()? {
            RobotBackend::Topics => {
                return Ok(Robot::Topics {
                    speech: bus.publisher(ROBOT_SPEECH)?,
                    emotion: bus.publisher(ROBOT_EMOTION)?,
                    gesture: bus.publisher(ROBOT_GESTURE)?,
                });
            }
            RobotBackend::QtRobot => RobotServices::V2 {
                say: bus.client(SPEECH_SAY)?,
                stop: bus.client(SPEECH_STOP)?,
                emotion: bus.client(EMOTION_SHOW)?,
                gesture: bus.client(GESTURE_PLAY)?,
            },
            RobotBackend::QtRobotRos2 => RobotServices::V3 {
                say: bus.client(v3::SAY_TEXT)?,
                cancel: match params.robot.qtrobot_ros2_stop_namespace.as_str() {
                    "" => bus.client(v3::TTS_CANCEL)?,
                    namespace => bus.client(under(namespace, v3::TTS_CANCEL))?,
                },
                emotion: bus.client(v3::EMOTION_SHOW)?,
                gesture: bus.client(v3::GESTURE_FILE_PLAY)?,
            },
        };
        Ok(Robot::Services {
            services,
            timeout: Duration::from_secs_f64(params.robot.robot_call_timeout_s),
            gesture_speed: params.robot.robot_gesture_speed as f32,
            calls: Vec::new(),
            inputs,
        })
    }

    /// Whether QTrobot's services answer (logged at start-up; calls fail later if not).
    pub async fn check(&self, bus: &impl Bus, wait: Duration) {
        let Robot::Services { services, .. } = self else {
            return;
        };
        let (reachable, name, hint) = match services {
            RobotServices::V2 { say, .. } => (
                bus.wait_for_service(say, wait).await,
                SPEECH_SAY.name,
                "ros1_bridge running?",
            ),
            RobotServices::V3 { say, .. } => (
                bus.wait_for_service(say, wait).await,
                v3::SAY_TEXT.name,
                "LuxAI's gateway running: python -m gateway.qtrobot_ros2?",
            ),
        };
        if reachable {
            tracing::info!("QTrobot's services reachable ({name})");
        } else {
            tracing::warn!(
                "no {name} server within {wait:?}: sessions pause at the robot's first act \
                 until QTrobot's services answer ({hint})"
            );
        }
        if let RobotServices::V3 { cancel, .. } = services
            && cancel.name() != v3::TTS_CANCEL.name
        {
            let stop = cancel.name();
            if bus.wait_for_service(cancel, wait).await {
                tracing::info!("QTrobot's stop gateway reachable ({stop})");
            } else {
                let namespace = stop.strip_suffix("/tts/engine/cancel").unwrap_or(stop);
                tracing::warn!(
                    "no {stop} server within {wait:?}: the emergency stop cannot cut the robot \
                     short; it goes silent when the call under way ends. Start a second gateway \
                     for stopping: python -m gateway.qtrobot_ros2 --ros-args -p \
                     robot_ip:=<ROBOT_IP> -r __ns:={namespace}"
                );
            }
        }
    }

    /// `topics`: waits (at most `wait`) until node `node` subscribes to the speech topic, so
    /// the robot hears the first line (a game manager started beside an already running
    /// robot spoke before discovery had matched the robot's subscriber, and the line was
    /// lost). The reason when it never does; None at once for the services.
    pub async fn wait_for_listener(
        &self,
        bus: &impl Bus,
        node: &str,
        wait: Duration,
    ) -> Option<String> {
        let Robot::Topics { speech, .. } = self else {
            return None;
        };
        if node.is_empty() || bus.wait_for_node_subscription(speech, node, wait).await {
            if !node.is_empty() {
                tracing::info!("the robot's speech subscriber ({node}) is there");
            }
            return None;
        }
        Some(format!(
            "the robot ({node}) did not subscribe to {} within {wait:?}: it may miss what is \
             said; check that the robot's speech node runs",
            speech.topic()
        ))
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
                    // The one place the core's silence becomes the empty utterance.
                    Act::Silence => (speech, SILENCE_ON_SPEECH_TOPIC.to_string()),
                    Act::Emotion(s) => (emotion, s),
                    Act::Gesture(s) => (gesture, s),
                };
                outbox.send(StringMsg { data });
            }
            Robot::Services {
                services,
                timeout,
                gesture_speed,
                calls,
                ..
            } => calls.push(services.call(act, *timeout, *gesture_speed)),
        }
    }

    /// The calls put out since the last step are step `step`: answered when all returned.
    pub fn await_step(&mut self, step: u64) {
        let Robot::Services { calls, inputs, .. } = self else {
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
        let Robot::Services { calls, .. } = self else {
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

impl RobotServices {
    /// Puts `act` out as the service call it is on this robot.
    fn call(&self, act: Act, timeout: Duration, gesture_speed: f32) -> Call {
        match self {
            RobotServices::V2 {
                say,
                stop,
                emotion,
                gesture,
            } => match act {
                Act::Silence => {
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
                        speed: gesture_speed,
                    };
                    spawn_call(gesture, request, timeout, |r| r.status)
                }
            },
            // The gateway answers `status` (the call reached the robot) and `result` (what
            // the robot said of it): both must be true.
            RobotServices::V3 {
                say,
                cancel,
                emotion,
                gesture,
            } => match act {
                Act::Silence => {
                    let request = v3::TtsEngineCancelRequest::default();
                    spawn_call(cancel, request, timeout, |r| r.status && r.result)
                }
                Act::Say(text) => {
                    // Empty fields and zeros leave the robot's own voice settings.
                    let request = v3::TtsEngineSayTextRequest {
                        text,
                        ..Default::default()
                    };
                    spawn_call(say, request, timeout, |r| r.status && r.result)
                }
                Act::Emotion(emotion_name) => {
                    let request = v3::FaceEmotionShowRequest {
                        emotion: emotion_name,
                        speed: 0.0,
                    };
                    spawn_call(emotion, request, timeout, |r| r.status && r.result)
                }
                Act::Gesture(name) => {
                    let request = v3::GestureFilePlayRequest {
                        gesture: name,
                        speed_factor: gesture_speed,
                    };
                    spawn_call(gesture, request, timeout, |r| r.status && r.result)
                }
            },
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
            Ok(_) => Err(format!("{} answered that it failed", client.name())),
            Err(e) => Err(e.to_string()),
        }
    })
}
