//! `openface_bridge`: follows the CSV OpenFace 2's FeatureExtraction writes (or standard input)
//! and publishes each face and frame on /qt_therapy/openface/features.
//!   openface_bridge --csv /home/qtrobot/openface/webcam.csv
//!   FeatureExtraction -device 0 -pose -aus -gaze -out_dir /tmp/of -of webcam  (writes it)

use anyhow::{Context, bail};
use clap::Parser;
use node_shell::logging::log_at;
use node_shell::{NodeShell, ShellOptions, now_nanos};
use openface_bridge::{Bridge, FollowEvent, Follower, OpenFaceBridgeParams, Output};
use qt_therapy_msgs::OpenFaceFeatures;
use qt_therapy_msgs::topics::OPENFACE_FEATURES;
use std::io::{BufRead, Read as _};
use std::path::PathBuf;
use std::time::Duration;
use tokio::sync::mpsc;

#[derive(Parser)]
#[command(
    about = "Publish OpenFace's CSV (FeatureExtraction output, followed as it grows) as OpenFaceFeatures messages"
)]
struct Cli {
    /// The CSV to follow, or - for standard input (overrides csv_path of the parameter file).
    #[arg(long)]
    csv: Option<String>,
    #[command(flatten)]
    shell: ShellOptions,
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let (mut shell, mut params): (NodeShell, OpenFaceBridgeParams) =
        NodeShell::start("openface_bridge", &cli.shell)?;
    if let Some(csv) = &cli.csv {
        params.csv_path = csv.clone();
    }
    let params_file = cli.shell.params_path(shell.name());
    let outcome = match params.validate() {
        Ok(stamp) => run(&mut shell, &params, Bridge::new(&params, stamp)).await,
        Err(e) => Err(anyhow::Error::new(e).context(format!(
            "parameter file {} (or --csv)",
            params_file.display()
        ))),
    };
    shell.stop().await;
    outcome
}

/// What the reading side hands to the publishing loop.
enum Read {
    Event(FollowEvent),
    /// Standard input ended: the producer is gone.
    End,
    Failed(String),
}

async fn run(
    shell: &mut NodeShell,
    params: &OpenFaceBridgeParams,
    mut bridge: Bridge,
) -> anyhow::Result<()> {
    let frames = shell.publisher(OPENFACE_FEATURES)?;
    let (tx, mut rx) = mpsc::channel::<Read>(1024);
    let source = if params.csv_path == "-" {
        spawn_stdin(tx, params.max_line_bytes);
        "standard input".to_string()
    } else {
        let path = PathBuf::from(&params.csv_path);
        spawn_follower(tx, &path, params)?;
        path.display().to_string()
    };
    tracing::info!(source = %source, frame_id = %params.frame_id, stamp = %params.stamp, "following OpenFace's CSV");
    let stop = shell.shutdown_signal();
    tokio::pin!(stop);
    let report_every = Duration::from_secs_f64(params.report_interval_s);
    let mut report = tokio::time::interval(report_every.max(Duration::from_millis(10)));
    report.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut last_reported = bridge.counts().clone();
    let publish = |m: OpenFaceFeatures| {
        if !frames.send(m) {
            tracing::warn!("publishing a frame on {} failed", OPENFACE_FEATURES.name);
        }
    };
    loop {
        let read = tokio::select! {
            _ = &mut stop => break,
            _ = report.tick(), if !report_every.is_zero() => {
                if *bridge.counts() != last_reported {
                    tracing::info!("{}", bridge.report());
                    last_reported = bridge.counts().clone();
                }
                continue;
            }
            read = rx.recv() => read,
        };
        let outputs = match read {
            Some(Read::Event(FollowEvent::Line { text, line_no })) => bridge
                .line(&text, line_no, now_nanos())
                .with_context(|| format!("{source}, line {line_no}"))?,
            Some(Read::Event(FollowEvent::TooLong { line_no })) => bridge.too_long(line_no),
            Some(Read::Event(FollowEvent::Restarted { why })) => bridge.restarted(why),
            Some(Read::Failed(e)) => bail!("reading {source}: {e}"),
            Some(Read::End) | None => {
                tracing::info!("{source} ended");
                break;
            }
        };
        for o in outputs {
            match o {
                Output::Publish(m) => publish(m),
                Output::Log(level, line) => log_at(level, &line),
            }
        }
    }
    tracing::info!("{}", bridge.report());
    Ok(())
}

/// Polls the file on a thread of its own (file reads block) and sends what it finds.
fn spawn_follower(
    tx: mpsc::Sender<Read>,
    path: &std::path::Path,
    params: &OpenFaceBridgeParams,
) -> anyhow::Result<()> {
    let mut follower = Follower::new(path, params.max_line_bytes, params.start_at_end);
    let every = Duration::from_secs_f64(params.poll_interval_s);
    std::thread::Builder::new()
        .name("csv-follower".into())
        .spawn(move || {
            let mut waiting_told = false;
            loop {
                match follower.poll() {
                    Ok(events) => {
                        for e in events {
                            if tx.blocking_send(Read::Event(e)).is_err() {
                                return;
                            }
                        }
                    }
                    Err(e) => {
                        let _ = tx.blocking_send(Read::Failed(e.to_string()));
                        return;
                    }
                }
                if !follower.is_open() && !waiting_told {
                    tracing::info!(path = %follower.path().display(), "waiting for OpenFace to create the CSV");
                    waiting_told = true;
                }
                if tx.is_closed() {
                    return;
                }
                std::thread::sleep(every);
            }
        })
        .context("starting the CSV follower")?;
    Ok(())
}

/// Reads standard input line by line on a thread of its own; a line over the limit is
/// skipped to its newline without being held.
fn spawn_stdin(tx: mpsc::Sender<Read>, max_line_bytes: usize) {
    std::thread::spawn(move || {
        let stdin = std::io::stdin();
        let mut input = stdin.lock();
        let mut buf = Vec::new();
        let mut line_no = 0;
        loop {
            buf.clear();
            let limit = max_line_bytes as u64 + 1;
            let read = (&mut input).take(limit).read_until(b'\n', &mut buf);
            let event = match read {
                Ok(0) => {
                    let _ = tx.blocking_send(Read::End);
                    return;
                }
                Ok(_) if buf.last() == Some(&b'\n') => {
                    buf.pop();
                    line_no += 1;
                    FollowEvent::Line {
                        text: String::from_utf8_lossy(&buf).into_owned(),
                        line_no,
                    }
                }
                Ok(_) if buf.len() as u64 >= limit => {
                    line_no += 1;
                    // The rest of the overlong line, to its newline.
                    let mut rest = Vec::new();
                    if let Err(e) = skip_line(&mut input, &mut rest) {
                        let _ = tx.blocking_send(Read::Failed(e.to_string()));
                        return;
                    }
                    FollowEvent::TooLong { line_no }
                }
                // The last line, without a newline: input ended.
                Ok(_) => {
                    line_no += 1;
                    FollowEvent::Line {
                        text: String::from_utf8_lossy(&buf).into_owned(),
                        line_no,
                    }
                }
                Err(e) => {
                    let _ = tx.blocking_send(Read::Failed(e.to_string()));
                    return;
                }
            };
            if tx.blocking_send(Read::Event(event)).is_err() {
                return;
            }
        }
    });
}

/// Reads up to and including the next newline, a bounded piece at a time.
fn skip_line(input: &mut impl BufRead, scratch: &mut Vec<u8>) -> std::io::Result<()> {
    loop {
        scratch.clear();
        let n = input.take(65_536).read_until(b'\n', scratch)?;
        if n == 0 || scratch.last() == Some(&b'\n') {
            return Ok(());
        }
    }
}
