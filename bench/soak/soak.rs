//! The soak: one running suite (bench/soak/soak.launch.yaml), many simulated sessions back to
//! back, each started and followed by the therapist console. Afterwards every reliable message
//! in the recorder's bag is counted by its publisher's sequence number (the bag keeps the DDS
//! sequence number of each sample; heartbeats carry their own counter), every session is
//! checked for completeness (10 results, tasks, answers, decisions, its start acknowledged,
//! its session file), and each node's memory and open files, sampled as sessions go by, must
//! stay flat. Run inside tests/loopback-netns (bench/soak/soak.sh does that).
//!   soak --sessions 1000 --out out/soak

use anyhow::{Context, bail};
use bag_file::BagReader;
use clap::Parser;
use qt_therapy_msgs::topics::{
    DECISION, EXPECTED_ENGAGEMENT, GAME_STATE, HEARTBEAT, ROBOT_EMOTION, ROBOT_GESTURE,
    ROBOT_SPEECH, SEQUENCE_RESULT, TABLET_ANSWER, TABLET_TASK, THERAPIST_COMMAND, USER_MODEL_INFO,
};
use qt_therapy_msgs::{
    Decision, GameState, Heartbeat, SequenceResult, TabletAnswer, TabletTask, TherapistCommand,
};
use std::collections::{BTreeMap, BTreeSet};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The nodes of bench/soak/soak.launch.yaml, whose memory and open files are sampled.
const NODES: [&str; 7] = [
    "bag_recorder",
    "user_model",
    "behaviour_policy",
    "engagement_classifier",
    "game_manager",
    "tablet_bridge",
    "simulated_child",
];

/// Reliable topics with exactly one publisher in the soak: the recorded DDS sequence numbers of
/// each must run without a gap or a repeat.
const ONE_PUBLISHER_TOPICS: [&str; 10] = [
    SEQUENCE_RESULT.name,
    TABLET_TASK.name,
    TABLET_ANSWER.name,
    GAME_STATE.name,
    DECISION.name,
    EXPECTED_ENGAGEMENT.name,
    USER_MODEL_INFO.name,
    ROBOT_SPEECH.name,
    ROBOT_EMOTION.name,
    ROBOT_GESTURE.name,
];

#[derive(Parser)]
#[command(
    about = "Simulated sessions back to back on one running suite; counts every reliable message"
)]
struct Cli {
    /// Sessions to run back to back (the run must be inside tests/loopback-netns).
    #[arg(long, default_value_t = 1000)]
    sessions: u32,
    /// Directory for the bag, the session files, the Q-tables and the logs (emptied first).
    #[arg(long)]
    out: PathBuf,
    /// Robot talking and child answering times x this (both nodes).
    #[arg(long, default_value_t = 0.01)]
    time_scale: f64,
    /// The game manager's engagement_wait_s (real seconds after a task before scoring). At
    /// time_scale 0.01 the robot talks for about 0.3 s, less than one of the classifier's
    /// one-second windows; 0 scores at once, leaving a sequence's engagement n/a, which the
    /// soak does not check (1.5, the default, makes a session about 15 s longer).
    #[arg(long, default_value_t = 0.0)]
    engagement_wait: f64,
    /// Sample memory and open files after every this many sessions (0: about 20 samples).
    #[arg(long, default_value_t = 0)]
    sample_every: u32,
    /// Directory of the suite's binaries [default: this binary's directory].
    #[arg(long)]
    bin: Option<PathBuf>,
    /// Largest allowed growth of a node's resident memory, last-quarter median over
    /// first-quarter median of the samples, in percent.
    #[arg(long, default_value_t = 10.0)]
    max_rss_growth_pct: f64,
    /// Largest allowed growth of a node's open file descriptors (same medians).
    #[arg(long, default_value_t = 2)]
    max_fd_growth: i64,
    /// Only report memory growth; do not fail on it (short runs measure warm-up, not leaks).
    #[arg(long)]
    report_memory_only: bool,
    /// Start no new session after this many minutes (0: no limit); the checks then cover the
    /// sessions run.
    #[arg(long, default_value_t = 0.0)]
    max_minutes: f64,
    /// A new console process, i.e. a new DDS participant, per session, instead of one console
    /// running every session (`therapist run-session --sessions N`, as the robot's one
    /// long-lived tablet bridge does). Each departed participant leaves RustDDS discovery data
    /// in every node (README, Soak), so memory grows in this mode. Only this mode honours
    /// --max-minutes.
    #[arg(long)]
    console_per_session: bool,
    /// Give up on a session after this many seconds.
    #[arg(long, default_value_t = 120)]
    session_timeout: u64,
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let ok = run(&cli)?;
    std::process::exit(if ok { 0 } else { 1 });
}

/// Memory and open files of one node at one moment.
#[derive(Clone, Copy)]
struct Usage {
    rss_kb: u64,
    /// The peak resident memory so far (VmHWM).
    hwm_kb: u64,
    fds: u64,
}

fn usage(pid: u32) -> Option<Usage> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kb = |key: &str| -> Option<u64> {
        status
            .lines()
            .find_map(|l| l.strip_prefix(key))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
    };
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).ok()?.count() as u64;
    Some(Usage {
        rss_kb: kb("VmRSS:")?,
        hwm_kb: kb("VmHWM:")?,
        fds,
    })
}

/// The DDS processes of this run must not reach any network but the namespace's loopback.
fn only_loopback() -> bool {
    // /proc/net/dev lists the interfaces of this process's own network namespace.
    std::fs::read_to_string("/proc/net/dev").is_ok_and(|t| {
        t.lines()
            .skip(2)
            .filter_map(|l| l.split(':').next())
            .all(|name| name.trim() == "lo")
    })
}

/// The node pids the launcher printed ("[launch] started NAME (pid N)").
fn node_pids(stderr_log: &Path) -> BTreeMap<String, u32> {
    let text = std::fs::read_to_string(stderr_log).unwrap_or_default();
    let mut pids = BTreeMap::new();
    for line in text.lines() {
        let Some(rest) = line
            .strip_prefix("[launch] started ")
            .or_else(|| line.strip_prefix("[launch] restarted "))
        else {
            continue;
        };
        let mut parts = rest.splitn(2, " (pid ");
        let (Some(name), Some(tail)) = (parts.next(), parts.next()) else {
            continue;
        };
        if let Some(pid) = tail.split(')').next().and_then(|p| p.parse().ok()) {
            pids.insert(name.to_string(), pid);
        }
    }
    pids
}

struct Launch {
    child: Child,
}

impl Launch {
    fn stop(mut self) -> anyhow::Result<Option<i32>> {
        let pid = nix::unistd::Pid::from_raw(self.child.id() as i32);
        let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT);
        let started = Instant::now();
        while started.elapsed() < Duration::from_secs(60) {
            if let Some(s) = self.child.try_wait()? {
                return Ok(s.code());
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        self.child.kill()?;
        Ok(self.child.wait()?.code())
    }
}

fn run(cli: &Cli) -> anyhow::Result<bool> {
    if !only_loopback() {
        bail!("run me inside tests/loopback-netns: DDS must not leave this machine");
    }
    let root = suite_tests::workspace_root();
    let bin = match &cli.bin {
        Some(b) => b.clone(),
        None => std::env::current_exe()?
            .parent()
            .context("binary directory")?
            .to_path_buf(),
    };
    let out = if cli.out.is_absolute() {
        cli.out.clone()
    } else {
        root.join(&cli.out)
    };
    if std::fs::read_dir(&out).is_ok_and(|mut d| d.next().is_some()) {
        bail!(
            "{} is not empty: give the soak a new directory",
            out.display()
        );
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let run_id = std::process::id();
    let every = if cli.sample_every > 0 {
        cli.sample_every
    } else {
        (cli.sessions / 20).max(1)
    };
    println!(
        "soak: {} sessions, time_scale {}, engagement_wait_s {}, samples every {every} sessions, output {}",
        cli.sessions,
        cli.time_scale,
        cli.engagement_wait,
        out.display()
    );

    let stderr_log = out.join("launch.stderr.log");
    let launch = Launch {
        child: Command::new(bin.join("launch"))
            .arg(root.join("bench/soak/soak.launch.yaml"))
            .arg(format!("bin:={}", bin.display()))
            .arg(format!("out:={}", out.display()))
            .arg(format!("time_scale:={}", cli.time_scale))
            .arg(format!("engagement_wait:={}", cli.engagement_wait))
            .current_dir(&root)
            .stdout(std::fs::File::create(out.join("launch.stdout.log"))?)
            .stderr(std::fs::File::create(&stderr_log)?)
            .spawn()
            .context("starting the launcher")?,
    };
    let driving = Driving {
        cli,
        bin: &bin,
        root: &root,
        out: &out,
        stderr_log: &stderr_log,
        run_id,
        every,
    };
    let result = if cli.console_per_session {
        drive(&driving)
    } else {
        drive_one_console(&driving)
    };
    let launch_exit = launch.stop()?;
    let driven = result?;
    println!("launch exit code: {launch_exit:?}");
    let checked = check_bag(&out, &driven)?;
    let resources_ok = resource_verdict(cli, &driven.samples);
    let sessions_ok = driven.failed.is_empty()
        && (driven.sessions.len() == cli.sessions as usize || cli.max_minutes > 0.0);
    // Every node ran to the end (the launcher reports a node that died with its exit code).
    let nodes_ok = launch_exit == Some(0);
    let ok = sessions_ok && nodes_ok && checked && (resources_ok || cli.report_memory_only);
    println!(
        "VERDICT: {} ({} of {} sessions finished, nodes {}, messages {}, resources {})",
        if ok { "PASS" } else { "FAIL" },
        driven.sessions.len() - driven.failed.len(),
        cli.sessions,
        if nodes_ok { "ran to the end" } else { "DIED" },
        if checked {
            "complete"
        } else {
            "LOST, DUPLICATED OR INCOMPLETE"
        },
        if resources_ok { "flat" } else { "GROWING" }
    );
    Ok(ok)
}

/// What the driving of the sessions left to check.
struct Driven {
    /// Session ids, in the order they ran.
    sessions: Vec<String>,
    /// Sessions whose START the console sent.
    started: Vec<String>,
    failed: Vec<String>,
    /// (sessions done, node -> usage)
    samples: Vec<(u32, BTreeMap<String, Usage>)>,
    q_updates_before: u64,
    wall: Duration,
}

impl Driven {
    /// Nothing driven yet; the policy's update count as the soak starts.
    fn starting(out: &Path) -> Self {
        Driven {
            sessions: Vec::new(),
            started: Vec::new(),
            failed: Vec::new(),
            samples: Vec::new(),
            // A missing file: the policy has not learned yet (a new table starts at 0 updates).
            q_updates_before: q_updates(out).unwrap_or(0),
            wall: Duration::ZERO,
        }
    }
}

/// `therapist run-session` for the simulated child of cluster 0, as every soak session runs it.
fn run_session_command(bin: &Path, root: &Path, session: &str, timeout_s: u64) -> Command {
    let mut command = Command::new(bin.join("therapist"));
    command
        .args(["run-session", "--user", "sim-child-soak", "--cluster", "0"])
        .args(["--session", session])
        .args(["--timeout", &timeout_s.to_string()])
        .current_dir(root)
        .env("ROS_LOCALHOST_ONLY", "1")
        .stdin(Stdio::null());
    command
}

fn q_updates(out: &Path) -> Option<u64> {
    let text = std::fs::read_to_string(out.join("q_tables/cluster_0.json")).ok()?;
    serde_json::from_str::<serde_json::Value>(&text).ok()?["updates"].as_u64()
}

/// Waits until the launcher started every node.
fn wait_for_nodes(stderr_log: &Path) -> anyhow::Result<()> {
    let started = Instant::now();
    loop {
        let pids = node_pids(stderr_log);
        if NODES.iter().all(|n| pids.contains_key(*n)) {
            return Ok(());
        }
        if started.elapsed() > Duration::from_secs(30) {
            bail!("the launcher did not start every node within 30 s: {pids:?}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Memory and open files of every node now (a respawned node is followed by its new pid).
fn sample_nodes(stderr_log: &Path) -> BTreeMap<String, Usage> {
    let mut now = node_pids(stderr_log);
    now.retain(|n, _| NODES.contains(&n.as_str()));
    now.iter()
        .filter_map(|(n, p)| usage(*p).map(|u| (n.clone(), u)))
        .collect()
}

fn progress(k: u32, total: u32, session: &str, ok: bool, took: Duration, since: Instant) {
    let elapsed = since.elapsed().as_secs_f64();
    let left = f64::from(total.saturating_sub(k)) * elapsed / f64::from(k.max(1));
    println!(
        "[soak] session {k:>5}/{total}  {session}  {}  {:>5.1} s  | {:.0} sessions/h, {:.0} min left",
        if ok { "ok  " } else { "FAIL" },
        took.as_secs_f64(),
        f64::from(k) * 3600.0 / elapsed.max(1e-9),
        left / 60.0
    );
}

/// What both ways of driving the sessions work with.
#[derive(Clone, Copy)]
struct Driving<'a> {
    cli: &'a Cli,
    bin: &'a Path,
    root: &'a Path,
    out: &'a Path,
    stderr_log: &'a Path,
    run_id: u32,
    every: u32,
}

/// All sessions from one console process: its output is followed line by line.
fn drive_one_console(d: &Driving) -> anyhow::Result<Driven> {
    use std::io::BufRead as _;
    wait_for_nodes(d.stderr_log)?;
    let mut driven = Driven::starting(d.out);
    // After start: every node up, no session yet.
    driven.samples.push((0, sample_nodes(d.stderr_log)));
    let base = format!("soak-{}", d.run_id);
    let soak_started = Instant::now();
    let mut console = run_session_command(d.bin, d.root, &base, d.cli.session_timeout)
        .args(["--sessions", &d.cli.sessions.to_string()])
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(d.out.join("console.stderr.log"))?)
        .spawn()
        .context("starting therapist run-session")?;
    let stdout = console.stdout.take().context("console stdout")?;
    let mut lines_of_session = 0;
    let mut t0 = Instant::now();
    let mut k = 0u32;
    for line in std::io::BufReader::new(stdout).lines() {
        let line = line?;
        if let Some(rest) = line.strip_prefix("session ") {
            let id = rest.split(' ').next().unwrap_or_default().to_string();
            if rest.contains(" started for user ") {
                driven.sessions.push(id.clone());
                driven.started.push(id);
                lines_of_session = 0;
                t0 = Instant::now();
                continue;
            }
            if driven.sessions.last() != Some(&id) {
                continue;
            }
            k += 1;
            let ok = rest.ends_with(" finished: 10 sequences") && lines_of_session == 10;
            if !ok {
                driven.failed.push(id.clone());
                println!("[soak]   {line}");
            }
            progress(k, d.cli.sessions, &id, ok, t0.elapsed(), soak_started);
            if k == 1 || k.is_multiple_of(d.every) || k == d.cli.sessions {
                driven.samples.push((k, sample_nodes(d.stderr_log)));
            }
        } else if line.starts_with("seq ") {
            lines_of_session += 1;
        }
    }
    let status = console.wait()?;
    if !status.success() {
        println!("[soak] the console exited with {:?}", status.code());
        if let Some(last) = driven.sessions.last()
            && !driven.failed.contains(last)
            && driven.sessions.len() as u32 > k
        {
            driven.failed.push(last.clone());
        }
    }
    driven.wall = soak_started.elapsed();
    Ok(driven)
}

fn drive(d: &Driving) -> anyhow::Result<Driven> {
    wait_for_nodes(d.stderr_log)?;
    let sample = |done: u32, samples: &mut Vec<(u32, BTreeMap<String, Usage>)>| {
        samples.push((done, sample_nodes(d.stderr_log)));
    };
    let mut driven = Driven::starting(d.out);
    sample(0, &mut driven.samples);
    let soak_started = Instant::now();
    let mut consecutive_failures = 0;
    for k in 1..=d.cli.sessions {
        if d.cli.max_minutes > 0.0
            && soak_started.elapsed().as_secs_f64() > d.cli.max_minutes * 60.0
        {
            println!(
                "[soak] {} minutes are up: stopping after {} sessions",
                d.cli.max_minutes,
                k - 1
            );
            if driven.samples.last().is_some_and(|(n, _)| *n != k - 1) {
                sample(k - 1, &mut driven.samples);
            }
            break;
        }
        let session = format!("soak-{}-{k:05}", d.run_id);
        let t0 = Instant::now();
        let output = run_session_command(d.bin, d.root, &session, d.cli.session_timeout)
            .output()
            .context("running therapist run-session")?;
        let took = t0.elapsed();
        let stdout = String::from_utf8_lossy(&output.stdout);
        let lines = stdout.lines().filter(|l| l.starts_with("seq ")).count();
        let finished = stdout.contains(&format!("session {session} finished: 10 sequences"));
        let ok = output.status.success() && finished && lines == 10;
        driven.sessions.push(session.clone());
        if stdout.contains(&format!("session {session} started")) {
            driven.started.push(session.clone());
        }
        progress(k, d.cli.sessions, &session, ok, took, soak_started);
        if ok {
            consecutive_failures = 0;
        } else {
            driven.failed.push(session.clone());
            consecutive_failures += 1;
            let log = d.out.join(format!("console-{session}.log"));
            let mut f = std::fs::File::create(&log)?;
            f.write_all(&output.stdout)?;
            f.write_all(&output.stderr)?;
            println!(
                "[soak]   console exit {:?}, {lines} sequence lines; its output: {}",
                output.status.code(),
                log.display()
            );
            if consecutive_failures >= 3 {
                println!("[soak] three sessions in a row failed: stopping");
                break;
            }
        }
        if k == 1 || k.is_multiple_of(d.every) || k == d.cli.sessions {
            sample(k, &mut driven.samples);
        }
    }
    driven.wall = soak_started.elapsed();
    Ok(driven)
}

/// Received, lost and duplicated messages of one publisher (or one topic).
#[derive(Default, Clone, Copy)]
struct Count {
    received: u64,
    lost: u64,
    duplicated: u64,
}

impl Count {
    /// From the sequence numbers one publisher's samples arrived with: every number between
    /// the first and the last recorded must be there exactly once.
    fn of(sequence_numbers: impl IntoIterator<Item = u64>) -> Count {
        let all: Vec<u64> = sequence_numbers.into_iter().collect();
        let distinct: BTreeSet<u64> = all.iter().copied().collect();
        let span = match (distinct.first(), distinct.last()) {
            (Some(a), Some(b)) => b - a + 1,
            _ => 0,
        };
        Count {
            received: all.len() as u64,
            lost: span - distinct.len() as u64,
            duplicated: (all.len() - distinct.len()) as u64,
        }
    }
    fn add(&mut self, o: Count) {
        self.received += o.received;
        self.lost += o.lost;
        self.duplicated += o.duplicated;
    }
}

/// Counts every reliable message of the bag and checks every session; prints the tables.
fn check_bag(out: &Path, driven: &Driven) -> anyhow::Result<bool> {
    let bag_path = out.join("session.mcap");
    let reader = BagReader::open(&bag_path)
        .with_context(|| format!("reading the recorder's bag {}", bag_path.display()))?;
    let mut ok = true;
    println!(
        "\nbag {}: {} messages, {:.1} MiB, closed cleanly: {}",
        bag_path.display(),
        reader.raw_messages().len(),
        reader.size_bytes() as f64 / 1048576.0,
        reader.is_complete()
    );

    // 1. By publisher sequence number.
    println!("\nreliable messages by publisher sequence number:");
    println!(
        "  {:<56} {:>10} {:>6} {:>11}",
        "topic (publisher)", "received", "lost", "duplicated"
    );
    let mut total = Count::default();
    let mut by_topic: BTreeMap<&str, Vec<u64>> = BTreeMap::new();
    for (channel, m) in reader.iter() {
        if let Some(t) = ONE_PUBLISHER_TOPICS
            .iter()
            .find(|t| **t == channel.topic.as_str())
        {
            by_topic.entry(t).or_default().push(u64::from(m.sequence));
        }
    }
    for topic in ONE_PUBLISHER_TOPICS {
        let c = Count::of(by_topic.remove(topic).unwrap_or_default());
        println!(
            "  {topic:<56} {:>10} {:>6} {:>11}",
            c.received, c.lost, c.duplicated
        );
        total.add(c);
    }
    let heartbeats = reader.messages::<Heartbeat>(HEARTBEAT.name)?;
    // One series per process: (node, pid), split where the counter starts again at 0, since
    // over hundreds of consoles the OS hands out a pid twice.
    let mut beats: BTreeMap<(String, u32), Vec<Vec<u64>>> = BTreeMap::new();
    for h in &heartbeats {
        let series = beats
            .entry((h.message.node_name.clone(), h.message.pid))
            .or_default();
        let restarted =
            h.message.sequence == 0 && series.last().and_then(|s| s.last()).is_some_and(|l| *l > 0);
        if restarted || series.is_empty() {
            series.push(Vec::new());
        }
        if let Some(s) = series.last_mut() {
            s.push(h.message.sequence);
        }
    }
    let mut per_node: BTreeMap<String, (u64, Count)> = BTreeMap::new();
    for ((node, _), all) in beats {
        let e = per_node.entry(node).or_default();
        for seqs in all {
            e.0 += 1;
            e.1.add(Count::of(seqs));
        }
    }
    for (node, (processes, c)) in &per_node {
        println!(
            "  {:<56} {:>10} {:>6} {:>11}",
            format!("{} ({node}, {processes} processes)", HEARTBEAT.name),
            c.received,
            c.lost,
            c.duplicated
        );
        total.add(*c);
    }
    let commands = reader.messages::<TherapistCommand>(THERAPIST_COMMAND.name)?;
    let mut command_ids: BTreeMap<u64, u64> = BTreeMap::new();
    for c in &commands {
        *command_ids.entry(c.message.command_id).or_default() += 1;
    }
    let command_dups: u64 = command_ids.values().map(|n| n - 1).sum();
    let starts: BTreeMap<&str, u64> = commands
        .iter()
        .filter(|c| c.message.command == TherapistCommand::START)
        .fold(BTreeMap::new(), |mut m, c| {
            *m.entry(c.message.session_id.as_str()).or_default() += 1;
            m
        });
    // A START the console sent (it said so) that the bag does not hold.
    let command_lost = driven
        .started
        .iter()
        .filter(|s| !starts.contains_key(s.as_str()))
        .count() as u64;
    let cc = Count {
        received: commands.len() as u64,
        lost: command_lost,
        duplicated: command_dups,
    };
    println!(
        "  {:<56} {:>10} {:>6} {:>11}",
        format!("{} (by command id)", THERAPIST_COMMAND.name),
        cc.received,
        cc.lost,
        cc.duplicated
    );
    total.add(cc);
    println!(
        "  {:<56} {:>10} {:>6} {:>11}",
        "all", total.received, total.lost, total.duplicated
    );
    if total.lost > 0 || total.duplicated > 0 {
        ok = false;
    }

    // 2. Per session: complete, in order, each start acknowledged once.
    let results = reader.messages::<SequenceResult>(SEQUENCE_RESULT.name)?;
    let tasks = reader.messages::<TabletTask>(TABLET_TASK.name)?;
    let answers = reader.messages::<TabletAnswer>(TABLET_ANSWER.name)?;
    let decisions = reader.messages::<Decision>(DECISION.name)?;
    let states = reader.messages::<GameState>(GAME_STATE.name)?;
    let group = |id: &str| -> String { id.to_string() };
    let mut by_session: BTreeMap<String, SessionRecord> = BTreeMap::new();
    for r in &results {
        let e = by_session.entry(group(&r.message.session_id)).or_default();
        e.results.push(r.message.sequence_index);
        e.scored.insert(
            r.message.sequence_index,
            (r.message.answer.clone(), r.message.timed_out),
        );
    }
    for t in &tasks {
        let e = by_session.entry(group(&t.message.session_id)).or_default();
        e.tasks.push(t.message.sequence_index);
        e.task_ids.push(t.message.sequence_id);
        e.task_index
            .insert(t.message.sequence_id, t.message.sequence_index);
    }
    for a in &answers {
        let e = by_session.entry(group(&a.message.session_id)).or_default();
        e.answers.push(a.message.sequence_id);
        e.answer_of_task
            .insert(a.message.sequence_id, a.message.answer.clone());
    }
    for d in &decisions {
        by_session
            .entry(group(&d.message.session_id))
            .or_default()
            .decisions
            .push(d.message.step);
    }
    // A command's answer stays in every state after it: count it where it first appears, by
    // its typed fields (the status text is for people).
    let mut last_answer: Option<(&str, u64, u8)> = None;
    for s in &states {
        let m = &s.message;
        let answer = (
            m.command_session_id.as_str(),
            m.command_id,
            m.command_outcome,
        );
        if m.command_outcome != GameState::COMMAND_NONE && last_answer != Some(answer) {
            let e = by_session.entry(group(&m.command_session_id)).or_default();
            match m.command_outcome {
                GameState::COMMAND_CARRIED_OUT => e.acks += 1,
                GameState::COMMAND_REFUSED => e.rejections += 1,
                // A repeat of a START carried out before: not carried out again.
                _ => {}
            }
        }
        last_answer = Some(answer);
        let e = by_session.entry(group(&s.message.session_id)).or_default();
        if s.message.phase == GameState::FINISHED {
            e.finished = true;
        }
        if s.message.policy_fallback {
            e.fallbacks.insert(s.message.sequence_index);
        }
        if s.message.phase == GameState::WAITING_FOR_ANSWER {
            e.waiting.insert(s.message.sequence_index);
        }
    }
    let expected: Vec<u8> = (1..=10).collect();
    let mut bad = Vec::new();
    let mut fallbacks = 0usize;
    for id in &driven.sessions {
        let e = by_session.remove(id).unwrap_or_default();
        let mut problems = Vec::new();
        if e.results != expected {
            problems.push(format!("results {:?}", e.results));
        }
        if e.tasks != expected {
            problems.push(format!("tasks {:?}", e.tasks));
        }
        let task_ids: BTreeSet<u32> = e.task_ids.iter().copied().collect();
        let answered: Vec<u32> = {
            let mut a = e.answers.clone();
            a.sort_unstable();
            a
        };
        if answered != task_ids.iter().copied().collect::<Vec<_>>() || task_ids.len() != 10 {
            problems.push(format!("answers {:?} to tasks {task_ids:?}", e.answers));
        }
        // What the game manager scored is what the child answered: no result timed out (the
        // simulated child always answers), and each result holds its task's answer as the bag
        // has it, so an answer lost between the tablet and the game manager cannot pass.
        let mismatched: Vec<u8> = e
            .answer_of_task
            .iter()
            .filter_map(|(task, answer)| {
                let index = *e.task_index.get(task)?;
                match e.scored.get(&index) {
                    Some((scored, false)) if scored == answer => None,
                    _ => Some(index),
                }
            })
            .collect();
        let timed_out: Vec<u8> = e
            .scored
            .iter()
            .filter(|(_, (_, t))| *t)
            .map(|(i, _)| *i)
            .collect();
        if !mismatched.is_empty() || !timed_out.is_empty() {
            problems.push(format!(
                "results not as answered: sequences {mismatched:?}; timed out: {timed_out:?}"
            ));
        }
        let mut steps = e.decisions.clone();
        steps.sort_unstable();
        let decided: BTreeSet<u8> = steps.iter().copied().collect();
        let undecided: BTreeSet<u8> = (1..=10u8).filter(|i| !decided.contains(i)).collect();
        if steps.len() != decided.len() || !undecided.is_subset(&e.fallbacks) {
            problems.push(format!(
                "decisions {:?} (policy fallbacks {:?})",
                e.decisions, e.fallbacks
            ));
        }
        if !e.results.is_empty() {
            fallbacks += undecided.len();
        }
        if e.acks != 1 {
            problems.push(format!("start acknowledged {} times", e.acks));
        }
        if e.rejections > 0 {
            problems.push(format!("{} commands rejected", e.rejections));
        }
        if !e.finished || e.waiting.len() != 10 {
            problems.push(format!(
                "game states: finished {}, waited for answers {:?}",
                e.finished, e.waiting
            ));
        }
        match session_file(out, id) {
            Ok(()) => {}
            Err(why) => problems.push(why),
        }
        if !problems.is_empty() {
            bad.push(format!("{id}: {}", problems.join("; ")));
        }
    }
    let n = driven.sessions.len();
    println!(
        "\nsessions: {n} run, {} complete (10 results 1..10 as answered, none timed out, 10 tasks \
         each answered once, a decision per sequence but {fallbacks} policy fallbacks, the start acknowledged once, \
         FINISHED, session file of 10 records)",
        n - bad.len()
    );
    for b in bad.iter().take(20) {
        println!("  INCOMPLETE {b}");
    }
    if !bad.is_empty() {
        ok = false;
    }
    let strangers: Vec<&String> = by_session.keys().filter(|k| !k.is_empty()).collect();
    if !strangers.is_empty() {
        println!("  messages of sessions this soak did not start: {strangers:?}");
        ok = false;
    }

    // 3. The policy learned from every result the game published.
    let ran: BTreeSet<&str> = driven.sessions.iter().map(String::as_str).collect();
    let published = results
        .iter()
        .filter(|r| ran.contains(r.message.session_id.as_str()))
        .count() as u64;
    match q_updates(out) {
        Some(after) => {
            let learned = after.saturating_sub(driven.q_updates_before);
            println!(
                "policy Q-table updates during the soak: {learned} (sequence results: {published})"
            );
            if learned != published {
                ok = false;
            }
        }
        None => {
            println!("policy Q-table file not found: no update count");
            ok = false;
        }
    }
    println!(
        "wall clock {:.0} s for {n} sessions: {:.1} s per session, {:.0} sessions/h",
        driven.wall.as_secs_f64(),
        driven.wall.as_secs_f64() / n.max(1) as f64,
        n as f64 * 3600.0 / driven.wall.as_secs_f64().max(1e-9)
    );
    Ok(ok)
}

#[derive(Default)]
struct SessionRecord {
    results: Vec<u8>,
    /// Sequence index -> (the answer scored, timed out).
    scored: BTreeMap<u8, (Vec<String>, bool)>,
    /// Task id -> its sequence index.
    task_index: BTreeMap<u32, u8>,
    /// Task id -> the answer the bag holds for it.
    answer_of_task: BTreeMap<u32, Vec<String>>,
    tasks: Vec<u8>,
    task_ids: Vec<u32>,
    answers: Vec<u32>,
    decisions: Vec<u8>,
    fallbacks: BTreeSet<u8>,
    waiting: BTreeSet<u8>,
    acks: u32,
    rejections: u32,
    finished: bool,
}

/// The game manager's session file: ten records 1..10 and a finished summary.
fn session_file(out: &Path, id: &str) -> Result<(), String> {
    let jsonl = std::fs::read_to_string(out.join(format!("{id}.jsonl")))
        .map_err(|e| format!("session file: {e}"))?;
    let indices: Vec<u64> = suite_tests::json_lines(&jsonl)
        .iter()
        .filter_map(|r| r["result"]["sequence_index"].as_u64())
        .collect();
    if indices != (1..=10).collect::<Vec<u64>>() {
        return Err(format!("session file indices {indices:?}"));
    }
    let summary = std::fs::read_to_string(out.join(format!("{id}.summary.json")))
        .map_err(|e| format!("summary: {e}"))?;
    let v: serde_json::Value =
        serde_json::from_str(&summary).map_err(|e| format!("summary: {e}"))?;
    if v["end"] != "finished" {
        return Err(format!("summary end {}", v["end"]));
    }
    Ok(())
}

fn median(mut v: Vec<u64>) -> f64 {
    v.sort_unstable();
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2] as f64,
        n => (v[n / 2 - 1] + v[n / 2]) as f64 / 2.0,
    }
}

/// Each node's resident memory and its peak (VmRSS / VmHWM, MiB) after start, after the first
/// session and after the last.
fn memory_table(samples: &[(u32, BTreeMap<String, Usage>)]) {
    let at = |done: u32| samples.iter().find(|(n, _)| *n == done);
    let (Some(start), Some(one), Some(last)) = (at(0), at(1), samples.last()) else {
        return;
    };
    println!(
        "\nresident memory / peak (VmRSS / VmHWM, MiB) after start, 1 session and {} sessions:",
        last.0
    );
    println!(
        "  {:<22} {:>15} {:>15} {:>15}",
        "node", "start", "1", last.0
    );
    for n in NODES {
        let cell = |row: &(u32, BTreeMap<String, Usage>)| match row.1.get(n) {
            Some(u) => format!(
                "{:.1} / {:.1}",
                u.rss_kb as f64 / 1024.0,
                u.hwm_kb as f64 / 1024.0
            ),
            None => "gone".into(),
        };
        println!(
            "  {n:<22} {:>15} {:>15} {:>15}",
            cell(start),
            cell(one),
            cell(last)
        );
    }
}

/// Prints the samples and, per node, first-quarter vs last-quarter medians; true when flat.
fn resource_verdict(cli: &Cli, samples: &[(u32, BTreeMap<String, Usage>)]) -> bool {
    println!("\nresident memory (MiB) / open file descriptors, after N sessions:");
    let short = |n: &str| {
        n.split('_')
            .map(|p| &p[..p.len().min(6)])
            .collect::<Vec<_>>()
            .join("_")
    };
    print!("  {:>7}", "N");
    for n in NODES {
        print!(" {:>16}", short(n));
    }
    println!();
    for (done, row) in samples {
        print!("  {done:>7}");
        for n in NODES {
            match row.get(n) {
                Some(u) => print!(" {:>10.1} / {:>3}", u.rss_kb as f64 / 1024.0, u.fds),
                None => print!(" {:>16}", "gone"),
            }
        }
        println!();
    }
    memory_table(samples);
    // Growth is over sessions played: the sample taken before the first is left out.
    let samples: Vec<(u32, BTreeMap<String, Usage>)> = samples
        .iter()
        .filter(|(done, _)| *done > 0)
        .cloned()
        .collect();
    let samples = samples.as_slice();
    let q = (samples.len() / 4).max(1);
    let first = &samples[..q.min(samples.len())];
    let last = &samples[samples.len().saturating_sub(q)..];
    let mut flat = true;
    println!(
        "\ngrowth, median of the last {q} samples over the first {q} (limits: RSS +{}%, fds +{}):",
        cli.max_rss_growth_pct, cli.max_fd_growth
    );
    for n in NODES {
        let pick = |s: &[(u32, BTreeMap<String, Usage>)], f: fn(&Usage) -> u64| -> Vec<u64> {
            s.iter().filter_map(|(_, r)| r.get(n).map(f)).collect()
        };
        let (r0, r1) = (
            median(pick(first, |u| u.rss_kb)),
            median(pick(last, |u| u.rss_kb)),
        );
        let (f0, f1) = (
            median(pick(first, |u| u.fds)),
            median(pick(last, |u| u.fds)),
        );
        let growth = (r1 - r0) / r0 * 100.0;
        let fd_growth = f1 - f0;
        let node_flat = growth <= cli.max_rss_growth_pct && fd_growth <= cli.max_fd_growth as f64;
        flat &= node_flat;
        println!(
            "  {n:<22} RSS {:>7.1} -> {:>7.1} MiB ({growth:+.1}%)  fds {f0:>4.0} -> {f1:>4.0}  {}",
            r0 / 1024.0,
            r1 / 1024.0,
            if node_flat { "flat" } else { "GROWS" }
        );
    }
    flat
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gap_is_lost_and_a_repeat_is_duplicated() {
        let c = Count::of([3, 4, 4, 6, 7]);
        assert_eq!((c.received, c.lost, c.duplicated), (5, 1, 1));
        let c = Count::of([1, 2, 3]);
        assert_eq!((c.received, c.lost, c.duplicated), (3, 0, 0));
        let c = Count::of([]);
        assert_eq!((c.received, c.lost, c.duplicated), (0, 0, 0));
    }

    #[test]
    fn medians_of_odd_and_even_samples() {
        assert_eq!(median(vec![5, 1, 3]), 3.0);
        assert_eq!(median(vec![4, 1, 3, 2]), 2.5);
    }
}
