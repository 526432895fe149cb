//! A DDS peer for the cross-process tests. `responder` subscribes to the tablet answers and
//! serves `PredictUser`; `caller` publishes answers (good, out of range, and undecodable),
//! calls the service and lingers; `logger` logs lines (to `/rosout` through the shell) and
//! `rosout-reader` prints the `/rosout` records it receives; `estimates` prints the engagement
//! classifier's per-frame estimates. Each prints one JSON line per event, so a test can check
//! what crossed.

use anyhow::Context;
use clap::{Parser, Subcommand};
use node_shell::{NoParameters, NodeShell, ShellOptions, header_now};
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::topics::{PREDICT_USER, TABLET_ANSWER};
use qt_therapy_msgs::{PredictUserRequest, PredictUserResponse, TabletAnswer, dds_type_name};
use std::time::Duration;

#[derive(Parser)]
struct Cli {
    #[command(subcommand)]
    role: Role,
    #[command(flatten)]
    shell: ShellOptions,
}

#[derive(Subcommand)]
enum Role {
    /// Print every valid TabletAnswer and answer PredictUser until SIGINT/SIGTERM.
    Responder,
    /// Publish `count` answers plus bad ones, call PredictUser, print `done`, then stay for
    /// `linger` seconds or until SIGINT/SIGTERM: a reliable sample lost on the way is sent again
    /// only while its writer lives (RustDDS's heartbeat comes every second), so a caller
    /// exiting at once lost its last answers in 1 of 10 runs.
    Caller {
        #[arg(long, default_value_t = 5)]
        count: u32,
        #[arg(long, default_value_t = 2.0)]
        linger: f64,
    },
    /// Log `lines` INFO lines "rosout probe line N", print `logged`, then idle until SIGINT.
    Logger {
        #[arg(long, default_value_t = 500)]
        lines: u32,
    },
    /// Print every `/rosout` record received (a late-joining, transient-local reader) for
    /// `seconds`, then exit.
    RosoutReader {
        #[arg(long, default_value_t = 3)]
        seconds: u64,
    },
    /// Print every EngagementEstimate received (after `ready`) until SIGINT/SIGTERM, and the
    /// ROS4HRI persons tracked and their engagement levels (each person's read from when it
    /// is first listed, as libhri does).
    Estimates,
}

fn emit(event: serde_json::Value) {
    println!("{event}");
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let (mut shell, NoParameters {}) = NodeShell::start("dds_probe", &cli.shell)?;
    match cli.role {
        Role::Responder => responder(&mut shell).await?,
        Role::Caller { count, linger } => {
            caller(&mut shell, count).await?;
            emit(serde_json::json!({"event": "done"}));
            let linger = Duration::try_from_secs_f64(linger).context("--linger")?;
            tokio::select! {
                _ = tokio::time::sleep(linger) => {}
                _ = shell.shutdown_signal() => {}
            }
        }
        Role::Logger { lines } => {
            for i in 1..=lines {
                tracing::info!("rosout probe line {i}");
            }
            emit(serde_json::json!({"event": "logged", "lines": lines}));
            shell.shutdown_signal().await;
        }
        Role::RosoutReader { seconds } => rosout_reader(&mut shell, seconds).await?,
        Role::Estimates => estimates(&mut shell).await?,
    }
    shell.stop().await;
    Ok(())
}

async fn responder(shell: &mut NodeShell) -> anyhow::Result<()> {
    let mut answers = shell.subscribe(TABLET_ANSWER, 64)?;
    let mut calls = shell.serve(PREDICT_USER, |e| PredictUserResponse {
        ok: false,
        error: e.to_string(),
        ..Default::default()
    })?;
    emit(serde_json::json!({"event": "ready"}));
    let stop = shell.shutdown_signal();
    tokio::pin!(stop);
    loop {
        tokio::select! {
            _ = &mut stop => break,
            Some(a) = answers.recv() => emit(serde_json::json!({
                "event": "answer", "sequence_id": a.sequence_id, "answer": a.answer,
            })),
            Some(call) = calls.recv() => {
                let r = call.request.clone();
                emit(serde_json::json!({"event": "request", "cluster": r.cluster, "level": r.level}));
                // A deterministic function of the request, so the caller can check the reply
                // came from this request.
                let p = f64::from(r.level) / 4.0;
                call.respond(PredictUserResponse {
                    ok: true,
                    error: String::new(),
                    success_probability: p,
                    success_std: 0.0,
                    engagement: f64::from(r.outcome) * 0.5,
                    engagement_std: f64::from(r.cluster),
                });
            }
        }
    }
    let drops = shell.drops();
    emit(
        serde_json::json!({"event": "stopped", "dropped_answers": drops.total(TABLET_ANSWER.name)}),
    );
    Ok(())
}

/// Same DDS type name as TabletAnswer, but only its header: a peer decoding it as a
/// TabletAnswer runs out of bytes.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct TruncatedAnswer {
    header: Header,
}
impl ros2_client::Message for TruncatedAnswer {}

async fn caller(shell: &mut NodeShell, count: u32) -> anyhow::Result<()> {
    let client = shell.client(PREDICT_USER)?;
    if !shell
        .wait_for_service(&client, Duration::from_secs(20))
        .await
    {
        anyhow::bail!("no PredictUser server appeared within 20 s");
    }
    let answers = shell.publisher(TABLET_ANSWER)?;
    let qos = node_shell::qos_profile(TABLET_ANSWER.qos);
    let node = shell.node_mut();
    let topic = node
        .create_topic(
            &ros2_client::Name::new("/qt_therapy/tablet", "answer")
                .map_err(|e| anyhow::anyhow!("{e:?}"))?,
            dds_type_name::<TabletAnswer>(),
            &qos,
        )
        .context("raw topic")?;
    let truncated = node
        .create_publisher::<TruncatedAnswer>(&topic, None)
        .context("raw publisher")?;
    if !answers
        .wait_for_subscribers(shell, Duration::from_secs(20))
        .await
    {
        anyhow::bail!("no TabletAnswer subscriber appeared within 20 s");
    }

    let valid = |i: u32| TabletAnswer {
        header: header_now(),
        session_id: "probe".into(),
        sequence_id: i,
        answer: vec!["happy".into(), "sad".into(), "angry".into()],
        response_time: 1.5,
    };
    answers.send(valid(1));
    // Out of range: an unknown emotion (three times: logged once, counted thrice), then a NaN
    // response time.
    for id in 1000..1003 {
        answers.send(TabletAnswer {
            answer: vec!["joyful".into()],
            ..valid(id)
        });
    }
    answers.send(TabletAnswer {
        response_time: f32::NAN,
        ..valid(1003)
    });
    // Undecodable as a TabletAnswer.
    truncated
        .publish(TruncatedAnswer {
            header: header_now(),
        })
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    for i in 2..=count {
        answers.send(valid(i));
    }
    emit(serde_json::json!({"event": "published", "count": count}));

    let good = client
        .call(
            PredictUserRequest {
                cluster: 1,
                level: 3,
                feedback: 2,
                previous_score: -3,
                outcome: -1,
            },
            Duration::from_secs(10),
        )
        .await?;
    emit(
        serde_json::json!({"event": "response", "ok": good.ok, "p": good.success_probability, "e": good.engagement, "cluster": good.engagement_std}),
    );
    let bad = client
        .call(
            PredictUserRequest {
                cluster: 0,
                level: 4,
                feedback: 0,
                previous_score: 0,
                outcome: 1,
            },
            Duration::from_secs(10),
        )
        .await?;
    emit(serde_json::json!({"event": "response", "ok": bad.ok, "error": bad.error}));
    Ok(())
}

async fn rosout_reader(shell: &mut NodeShell, seconds: u64) -> anyhow::Result<()> {
    use futures::StreamExt as _;
    let qos = node_shell::qos_profile(qt_therapy_msgs::topics::QosKind::Durable)
        .history(ros2_client::qos::History::KeepLast { depth: 10_000 });
    let node = shell.node_mut();
    let topic = node
        .create_topic(
            &ros2_client::Name::new("/", "rosout").map_err(|e| anyhow::anyhow!("{e:?}"))?,
            ros2_client::MessageTypeName::new("rcl_interfaces", "Log"),
            &qos,
        )
        .context("the /rosout topic")?;
    let reader = node
        .create_subscription::<ros2_client::log::Log>(&topic, Some(qos))
        .context("a /rosout subscription")?;
    let records = reader.async_stream();
    tokio::pin!(records);
    let until = tokio::time::sleep(Duration::from_secs(seconds));
    tokio::pin!(until);
    loop {
        tokio::select! {
            _ = &mut until => break,
            Some(Ok((log, _))) = records.next() => {
                emit(serde_json::json!({"event": "rosout", "name": log.name, "msg": log.msg}));
            }
        }
    }
    Ok(())
}

async fn estimates(shell: &mut NodeShell) -> anyhow::Result<()> {
    use qt_therapy_msgs::topics::{PERSONS_TRACKED, engagement_status};
    let mut estimates = shell.subscribe(qt_therapy_msgs::topics::ENGAGEMENT_ESTIMATE, 4096)?;
    let mut tracked = shell.subscribe(PERSONS_TRACKED, 64)?;
    let (level_tx, mut levels) = tokio::sync::mpsc::channel(256);
    let mut followed = std::collections::BTreeSet::new();
    emit(serde_json::json!({"event": "ready"}));
    let stop = shell.shutdown_signal();
    tokio::pin!(stop);
    loop {
        tokio::select! {
            _ = &mut stop => break,
            Some(e) = estimates.recv() => emit(serde_json::json!({
                "event": "estimate", "face_id": e.face_id, "frame_id": e.header.frame_id,
                "stamp_ns": e.header.stamp.to_nanos(), "label": e.label,
            })),
            Some(t) = tracked.recv() => {
                for id in &t.ids {
                    if followed.insert(id.clone()) {
                        let mut rx = shell.subscribe(engagement_status(id), 256)?;
                        let (tx, id) = (level_tx.clone(), id.clone());
                        tokio::spawn(async move {
                            while let Some(l) = rx.recv().await {
                                if tx.send((id.clone(), l)).await.is_err() {
                                    break;
                                }
                            }
                        });
                    }
                }
                emit(serde_json::json!({"event": "tracked", "ids": t.ids}));
            }
            Some((person, l)) = levels.recv() => emit(serde_json::json!({
                "event": "engagement_status", "person": person, "level": l.level,
                "stamp_ns": l.header.stamp.to_nanos(),
            })),
        }
    }
    Ok(())
}
