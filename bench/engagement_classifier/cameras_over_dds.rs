//! Several cameras over DDS into the real `engagement_classifier run` process: N cameras of
//! SYNTHETIC OpenFace frames at F fps each, stamped with their send time, and the node's
//! `EngagementEstimate`s and `ExpectedEngagement`s matched back to them. Prints losses, latency
//! from send to estimate, whether latency grows (a backlog), the achieved estimate rate against
//! the offered one, and the seconds reported per camera. Run by
//! `bench/engagement_classifier/cameras_over_dds.sh`, inside the loopback namespace like every
//! DDS process here.

use anyhow::Context as _;
use clap::Parser;
use node_shell::{NoParameters, NodeShell, ShellOptions, now_nanos};
use openface::synthetic::{SyntheticSpec, generate};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::topics::{ENGAGEMENT_ESTIMATE, EXPECTED_ENGAGEMENT, OPENFACE_FEATURES};
use qt_therapy_msgs::{EngagementEstimate, ExpectedEngagement, OpenFaceFeatures};
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio::time::Instant;

const SECOND_NS: i64 = 1_000_000_000;
/// Every camera sees one face; the node's source is "<frame_id>/<face_id>".
const FACE_ID: &str = "0";
/// Frames per synthetic participant; a camera cycles through its participant's frames.
const FRAMES_PER_CAMERA: usize = 600;

#[derive(Parser)]
#[command(
    about = "N cameras of SYNTHETIC OpenFace frames over DDS into `engagement_classifier run`: \
                   losses, latency, backlog and rates"
)]
struct Cli {
    /// Cameras, each a separate source of the node (header.frame_id "camera<i>"). The node
    /// tracks at most its `max_sources` (8 in params/engagement_classifier.yaml).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=64))]
    cameras: u16,
    /// Seconds measured (after the warm-up).
    #[arg(long, default_value_t = 20.0)]
    seconds: f64,
    /// Frames per second of each camera.
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    /// Seed of the synthetic frames.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Longest wait (s) for the node to answer every camera before measuring.
    #[arg(long, default_value_t = 30.0)]
    warmup_timeout: f64,
    /// Longest wait (s) after the last frame for its estimate and for the last seconds.
    #[arg(long, default_value_t = 3.0)]
    settle: f64,
    /// Append one tab-separated summary row to this file (header first when it is new).
    #[arg(long)]
    tsv: Option<PathBuf>,
    /// Also print, for every elapsed second, how many seconds each camera has had reported.
    #[arg(long)]
    timeline: bool,
    #[command(flatten)]
    shell: ShellOptions,
}

const NODE: &str = "cameras_over_dds";

fn main() -> anyhow::Result<()> {
    let mut cli = Cli::parse();
    anyhow::ensure!(
        cli.fps.is_finite() && cli.fps > 0.0 && cli.fps <= 1000.0,
        "--fps {} is not in (0, 1000]",
        cli.fps
    );
    anyhow::ensure!(
        cli.seconds.is_finite() && cli.seconds >= 1.0,
        "--seconds {} is less than 1",
        cli.seconds
    );
    for (flag, v) in [
        ("--warmup-timeout", cli.warmup_timeout),
        ("--settle", cli.settle),
    ] {
        anyhow::ensure!(v.is_finite() && v >= 0.0, "{flag} {v} is not a duration");
    }
    // The peer's own (empty) parameter section lives beside the script, not in params/, which
    // holds the suite's nodes only.
    if cli.shell.params_file.is_none() && std::env::var_os("QT_PARAMS_DIR").is_none() {
        cli.shell.params_file = Some(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("engagement_classifier/cameras_over_dds.yaml"),
        );
    }
    let run = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?
        .block_on(measure(&cli))?;
    let summary = Summary::of(&cli, &run);
    summary.print(&cli, &run);
    if let Some(path) = &cli.tsv {
        summary
            .append_tsv(path)
            .with_context(|| format!("appending to {}", path.display()))?;
    }
    Ok(())
}

/// One frame sent.
struct Sent {
    camera: usize,
    /// Header stamp = wall-clock send time (ns).
    stamp_ns: i64,
    measured: bool,
    /// Wall-clock receipt of its estimate.
    estimate_at: Option<i64>,
}

/// One `ExpectedEngagement` of one of our cameras.
struct Reported {
    camera: usize,
    window_start_ns: i64,
    window_end_ns: i64,
    has_faces: bool,
    /// Frames the node counted in the window (faces and "no face").
    counted: u32,
    received_at: i64,
}

/// What one run saw, raw.
struct Run {
    sent: Vec<Sent>,
    reported: Vec<Reported>,
    /// Stamps of the first and last measured frame.
    measured_ns: (i64, i64),
    /// How far the sender fell behind its schedule at worst (ns).
    sender_behind_ns: i64,
    duplicates: usize,
    /// Estimates for frames we never sent (another publisher, or an earlier run's frames).
    foreign: usize,
    interrupted: bool,
}

fn camera_name(c: usize) -> String {
    format!("camera{c}")
}

/// The camera index of a `camera<i>` frame id with our face id.
fn camera_of(frame_id: &str, face_id: &str, cameras: usize) -> Option<usize> {
    let c: usize = frame_id.strip_prefix("camera")?.parse().ok()?;
    (face_id == FACE_ID && c < cameras).then_some(c)
}

fn camera_of_source(source: &str, cameras: usize) -> Option<usize> {
    let (frame_id, face_id) = source.rsplit_once('/')?;
    camera_of(frame_id, face_id, cameras)
}

async fn measure(cli: &Cli) -> anyhow::Result<Run> {
    let cameras = usize::from(cli.cameras);
    // Camera c shows participant c of the seeded generator, so cameras differ from each other.
    let table = generate(&SyntheticSpec {
        participants: cameras,
        frames_per_participant: FRAMES_PER_CAMERA,
        fps: cli.fps,
        label_noise: 0.0,
        seed: cli.seed,
    });
    let rows: Vec<Vec<f32>> = table
        .rows
        .iter()
        .map(|r| r.iter().map(|&v| v as f32).collect())
        .collect();

    let (mut shell, NoParameters {}) = NodeShell::start(NODE, &cli.shell)?;
    let features = shell.publisher(OPENFACE_FEATURES)?;
    // Room for every estimate of the run, so this process never drops one it was handed.
    let mut estimates = shell.subscribe(ENGAGEMENT_ESTIMATE, 1 << 16)?;
    let mut seconds = shell.subscribe(EXPECTED_ENGAGEMENT, 1 << 12)?;
    if !features
        .wait_for_subscribers(&shell, Duration::from_secs(30))
        .await
    {
        anyhow::bail!(
            "nothing subscribed to {} within 30 s: is `engagement_classifier run` up in this \
             network namespace?",
            OPENFACE_FEATURES.name
        );
    }

    // Cameras are not synchronised: frames of the N cameras are spread evenly over each frame
    // period rather than sent in bursts of N.
    let slots_per_s = cli.fps * cameras as f64;
    let measured_slots = (cli.seconds * cli.fps).round() as usize * cameras;
    let start = Instant::now();
    let mut next_slot = 0usize;
    let mut first_measured_slot: Option<usize> = None;
    let mut tally = Tally::new(cameras, measured_slots + 4096);
    let mut any_second = false;
    let mut reported: Vec<Reported> = Vec::new();
    let mut sender_behind_ns = 0i64;
    let warmup_deadline = start + Duration::from_secs_f64(cli.warmup_timeout);
    let mut settle_deadline: Option<Instant> = None;
    let stop = shell.shutdown_signal();
    tokio::pin!(stop);
    let mut interrupted = false;

    loop {
        if first_measured_slot.is_none() {
            // Measuring starts once both directions are matched for every camera, so discovery
            // is not in the numbers.
            if tally.answered.iter().all(|&a| a) && any_second {
                first_measured_slot = Some(next_slot);
            } else if Instant::now() > warmup_deadline {
                anyhow::bail!(
                    "warm-up: after {} s, estimates came back for {} of {cameras} cameras and \
                     {} ExpectedEngagement",
                    cli.warmup_timeout,
                    tally.answered.iter().filter(|&&a| a).count(),
                    if any_second { "an" } else { "no" }
                );
            }
        }
        let sending = first_measured_slot.is_none_or(|f| next_slot < f + measured_slots);
        let due = start + Duration::from_secs_f64(next_slot as f64 / slots_per_s);
        let wake = if sending {
            due
        } else {
            let deadline = *settle_deadline
                .get_or_insert_with(|| Instant::now() + Duration::from_secs_f64(cli.settle));
            if Instant::now() >= deadline || all_in(&tally.sent, &reported, cameras) {
                break;
            }
            deadline.min(Instant::now() + Duration::from_millis(50))
        };
        tokio::select! {
            // Sending before receiving: the offered rate is what the node is measured against.
            biased;
            _ = &mut stop => {
                interrupted = true;
                break;
            }
            _ = tokio::time::sleep_until(wake) => {
                if !sending {
                    continue;
                }
                let camera = next_slot % cameras;
                let measured = first_measured_slot.is_some();
                let stamp_ns = now_nanos();
                if measured {
                    let behind = Instant::now().saturating_duration_since(due);
                    sender_behind_ns = sender_behind_ns.max(behind.as_nanos() as i64);
                }
                let frame_number = next_slot / cameras;
                let row = &rows[camera * FRAMES_PER_CAMERA + frame_number % FRAMES_PER_CAMERA];
                features.send(OpenFaceFeatures {
                    header: Header {
                        stamp: Time::from_nanos(stamp_ns),
                        frame_id: camera_name(camera),
                    },
                    face_id: FACE_ID.into(),
                    confidence: 0.98,
                    success: true,
                    features: row.clone(),
                });
                tally.sent(camera, stamp_ns, measured);
                next_slot += 1;
            }
            Some(e) = estimates.recv() => tally.estimate(&e, now_nanos()),
            Some(s) = seconds.recv() => {
                let at = now_nanos();
                if let Some(camera) = camera_of_source(&s.source, cameras) {
                    any_second = true;
                    reported.push(reported_second(camera, &s, at));
                }
            }
        }
    }
    // Whatever arrived in the meantime still counts.
    while let Ok(e) = estimates.try_recv() {
        tally.estimate(&e, now_nanos());
    }
    while let Ok(s) = seconds.try_recv() {
        if let Some(camera) = camera_of_source(&s.source, cameras) {
            reported.push(reported_second(camera, &s, now_nanos()));
        }
    }
    drop((features, estimates, seconds));
    shell.stop().await;

    let mut measured = tally.sent.iter().filter(|s| s.measured).map(|s| s.stamp_ns);
    let Some(first) = measured.next() else {
        anyhow::bail!("interrupted before any frame was measured");
    };
    let last = measured.next_back().unwrap_or(first);
    Ok(Run {
        sent: tally.sent,
        reported,
        measured_ns: (first, last),
        sender_behind_ns,
        duplicates: tally.duplicates,
        foreign: tally.foreign,
        interrupted,
    })
}

/// The frames sent so far and what came back for them.
struct Tally {
    cameras: usize,
    sent: Vec<Sent>,
    index: HashMap<(usize, i64), usize>,
    /// Cameras with at least one estimate back (the warm-up waits for all).
    answered: Vec<bool>,
    duplicates: usize,
    foreign: usize,
}

impl Tally {
    fn new(cameras: usize, capacity: usize) -> Tally {
        Tally {
            cameras,
            sent: Vec::with_capacity(capacity),
            index: HashMap::with_capacity(capacity),
            answered: vec![false; cameras],
            duplicates: 0,
            foreign: 0,
        }
    }

    fn sent(&mut self, camera: usize, stamp_ns: i64, measured: bool) {
        self.index.insert((camera, stamp_ns), self.sent.len());
        self.sent.push(Sent {
            camera,
            stamp_ns,
            measured,
            estimate_at: None,
        });
    }

    /// Matches an estimate to its frame by camera and stamp; `at` is its receipt.
    fn estimate(&mut self, e: &EngagementEstimate, at: i64) {
        let Some(&i) = camera_of(&e.header.frame_id, &e.face_id, self.cameras)
            .and_then(|c| self.index.get(&(c, e.header.stamp.to_nanos())))
        else {
            self.foreign += 1;
            return;
        };
        let frame = &mut self.sent[i];
        self.answered[frame.camera] = true;
        match frame.estimate_at {
            None => frame.estimate_at = Some(at),
            Some(_) => self.duplicates += 1,
        }
    }
}

fn reported_second(camera: usize, s: &ExpectedEngagement, at: i64) -> Reported {
    Reported {
        camera,
        window_start_ns: s.window_start.to_nanos(),
        window_end_ns: s.window_end.to_nanos(),
        has_faces: s.has_faces,
        counted: s.frame_count.saturating_add(s.missing_count),
        received_at: at,
    }
}

/// Every measured frame answered and, for every camera, the second holding its last frame
/// reported: nothing more to wait for.
fn all_in(sent: &[Sent], reported: &[Reported], cameras: usize) -> bool {
    if sent.iter().any(|s| s.measured && s.estimate_at.is_none()) {
        return false;
    }
    (0..cameras).all(|c| {
        let Some(last) = sent.iter().rev().find(|s| s.camera == c) else {
            return true;
        };
        reported
            .iter()
            .any(|r| r.camera == c && r.window_end_ns > last.stamp_ns)
    })
}

/// Nearest-rank quantile of sorted values.
fn quantile(sorted: &[i64], q: f64) -> Option<i64> {
    if sorted.is_empty() {
        return None;
    }
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    Some(sorted[rank - 1])
}

fn ms(ns: Option<i64>) -> f64 {
    ns.map_or(f64::NAN, |v| v as f64 / 1e6)
}

/// One camera's seconds: windows wholly inside the measured stretch.
struct CameraSeconds {
    whole_windows: usize,
    reported: usize,
    with_faces: usize,
    /// Frames the node counted in those windows, and frames we sent in them.
    counted: u64,
    sent: u64,
}

/// The numbers a run yields.
struct Summary {
    cameras: usize,
    offered_per_s: f64,
    sent: usize,
    sent_per_s: f64,
    estimates: usize,
    lost: usize,
    latencies_ns: Vec<i64>,
    first_quarter_median_ns: Option<i64>,
    last_quarter_median_ns: Option<i64>,
    achieved_per_s: f64,
    per_camera: Vec<CameraSeconds>,
    /// Of the frames in whole measured windows: sent, counted by the node, answered.
    whole_window_frames: (u64, u64, u64),
    /// The whole windows [k s, (k + 1) s) of the measured stretch: k in from..to.
    whole_windows: (i64, i64),
    second_delays_ns: Vec<i64>,
}

impl Summary {
    fn of(cli: &Cli, run: &Run) -> Summary {
        let cameras = usize::from(cli.cameras);
        let (first, last) = run.measured_ns;
        let measured: Vec<&Sent> = run.sent.iter().filter(|s| s.measured).collect();
        let answered: Vec<&Sent> = measured
            .iter()
            .copied()
            .filter(|s| s.estimate_at.is_some())
            .collect();
        let mut latencies_ns: Vec<i64> = answered
            .iter()
            .filter_map(|s| s.estimate_at.map(|at| at - s.stamp_ns))
            .collect();
        latencies_ns.sort_unstable();
        let span = (last - first).max(1);
        let quarter_median = |from: i64, to: i64| {
            let mut l: Vec<i64> = answered
                .iter()
                .filter(|s| (from..to).contains(&s.stamp_ns))
                .filter_map(|s| s.estimate_at.map(|at| at - s.stamp_ns))
                .collect();
            l.sort_unstable();
            quantile(&l, 0.5)
        };
        let receipts = answered.iter().filter_map(|s| s.estimate_at);
        let (first_receipt, last_receipt) = (receipts.clone().min(), receipts.max());
        // Estimates per second between the first and the last receipt, counted like the send
        // rate (n estimates, n - 1 intervals): a node that falls behind stretches the interval
        // and shows a rate below the offered one.
        let achieved_per_s = match (first_receipt, last_receipt) {
            (Some(a), Some(b)) if b > a => (answered.len() - 1) as f64 / ((b - a) as f64 / 1e9),
            _ => f64::NAN,
        };
        let sent_per_s = if measured.len() > 1 {
            (measured.len() - 1) as f64 / (span as f64 / 1e9)
        } else {
            f64::NAN
        };

        // Whole windows [k s, (k+1) s) inside the measured stretch.
        let first_window = (first + SECOND_NS - 1).div_euclid(SECOND_NS);
        let end_window = last.div_euclid(SECOND_NS); // exclusive: (k + 1) s <= last
        let windows: Vec<i64> = (first_window..end_window).collect();
        let mut sent_in: BTreeMap<(usize, i64), (u64, u64)> = BTreeMap::new();
        for s in &measured {
            let entry = sent_in
                .entry((s.camera, s.stamp_ns.div_euclid(SECOND_NS)))
                .or_default();
            entry.0 += 1;
            entry.1 += u64::from(s.estimate_at.is_some());
        }
        let mut whole_window_frames = (0u64, 0u64, 0u64);
        let per_camera = (0..cameras)
            .map(|c| {
                let mine: BTreeMap<i64, &Reported> = run
                    .reported
                    .iter()
                    .filter(|r| r.camera == c)
                    .filter(|r| r.window_start_ns >= first_window * SECOND_NS)
                    .filter(|r| r.window_end_ns <= end_window * SECOND_NS)
                    .map(|r| (r.window_start_ns.div_euclid(SECOND_NS), r))
                    .collect();
                let mut cs = CameraSeconds {
                    whole_windows: windows.len(),
                    reported: mine.len(),
                    with_faces: mine.values().filter(|r| r.has_faces).count(),
                    counted: 0,
                    sent: 0,
                };
                for k in &windows {
                    let (sent, answered) = sent_in.get(&(c, *k)).copied().unwrap_or_default();
                    cs.sent += sent;
                    whole_window_frames.0 += sent;
                    if let Some(r) = mine.get(k) {
                        cs.counted += u64::from(r.counted);
                        whole_window_frames.1 += u64::from(r.counted);
                        whole_window_frames.2 += answered;
                    }
                }
                cs
            })
            .collect();
        let measured_windows: BTreeSet<i64> = windows.iter().copied().collect();
        let mut second_delays_ns: Vec<i64> = run
            .reported
            .iter()
            .filter(|r| measured_windows.contains(&r.window_start_ns.div_euclid(SECOND_NS)))
            .map(|r| r.received_at - r.window_end_ns)
            .collect();
        second_delays_ns.sort_unstable();

        Summary {
            cameras,
            offered_per_s: cli.fps * cameras as f64,
            sent: measured.len(),
            sent_per_s,
            estimates: answered.len(),
            lost: measured.len() - answered.len(),
            first_quarter_median_ns: quarter_median(first, first + span / 4),
            last_quarter_median_ns: quarter_median(last - span / 4, last + 1),
            latencies_ns,
            achieved_per_s,
            per_camera,
            whole_window_frames,
            second_delays_ns,
            whole_windows: (first_window, end_window),
        }
    }

    fn growth(&self) -> f64 {
        ms(self.last_quarter_median_ns) / ms(self.first_quarter_median_ns)
    }

    fn print(&self, cli: &Cli, run: &Run) {
        let l = |q| ms(quantile(&self.latencies_ns, q));
        println!(
            "cameras_over_dds: {} camera(s) x {} fps = {} frames/s offered for {} s (seed {}); \
             header stamps = send time{}",
            self.cameras,
            cli.fps,
            self.offered_per_s,
            cli.seconds,
            cli.seed,
            if run.interrupted {
                "; INTERRUPTED, partial"
            } else {
                ""
            }
        );
        if self.cameras > 8 {
            println!(
                "  note: more cameras than the node's max_sources in \
                 params/engagement_classifier.yaml (8) are dropped by the node"
            );
        }
        println!(
            "frames sent           {} ({:.1}/s; the sender was at most {:.1} ms behind its schedule)",
            self.sent,
            self.sent_per_s,
            run.sender_behind_ns as f64 / 1e6
        );
        println!(
            "estimates received    {} ({} lost = {:.2} %; OpenFaceFeatures and EngagementEstimate \
             are BEST EFFORT, keep last 10: a frame or its estimate may be dropped, never resent)",
            self.estimates,
            self.lost,
            100.0 * self.lost as f64 / self.sent.max(1) as f64
        );
        let (w_sent, w_counted, w_answered) = self.whole_window_frames;
        println!(
            "  in whole seconds:   {w_sent} frames sent, {w_counted} counted by the node \
             (its ExpectedEngagement frame counts), {w_answered} estimates back: {} lost on the \
             way in, {} on the way out",
            w_sent.saturating_sub(w_counted),
            w_counted.saturating_sub(w_answered)
        );
        if run.duplicates + run.foreign > 0 {
            println!(
                "  also: {} duplicate estimates, {} for frames this run did not send",
                run.duplicates, run.foreign
            );
        }
        println!(
            "latency send -> estimate received: median {:.3} ms, p99 {:.3} ms, max {:.3} ms",
            l(0.5),
            l(0.99),
            l(1.0)
        );
        println!(
            "backlog check: median latency first quarter {:.3} ms, last quarter {:.3} ms \
             (last/first {:.2}, last - first {:+.3} ms; a backlog grows it)",
            ms(self.first_quarter_median_ns),
            ms(self.last_quarter_median_ns),
            self.growth(),
            ms(self.last_quarter_median_ns) - ms(self.first_quarter_median_ns)
        );
        println!(
            "achieved estimate rate {:.1}/s of {} offered = {:.3} (first to last estimate \
             received)",
            self.achieved_per_s,
            self.offered_per_s,
            self.achieved_per_s / self.offered_per_s
        );
        let d = |q| ms(quantile(&self.second_delays_ns, q));
        println!(
            "ExpectedEngagement per camera, {} whole seconds elapsed in the run (a second is \
             reported once message time passes its end by max_lateness_s; received after the \
             window's end: median {:.0} ms, max {:.0} ms):",
            self.per_camera.first().map_or(0, |c| c.whole_windows),
            d(0.5),
            d(1.0)
        );
        for (c, cs) in self.per_camera.iter().enumerate() {
            println!(
                "  {}/{FACE_ID}: {} reported ({} with faces) of {} seconds; {} of {} frames \
                 counted",
                camera_name(c),
                cs.reported,
                cs.with_faces,
                cs.whole_windows,
                cs.counted,
                cs.sent
            );
        }
        if cli.timeline {
            self.print_timeline(run);
        }
    }

    /// At each elapsed second of the measured stretch: how many of its whole seconds have
    /// ended, and how many of them each camera has had reported. A node that keeps up stays
    /// level with the seconds ended (one behind for the ~0.2 s after a second ends); a backlog
    /// falls further behind as the run goes on.
    fn print_timeline(&self, run: &Run) {
        let (first, last) = run.measured_ns;
        let (from, to) = self.whole_windows;
        let whole = |k: i64| (from..to).contains(&k);
        print!("elapsed s | ended |");
        for c in 0..self.cameras {
            print!(" {:>8}", camera_name(c));
        }
        println!("   (whole seconds: ended / reported per camera)");
        let elapsed = (last - first).div_euclid(SECOND_NS) + 1;
        for t in 1..=elapsed {
            let at = first + t * SECOND_NS;
            let ended = (from..to).filter(|k| (k + 1) * SECOND_NS <= at).count();
            print!("{t:>9} | {ended:>5} |");
            for c in 0..self.cameras {
                let n = run
                    .reported
                    .iter()
                    .filter(|r| r.camera == c && whole(r.window_start_ns.div_euclid(SECOND_NS)))
                    .filter(|r| r.received_at <= at)
                    .count();
                print!(" {n:>8}");
            }
            println!();
        }
    }

    fn append_tsv(&self, path: &Path) -> std::io::Result<()> {
        let new = !matches!(std::fs::metadata(path), Ok(m) if m.len() > 0);
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)?;
        if new {
            writeln!(
                f,
                "cameras\toffered_per_s\tsent\testimates\tlost\tlost_pct\tachieved_per_s\t\
                 achieved_over_offered\tmedian_ms\tp99_ms\tmax_ms\tfirst_quarter_median_ms\t\
                 last_quarter_median_ms\tlast_over_first\tseconds_reported\tseconds_elapsed\t\
                 second_delay_median_ms\tsecond_delay_max_ms"
            )?;
        }
        let l = |q| ms(quantile(&self.latencies_ns, q));
        let d = |q| ms(quantile(&self.second_delays_ns, q));
        let reported: usize = self.per_camera.iter().map(|c| c.reported).sum();
        let elapsed: usize = self.per_camera.iter().map(|c| c.whole_windows).sum();
        writeln!(
            f,
            "{}\t{}\t{}\t{}\t{}\t{:.2}\t{:.1}\t{:.3}\t{:.3}\t{:.3}\t{:.3}\t{:.3}\t{:.3}\t{:.2}\t{}\t{}\t{:.0}\t{:.0}",
            self.cameras,
            self.offered_per_s,
            self.sent,
            self.estimates,
            self.lost,
            100.0 * self.lost as f64 / self.sent.max(1) as f64,
            self.achieved_per_s,
            self.achieved_per_s / self.offered_per_s,
            l(0.5),
            l(0.99),
            l(1.0),
            ms(self.first_quarter_median_ns),
            ms(self.last_quarter_median_ns),
            self.growth(),
            reported,
            elapsed,
            d(0.5),
            d(1.0),
        )
    }
}
