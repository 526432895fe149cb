//! Benchmark: one hour of a session replayed through the engagement classifier's and the
//! behaviour policy's sans-IO cores as fast as possible, against real time (target >= 1000x).
//!   cargo bench -p suite_bench --bench replay [-- BAG]     (default bags/cluster0_seed7.mcap)
//!
//! The hour is synthesised from a sample bag recorded from the simulated suite: the whole bag
//! (every topic: 30 fps OpenFace frames, per-frame estimates, heartbeats, game states,
//! decisions, results, ...) is repeated back to back, each copy shifted in log time and frame
//! stamps, until the frames span 3,600 s (108,000 frames), and written as one zstd MCAP file.
//! Then, best of REPEATS, on one thread:
//!   bag + cores: open the MCAP (read, check, decompress), decode every frame, decision and
//!                result from CDR in log-time order, classify each frame and aggregate per
//!                second, decide each recorded state and learn from each result;
//!   cores only:  the same on messages decoded beforehand.
//! References: real time (3,600 s), and, measured in the same run, Python's `mcap` +
//! `mcap-ros2-support` only decoding the same frames, decisions and results from the same file
//! (bench/replay/decode_reference.py, once; skipped with a note where Python lacks them): a
//! Python replay would do at least that. The per-frame model against Python xgboost is
//! bench/engagement_classifier/bench_inference.py, the policy's Q-learning against NumPy is
//! bench/behaviour_policy/bench_policy.py.

use bag_file::{BagReader, BagWriter, Compression, Stamp, WriterOptions};
use behaviour_policy::BehaviourPolicyParams;
use engagement_classifier::messages::Sources;
use engagement_classifier::{EngagementClassifierParams, EngagementEstimator};
use q_learning::messages::transition;
use q_learning::{PolicyCore, QTableFile};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::topics::{DECISION, OPENFACE_FEATURES, SEQUENCE_RESULT};
use qt_therapy_msgs::{Decision, OpenFaceFeatures, SequenceResult};
use std::path::{Path, PathBuf};
use std::time::Instant;

const HOUR_NS: i64 = 3_600_000_000_000;
const REPEATS: usize = 3;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Writes the synthetic hour; returns (frames, span of their stamps in ns).
fn synthesise_hour(sample: &Path, out: &Path) -> anyhow::Result<(usize, i64)> {
    let reader = BagReader::open(sample)?.strict()?;
    let (first, last) = reader
        .time_range()
        .ok_or_else(|| anyhow::anyhow!("empty bag"))?;
    // One copy every (bag span + 1 s): frames stay monotonic and 30 fps within each copy.
    let period = (last - first) as i64 + 1_000_000_000;
    let mut w = BagWriter::create(
        out,
        &WriterOptions {
            compression: Compression::Zstd,
            ..WriterOptions::default()
        },
    )?;
    let mut channels = std::collections::BTreeMap::new();
    for c in reader.channels() {
        let schema = c
            .schema
            .as_ref()
            .ok_or_else(|| anyhow::anyhow!("{} has no schema", c.topic))?;
        let qos = c
            .metadata
            .get("offered_qos_profiles")
            .cloned()
            .unwrap_or_default();
        let id = w.add_channel(
            &c.topic,
            &schema.name,
            &String::from_utf8_lossy(&schema.data),
            &qos,
        )?;
        channels.insert(c.id, (id, c.topic.clone()));
    }
    let first_stamp = reader
        .messages::<OpenFaceFeatures>(OPENFACE_FEATURES.name)?
        .first()
        .map(|m| m.message.header.stamp.to_nanos())
        .ok_or_else(|| anyhow::anyhow!("no frames"))?;
    let (mut frames, mut span) = (0usize, 0i64);
    'copies: for copy in 0.. {
        let shift = copy as i64 * period;
        for (c, raw) in reader.iter() {
            let (id, topic) = &channels[&c.id];
            let log_time = raw.log_time + shift as u64;
            let stamp = Stamp {
                log_time,
                publish_time: raw.publish_time + shift as u64,
                sequence: raw.sequence,
            };
            if topic == OPENFACE_FEATURES.name {
                let mut f: OpenFaceFeatures = bag_file::cdr::decode(&raw.data)?;
                let t = f.header.stamp.to_nanos() + shift;
                if t - first_stamp >= HOUR_NS {
                    break 'copies;
                }
                f.header.stamp = Time::from_nanos(t);
                w.write_cdr(*id, stamp, &bag_file::cdr::encode(&f)?)?;
                frames += 1;
                span = t - first_stamp;
            } else {
                w.write_cdr(*id, stamp, &raw.data)?;
            }
        }
    }
    w.finish()?;
    Ok((frames, span))
}

/// What the cores gave, to check the runs did the same work.
#[derive(Debug, Default, PartialEq)]
struct Tally {
    frames: usize,
    seconds: usize,
    decisions: usize,
    updates: usize,
    /// Sum of the chosen action indices, a cheap fingerprint of the decisions.
    actions: usize,
}

enum Event {
    Frame(OpenFaceFeatures),
    Decide(Decision),
    Learn(SequenceResult),
}

struct Cores {
    estimator: EngagementEstimator,
    sources: Sources,
    policy: PolicyCore,
    tally: Tally,
}

impl Cores {
    fn new() -> anyhow::Result<Cores> {
        let p: EngagementClassifierParams = node_shell::params::load_parameters(
            &root().join("params/engagement_classifier.yaml"),
            "engagement_classifier",
        )?;
        let estimator = EngagementEstimator::from_params(&p, &root())?;
        let b: BehaviourPolicyParams = node_shell::params::load_parameters(
            &root().join("params/behaviour_policy.yaml"),
            "behaviour_policy",
        )?;
        let file = QTableFile::load(&root().join("bags/q_tables/cluster_0.json"))?;
        let policy = PolicyCore::new(file.table, b.learning()?, b.mode(), b.seed(), file.updates);
        Ok(Cores {
            estimator,
            sources: Sources::default(),
            policy,
            tally: Tally::default(),
        })
    }

    fn on(&mut self, e: &Event) -> anyhow::Result<()> {
        let t = &mut self.tally;
        match e {
            Event::Frame(f) => {
                // As the node converts it, source lookup included.
                let face = self.sources.face_frame(f);
                self.estimator.on_frame(&face, &mut |_| t.seconds += 1)?;
                t.frames += 1;
            }
            Event::Decide(d) => {
                let decision = self.policy.decide(d.state.to_state()?, d.step)?;
                t.decisions += 1;
                t.actions += decision.action.index();
            }
            Event::Learn(r) => {
                self.policy.learn(&transition(r)?)?;
                t.updates += 1;
            }
        }
        Ok(())
    }

    fn finish(mut self) -> Tally {
        let t = &mut self.tally;
        self.estimator.flush(&mut |_| t.seconds += 1);
        self.tally
    }
}

/// The events of the bag, decoded, in log-time order.
fn decoded(reader: &BagReader) -> anyhow::Result<Vec<Event>> {
    let mut out = Vec::new();
    for (c, raw) in reader.iter() {
        let e = match c.topic.as_str() {
            t if t == OPENFACE_FEATURES.name => Event::Frame(bag_file::cdr::decode(&raw.data)?),
            t if t == DECISION.name => Event::Decide(bag_file::cdr::decode(&raw.data)?),
            t if t == SEQUENCE_RESULT.name => Event::Learn(bag_file::cdr::decode(&raw.data)?),
            _ => continue,
        };
        out.push(e);
    }
    Ok(out)
}

fn main() -> anyhow::Result<()> {
    // `cargo bench` passes --bench; the only other argument is an optional bag.
    let sample = std::env::args()
        .skip(1)
        .find(|a| !a.starts_with("--"))
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("bags/cluster0_seed7.mcap"));
    let dir = tempfile::tempdir()?;
    let hour = dir.path().join("hour.mcap");
    let (frames, span) = synthesise_hour(&sample, &hour)?;
    let bytes = std::fs::metadata(&hour)?.len();
    let span_s = span as f64 * 1e-9;

    let mut best_full = f64::INFINITY;
    let mut best_cores = f64::INFINITY;
    let mut tallies = Vec::new();
    let mut messages = 0;
    for _ in 0..REPEATS {
        let started = Instant::now();
        let reader = BagReader::open(&hour)?.strict()?;
        messages = reader.raw_messages().len();
        let mut cores = Cores::new()?;
        for e in decoded(&reader)? {
            cores.on(&e)?;
        }
        tallies.push(cores.finish());
        best_full = best_full.min(started.elapsed().as_secs_f64());
    }
    let events = decoded(&BagReader::open(&hour)?)?;
    for _ in 0..REPEATS {
        // Setup (model and Q-table files) outside the timing, like the decoding.
        let mut cores = Cores::new()?;
        let started = Instant::now();
        for e in &events {
            cores.on(e)?;
        }
        let tally = cores.finish();
        best_cores = best_cores.min(started.elapsed().as_secs_f64());
        tallies.push(tally);
    }
    anyhow::ensure!(
        tallies.windows(2).all(|w| w[0] == w[1]),
        "runs differ: {tallies:?}"
    );
    let t = &tallies[0];
    println!(
        "one hour from {}: {frames} frames over {span_s:.1} s, {messages} messages, {:.1} MB \
         zstd MCAP; {} seconds of engagement, {} decisions, {} updates",
        sample.display(),
        bytes as f64 / 1e6,
        t.seconds,
        t.decisions,
        t.updates
    );
    println!(
        "bag + cores: {:.3} s = {:.0}x real time ({:.0} ns per frame, all work included)",
        best_full,
        span_s / best_full,
        best_full * 1e9 / frames as f64
    );
    println!(
        "cores only:  {:.3} s = {:.0}x real time ({:.0} ns per frame)",
        best_cores,
        span_s / best_cores,
        best_cores * 1e9 / frames as f64
    );
    println!("best of {REPEATS}, one thread; target >= 1000x real time");
    let script = root().join("bench/replay/decode_reference.py");
    match std::process::Command::new("python3")
        .arg(&script)
        .arg(&hour)
        .output()
    {
        Ok(out) if out.status.success() => {
            let line: serde_json::Value = serde_json::from_slice(&out.stdout)?;
            let seconds = line["seconds"].as_f64().unwrap_or(f64::NAN);
            println!(
                "Python mcap-ros2, decoding only ({} messages): {seconds:.3} s; bag + cores \
                 is {:.1}x faster while also classifying, deciding and learning",
                line["messages"],
                seconds / best_full
            );
        }
        Ok(out) => println!(
            "Python reference skipped (pip install mcap mcap-ros2-support): {}",
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("")
        ),
        Err(e) => println!("Python reference skipped: python3 not runnable: {e}"),
    }
    Ok(())
}
