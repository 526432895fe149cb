//! TEST TOOL ONLY: a stand-in for QTrobot's services. By default those of a QTrobot V2 as
//! ros1_bridge offers them (`qt_robot_interface`: `/qt_robot/speech/say`, `/speech/stop`,
//! `/emotion/show`, `/gesture/play`); with `--v3`, those of a QTrobot V3's ROS 2 gateway
//! (`qtrobot_interfaces`: `/qtrobot/tts/engine/say/text`, `/tts/engine/cancel`,
//! `/face/emotion/show`, `/gesture/file/play`). Each call takes as long as a robot would
//! (speech: a time per character; a stop or cancel cuts the speech under way short), is printed
//! as one JSON line when it starts and when it ends, and succeeds, or fails for the speech
//! containing `--fail-say` (once), or answers only after `--hang-ms` for the speech containing
//! `--hang-say` (once), as a robot that hung for a while would.

use clap::Parser;
use node_shell::{NoParameters, NodeShell, Outbox, ShellOptions, now_nanos};
use qt_therapy_msgs::qt_robot_interface as v2;
use qt_therapy_msgs::qtrobot_interfaces as v3;
use qt_therapy_msgs::std_msgs::StringMsg;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use tokio::sync::Notify;

#[derive(Parser)]
struct Cli {
    /// Serve QTrobot V3's ROS 2 gateway services instead of V2's.
    #[arg(long)]
    v3: bool,
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
    /// Also publish each emotion shown on /qt_robot/emotion/show, for a test's child to see.
    #[arg(long)]
    echo_emotions: bool,
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

/// What the stand-in robot does, whichever services reach it.
struct StandIn {
    per_char: Duration,
    animation: Duration,
    hang_for: Duration,
    fail: Once,
    hang: Once,
    /// A stop or cancel: wakes the speech under way.
    silence: Notify,
    echo: Option<Outbox<StringMsg>>,
}

impl StandIn {
    /// Says `text`; whether it was said to the end without failing.
    async fn say(&self, text: String) -> bool {
        emit(
            serde_json::json!({"event": "start", "service": "say", "arg": text, "at_ns": now_nanos()}),
        );
        if self.hang.hit(&text) {
            emit(serde_json::json!({"event": "hang", "service": "say", "arg": text}));
            tokio::time::sleep(self.hang_for).await;
        }
        let speaking = tokio::time::sleep(self.per_char * text.chars().count() as u32);
        let interrupted = tokio::select! {
            _ = speaking => false,
            _ = self.silence.notified() => true,
        };
        let ok = !interrupted && !self.fail.hit(&text);
        emit(
            serde_json::json!({"event": "end", "service": "say", "arg": text, "status": ok,
            "interrupted": interrupted, "at_ns": now_nanos()}),
        );
        ok
    }

    fn stop(&self, service: &str) -> bool {
        emit(serde_json::json!({"event": "start", "service": service, "at_ns": now_nanos()}));
        self.silence.notify_waiters();
        true
    }

    async fn emotion(&self, name: String) -> bool {
        emit(
            serde_json::json!({"event": "start", "service": "emotion", "arg": name, "at_ns": now_nanos()}),
        );
        if let Some(echo) = &self.echo {
            echo.send(StringMsg { data: name.clone() });
        }
        tokio::time::sleep(self.animation).await;
        emit(
            serde_json::json!({"event": "end", "service": "emotion", "arg": name, "at_ns": now_nanos()}),
        );
        true
    }

    async fn gesture(&self, name: String, speed: f32) -> bool {
        emit(
            serde_json::json!({"event": "start", "service": "gesture", "arg": name,
            "speed": speed, "at_ns": now_nanos()}),
        );
        tokio::time::sleep(self.animation).await;
        emit(
            serde_json::json!({"event": "end", "service": "gesture", "arg": name, "at_ns": now_nanos()}),
        );
        true
    }
}

/// Serves `$service` on `$shell`, each call on a task of its own (a speech must be stoppable
/// while it runs), answering `$answer(&robot, request).await`'s bool through `$respond`.
macro_rules! serve {
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
        echo: if cli.echo_emotions {
            Some(shell.publisher(qt_therapy_msgs::topics::ROBOT_EMOTION)?)
        } else {
            None
        },
    });
    if cli.v3 {
        // The gateway's `status`: the call reached the robot; `result`: what it answered.
        let v3_answer = |ok: bool| (true, ok);
        serve!(
            shell,
            robot,
            v3::SAY_TEXT,
            v3::TtsEngineSayTextResponse::default(),
            |r, req| r.say(req.text).await,
            |ok| {
                let (status, result) = v3_answer(ok);
                v3::TtsEngineSayTextResponse { status, result }
            }
        );
        serve!(
            shell,
            robot,
            v3::TTS_CANCEL,
            v3::TtsEngineCancelResponse::default(),
            |r, _req| r.stop("cancel"),
            |ok| v3::TtsEngineCancelResponse {
                status: true,
                result: ok
            }
        );
        serve!(
            shell,
            robot,
            v3::EMOTION_SHOW,
            v3::FaceEmotionShowResponse::default(),
            |r, req| r.emotion(req.emotion).await,
            |ok| v3::FaceEmotionShowResponse {
                status: true,
                result: ok
            }
        );
        serve!(
            shell,
            robot,
            v3::GESTURE_FILE_PLAY,
            v3::GestureFilePlayResponse::default(),
            |r, req| r.gesture(req.gesture, req.speed_factor).await,
            |ok| v3::GestureFilePlayResponse {
                status: true,
                result: ok
            }
        );
    } else {
        serve!(
            shell,
            robot,
            v2::SPEECH_SAY,
            v2::SpeechSayResponse::default(),
            |r, req| r.say(req.message).await,
            |status| v2::SpeechSayResponse { status }
        );
        serve!(
            shell,
            robot,
            v2::SPEECH_STOP,
            v2::SpeechStopResponse::default(),
            |r, _req| r.stop("stop"),
            |status| v2::SpeechStopResponse { status }
        );
        serve!(
            shell,
            robot,
            v2::EMOTION_SHOW,
            v2::EmotionShowResponse::default(),
            |r, req| r.emotion(req.name).await,
            |status| v2::EmotionShowResponse { status }
        );
        serve!(
            shell,
            robot,
            v2::GESTURE_PLAY,
            v2::GesturePlayResponse::default(),
            |r, req| r.gesture(req.name, req.speed).await,
            |status| v2::GesturePlayResponse { status }
        );
    }
    emit(serde_json::json!({"event": "ready", "v3": cli.v3}));
    shell.shutdown_signal().await;
    shell.stop().await;
    Ok(())
}
