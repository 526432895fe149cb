//! TEST TOOL ONLY: a stand-in for QTrobot's services. By default those of a QTrobot V2 as
//! ros1_bridge offers them (`qt_robot_interface`: `/qt_robot/speech/say`, `/speech/stop`,
//! `/emotion/show`, `/gesture/play`), each call served on its own as rospy does; with `--v3`,
//! those of a QTrobot V3's ROS 2 gateway (`qtrobot_interfaces`: `/qtrobot/tts/engine/say/text`,
//! `/tts/engine/cancel`, `/face/emotion/show`, `/gesture/file/play`), one call at a time as
//! the gateway serves them (see [`Gateway`]). Each call takes as long as a robot would (speech:
//! a time per character; a stop or cancel cuts the speech under way short), is printed as one
//! JSON line when it starts (with when it was asked and which gateway serves it) and when it
//! ends, and succeeds, or fails for the speech containing `--fail-say` (once), or answers only
//! after `--hang-ms` for the speech containing `--hang-say` (once), as a robot that hung for a
//! while would.

use clap::Parser;
use node_shell::{NoParameters, NodeShell, Outbox, ServiceCall, ShellOptions, now_nanos};
use qt_therapy_msgs::ServiceDefinition;
use qt_therapy_msgs::qt_robot_interface as v2;
use qt_therapy_msgs::qtrobot_interfaces as v3;
use qt_therapy_msgs::std_msgs::StringMsg;
use qt_therapy_msgs::topics::Service;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use tokio::sync::{Notify, mpsc};

#[derive(Parser)]
struct Cli {
    /// Serve QTrobot V3's ROS 2 gateway services instead of V2's.
    #[arg(long)]
    v3: bool,
    /// V3: also serve the services of a second gateway process started under this namespace
    /// (e.g. /qtrobot_stop), one call at a time of its own, driving the same robot.
    #[arg(long)]
    second_gateway: Option<String>,
    /// Speaking time per character of text, ms.
    #[arg(long, default_value_t = 20)]
    ms_per_char: u64,
    /// Time an emotion or a gesture takes, ms.
    #[arg(long, default_value_t = 150)]
    animation_ms: u64,
    /// Fail the first speech containing this.
    #[arg(long)]
    fail_say: Option<String>,
    /// Answer the first speech containing this only after --hang-ms.
    #[arg(long)]
    hang_say: Option<String>,
    #[arg(long, default_value_t = 5000)]
    hang_ms: u64,
    /// Also publish each emotion shown on /qt_robot/emotion/show as it starts, for a test's
    /// child to see.
    #[arg(long)]
    echo_emotions: bool,
    /// Also publish each text on /qt_robot/speech/say as the robot starts saying it, for a
    /// test's therapist to hear.
    #[arg(long)]
    echo_speech: bool,
    #[command(flatten)]
    shell: ShellOptions,
}

fn emit(event: serde_json::Value) {
    println!("{event}");
}

/// Once-only trigger on a text.
struct Once {
    text: Option<String>,
    used: AtomicBool,
}

impl Once {
    fn new(text: Option<String>) -> Once {
        Once {
            text,
            used: AtomicBool::new(false),
        }
    }

    fn hit(&self, message: &str) -> bool {
        self.text.as_deref().is_some_and(|t| message.contains(t))
            && !self.used.swap(true, Ordering::SeqCst)
    }
}

/// Who serves a call and when it was asked for: the start event says both.
#[derive(Clone, Copy)]
struct Served {
    /// The V3 gateway's namespace, or "v2".
    by: &'static str,
    asked_ns: i64,
}

impl Served {
    /// A V2 call: served as soon as it arrives.
    fn now() -> Served {
        Served {
            by: "v2",
            asked_ns: now_nanos(),
        }
    }

    fn start(&self, service: &str, arg: &str) {
        emit(
            serde_json::json!({"event": "start", "service": service, "arg": arg,
            "gateway": self.by, "asked_ns": self.asked_ns, "at_ns": now_nanos()}),
        );
    }
}

/// What the stand-in robot does, whichever services reach it.
struct StandIn {
    per_char: Duration,
    animation: Duration,
    hang_for: Duration,
    fail: Once,
    hang: Once,
    /// A stop or cancel: wakes the speech under way.
    silence: Notify,
    echo_emotions: Option<Outbox<StringMsg>>,
    echo_speech: Option<Outbox<StringMsg>>,
}

impl StandIn {
    /// Says `text`; whether it was said to the end without failing.
    async fn say(&self, text: String, served: Served) -> bool {
        served.start("say", &text);
        if self.hang.hit(&text) {
            emit(serde_json::json!({"event": "hang", "service": "say", "arg": text}));
            tokio::time::sleep(self.hang_for).await;
        }
        if let Some(echo) = &self.echo_speech {
            echo.send(StringMsg { data: text.clone() });
        }
        let speaking = tokio::time::sleep(self.per_char * text.chars().count() as u32);
        let interrupted = tokio::select! {
            _ = speaking => false,
            _ = self.silence.notified() => true,
        };
        let ok = !interrupted && !self.fail.hit(&text);
        emit(
            serde_json::json!({"event": "end", "service": "say", "arg": text, "status": ok,
            "interrupted": interrupted, "gateway": served.by, "at_ns": now_nanos()}),
        );
        ok
    }

    fn stop(&self, service: &str, served: Served) -> bool {
        served.start(service, "");
        self.silence.notify_waiters();
        emit(
            serde_json::json!({"event": "end", "service": service, "gateway": served.by,
            "at_ns": now_nanos()}),
        );
        true
    }

    async fn emotion(&self, name: String, served: Served) -> bool {
        served.start("emotion", &name);
        if let Some(echo) = &self.echo_emotions {
            echo.send(StringMsg { data: name.clone() });
        }
        tokio::time::sleep(self.animation).await;
        emit(
            serde_json::json!({"event": "end", "service": "emotion", "arg": name,
            "gateway": served.by, "at_ns": now_nanos()}),
        );
        true
    }

    async fn gesture(&self, name: String, speed: f32, served: Served) -> bool {
        emit(
            serde_json::json!({"event": "start", "service": "gesture", "arg": name,
            "speed": speed, "gateway": served.by, "asked_ns": served.asked_ns, "at_ns": now_nanos()}),
        );
        tokio::time::sleep(self.animation).await;
        emit(
            serde_json::json!({"event": "end", "service": "gesture", "arg": name,
            "gateway": served.by, "at_ns": now_nanos()}),
        );
        true
    }
}

/// Serves a V2 service on `$shell`, each call on a task of its own (rospy serves every call
/// in a thread of its own, and a speech must be stoppable while it runs), answering
/// `$answer(&robot, request).await`'s bool through `$respond`.
macro_rules! serve_v2 {
    ($shell:expr, $robot:expr, $service:expr, $refused:expr, |$r:ident, $req:ident| $answer:expr, $respond:expr) => {{
        let mut calls = $shell.serve($service, |_| $refused)?;
        let robot = $robot.clone();
        tokio::spawn(async move {
            while let Some(call) = calls.recv().await {
                let $r = robot.clone();
                tokio::spawn(async move {
                    let $req = call.request.clone();
                    let ok = $answer;
                    call.respond($respond(ok));
                });
            }
        });
    }};
}

/// A call to a V3 gateway, waiting for it to be served.
enum V3Call {
    Emotion(ServiceCall<v3::FaceEmotionShow>),
    Gesture(ServiceCall<v3::GestureFilePlay>),
    Cancel(ServiceCall<v3::TtsEngineCancel>),
    Say(ServiceCall<v3::TtsEngineSayText>),
}

impl V3Call {
    /// The order LuxAI's gateway creates these services in, which is the order rclpy looks
    /// for waiting calls in (see [`Gateway`]): gateway/qtrobot_ros2/api_list.py lists
    /// /face/emotion/show (line 44), /gesture/file/play (88), /tts/engine/cancel (581),
    /// /tts/engine/say/text (629).
    fn created(&self) -> u8 {
        match self {
            V3Call::Emotion(_) => 0,
            V3Call::Gesture(_) => 1,
            V3Call::Cancel(_) => 2,
            V3Call::Say(_) => 3,
        }
    }
}

/// One process of LuxAI's QTrobot V3 gateway (github luxai-qtrobot/qtrobot-service-hub-
/// gateway-ros, `python -m gateway.qtrobot_ros2 --ros-args -r __ns:=<namespace>`), as it
/// serves calls:
/// - gateway/core/rpc_bridge.py `_setup` (line 67) creates every service with
///   `node.create_service(srv_class, name, callback)`, no callback group, so all of them are
///   in the node's default group, a `MutuallyExclusiveCallbackGroup` (rclpy node.py); the
///   `MultiThreadedExecutor` of gateway/qtrobot_ros2/__main__.py (line 16) runs one callback
///   of a mutually exclusive group at a time, whatever its threads.
/// - A callback returns only when the robot's service hub answers
///   (`requester.call(request_obj, timeout=rpc_timeout)`, rpc_bridge.py line 79): a speech
///   when it has been said, a face or gesture when it has played.
/// - Calls that arrive meanwhile wait. When the callback returns, rclpy (jazzy 7.1,
///   executors.py `_wait_for_ready_callbacks`: `for srv in node.services`) serves the first
///   service, in the order the node created them, that has a call waiting; each service's
///   own calls in the order they came.
///
/// Two gateway processes share the robot: its service hub serves calls in parallel (LuxAI's
/// SDK cancels a speech with a second call while the first is under way: robot-sdk-python
/// src/luxai/robot/core/actions.py `ActionHandle.cancel`, examples/tts_examples.py
/// `say_text_cancel`), so a second gateway's cancel cuts the first one's speech short.
struct Gateway {
    namespace: &'static str,
}

/// `service` (named under /qtrobot) under `namespace`.
fn under<S: ServiceDefinition>(namespace: &str, service: Service<S>) -> Service<S> {
    let tail = service
        .name
        .strip_prefix("/qtrobot")
        .unwrap_or(service.name);
    // Once per service at start-up.
    Service::new(Box::leak(format!("{namespace}{tail}").into_boxed_str()))
}

impl Gateway {
    fn serve(self, shell: &mut NodeShell, robot: Arc<StandIn>) -> anyhow::Result<()> {
        let (tx, mut waiting_calls) = mpsc::unbounded_channel::<(V3Call, i64)>();
        let ns = self.namespace;
        forward(
            shell.serve(under(ns, v3::EMOTION_SHOW), |_| Default::default())?,
            tx.clone(),
            V3Call::Emotion,
        );
        forward(
            shell.serve(under(ns, v3::GESTURE_FILE_PLAY), |_| Default::default())?,
            tx.clone(),
            V3Call::Gesture,
        );
        forward(
            shell.serve(under(ns, v3::TTS_CANCEL), |_| Default::default())?,
            tx.clone(),
            V3Call::Cancel,
        );
        forward(
            shell.serve(under(ns, v3::SAY_TEXT), |_| Default::default())?,
            tx,
            V3Call::Say,
        );
        tokio::spawn(async move {
            // (created, arrival, asked at, call)
            let mut waiting: Vec<(u8, u64, i64, V3Call)> = Vec::new();
            let mut arrivals = 0u64;
            loop {
                if waiting.is_empty() {
                    let Some((call, asked)) = waiting_calls.recv().await else {
                        return;
                    };
                    waiting.push((call.created(), arrivals, asked, call));
                    arrivals += 1;
                }
                while let Ok((call, asked)) = waiting_calls.try_recv() {
                    waiting.push((call.created(), arrivals, asked, call));
                    arrivals += 1;
                }
                let Some(next) = (0..waiting.len()).min_by_key(|i| (waiting[*i].0, waiting[*i].1))
                else {
                    continue;
                };
                let (_, _, asked_ns, call) = waiting.remove(next);
                let served = Served { by: ns, asked_ns };
                // The callback: the gateway serves nothing else until the robot answered.
                match call {
                    V3Call::Say(c) => {
                        let ok = robot.say(c.request.text.clone(), served).await;
                        c.respond(v3::TtsEngineSayTextResponse {
                            status: true,
                            result: ok,
                        });
                    }
                    V3Call::Cancel(c) => {
                        let ok = robot.stop("cancel", served);
                        c.respond(v3::TtsEngineCancelResponse {
                            status: true,
                            result: ok,
                        });
                    }
                    V3Call::Emotion(c) => {
                        let ok = robot.emotion(c.request.emotion.clone(), served).await;
                        c.respond(v3::FaceEmotionShowResponse {
                            status: true,
                            result: ok,
                        });
                    }
                    V3Call::Gesture(c) => {
                        let (name, speed) = (c.request.gesture.clone(), c.request.speed_factor);
                        let ok = robot.gesture(name, speed, served).await;
                        c.respond(v3::GestureFilePlayResponse {
                            status: true,
                            result: ok,
                        });
                    }
                }
            }
        });
        Ok(())
    }
}

/// Hands each call of one service to its gateway with the time it arrived.
fn forward<S: ServiceDefinition + 'static>(
    mut calls: mpsc::Receiver<ServiceCall<S>>,
    to: mpsc::UnboundedSender<(V3Call, i64)>,
    wrap: fn(ServiceCall<S>) -> V3Call,
) {
    tokio::spawn(async move {
        while let Some(call) = calls.recv().await {
            if to.send((wrap(call), now_nanos())).is_err() {
                return;
            }
        }
    });
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let (mut shell, NoParameters {}) = NodeShell::start("qtrobot_peer", &cli.shell)?;
    let robot = Arc::new(StandIn {
        per_char: Duration::from_millis(cli.ms_per_char),
        animation: Duration::from_millis(cli.animation_ms),
        hang_for: Duration::from_millis(cli.hang_ms),
        fail: Once::new(cli.fail_say.clone()),
        hang: Once::new(cli.hang_say.clone()),
        silence: Notify::new(),
        echo_emotions: if cli.echo_emotions {
            Some(shell.publisher(qt_therapy_msgs::topics::ROBOT_EMOTION)?)
        } else {
            None
        },
        echo_speech: if cli.echo_speech {
            Some(shell.publisher(qt_therapy_msgs::topics::ROBOT_SPEECH)?)
        } else {
            None
        },
    });
    if cli.v3 {
        Gateway {
            namespace: "/qtrobot",
        }
        .serve(&mut shell, robot.clone())?;
        if let Some(ns) = &cli.second_gateway {
            let namespace: &'static str = Box::leak(ns.clone().into_boxed_str());
            Gateway { namespace }.serve(&mut shell, robot.clone())?;
        }
    } else {
        serve_v2!(
            shell,
            robot,
            v2::SPEECH_SAY,
            v2::SpeechSayResponse::default(),
            |r, req| r.say(req.message, Served::now()).await,
            |status| v2::SpeechSayResponse { status }
        );
        serve_v2!(
            shell,
            robot,
            v2::SPEECH_STOP,
            v2::SpeechStopResponse::default(),
            |r, _req| r.stop("stop", Served::now()),
            |status| v2::SpeechStopResponse { status }
        );
        serve_v2!(
            shell,
            robot,
            v2::EMOTION_SHOW,
            v2::EmotionShowResponse::default(),
            |r, req| r.emotion(req.name, Served::now()).await,
            |status| v2::EmotionShowResponse { status }
        );
        serve_v2!(
            shell,
            robot,
            v2::GESTURE_PLAY,
            v2::GesturePlayResponse::default(),
            |r, req| r.gesture(req.name, req.speed, Served::now()).await,
            |status| v2::GesturePlayResponse { status }
        );
    }
    emit(serde_json::json!({"event": "ready", "v3": cli.v3,
        "second_gateway": cli.second_gateway}));
    shell.shutdown_signal().await;
    shell.stop().await;
    Ok(())
}
