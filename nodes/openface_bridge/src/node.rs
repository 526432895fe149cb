//! The OpenFace bridge node's run loop, on any bus (`node_shell::Bus`): reads OpenFace's CSV
//! (followed as it grows, a finished one replayed, or standard input) on a thread of its own
//! and publishes each row through the sans-IO `Bridge` when it is due, on the bus's clock.

use crate::{Bridge, FollowEvent, Follower, LogLine, OpenFaceBridgeParams};
use anyhow::{Context, bail};
use node_shell::Bus;
use node_shell::logging::log_at;
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::topics::OPENFACE_FEATURES;
use std::io::{BufRead, Read as _};
use std::path::PathBuf;
use std::time::Duration;
use tokio::sync::mpsc;

/// The node's name on the graph (and its parameter file's).
pub const NODE: &str = "openface_bridge";

/// What the reading side hands to the publishing loop.
enum Read {
    /// What one read of the file (one poll) or of the pipe (one line) found.
    Events(Vec<FollowEvent>),
    /// The input ended: standard input closed, or a replayed file read to its end.
    End,
    Failed(String),
}

/// How long publication waits for a first reader to match.
const READER_WAIT: Duration = Duration::from_secs(3);

/// Messages queued for their time past which the reading waits (bounded memory on a long
/// recording replayed slowly).
const MAX_QUEUED: usize = 4096;

/// Follows the CSV (or standard input) that `params` names and publishes each row through
/// `bridge` until the input ends (a replay) or the node is asked to stop.
pub async fn run(
    bus: &mut impl Bus,
    params: &OpenFaceBridgeParams,
    mut bridge: Bridge,
) -> anyhow::Result<()> {
    let frames = bus.publisher(OPENFACE_FEATURES)?;
    let clock = bus.clock();
    let (tx, mut rx) = mpsc::channel::<Read>(8);
    let replay = params.replay_rate > 0.0;
    let source = if params.csv_path == "-" {
        spawn_stdin(tx, params.max_line_bytes);
        "standard input".to_string()
    } else {
        let path = PathBuf::from(&params.csv_path);
        spawn_follower(tx, &path, params, replay)?;
        path.display().to_string()
    };
    if replay {
        tracing::info!(source = %source, frame_id = %params.frame_id, rate = params.replay_rate, "replaying a finished OpenFace CSV on its own clock");
    } else {
        tracing::info!(source = %source, frame_id = %params.frame_id, stamp = %params.stamp, "following OpenFace's CSV");
    }
    let bus = &*bus;
    let stop = bus.shutdown_signal();
    tokio::pin!(stop);
    // Frames are best effort: those sent before the classifier has matched this writer (a
    // respawned bridge's backlog) would be lost. Reading goes on meanwhile; publication
    // waits for a reader, or READER_WAIT.
    let reader = frames.wait_for_subscribers(bus, READER_WAIT);
    tokio::pin!(reader);
    let mut reader_ready = false;
    let report_every = Duration::from_secs_f64(params.report_interval_s);
    let mut report = tokio::time::interval(report_every.max(Duration::from_millis(10)));
    report.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut last_reported = bridge.counts().clone();
    let mut input_open = true;
    let mut not_sent = 0u64;
    loop {
        if !input_open && bridge.queued() == 0 {
            break;
        }
        let wait_due = bridge.next_due_ns().filter(|_| reader_ready);
        // Biased: what is ready is taken in this order, never by tokio's random pick.
        tokio::select! {
            biased;
            _ = &mut stop => {
                if bridge.queued() > 0 {
                    tracing::info!("stopped with {} frames not yet due: not published", bridge.queued());
                }
                break;
            }
            _ = report.tick(), if !report_every.is_zero() => {
                if *bridge.counts() != last_reported {
                    tracing::info!("{}", bridge.report());
                    last_reported = bridge.counts().clone();
                }
            }
            matched = &mut reader, if !reader_ready => {
                if !matched {
                    tracing::info!("no reader of {} after {READER_WAIT:?}: publishing anyway", OPENFACE_FEATURES.name);
                }
                reader_ready = true;
            }
            _ = clock.sleep_until(wait_due.unwrap_or_default()), if wait_due.is_some() => {}
            read = rx.recv(), if input_open && bridge.queued() < MAX_QUEUED => {
                let mut read = read;
                // Everything read by now is one read: stamped together.
                loop {
                    match read {
                        Some(Read::Events(events)) => {
                            for event in events {
                                let logs = match event {
                                    FollowEvent::Line { text, line_no } => bridge
                                        .line(&text, line_no, clock.steady_nanos())
                                        .with_context(|| format!("{source}, line {line_no}"))?,
                                    FollowEvent::TooLong { line_no } => bridge.too_long(line_no),
                                    FollowEvent::Restarted { why } => bridge.restarted(why),
                                    FollowEvent::CaughtUp => bridge.caught_up(),
                                };
                                for LogLine(level, line) in logs {
                                    log_at(level, &line);
                                }
                            }
                        }
                        Some(Read::Failed(e)) => bail!("reading {source}: {e}"),
                        Some(Read::End) | None => {
                            tracing::info!("{source} ended");
                            input_open = false;
                            break;
                        }
                    }
                    match rx.try_recv() {
                        Ok(more) => read = Some(more),
                        Err(_) => break,
                    }
                }
                for LogLine(level, line) in bridge.end_of_read(clock.steady_nanos()) {
                    log_at(level, &line);
                }
            }
        }
        if reader_ready {
            // The core stamps on the steady clock; what goes out is on the wall clock.
            let wall_offset = clock.now_nanos() - clock.steady_nanos();
            for mut m in bridge.due(clock.steady_nanos()) {
                m.header.stamp = Time::from_nanos(m.header.stamp.to_nanos() + wall_offset);
                if !frames.send(m) {
                    not_sent += 1;
                }
            }
        }
    }
    if not_sent > 0 {
        tracing::warn!(
            "{not_sent} frames could not be published on {}",
            OPENFACE_FEATURES.name
        );
    }
    tracing::info!("{}", bridge.report());
    Ok(())
}

/// Polls the file on a thread of its own (file reads block) and sends what each poll finds.
/// In a replay the file is finished: read to its end, then `End`.
fn spawn_follower(
    tx: mpsc::Sender<Read>,
    path: &std::path::Path,
    params: &OpenFaceBridgeParams,
    replay: bool,
) -> anyhow::Result<()> {
    let mut follower = Follower::new(path, params.max_line_bytes);
    let every = Duration::from_secs_f64(params.poll_interval_s);
    std::thread::Builder::new()
        .name("csv-follower".into())
        .spawn(move || {
            let mut waiting_told = false;
            loop {
                let events = match follower.poll() {
                    Ok(events) => events,
                    Err(e) => {
                        let _ = tx.blocking_send(Read::Failed(e.to_string()));
                        return;
                    }
                };
                if replay && !follower.is_open() {
                    let _ = tx.blocking_send(Read::Failed("no such file".into()));
                    return;
                }
                let at_end = replay && events.iter().all(|e| matches!(e, FollowEvent::CaughtUp));
                if at_end {
                    let last = follower.finish().into_iter().collect();
                    let _ = tx.blocking_send(Read::Events(last));
                    let _ = tx.blocking_send(Read::End);
                    return;
                }
                if !events.is_empty() && tx.blocking_send(Read::Events(events)).is_err() {
                    return;
                }
                if !follower.is_open() && !waiting_told {
                    tracing::info!(path = %follower.path().display(), "waiting for OpenFace to create the CSV");
                    waiting_told = true;
                }
                if tx.is_closed() {
                    return;
                }
                if !replay {
                    std::thread::sleep(every);
                }
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
            if tx.blocking_send(Read::Events(vec![event])).is_err() {
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
