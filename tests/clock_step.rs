//! The wall clock stepped mid-session, as NTP does when it first syncs after boot or as someone
//! setting the clock by hand does: every process of the main job has its wall clock stepped
//! one hour back (one session) or two hours forward (another) after sequence 3, the monotonic
//! clock untouched. libfaketime (Debian's `libfaketime`) does it, preloaded into every process
//! of the launch and driven from a file the test rewrites. The session must go on as if
//! nothing happened: every sequence played and answered, no node taken for lost, no timer
//! fired early or late, the policy learning first and deciding every sequence, the bag's log
//! times in order with the step recorded (and `bag info` telling it), each sequence's
//! per-second engagement counted over its own seconds, and the report's timeline whole.
//!   cargo test -p suite_tests --test clock_step -- --nocapture
//!   QT_KEEP_TEST_OUTPUT=1 ...   keeps each run's directory (bag, logs, session files)

use qt_therapy_msgs::topics::{GAME_STATE, HEARTBEAT};
use qt_therapy_msgs::{GameState, Heartbeat};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use suite_tests::{COUNTED_TOPICS, gaps_and_repeats, run_in_loopback_netns, workspace_bin};

/// Debian's libfaketime (package `libfaketime`, which `faketime` pulls in), the thread-safe
/// build: every node runs several threads.
const LIBFAKETIME: &str = "/usr/lib/x86_64-linux-gnu/faketime/libfaketimeMT.so.1";

/// The session's pace: a session takes about 30 s.
const TIME_SCALE: f64 = 0.05;

/// What one stepped session left.
struct SteppedRun {
    out: PathBuf,
    /// The script's output: the launcher's exit and when the clock was stepped.
    script: String,
    /// From the launch's start to its end, on the test's own (monotonic) clock.
    took: Duration,
    /// From the step to the launch's end, likewise.
    after_step: Duration,
}

impl SteppedRun {
    fn read(&self, file: &str) -> String {
        std::fs::read_to_string(self.out.join(file)).unwrap_or_default()
    }

    /// Where a failure says what happened: the script, the console and the nodes' logs' tail.
    fn context(&self) -> String {
        let stderr = self.read("stderr.log");
        let lines: Vec<&str> = stderr.lines().collect();
        format!(
            "{}\nconsole:\n{}\nstderr (tail):\n{}",
            self.script,
            self.read("stdout.log"),
            lines[lines.len().saturating_sub(40)..].join("\n")
        )
    }
}

/// Runs the main job (the kill test's launch file: every node but the child respawned, as
/// on the robot) with every process's wall clock following `<out>/faketime`, and steps it by
/// `step` (libfaketime's offset syntax, e.g. `-3600`) once the console printed sequence 3.
/// None where namespaces cannot be made.
fn stepped_session(name: &str, step: &str) -> Option<SteppedRun> {
    let launch = workspace_bin("launch");
    let bin = launch.parent().expect("target dir").display().to_string();
    let out = std::env::temp_dir().join(format!("clock_step_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).expect("out dir");
    let o = out.display();
    // libfaketime reads the file again at every clock read (FAKETIME_NO_CACHE), so the step
    // is one `mv`: atomic, so no read sees half a file. The script's own clock is not faked.
    let script = format!(
        r#"o={o}
sequences() {{ grep -cE '^\[therapist\] seq +[0-9]+/' "$o/stdout.log"; }}
printf '+0\n' > $o/faketime
LD_PRELOAD={LIBFAKETIME} FAKETIME_TIMESTAMP_FILE=$o/faketime FAKETIME_NO_CACHE=1 FAKETIME_DONT_FAKE_MONOTONIC=1 \
  {launch} tests/reliability/kill_session.launch.yaml bin:={bin} out:=$o time_scale:={TIME_SCALE} > $o/stdout.log 2> $o/stderr.log &
launch=$!
for _ in $(seq 1 1200); do [ "$(sequences)" -ge 3 ] && break; sleep 0.05; done
[ "$(sequences)" -ge 3 ] || {{ echo "no sequence 3 within 60 s"; kill -INT $launch; wait $launch; exit 1; }}
printf '%s\n' '{step}' > $o/faketime.new && mv $o/faketime.new $o/faketime
echo "stepped {step} at $(cut -d' ' -f1 /proc/uptime) after sequence $(sequences)"
wait $launch
echo "launch_exit=$?"
echo "ended at $(cut -d' ' -f1 /proc/uptime)"
"#,
        launch = launch.display(),
    );
    let started = Instant::now();
    let result = run_in_loopback_netns(&script, Duration::from_secs(150))?;
    let took = started.elapsed();
    let script = String::from_utf8_lossy(&result.stdout).to_string()
        + &String::from_utf8_lossy(&result.stderr);
    // /proc/uptime is the monotonic clock (CLOCK_BOOTTIME) of the script, never stepped.
    let uptime = |prefix: &str| {
        script.lines().find_map(|l| {
            let rest = l.strip_prefix(prefix)?;
            let at = rest.rsplit_once(" at ").map_or(rest, |(_, at)| at);
            at.split_whitespace().next()?.parse::<f64>().ok()
        })
    };
    let after_step = match (uptime("stepped "), uptime("ended at ")) {
        (Some(a), Some(b)) => Duration::from_secs_f64((b - a).max(0.0)),
        _ => Duration::ZERO,
    };
    Some(SteppedRun {
        out,
        script,
        took,
        after_step,
    })
}

/// What the test requires of a session whose wall clock was stepped by `step_s` seconds.
fn check(run: &SteppedRun, step_s: f64) {
    let context = run.context();
    assert!(run.script.contains("launch_exit=0"), "{context}");
    let console = run.read("stdout.log");
    assert!(console.contains("finished: 10 sequences"), "{context}");
    let stderr = run.read("stderr.log");

    // No node died; none was taken for lost (the game manager's watch, the tablet bridge's
    // watch of the game manager); RustDDS's history did not stall.
    let launcher: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("[launch]") && (l.contains(" died ") || l.contains("restarted")))
        .collect();
    assert!(launcher.is_empty(), "{launcher:?}\n{context}");
    for wrong in [
        "node lost",
        "no heartbeat for",
        "game manager lost",
        "Did my clock jump backwards",
        "refused a decision",
    ] {
        assert!(!stderr.contains(wrong), "{wrong:?} in the log\n{context}");
    }

    // The session: whole, every sequence answered and decided by the policy (its
    // learn-first gate and the game manager's deadlines did not run out early).
    let bag = run.out.join("session.mcap");
    let session = suite_tests::whole_session_bag(&bag, &context);
    let timed_out: Vec<u8> = session
        .results
        .iter()
        .filter(|r| r.timed_out)
        .map(|r| r.sequence_index)
        .collect();
    assert!(timed_out.is_empty(), "timed out: {timed_out:?}\n{context}");
    let jsonl = std::fs::read_dir(&run.out)
        .expect("out dir")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "jsonl"))
        .unwrap_or_else(|| panic!("no session file\n{context}"));
    let records = suite_tests::json_lines(&std::fs::read_to_string(&jsonl).expect("read"));
    assert_eq!(records.len(), 10, "{context}");
    let fallbacks: Vec<&serde_json::Value> = records
        .iter()
        .filter(|r| r["policy_fallback"] == true)
        .map(|r| &r["decision_reason"])
        .collect();
    assert!(fallbacks.is_empty(), "fallbacks: {fallbacks:?}\n{context}");
    let q_table: serde_json::Value = serde_json::from_str(&run.read("q_tables/cluster_0.json"))
        .unwrap_or_else(|e| panic!("the Q-table: {e}\n{context}"));
    assert_eq!(q_table["updates"], 10, "{context}");
    let states = bag_file::BagReader::open(&bag)
        .expect("bag")
        .messages::<GameState>(GAME_STATE.name)
        .expect("states");
    assert!(
        states.iter().all(|s| !s.message.status.contains("lost")),
        "{context}"
    );

    // Each sequence's engagement: the seconds of its own period, counted once. A period is
    // its talking time (a few seconds at this pace), its ends stamped on one clock.
    for r in &session.results {
        let start = r.engagement_period_start.to_nanos();
        let end = r.engagement_period_end.to_nanos();
        let length_s = (end - start) as f64 * 1e-9;
        let seconds = r.engagement_per_second.len();
        assert!(
            (0.0..30.0).contains(&length_s) && seconds >= 1 && seconds as f64 <= length_s + 2.0,
            "sequence {}: {seconds} seconds of engagement over a period of {length_s:.1} s\n\
             {context}",
            r.sequence_index
        );
    }

    // The bag: log times in order and as long as the run (the recorder's clock did not
    // step), the step recorded and told by `bag info`.
    let reader = bag_file::BagReader::open(&bag).expect("bag");
    let (first, last) = reader.time_range().expect("a bag with messages");
    let span_s = (last - first) as f64 * 1e-9;
    assert!(
        span_s > run.after_step.as_secs_f64() && span_s < run.took.as_secs_f64() + 5.0,
        "the bag's log times span {span_s:.1} s; the run took {:.1} s, {:.1} s of them after \
         the step",
        run.took.as_secs_f64(),
        run.after_step.as_secs_f64()
    );
    let mut previous = 0;
    for (channel, m) in reader.iter() {
        assert!(
            m.log_time + 1_000_000_000 >= previous,
            "{}: log time {} after {previous}",
            channel.topic,
            m.log_time
        );
        previous = previous.max(m.log_time);
    }
    let info = std::process::Command::new(workspace_bin("bag"))
        .args(["info"])
        .arg(&bag)
        .output()
        .expect("bag info");
    let info = String::from_utf8_lossy(&info.stdout).to_string();
    let told = info
        .lines()
        .find(|l| l.starts_with("Clock steps:"))
        .unwrap_or_else(|| panic!("bag info tells no clock step:\n{info}"));
    let told_s: f64 = told
        .split_whitespace()
        .find_map(|w| w.strip_suffix('s')?.parse().ok())
        .unwrap_or_else(|| panic!("no step in seconds in {told:?}"));
    assert!((told_s - step_s).abs() < 1.0, "{told}");

    // The report: one timeline for the whole session, the step taken out.
    let log =
        session_report::SessionLog::from_bag(&bag_file::BagReader::open(&bag).expect("bag"), None)
            .expect("the report reads the bag");
    let figures = session_report::engagement_figures(&log);
    assert!(!figures.is_empty(), "no engagement figure");
    for f in &figures {
        let span =
            f.seconds.last().copied().unwrap_or(0.0) - f.seconds.first().copied().unwrap_or(0.0);
        assert!(
            span > 10.0 && span < run.took.as_secs_f64() + 5.0,
            "the report's engagement spans {span:.1} s"
        );
        assert!(
            f.seconds_with_faces() >= 10,
            "{} seconds with faces",
            f.seconds_with_faces()
        );
        assert!(
            f.answers
                .windows(2)
                .all(|w| w[0] <= w[1] && w[1] - w[0] < 30.0)
                && f.answers.iter().all(|a| *a >= 0.0 && *a <= span + 5.0),
            "the answers on the report's timeline: {:?}",
            f.answers
        );
    }
    // Nothing lost or repeated across the step: every reliable message by its publisher's
    // sequence number, every heartbeat by its process's counter.
    let mut by_topic: BTreeMap<&str, Vec<u64>> = BTreeMap::new();
    for (channel, m) in reader.iter() {
        if let Some(t) = COUNTED_TOPICS.iter().find(|t| **t == channel.topic) {
            by_topic.entry(t).or_default().push(u64::from(m.sequence));
        }
    }
    let mut counted = 0;
    for topic in COUNTED_TOPICS {
        let numbers = by_topic.remove(topic).unwrap_or_default();
        assert_eq!(gaps_and_repeats(&numbers), (0, 0), "{topic}: {numbers:?}");
        counted += numbers.len();
    }
    let mut beats: BTreeMap<u32, Vec<u64>> = BTreeMap::new();
    for h in reader
        .messages::<Heartbeat>(HEARTBEAT.name)
        .expect("heartbeats")
    {
        beats
            .entry(h.message.pid)
            .or_default()
            .push(h.message.sequence);
    }
    for (pid, numbers) in &beats {
        assert_eq!(gaps_and_repeats(numbers), (0, 0), "heartbeats of pid {pid}");
        counted += numbers.len();
    }
    eprintln!(
        "wall clock stepped {step_s:+.0} s after sequence 3: 10 sequences, {} seconds of \
         engagement with a face, {counted} reliable messages counted (0 lost, 0 repeated), \
         the bag spans {span_s:.1} s; the run took {:.1} s ({:.1} s after the step)",
        session.engagement.iter().filter(|e| e.has_faces).count(),
        run.took.as_secs_f64(),
        run.after_step.as_secs_f64(),
    );
}

fn keep_or_remove(out: &Path) {
    if std::env::var_os("QT_KEEP_TEST_OUTPUT").is_none() {
        let _ = std::fs::remove_dir_all(out);
    }
}

/// One session with its wall clock stepped an hour back and one two hours forward, side by
/// side (each in its own namespace), so the test takes about as long as one session.
#[test]
fn a_session_goes_on_when_the_wall_clock_is_stepped_back_or_forward() {
    if !Path::new(LIBFAKETIME).exists()
        && loopback_netns::skip_or_fail(&format!(
            "{LIBFAKETIME} is missing: apt-get install faketime (tests/run.sh does)"
        ))
    {
        return;
    }
    let back = std::thread::spawn(|| stepped_session("back", "-3600"));
    let forward = stepped_session("forward", "+7200");
    let back = back.join().expect("the backward run");
    let (Some(back), Some(forward)) = (back, forward) else {
        return;
    };
    check(&back, -3600.0);
    check(&forward, 7200.0);
    keep_or_remove(&back.out);
    keep_or_remove(&forward.out);
}
