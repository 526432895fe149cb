//! TEST TOOL ONLY: a stand-in for QTrobot's services (the ROS 2 side of `qt_robot_interface`
//! as ros1_bridge offers it): `/qt_robot/speech/say`, `/qt_robot/speech/stop`,
//! `/qt_robot/emotion/show` and `/qt_robot/gesture/play`. Each call takes as long as a robot
//! would (speech: a time per character), is printed as one JSON line when it starts and when it
//! ends, and answers `status: true`, or `false` for the speech containing `--fail-say` (once),
//! or only after `--hang-ms` for the speech containing `--hang-say` (once), as a robot that
//! hung for a while would.

use clap::Parser;
use node_shell::{NoParameters, NodeShell, ShellOptions, now_nanos};
use qt_therapy_msgs::qt_robot_interface::*;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

#[derive(Parser)]
struct Cli {
    /// Speaking time per character of text, ms.
    #[arg(long, default_value_t = 20)]
    ms_per_char: u64,
    /// Time an emotion or a gesture takes, ms.
    #[arg(long, default_value_t = 150)]
    animation_ms: u64,
    /// Answer status false to the first speech containing this.
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
    fn hit(&self, message: &str) -> bool {
        self.text.as_deref().is_some_and(|t| message.contains(t))
            && !self.used.swap(true, Ordering::SeqCst)
    }
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let (mut shell, NoParameters {}) = NodeShell::start("qtrobot_peer", &cli.shell)?;
    let mut say = shell.serve(SPEECH_SAY, |_| SpeechSayResponse { status: false })?;
    let mut stop = shell.serve(SPEECH_STOP, |_| SpeechStopResponse { status: false })?;
    let mut emotion = shell.serve(EMOTION_SHOW, |_| EmotionShowResponse { status: false })?;
    let mut gesture = shell.serve(GESTURE_PLAY, |_| GesturePlayResponse { status: false })?;
    let echo = if cli.echo_emotions {
        Some(shell.publisher(qt_therapy_msgs::topics::ROBOT_EMOTION)?)
    } else {
        None
    };
    let fail = Arc::new(Once {
        text: cli.fail_say.clone(),
        used: AtomicBool::new(false),
    });
    let hang = Arc::new(Once {
        text: cli.hang_say.clone(),
        used: AtomicBool::new(false),
    });
    let (per_char, animation, hang_for) = (
        Duration::from_millis(cli.ms_per_char),
        Duration::from_millis(cli.animation_ms),
        Duration::from_millis(cli.hang_ms),
    );
    emit(serde_json::json!({"event": "ready"}));
    tokio::spawn(async move {
        while let Some(call) = say.recv().await {
            let message = call.request.message.clone();
            let start = now_nanos();
            emit(
                serde_json::json!({"event": "start", "service": "say", "arg": message, "at_ns": start}),
            );
            if hang.hit(&message) {
                emit(serde_json::json!({"event": "hang", "service": "say", "arg": message}));
                tokio::time::sleep(hang_for).await;
            }
            tokio::time::sleep(per_char * message.chars().count() as u32).await;
            let status = !fail.hit(&message);
            emit(
                serde_json::json!({"event": "end", "service": "say", "arg": message,
                "status": status, "at_ns": now_nanos()}),
            );
            call.respond(SpeechSayResponse { status });
        }
    });
    tokio::spawn(async move {
        while let Some(call) = stop.recv().await {
            emit(serde_json::json!({"event": "start", "service": "stop", "at_ns": now_nanos()}));
            call.respond(SpeechStopResponse { status: true });
        }
    });
    tokio::spawn(async move {
        while let Some(call) = emotion.recv().await {
            let name = call.request.name.clone();
            emit(
                serde_json::json!({"event": "start", "service": "emotion", "arg": name, "at_ns": now_nanos()}),
            );
            if let Some(echo) = &echo {
                echo.send(qt_therapy_msgs::std_msgs::StringMsg { data: name.clone() });
            }
            tokio::time::sleep(animation).await;
            emit(
                serde_json::json!({"event": "end", "service": "emotion", "arg": name, "at_ns": now_nanos()}),
            );
            call.respond(EmotionShowResponse { status: true });
        }
    });
    tokio::spawn(async move {
        while let Some(call) = gesture.recv().await {
            let name = call.request.name.clone();
            emit(
                serde_json::json!({"event": "start", "service": "gesture", "arg": name,
                "speed": call.request.speed, "at_ns": now_nanos()}),
            );
            tokio::time::sleep(animation).await;
            emit(
                serde_json::json!({"event": "end", "service": "gesture", "arg": name, "at_ns": now_nanos()}),
            );
            call.respond(GesturePlayResponse { status: true });
        }
    });
    shell.shutdown_signal().await;
    shell.stop().await;
    Ok(())
}
