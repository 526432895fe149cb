//! Round trips over the suite's DDS stack (node_shell over ros2-client and RustDDS), to set
//! beside Cyclone DDS's `ddsperf` ping-pong on the same loopback (bench/dds/dds_vs_cyclone.sh):
//!   `serve --case C`   answers: the DecideAction service (a fixed decision, no policy work),
//!                      or echoes the ping topic onto the pong topic;
//!   `ping --case C`    calls or publishes one at a time, each after the previous answer, and
//!                      prints per-second statistics of the round trips as JSON lines;
//!   `compare`          reads those lines and ddsperf's output and prints the table.
//! `--current-thread`: a one-thread runtime instead of the multi-threaded one.
//! `--raw` on both: ros2-client's server, subscription and publisher used directly in one task,
//! without node_shell's channel between the DDS reader and the node's code (its validation,
//! drop log and core task): what is left is RustDDS's and ros2-client's own cost.
//! Cases: `decide` (DecideAction, the game manager's call to the policy), `decide-policy` (the
//! same call to the real `behaviour_policy run`), `results` (a ~300-byte SequenceResult on the
//! results' reliable, transient-local QoS), `faces` (an OpenFaceFeatures frame, best effort).

use anyhow::Context as _;
use clap::{Parser, Subcommand, ValueEnum};
use node_shell::{NoParameters, NodeShell, ShellOptions, qos_profile, ros_name, service_qos};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::services::ServiceDefinition as _;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::topics::{DECIDE_ACTION, QosKind, SEQUENCE_RESULT, Service, Topic};
use qt_therapy_msgs::{
    BehaviourState, DecideAction, DecideActionRequest, DecideActionResponse, Decision,
    OpenFaceFeatures, SequenceResult,
};
use qt_therapy_msgs::{MessageDefinition, dds_type_name};
use ros2_client::{Message, ServiceMapping, ServiceTypeName};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

const DECIDE_BENCH: Service<DecideAction> = Service::new("/bench/decide_action");
const RESULTS_PING: Topic<SequenceResult> = Topic::new("/bench/results_ping", SEQUENCE_RESULT.qos);
const RESULTS_PONG: Topic<SequenceResult> = Topic::new("/bench/results_pong", SEQUENCE_RESULT.qos);
const FACES_PING: Topic<OpenFaceFeatures> = Topic::new("/bench/faces_ping", QosKind::Features);
const FACES_PONG: Topic<OpenFaceFeatures> = Topic::new("/bench/faces_pong", QosKind::Features);

#[derive(Parser)]
#[command(about = "Round trips over the suite's DDS stack, beside Cyclone DDS's ddsperf")]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// One-thread tokio runtime (as the engagement classifier runs) instead of the
    /// multi-threaded one: a sample handed from node_shell's reader task to the node's code
    /// then wakes no other thread.
    #[arg(long, global = true)]
    current_thread: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Answer pings until SIGINT.
    Serve {
        #[arg(long, value_enum)]
        case: Case,
        /// ros2-client directly, without node_shell's channel (see the module's doc).
        #[arg(long)]
        raw: bool,
        #[command(flatten)]
        shell: ShellOptions,
    },
    /// Round trips for --seconds after --warmup seconds; JSON lines on stdout.
    Ping {
        #[arg(long, value_enum)]
        case: Case,
        #[arg(long, default_value_t = 10)]
        seconds: u64,
        #[arg(long, default_value_t = 2)]
        warmup: u64,
        /// How long a lost best-effort sample is waited for before the next ping.
        #[arg(long, default_value_t = 100)]
        lost_after_ms: u64,
        /// The pongs read from ros2-client's subscription directly (see the module's doc).
        #[arg(long)]
        raw: bool,
        #[command(flatten)]
        shell: ShellOptions,
    },
    /// The payload sizes the cases send (CDR, without the 4-byte encapsulation), for ddsperf.
    Sizes,
    /// The table: this tool's JSON lines and ddsperf's outputs, by case.
    Compare {
        /// FILE as CASE=FILE, from `ping` (repeatable; rounds of one case are pooled).
        #[arg(long, value_parser = case_file)]
        ours: Vec<(String, PathBuf)>,
        /// FILE as CASE=FILE, the stdout of `ddsperf ping` (repeatable).
        #[arg(long, value_parser = case_file)]
        cyclone: Vec<(String, PathBuf)>,
    },
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
enum Case {
    Decide,
    DecidePolicy,
    Results,
    Faces,
}

fn case_file(s: &str) -> Result<(String, PathBuf), String> {
    let (case, file) = s
        .split_once('=')
        .ok_or_else(|| format!("{s:?} is not CASE=FILE"))?;
    Ok((case.to_string(), PathBuf::from(file)))
}

fn header(counter: u64) -> Header {
    Header {
        stamp: Time {
            sec: (counter / 1_000_000_000) as i32,
            nanosec: (counter % 1_000_000_000) as u32,
        },
        frame_id: "bench".into(),
    }
}

fn counter_of(h: &Header) -> u64 {
    h.stamp.sec as u64 * 1_000_000_000 + u64::from(h.stamp.nanosec)
}

fn decide_request(counter: u64) -> DecideActionRequest {
    DecideActionRequest {
        session_id: format!("bench-{}", counter / 10),
        user_id: "bench-child".into(),
        user_model_cluster: 0,
        state: BehaviourState {
            level: 0,
            feedback: 0,
            previous_score: 0,
        },
        step: 1,
        after_sequence: 0,
    }
}

/// A decision as the policy sends one (five actions' values and probabilities).
fn decide_response(request: &DecideActionRequest) -> DecideActionResponse {
    DecideActionResponse {
        ok: true,
        error: String::new(),
        decision: Decision {
            header: header(0),
            session_id: request.session_id.clone(),
            step: request.step,
            state: request.state.clone(),
            action: 1,
            level: 2,
            feedback: 0,
            q_values: vec![0.5, 1.25, 0.75, 0.0, 0.0],
            probabilities: vec![0.2, 0.5, 0.3, 0.0, 0.0],
            temperature: 1.0,
            explored: false,
            exploitation_only: true,
            model_used: "cluster_0".into(),
            // As the main job's: planned on the child's belief.
            planned_on_belief: true,
            belief_observations: 12,
            belief_success: vec![0.9, 0.6, 0.3],
            belief_success_sd: vec![0.05, 0.1, 0.2],
            belief_engagement: vec![0.4, 0.3, 0.1],
            belief_engagement_sd: vec![0.1, 0.15, 0.2],
            baseline_action: 1,
        },
    }
}

/// A result as the game manager sends one: a level-2 sequence with 12 seconds of engagement
/// (~300 bytes).
fn result(counter: u64) -> SequenceResult {
    let words: Vec<String> = ["happy", "sad", "angry", "disgusted", "happy"]
        .iter()
        .map(|w| w.to_string())
        .collect();
    SequenceResult {
        header: header(counter),
        session_id: "session-1796402955".into(),
        user_id: "sim-child-1".into(),
        user_model_cluster: 0,
        sequence_index: 3,
        state: BehaviourState {
            level: 2,
            feedback: 0,
            previous_score: 2,
        },
        action: 1,
        level: 2,
        feedback: 0,
        overridden: false,
        sequence: words.clone(),
        answer: words,
        outcome: 1,
        timed_out: false,
        activity_result: 2.0,
        engagement: 0.4,
        engagement_per_second: vec![0.4; 12],
        engagement_period_start: Time { sec: 1, nanosec: 0 },
        engagement_period_end: Time {
            sec: 13,
            nanosec: 0,
        },
        response_time: 3.5,
        sequences_planned: 10,
    }
}

fn face(counter: u64) -> OpenFaceFeatures {
    OpenFaceFeatures {
        header: header(counter),
        face_id: "0".into(),
        confidence: 0.98,
        success: true,
        features: vec![0.0; 32],
    }
}

fn body_len<M: serde::Serialize>(m: &M) -> anyhow::Result<usize> {
    Ok(bag_file::cdr::encode(m)?.len() - 4)
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let runtime = if cli.current_thread {
        tokio::runtime::Builder::new_current_thread()
    } else {
        tokio::runtime::Builder::new_multi_thread()
    }
    .enable_all()
    .build()
    .context("starting the async runtime")?;
    runtime.block_on(run(cli.command))
}

async fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Serve { case, raw, shell } => serve(case, raw, &shell).await,
        Command::Ping {
            case,
            seconds,
            warmup,
            lost_after_ms,
            raw,
            shell,
        } => {
            ping(
                case,
                Duration::from_secs(seconds),
                Duration::from_secs(warmup),
                Duration::from_millis(lost_after_ms),
                raw,
                &shell,
            )
            .await
        }
        Command::Sizes => {
            let request = decide_request(1);
            println!(
                "{}",
                serde_json::json!({
                    "decide_request": body_len(&request)?,
                    "decide_response": body_len(&decide_response(&request))?,
                    "results": body_len(&result(1))?,
                    "faces": body_len(&face(1))?,
                })
            );
            Ok(())
        }
        Command::Compare { ours, cyclone } => compare(&ours, &cyclone),
    }
}

async fn serve(case: Case, raw: bool, options: &ShellOptions) -> anyhow::Result<()> {
    let (mut shell, NoParameters {}) = NodeShell::start("bench_dds_serve", options)?;
    match case {
        Case::Decide if raw => {
            let server = shell
                .node_mut()
                .create_server::<DecideActionRequest, DecideActionResponse>(
                    ServiceMapping::Enhanced,
                    &ros_name(DECIDE_BENCH.name)?,
                    &ServiceTypeName::new(DecideAction::PACKAGE, DecideAction::NAME),
                    service_qos(),
                    service_qos(),
                )?;
            tokio::spawn(async move {
                loop {
                    if let Ok((id, request)) = server.async_receive_request().await {
                        let response = decide_response(&request);
                        let _ = server.async_send_response(id, response).await;
                    }
                }
            });
        }
        Case::Results if raw => echo_raw(&mut shell, RESULTS_PING, RESULTS_PONG)?,
        Case::Faces if raw => echo_raw(&mut shell, FACES_PING, FACES_PONG)?,
        Case::Decide => {
            let mut calls = shell.serve(DECIDE_BENCH, |e| DecideActionResponse {
                ok: false,
                error: e.to_string(),
                ..Default::default()
            })?;
            tokio::spawn(async move {
                while let Some(call) = calls.recv().await {
                    let response = decide_response(&call.request);
                    call.respond(response);
                }
            });
        }
        Case::DecidePolicy => anyhow::bail!("decide-policy is served by `behaviour_policy run`"),
        Case::Results => echo!(shell, RESULTS_PING, RESULTS_PONG),
        Case::Faces => echo!(shell, FACES_PING, FACES_PONG),
    }
    println!("{}", serde_json::json!({"event": "serving"}));
    shell.shutdown_signal().await;
    shell.stop().await;
    Ok(())
}

/// ros2-client's subscription on `topic`, without node_shell's channel.
fn raw_subscription<M>(
    shell: &mut NodeShell,
    topic: Topic<M>,
) -> anyhow::Result<ros2_client::Subscription<M>>
where
    M: MessageDefinition + Message,
{
    let qos = qos_profile(topic.qos);
    let node = shell.node_mut();
    let dds_topic = node.create_topic(&ros_name(topic.name)?, dds_type_name::<M>(), &qos)?;
    Ok(node.create_subscription::<M>(&dds_topic, Some(qos))?)
}

/// Echoes every ping onto the pong topic in the task that takes it from ros2-client.
fn echo_raw<M>(shell: &mut NodeShell, ping: Topic<M>, pong: Topic<M>) -> anyhow::Result<()>
where
    M: MessageDefinition + Message + Send + 'static,
{
    let pings = raw_subscription(shell, ping)?;
    let qos = qos_profile(pong.qos);
    let node = shell.node_mut();
    let dds_topic = node.create_topic(&ros_name(pong.name)?, dds_type_name::<M>(), &qos)?;
    let pongs = node.create_publisher::<M>(&dds_topic, Some(qos))?;
    tokio::spawn(async move {
        loop {
            if let Ok((m, _)) = pings.async_take().await {
                let _ = pongs.publish(m);
            }
        }
    });
    Ok(())
}

/// Echoes every ping onto the pong topic (a macro: the message bounds are ros2-client's).
macro_rules! echo {
    ($shell:expr, $ping:expr, $pong:expr) => {{
        let mut pings = $shell.subscribe($ping, 16)?;
        let pongs = $shell.publisher($pong)?;
        tokio::spawn(async move {
            while let Some(m) = pings.recv().await {
                pongs.send(m);
            }
        });
    }};
}
use echo;

/// Per-second statistics of the round trips, in ns.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
struct Second {
    p50_ns: u64,
    p99_ns: u64,
    max_ns: u64,
    count: u64,
}

fn percentile(sorted: &[u64], p: f64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    let rank = ((p / 100.0) * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

fn second_of(mut rtts: Vec<u64>) -> Second {
    rtts.sort_unstable();
    Second {
        p50_ns: percentile(&rtts, 50.0),
        p99_ns: percentile(&rtts, 99.0),
        max_ns: rtts.last().copied().unwrap_or(0),
        count: rtts.len() as u64,
    }
}

/// Runs round trips with `one` (which returns false for a lost one) for `warmup` then
/// `measure`, printing one JSON line per measured second and a summary line.
async fn round_trips<F, Fut>(
    case: Case,
    warmup: Duration,
    measure: Duration,
    mut one: F,
) -> anyhow::Result<()>
where
    F: FnMut(u64) -> Fut,
    Fut: std::future::Future<Output = anyhow::Result<bool>>,
{
    let mut counter = 0u64;
    let start = Instant::now();
    while start.elapsed() < warmup {
        counter += 1;
        one(counter).await?;
    }
    let begin = Instant::now();
    let mut second = Vec::new();
    let mut seconds = 0u64;
    let mut lost = 0u64;
    let mut all = Vec::new();
    while begin.elapsed() < measure {
        counter += 1;
        let sent = Instant::now();
        if !one(counter).await? {
            lost += 1;
            continue;
        }
        let rtt = sent.elapsed().as_nanos() as u64;
        if begin.elapsed().as_secs() > seconds {
            let s = second_of(std::mem::take(&mut second));
            println!(
                "{}",
                serde_json::json!({"case": format!("{case:?}"), "second": seconds, "stats": s})
            );
            seconds = begin.elapsed().as_secs();
        }
        second.push(rtt);
        all.push(rtt);
    }
    // The last second counts only if it lies inside the measured time.
    if !second.is_empty() && seconds < measure.as_secs() {
        let s = second_of(second);
        println!(
            "{}",
            serde_json::json!({"case": format!("{case:?}"), "second": seconds, "stats": s})
        );
    }
    let total = second_of(all);
    println!(
        "{}",
        serde_json::json!({"case": format!("{case:?}"), "summary": total, "lost": lost})
    );
    Ok(())
}

async fn ping(
    case: Case,
    measure: Duration,
    warmup: Duration,
    lost_after: Duration,
    raw: bool,
    options: &ShellOptions,
) -> anyhow::Result<()> {
    let (mut shell, NoParameters {}) = NodeShell::start("bench_dds_ping", options)?;
    let wait = Duration::from_secs(30);
    match case {
        Case::Decide | Case::DecidePolicy => {
            let service = if case == Case::Decide {
                DECIDE_BENCH
            } else {
                DECIDE_ACTION
            };
            let client = shell.client(service)?;
            anyhow::ensure!(
                shell.wait_for_service(&client, wait).await,
                "no {} server within {wait:?}",
                service.name
            );
            round_trips(case, warmup, measure, |counter| {
                let client = client.clone();
                async move {
                    let response = client
                        .call(decide_request(counter), Duration::from_secs(5))
                        .await?;
                    anyhow::ensure!(response.ok, "the policy refused: {}", response.error);
                    Ok(true)
                }
            })
            .await?;
        }
        Case::Results => {
            ping_pong!(
                shell,
                raw,
                case,
                warmup,
                measure,
                lost_after,
                wait,
                RESULTS_PING,
                RESULTS_PONG,
                result
            )
        }
        Case::Faces => {
            ping_pong!(
                shell, raw, case, warmup, measure, lost_after, wait, FACES_PING, FACES_PONG, face
            )
        }
    }
    shell.stop().await;
    Ok(())
}

/// Publishes `$make(counter)` on the ping topic and waits for the same counter on the pong
/// topic (older ones, late after a loss, are passed over).
macro_rules! ping_pong {
    ($shell:expr, $raw:expr, $case:expr, $warmup:expr, $measure:expr, $lost_after:expr, $wait:expr,
     $ping:expr, $pong:expr, $make:expr) => {{
        let pings = $shell.publisher($ping)?;
        let pongs = if $raw {
            Pongs::Raw(Box::new(raw_subscription(&mut $shell, $pong)?))
        } else {
            Pongs::Shell($shell.subscribe($pong, 16)?)
        };
        let pongs = std::sync::Arc::new(tokio::sync::Mutex::new(pongs));
        anyhow::ensure!(
            pings.wait_for_subscribers(&$shell, $wait).await,
            "no echo on {} within {:?}",
            $ping.name,
            $wait
        );
        let pings = std::sync::Arc::new(pings);
        round_trips($case, $warmup, $measure, |counter| {
            let (pings, pongs) = (pings.clone(), pongs.clone());
            async move {
                pings.send($make(counter));
                let mut pongs = pongs.lock().await;
                let deadline = tokio::time::Instant::now() + $lost_after;
                loop {
                    match tokio::time::timeout_at(deadline, pongs.recv()).await {
                        Err(_) => return Ok(false),
                        Ok(None) => anyhow::bail!("the pong subscription ended"),
                        Ok(Some(m)) if counter_of(&m.header) == counter => return Ok(true),
                        Ok(Some(_)) => continue,
                    }
                }
            }
        })
        .await?;
    }};
}
use ping_pong;

/// Where the pongs are read: node_shell's channel, or ros2-client's subscription directly.
enum Pongs<M> {
    Shell(tokio::sync::mpsc::Receiver<M>),
    Raw(Box<ros2_client::Subscription<M>>),
}

impl<M: MessageDefinition + Message> Pongs<M> {
    async fn recv(&mut self) -> Option<M> {
        match self {
            Pongs::Shell(rx) => rx.recv().await,
            Pongs::Raw(subscription) => loop {
                if let Ok((m, _)) = subscription.async_take().await {
                    return Some(m);
                }
            },
        }
    }
}

/// One case's pooled seconds: the median of the per-second medians and of the per-second
/// p99s, the largest maximum, the count.
fn pooled(seconds: &[Second]) -> Option<Second> {
    if seconds.is_empty() {
        return None;
    }
    let median = |f: fn(&Second) -> u64| {
        let mut v: Vec<u64> = seconds.iter().map(f).collect();
        v.sort_unstable();
        v[v.len() / 2]
    };
    Some(Second {
        p50_ns: median(|s| s.p50_ns),
        p99_ns: median(|s| s.p99_ns),
        max_ns: seconds.iter().map(|s| s.max_ns).max().unwrap_or(0),
        count: seconds.iter().map(|s| s.count).sum(),
    })
}

fn read_ours(file: &std::path::Path) -> anyhow::Result<Vec<Second>> {
    let text =
        std::fs::read_to_string(file).with_context(|| format!("reading {}", file.display()))?;
    let mut seconds = Vec::new();
    for line in text.lines().filter(|l| l.starts_with('{')) {
        let v: serde_json::Value = serde_json::from_str(line)
            .with_context(|| format!("{}: a line that is not JSON: {line}", file.display()))?;
        if let Some(stats) = v.get("stats") {
            seconds.push(serde_json::from_value(stats.clone())?);
        }
    }
    Ok(seconds)
}

/// ddsperf's per-second ping lines: `... size 300 mean 13.591us min 8.612us 50% 10.961us 90%
/// 12.062us 99% 36.819us max 2501.844us cnt 36567`. ddsperf records half of each round trip
/// (ddsperf.c, `update_roundtrip (..., (tnow - source_timestamp) / 2, ...)`), so its values
/// are doubled into round trips here. The first second (discovery, warm-up) is left out.
fn read_ddsperf(file: &std::path::Path) -> anyhow::Result<Vec<Second>> {
    let text =
        std::fs::read_to_string(file).with_context(|| format!("reading {}", file.display()))?;
    let mut seconds = Vec::new();
    for line in text
        .lines()
        .filter(|l| l.contains(" cnt ") && l.contains(" 50% "))
    {
        let words: Vec<&str> = line.split_whitespace().collect();
        let after = |key: &str| -> anyhow::Result<&str> {
            let i = words
                .iter()
                .position(|w| *w == key)
                .with_context(|| format!("no {key:?} in ddsperf line {line:?}"))?;
            words
                .get(i + 1)
                .copied()
                .with_context(|| format!("nothing after {key:?} in {line:?}"))
        };
        let us = |key: &str| -> anyhow::Result<u64> {
            let v = after(key)?;
            let n: f64 = v
                .strip_suffix("us")
                .with_context(|| format!("{v:?} is not in us"))?
                .parse()
                .with_context(|| format!("{v:?} is not a number"))?;
            Ok((2.0 * n * 1000.0).round() as u64)
        };
        let count: u64 = after("cnt")?.parse()?;
        if count == 0 {
            continue;
        }
        seconds.push(Second {
            p50_ns: us("50%")?,
            p99_ns: us("99%")?,
            max_ns: us("max")?,
            count,
        });
    }
    Ok(seconds.into_iter().skip(1).collect())
}

fn compare(ours: &[(String, PathBuf)], cyclone: &[(String, PathBuf)]) -> anyhow::Result<()> {
    let mut by_case: BTreeMap<&str, (Vec<Second>, Vec<Second>)> = BTreeMap::new();
    for (case, file) in ours {
        by_case.entry(case).or_default().0.extend(read_ours(file)?);
    }
    for (case, file) in cyclone {
        by_case
            .entry(case)
            .or_default()
            .1
            .extend(read_ddsperf(file)?);
    }
    let us = |ns: u64| ns as f64 / 1000.0;
    println!(
        "round trip, µs (median of per-second medians | of per-second p99s | largest max; round trips)"
    );
    println!(
        "{:<14} {:>32} {:>32} {:>16}",
        "case", "suite (RustDDS)", "Cyclone ddsperf", "ratio p50 / p99"
    );
    for (case, (o, c)) in &by_case {
        let cell = |s: Option<Second>| match s {
            Some(s) => format!(
                "{:>7.1} {:>7.1} {:>8.1} {:>7}",
                us(s.p50_ns),
                us(s.p99_ns),
                us(s.max_ns),
                s.count
            ),
            None => "-".into(),
        };
        // A -raw or -ct case is set beside its plain case's Cyclone figures.
        let c = match case
            .strip_suffix("-raw")
            .or_else(|| case.strip_suffix("-ct"))
        {
            Some(plain) if c.is_empty() => by_case.get(plain).map_or(c, |(_, c)| c),
            _ => c,
        };
        let (po, pc) = (pooled(o), pooled(c));
        let ratio = match (&po, &pc) {
            (Some(a), Some(b)) if b.p50_ns > 0 && b.p99_ns > 0 => format!(
                "{:.2}x / {:.2}x",
                a.p50_ns as f64 / b.p50_ns as f64,
                a.p99_ns as f64 / b.p99_ns as f64
            ),
            _ => "-".into(),
        };
        println!("{case:<14} {:>32} {:>32} {ratio:>16}", cell(po), cell(pc));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use qt_therapy_msgs::Validate;

    #[test]
    fn the_messages_sent_are_valid() {
        result(7).validate().expect("a valid result");
        face(7).validate().expect("a valid face");
        decide_request(7).validate().expect("a valid request");
        assert_eq!(
            counter_of(&result(1_234_567_890_123).header),
            1_234_567_890_123
        );
    }

    #[test]
    fn ddsperf_lines_become_doubled_round_trips() {
        let dir = tempfile::tempdir().expect("temp dir");
        let f = dir.path().join("ping.out");
        std::fs::write(
            &f,
            "[1] participant vm:1: new (self)\n\
             [1] 1.000  vm:2 size 300 mean 20.0us min 9.0us 50% 11.0us 90% 12.0us 99% 40.0us max 900.0us cnt 100\n\
             [1] 2.000  vm:2 size 300 mean 13.5us min 8.6us 50% 10.5us 90% 12.0us 99% 36.5us max 2501.5us cnt 36567\n\
             [1] 2.000  rss:7.5MB vcsw:20222 ivcsw:16543 recvUC:15%+26%\n",
        )
        .expect("writes");
        let seconds = read_ddsperf(&f).expect("parses");
        assert_eq!(
            seconds,
            vec![Second {
                p50_ns: 21_000,
                p99_ns: 73_000,
                max_ns: 5_003_000,
                count: 36_567
            }]
        );
    }

    #[test]
    fn percentiles_are_nearest_rank() {
        let v: Vec<u64> = (1..=100).collect();
        assert_eq!((percentile(&v, 50.0), percentile(&v, 99.0)), (50, 99));
        assert_eq!(percentile(&[5], 99.0), 5);
        assert_eq!(pooled(&[]), None);
    }
}
