//! The two tablets in a real headless Chromium, against the REAL suite over real DDS: the test
//! runs `launch_scripts/tablet_session.launch.yaml` (bag recorder, user model, behaviour policy,
//! engagement classifier, game manager and tablet bridge, each its own process) with the robot's
//! timings scaled down, logs in on the therapist page, starts a session and plays all ten
//! sequences on the child page by tapping what the robot said. It hears the robot as the child
//! does: it listens to `/qt_robot/speech/say` over DDS (and to the tasks, decisions and answers,
//! to check what crossed). It is the camera too: 30 fps of SYNTHETIC faces looking at the robot
//! (the classifier's generator) for the real classifier. Bad input from both pages is refused
//! on the way, and mid-session the bridge itself is SIGKILLed: the launcher respawns it and
//! both pages reconnect to it by themselves. Supervised autonomy is on and proposes every
//! decision of the policy on the therapist page: one is accepted, one replaced by feedback, one
//! by another level, one left to run out, the rest accepted at once, and what the game manager
//! says of each over DDS must be what the page did. The pages are served over HTTPS with a
//! certificate `tablet_tls` made for the robot's name, and Chromium trusts its CA as a tablet
//! that installed it does (an NSS database made with `certutil`). Everything runs inside one
//! private loopback-only network namespace: the test re-runs itself in there.
//!
//! Needs Debian's `chromium`, `chromium-driver` and `libnss3-tools` (skips with a message where
//! they are absent) and the suite's binaries (`cargo build --workspace --bins`; tests/run.sh
//! builds them first).
//! Screenshots land in target/tablet_bridge_screenshots/ (or $TABLET_SCREENSHOT_DIR).

mod support;

use node_shell::{NoParameters, NodeShell, ShellOptions, header_now};
use openface::synthetic::{SyntheticSpec, generate};
use qt_therapy_msgs::topics::{
    ACTION_PROPOSAL, DECISION, OPENFACE_FEATURES, ROBOT_SPEECH, TABLET_ANSWER, TABLET_TASK,
    THERAPIST_COMMAND,
};
use qt_therapy_msgs::{
    ActionProposal, Decision, OpenFaceFeatures, TabletAnswer, TabletTask, TherapistCommand,
};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use support::*;

const TEST_NAME: &str = "a_therapist_plays_a_whole_session_with_the_real_suite_on_both_tablets";
const INNER: &str = "TABLET_BROWSER_TEST_INNER";
const HTTP_PORT: u16 = 18080;
const DRIVER_PORT: u16 = 19515;
const PIN: &str = "2468";
const WAIT: Duration = Duration::from_secs(30);
/// The policy pretrains its Q-tables before it serves; the game waits for it.
const STARTUP: Duration = Duration::from_secs(120);
const EMOTIONS: [&str; 4] = ["happy", "disgusted", "sad", "angry"];
/// The robot talks 20x faster than real; the child still gets 30 s per answer. Supervised
/// autonomy proposes every decision of the policy (every temperature is above 0) on the
/// therapist page, with 200 s x 0.05 = 10 s to answer.
const GAME_ARGS: &str = "--param time_scale:=0.05 --param answer_timeout_s:=600 \
     --param engagement_wait_s:=0.2 --param policy_startup_wait_s:=120 --param policy_deadline_s:=10 \
     --param seed:=11 --param supervised_autonomy:=true --param propose_above_temperature:=0.0 \
     --param proposal_countdown_s:=200.0";
/// The proposal's countdown as the page gets it (proposal_countdown_s x time_scale).
const COUNTDOWN_S: f32 = 10.0;
/// Sequence answered wrongly on purpose; before answering sequence OVERRIDE_AT the therapist
/// pauses, overrides the next level to 3 and resumes.
const WRONG_AT: usize = 5;
const OVERRIDE_AT: usize = 2;
/// While sequence BRIDGE_KILLED_AT waits for the child's answer, the tablet bridge is
/// SIGKILLed; the launcher respawns it (5 s) and both pages reconnect by themselves.
const BRIDGE_KILLED_AT: usize = 8;
/// The policy's proposal for sequence RUN_OUT_AT is left to run out; REPLACED_BY_FEEDBACK_AT's
/// is replaced by encouraging (or challenging) feedback, REPLACED_BY_LEVEL_AT's by another
/// level; every other one is accepted at once. Sequence OVERRIDE_AT + 1 is not proposed: the
/// therapist set it before it was decided.
const RUN_OUT_AT: usize = 2;
const REPLACED_BY_FEEDBACK_AT: usize = 4;
const REPLACED_BY_LEVEL_AT: usize = 6;
/// The suite's binaries the launch file starts, besides this crate's own.
const SUITE_BINARIES: [&str; 6] = [
    "launch",
    "bag",
    "user_model",
    "behaviour_policy",
    "engagement_classifier",
    "game_manager",
];

/// Where cargo put this profile's binaries (the launch file's `bin`).
fn bin_dir() -> PathBuf {
    Path::new(env!("CARGO_BIN_EXE_tablet_bridge"))
        .parent()
        .map(Path::to_path_buf)
        .expect("the binaries' directory")
}

/// The target directory (tests/run.sh installs axe-core in it).
fn target_dir() -> PathBuf {
    bin_dir()
        .parent()
        .map(Path::to_path_buf)
        .expect("the target directory")
}

#[test]
fn a_therapist_plays_a_whole_session_with_the_real_suite_on_both_tablets() {
    if std::env::var_os(INNER).is_some() {
        let runtime = tokio::runtime::Runtime::new().expect("tokio runtime");
        runtime.block_on(inner());
        return;
    }
    if browser_missing() {
        return;
    }
    for b in SUITE_BINARIES {
        let path = bin_dir().join(b);
        assert!(
            path.exists(),
            "{} is not built: run `cargo build --workspace --bins` first (tests/run.sh does)",
            path.display()
        );
    }
    let Some(axe) = axe_script(&target_dir()) else {
        return;
    };
    let shots = screenshot_dir();
    let Some(out) = loopback_netns::rerun_test_inside(
        TEST_NAME,
        &[
            (INNER, "1".as_ref()),
            ("ROS_LOCALHOST_ONLY", "1".as_ref()),
            ("TABLET_SCREENSHOT_DIR", shots.as_os_str()),
            ("QT_AXE_JS", axe.as_os_str()),
        ],
        Duration::from_secs(300),
    ) else {
        return;
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "inside the namespace:\n{stdout}\n{stderr}"
    );
    for line in stderr
        .lines()
        .filter(|l| l.starts_with("tablet_bridge SIGKILLed") || l.starts_with("whole session: "))
    {
        eprintln!("{line}");
    }
    eprintln!("browser test passed; screenshots in {}", shots.display());
}

/// True (after saying why) where the test cannot run: no Chromium, chromedriver or certutil.
fn browser_missing() -> bool {
    (which("chromium").is_none() || which("chromedriver").is_none() || which("certutil").is_none())
        && loopback_netns::skip_or_fail(
            "chromium, chromedriver or certutil is not installed \
             (apt-get update && apt-get install -y chromium chromium-driver libnss3-tools)",
        )
}

fn screenshot_dir() -> PathBuf {
    let shots = std::env::var_os("TABLET_SCREENSHOT_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("target/tablet_bridge_screenshots"));
    std::fs::create_dir_all(&shots).expect("screenshot dir");
    shots
}

const PLAIN_TEST_NAME: &str = "the_therapist_page_says_when_it_is_served_unencrypted";
const PLAIN_INNER: &str = "TABLET_PLAIN_TEST_INNER";

/// The bridge alone (no game manager) with `allow_plain_http` on every address: the therapist
/// page opened by the robot's name says its link is unencrypted; opened on loopback (the
/// simulated session's case: nothing crosses a network) it does not.
#[test]
fn the_therapist_page_says_when_it_is_served_unencrypted() {
    const PORT: u16 = 18090;
    const DRIVER: u16 = 19516;
    if std::env::var_os(PLAIN_INNER).is_some() {
        let runtime = tokio::runtime::Runtime::new().expect("tokio runtime");
        runtime.block_on(async {
            let logs = Logs {
                dir: tempfile::tempdir().expect("temp dir"),
            };
            let bridge = Guard::spawn(
                "tablet_bridge",
                Command::new(env!("CARGO_BIN_EXE_tablet_bridge"))
                    .args(["--param", &format!("http_bind:=0.0.0.0:{PORT}")])
                    .args(["--param", "allow_plain_http:=true"])
                    .env("QT_TABLET_PIN", PIN)
                    .stdout(logs.file("bridge.out"))
                    .stderr(logs.file("bridge.err")),
            );
            let _driver = Guard::spawn(
                "chromedriver",
                Command::new("chromedriver")
                    .args([format!("--port={DRIVER}"), "--allowed-ips=127.0.0.1".into()])
                    .env("HOME", logs.dir.path())
                    .stdout(logs.file("chromedriver.log"))
                    .stderr(Stdio::null()),
            );
            until("the bridge and chromedriver", WAIT, || async {
                (port_open(PORT) && port_open(DRIVER)).then_some(())
            })
            .await;
            let profiles = tempfile::tempdir().expect("profiles");
            let page = Page::open("therapist", DRIVER, profiles.path(), (1280, 800)).await;
            for (host, warned) in [(ROBOT_HOST, true), ("127.0.0.1", false)] {
                let url = format!("http://{host}:{PORT}/therapist");
                page.client.goto(&url).await.expect("goto");
                page.wait_text("#login", "Unlock", WAIT).await;
                let hidden = page.count("#unencrypted.hidden").await == 1;
                assert_eq!(!hidden, warned, "{url}");
                if warned {
                    let text = page.text("#unencrypted").await;
                    assert!(text.starts_with("Unencrypted connection"), "{text}");
                    page.screenshot(&screenshot_dir(), "therapist_unencrypted_1280x800")
                        .await;
                    page.assert_accessible("therapist login, unencrypted bar, 1280x800")
                        .await;
                }
            }
            assert_eq!(bridge.interrupt(Duration::from_secs(10)), Some(0));
            let log = logs.read("bridge.err");
            assert!(log.contains("UNENCRYPTED"), "{log}");
        });
        return;
    }
    if browser_missing() {
        return;
    }
    let Some(axe) = axe_script(&target_dir()) else {
        return;
    };
    let shots = screenshot_dir();
    let Some(out) = loopback_netns::rerun_test_inside(
        PLAIN_TEST_NAME,
        &[
            (PLAIN_INNER, "1".as_ref()),
            ("ROS_LOCALHOST_ONLY", "1".as_ref()),
            ("TABLET_SCREENSHOT_DIR", shots.as_os_str()),
            ("QT_AXE_JS", axe.as_os_str()),
        ],
        Duration::from_secs(60),
    ) else {
        return;
    };
    assert!(
        out.status.success(),
        "inside the namespace:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

const CHILDREN_TEST_NAME: &str =
    "the_therapist_finds_a_child_among_200_and_prints_their_progress_in_both_languages";
const CHILDREN_INNER: &str = "TABLET_CHILDREN_TEST_INNER";

/// The bridge alone (no game) over a robot's stored sessions as the suite writes them
/// (`stored_sessions`: 200 children with a session each, one with 50 sessions whose runs
/// include a bag cut short and one without a bag and whose decisions were planned on a belief
/// about the child, one with a single session), once in English and once in German, at the
/// tablet's two orientations: the list holds all 202 codes and its search finds one; the
/// progress of 50, 1 and 0 sessions shows, naming the damaged and the missing bag, with what
/// the robot believes about the fifty-session child in words and a picture and that it has no
/// belief about the one-session child; a new code is checked by the bridge; the 50 sessions
/// print to A4. axe-core checks every page and state.
#[test]
fn the_therapist_finds_a_child_among_200_and_prints_their_progress_in_both_languages() {
    if std::env::var_os(CHILDREN_INNER).is_some() {
        let runtime = tokio::runtime::Runtime::new().expect("tokio runtime");
        runtime.block_on(children_inner());
        return;
    }
    if browser_missing() {
        return;
    }
    let Some(axe) = axe_script(&target_dir()) else {
        return;
    };
    let stored = bin_dir().join("stored_sessions");
    assert!(
        stored.exists(),
        "{} is not built: run `cargo build --workspace --bins` first (tests/run.sh does)",
        stored.display()
    );
    let shots = screenshot_dir();
    let Some(out) = loopback_netns::rerun_test_inside(
        CHILDREN_TEST_NAME,
        &[
            (CHILDREN_INNER, "1".as_ref()),
            ("ROS_LOCALHOST_ONLY", "1".as_ref()),
            ("TABLET_SCREENSHOT_DIR", shots.as_os_str()),
            ("QT_AXE_JS", axe.as_os_str()),
        ],
        Duration::from_secs(180),
    ) else {
        return;
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "inside the namespace:\n{}\n{stderr}",
        String::from_utf8_lossy(&out.stdout)
    );
    for line in stderr
        .lines()
        .filter(|l| l.starts_with("printed") || l.starts_with("children and progress: axe"))
    {
        eprintln!("{line}");
    }
}

/// The words the children test looks for, per language.
struct Words {
    lang: &'static str,
    unlock: &'static str,
    no_match: &'static str,
    progress_of: &'static str,
    no_session: &'static str,
    empty_code: &'static str,
    /// What the robot believes: a level's line, how often it left the group's table, and
    /// that it has none.
    belief_level: &'static str,
    belief_left_table: &'static str,
    belief_not_carried: &'static str,
}

const ENGLISH: Words = Words {
    lang: "en",
    unlock: "Unlock",
    no_match: "No code matches",
    progress_of: "Progress of",
    no_session: "No session of this child",
    empty_code: "is empty",
    belief_level: "Level 2 (5 emotions): right about",
    belief_left_table: "chose differently from the group's table in",
    belief_not_carried: "Not available: the robot did not learn about this child",
};
const GERMAN: Words = Words {
    lang: "de",
    unlock: "Entsperren",
    no_match: "Kein Code passt",
    progress_of: "Verlauf von",
    no_session: "noch keine Sitzung gespeichert",
    empty_code: "is empty",
    belief_level: "Level 2 (5 Emotionen): etwa",
    belief_left_table: "anders als die Tabelle der Gruppe",
    belief_not_carried: "Nicht verfügbar: der Roboter hat dieses Kind nicht",
};

async fn children_inner() {
    const DRIVER: u16 = 19517;
    let shots = PathBuf::from(std::env::var_os("TABLET_SCREENSHOT_DIR").expect("dir"));
    let logs = Logs {
        dir: tempfile::tempdir().expect("temp dir"),
    };
    // In memory where the machine has /dev/shm: the game manager's writer fsyncs every line
    // (3,500 here: 20 s on this machine's disk, 0.7 s in memory).
    let shm = Path::new("/dev/shm");
    let stored = shm
        .is_dir()
        .then(|| tempfile::tempdir_in(shm).ok())
        .flatten();
    let stored = stored.unwrap_or_else(|| tempfile::tempdir().expect("temp dir"));
    let root = stored.path().join("sessions");
    let made = Command::new(bin_dir().join("stored_sessions"))
        .arg("--root")
        .arg(&root)
        .args(["--children", "200", "--child", "child-fifty:50"])
        .args(["--planned-on-belief", "child-fifty"])
        .args([
            "--child",
            "child-one:1",
            "--damaged-bag",
            "2",
            "--missing-bag",
            "4",
        ])
        .output()
        .expect("stored_sessions runs");
    assert!(made.status.success(), "{made:?}");
    let bridges: Vec<(Guard, u16, &Words)> = [(18100, &ENGLISH), (18101, &GERMAN)]
        .into_iter()
        .map(|(port, words)| {
            let bridge = Guard::spawn(
                "tablet_bridge",
                Command::new(env!("CARGO_BIN_EXE_tablet_bridge"))
                    .args(["--param", &format!("http_bind:=127.0.0.1:{port}")])
                    .args(["--param", &format!("language:={}", words.lang)])
                    .arg("--param")
                    .arg(format!("sessions_root:={}", root.display()))
                    .env("QT_TABLET_PIN", PIN)
                    .stdout(logs.file(&format!("bridge_{}.out", words.lang)))
                    .stderr(logs.file(&format!("bridge_{}.err", words.lang))),
            );
            (bridge, port, words)
        })
        .collect();
    let _driver = Guard::spawn(
        "chromedriver",
        Command::new("chromedriver")
            .args([format!("--port={DRIVER}"), "--allowed-ips=127.0.0.1".into()])
            .env("HOME", logs.dir.path())
            .stdout(logs.file("chromedriver.log"))
            .stderr(Stdio::null()),
    );
    until("the bridges and chromedriver", WAIT, || async {
        (port_open(18100) && port_open(18101) && port_open(DRIVER)).then_some(())
    })
    .await;
    let profiles = tempfile::tempdir().expect("profiles");
    // A browser window per language, each starting in landscape as a tablet might.
    for (_, port, words) in &bridges {
        let profile = profiles.path().join(words.lang);
        let page = Page::open("therapist", DRIVER, &profile, (1280, 800)).await;
        if words.lang == "en" {
            page.client
                .goto(&format!("http://127.0.0.1:{port}/"))
                .await
                .expect("goto");
            page.assert_accessible("index").await;
        }
        the_children_in_one_language(&page, *port, words, &shots).await;
        let _ = page.client.close().await;
    }
    eprintln!("children and progress: {}", axe_spent());
    for (bridge, _, words) in bridges {
        assert_eq!(
            bridge.interrupt(Duration::from_secs(10)),
            Some(0),
            "{}",
            logs.read(&format!("bridge_{}.err", words.lang))
        );
    }
}

/// Types `query` into the list's search as a therapist would (an input event per change).
async fn search(page: &Page, query: &str) {
    page.js(
        "const e = document.getElementById('child-search'); e.value = arguments[0]; \
         e.dispatchEvent(new Event('input')); return true;",
        vec![json!(query)],
    )
    .await;
}

/// The therapist page in one language: the list, a search, the progress of 50, 1 and 0
/// sessions, in landscape and portrait; then the child page.
async fn the_children_in_one_language(page: &Page, port: u16, words: &Words, shots: &Path) {
    let lang = words.lang;
    let base = format!("http://127.0.0.1:{port}");
    page.client
        .goto(&format!("{base}/therapist"))
        .await
        .expect("goto");
    page.wait_text("#login", words.unlock, WAIT).await;
    page.assert_accessible(&format!("therapist login, {lang}"))
        .await;
    page.type_into("#pin", PIN).await;
    page.click("#login").await;
    page.wait_count("#children li", 202, WAIT).await;
    // The most recent first: the fifty-session child played last.
    assert_eq!(
        page.text("#children li:first-child .code").await,
        "child-fifty"
    );
    page.screenshot(shots, &format!("therapist_children_{lang}_1280x800"))
        .await;
    page.assert_accessible(&format!("therapist, 202 children, {lang}, 1280x800"))
        .await;
    search(page, "zzz").await;
    page.wait_count("#children li", 0, WAIT).await;
    page.wait_text("#children-empty", words.no_match, WAIT)
        .await;
    page.assert_accessible(&format!("therapist, no code matches, {lang}"))
        .await;
    search(page, "FIFTY").await;
    page.wait_count("#children li", 1, WAIT).await;
    page.click("#children button[data-user=\"child-fifty\"]")
        .await;
    page.wait_text("#chosen-code", "child-fifty", WAIT).await;

    // Fifty sessions: a row each, both figures, the damaged and the missing bag named.
    page.click("#show-progress").await;
    let article = "#progress article[data-user=\"child-fifty\"][data-sessions=\"50\"]";
    page.wait_count(article, 1, WAIT).await;
    assert!(
        page.text("#progress h2")
            .await
            .starts_with(words.progress_of)
    );
    assert_eq!(page.count("#progress tbody tr").await, 50);
    // Across sessions two figures, and what the robot believes as the third.
    assert_eq!(page.count("#progress figure svg[role=img]").await, 3);
    let belief = page.text("#progress .belief").await;
    assert!(
        belief.contains(words.belief_level)
            && belief.contains(words.belief_left_table)
            && belief.contains("→"),
        "{belief}"
    );
    assert_eq!(page.count("#progress .belief li").await, 6, "{belief}");
    assert_eq!(
        page.count("#progress .belief svg[aria-labelledby=progress-belief-caption]")
            .await,
        1
    );
    let problems = page.text("#progress .problems").await;
    assert!(
        problems.contains("run-002/session.mcap is damaged") && problems.contains("no bag in"),
        "{problems}"
    );
    page.screenshot(
        shots,
        &format!("therapist_progress_50_sessions_{lang}_1280x800"),
    )
    .await;
    page.assert_accessible(&format!(
        "therapist, progress of 50 sessions, {lang}, 1280x800"
    ))
    .await;
    if lang == "en" {
        let pdf = page
            .print_pdf(shots, "therapist_progress_50_sessions")
            .await;
        assert!(pdf.starts_with(b"%PDF"), "a PDF");
        let pages = pdf.windows(11).filter(|w| w == b"/Type /Page").count()
            - pdf.windows(12).filter(|w| w == b"/Type /Pages").count();
        eprintln!("printed the progress of 50 sessions: {pages} A4 pages");
        assert!((1..=8).contains(&pages), "{pages} pages");
    }
    page.resize(800, 1280).await;
    page.screenshot(
        shots,
        &format!("therapist_progress_50_sessions_{lang}_800x1280"),
    )
    .await;
    page.assert_accessible(&format!(
        "therapist, progress of 50 sessions, {lang}, 800x1280"
    ))
    .await;
    page.click("#progress-back").await;
    search(page, "").await;
    page.wait_count("#children li", 202, WAIT).await;
    page.screenshot(shots, &format!("therapist_children_{lang}_800x1280"))
        .await;
    page.assert_accessible(&format!("therapist, 202 children, {lang}, 800x1280"))
        .await;

    // One session.
    page.click("#children button[data-user=\"child-one\"]")
        .await;
    page.click("#show-progress").await;
    page.wait_count(
        "#progress article[data-user=\"child-one\"][data-sessions=\"1\"]",
        1,
        WAIT,
    )
    .await;
    assert_eq!(page.count("#progress tbody tr").await, 1);
    assert!(
        page.text("#progress .belief")
            .await
            .contains(words.belief_not_carried),
        "no belief about the one-session child"
    );
    page.assert_accessible(&format!(
        "therapist, progress of 1 session, {lang}, 800x1280"
    ))
    .await;
    page.click("#progress-back").await;

    // A new code: an empty one is refused by the bridge; a good one is chosen, has no session.
    page.type_into("#new-code", " ").await;
    page.click("#add-child").await;
    page.wait_text("#toast", words.empty_code, WAIT).await;
    page.type_into("#new-code", "child-new").await;
    page.click("#add-child").await;
    page.wait_text("#chosen-code", "child-new", WAIT).await;
    assert_eq!(
        page.count("#children li").await,
        203,
        "the new code on the list"
    );
    page.click("#show-progress").await;
    page.wait_count(
        "#progress article[data-user=\"child-new\"][data-sessions=\"0\"]",
        1,
        WAIT,
    )
    .await;
    assert!(page.text("#progress").await.contains(words.no_session));
    page.resize(1280, 800).await;
    page.screenshot(
        shots,
        &format!("therapist_progress_0_sessions_{lang}_1280x800"),
    )
    .await;
    page.assert_accessible(&format!(
        "therapist, progress of 0 sessions, {lang}, 1280x800"
    ))
    .await;

    page.client
        .goto(&format!("{base}/child"))
        .await
        .expect("goto");
    page.wait_count("#prompt:not(:empty)", 1, WAIT).await;
    page.assert_accessible(&format!("child waiting, {lang}, 1280x800"))
        .await;
    page.resize(800, 1280).await;
    page.screenshot(shots, &format!("child_waiting_{lang}_800x1280"))
        .await;
    page.assert_accessible(&format!("child waiting, {lang}, 800x1280"))
        .await;
}

/// What the test heard over DDS: every utterance of the robot, the tasks (with how many
/// utterances came before each), the policy's decisions and the answers the bridge published.
#[derive(Default)]
struct Heard {
    utterances: Vec<String>,
    tasks: Vec<(usize, TabletTask)>,
    decisions: Vec<Decision>,
    answers: Vec<TabletAnswer>,
    proposals: Vec<ActionProposal>,
    commands: Vec<TherapistCommand>,
}

/// The test's own DDS participant: listens, and plays the camera.
struct Ears {
    heard: Arc<Mutex<Heard>>,
    shell: NodeShell,
}

fn listen<M: Send + 'static>(
    mut rx: tokio::sync::mpsc::Receiver<M>,
    heard: &Arc<Mutex<Heard>>,
    put: fn(&mut Heard, M),
) {
    let heard = heard.clone();
    tokio::spawn(async move {
        while let Some(m) = rx.recv().await {
            put(&mut heard.lock().expect("heard"), m);
        }
    });
}

/// 30 frames a second of one SYNTHETIC person looking at the robot (the frames the
/// classifier's generator labels engaged), as the robot's camera and OpenFace would send them.
fn camera(shell: &mut NodeShell) {
    let frames = shell.publisher(OPENFACE_FEATURES).expect("camera");
    let table = generate(&SyntheticSpec {
        participants: 1,
        frames_per_participant: 600,
        fps: 30.0,
        label_noise: 0.0,
        seed: 11,
    });
    let faces: Vec<Vec<f32>> = table
        .rows
        .iter()
        .zip(&table.labels)
        .filter(|(_, label)| **label > 0)
        .map(|(row, _)| row.iter().map(|v| *v as f32).collect())
        .collect();
    assert!(!faces.is_empty(), "the generator gave no engaged face");
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / 30.0));
        for features in faces.iter().cycle() {
            tick.tick().await;
            frames.send(OpenFaceFeatures {
                header: header_now(),
                face_id: "0".into(),
                confidence: 0.97,
                success: true,
                features: features.clone(),
            });
        }
    });
}

impl Ears {
    fn start(dir: &Path) -> Ears {
        let params = dir.join("browser_test_ears.yaml");
        std::fs::write(&params, "browser_test_ears:\n  ros__parameters: {}\n").expect("params");
        let options = ShellOptions {
            params_file: Some(params),
            node_name: None,
            namespace: "/".into(),
            service_mapping: "enhanced".into(),
            param_overrides: Vec::new(),
            ..Default::default()
        };
        let (mut shell, NoParameters {}) =
            NodeShell::start("browser_test_ears", &options).expect("the test's DDS participant");
        let heard = Arc::new(Mutex::new(Heard::default()));
        let speech = shell.subscribe(ROBOT_SPEECH, 1024).expect("speech");
        listen(speech, &heard, |h, m| h.utterances.push(m.data));
        let tasks = shell.subscribe(TABLET_TASK, 64).expect("tasks");
        listen(tasks, &heard, |h, t| {
            // A task can come again (transient-local, resume); it is the same task.
            let seen = h
                .tasks
                .iter()
                .any(|(_, s)| s.session_id == t.session_id && s.sequence_id == t.sequence_id);
            if !seen {
                let mark = h.utterances.len();
                h.tasks.push((mark, t));
            }
        });
        let decisions = shell.subscribe(DECISION, 64).expect("decisions");
        listen(decisions, &heard, |h, d| h.decisions.push(d));
        let answers = shell.subscribe(TABLET_ANSWER, 64).expect("answers");
        listen(answers, &heard, |h, a| h.answers.push(a));
        let proposals = shell.subscribe(ACTION_PROPOSAL, 64).expect("proposals");
        listen(proposals, &heard, |h, p| h.proposals.push(p));
        let commands = shell.subscribe(THERAPIST_COMMAND, 64).expect("commands");
        listen(commands, &heard, |h, c| h.commands.push(c));
        camera(&mut shell);
        Ears { heard, shell }
    }

    fn with<T>(&self, f: impl FnOnce(&Heard) -> T) -> T {
        f(&self.heard.lock().expect("heard"))
    }

    /// The `k`-th task (1-based) of `session` (any session when None), once it has come.
    async fn task(&self, session: Option<&str>, k: usize) -> TabletTask {
        until(&format!("task {k} over DDS"), WAIT, || async {
            self.with(|h| {
                h.tasks
                    .iter()
                    .filter(|(_, t)| session.is_none_or(|s| t.session_id == s))
                    .nth(k - 1)
                    .map(|(_, t)| t.clone())
            })
        })
        .await
    }

    /// The first proposal message of `session` for sequence `step` with `status`, once heard.
    async fn proposal(&self, session: &str, step: u8, status: u8) -> ActionProposal {
        let what = format!("proposal {step} of {session} with status {status} over DDS");
        until(&what, WAIT, || async {
            self.with(|h| {
                h.proposals
                    .iter()
                    .find(|p| p.session_id == session && p.step == step && p.status == status)
                    .cloned()
            })
        })
        .await
    }

    /// The emotions the robot said for `task`: the emotion words it spoke after the task
    /// before it (the feedback and "well done" lines are sentences, never a single emotion).
    async fn said(&self, task: &TabletTask) -> Vec<String> {
        let n = usize::from(task.length);
        let words = || {
            self.with(|h| {
                let i = h
                    .tasks
                    .iter()
                    .position(|(_, t)| t.sequence_id == task.sequence_id)
                    .expect("a heard task");
                let from = if i == 0 { 0 } else { h.tasks[i - 1].0 };
                h.utterances[from..]
                    .iter()
                    .filter(|u| EMOTIONS.contains(&u.as_str()))
                    .cloned()
                    .collect::<Vec<_>>()
            })
        };
        let what = format!(
            "the robot to say {n} emotions for task {}",
            task.sequence_id
        );
        until(&what, WAIT, || async { (words().len() >= n).then_some(()) }).await;
        let said = words();
        assert_eq!(said.len(), n, "said once, nothing else: {said:?}");
        said
    }
}

async fn inner() {
    let shots = PathBuf::from(std::env::var_os("TABLET_SCREENSHOT_DIR").expect("dir"));
    let logs = Logs {
        dir: tempfile::tempdir().expect("temp dir"),
    };
    let out = logs.dir.path().join("out");
    std::fs::create_dir_all(&out).expect("out dir");
    let ears = Ears::start(logs.dir.path());
    let bin = bin_dir();
    // The robot's own CA and a certificate for its name, as the package makes them at
    // install, and a browser profile home that trusts the CA.
    let tls = logs.dir.path().join("tls");
    let made = Command::new(env!("CARGO_BIN_EXE_tablet_tls"))
        .arg("--dir")
        .arg(&tls)
        .args([
            "init",
            "--only-names",
            "--name",
            ROBOT_HOST,
            "--name",
            "127.0.0.1",
        ])
        .output()
        .expect("tablet_tls runs");
    assert!(made.status.success(), "tablet_tls init: {made:?}");
    let home = logs.dir.path().join("home");
    home_trusting(&home, &tls.join("ca.crt"));
    let launch = Guard::spawn(
        "launch",
        Command::new(bin.join("launch"))
            .arg("launch_scripts/tablet_session.launch.yaml")
            .arg(format!("bin:={}", bin.display()))
            .arg(format!("out:={}", out.display()))
            .arg(format!("game_args:={GAME_ARGS}"))
            .arg(format!(
                "policy_args:=--param q_table_dir:={}/q_tables",
                out.display()
            ))
            .arg(format!(
                "bridge_args:=--param http_bind:=127.0.0.1:{HTTP_PORT} \
                 --param ws_max_dropped_before_close:=100 --param sessions_root:={out} \
                 --param tls_cert_file:={tls}/server.crt --param tls_key_file:={tls}/server.key",
                tls = tls.display(),
                out = out.display()
            ))
            .env("QT_TABLET_PIN", PIN)
            .stdout(logs.file("launch.out"))
            .stderr(logs.file("launch.err")),
    );
    let driver = Guard::spawn(
        "chromedriver",
        Command::new("chromedriver")
            .args([
                format!("--port={DRIVER_PORT}"),
                "--allowed-ips=127.0.0.1".into(),
            ])
            // Chromium (started by chromedriver) finds its NSS database under $HOME.
            .env("HOME", &home)
            .stdout(logs.file("chromedriver.log"))
            .stderr(Stdio::null()),
    );
    let ports = async {
        until("the bridge's HTTP port", WAIT, || async {
            port_open(HTTP_PORT).then_some(())
        })
        .await;
        until("chromedriver", WAIT, || async {
            port_open(DRIVER_PORT).then_some(())
        })
        .await;
    };
    let run = std::panic::AssertUnwindSafe(async {
        ports.await;
        session(&shots, &ears, &logs).await
    });
    let sessions = match futures::FutureExt::catch_unwind(run).await {
        Ok(s) => s,
        Err(panic) => {
            eprintln!("{}", logs.dump());
            std::panic::resume_unwind(panic);
        }
    };
    drop(driver);
    // Ctrl-C ends the launch: every node stops cleanly, the bag is closed.
    assert_eq!(
        launch.interrupt(Duration::from_secs(20)),
        Some(0),
        "launch exit\n{}",
        logs.dump()
    );
    assert!(out.join("session.mcap").is_file(), "{}", logs.dump());
    // The game manager's session files agree with what the pages showed.
    let summary = |id: &str| -> Value {
        let text = std::fs::read_to_string(out.join(format!("{id}.summary.json")))
            .unwrap_or_else(|e| panic!("summary of {id}: {e}\n{}", logs.dump()));
        serde_json::from_str(&text).expect("summary JSON")
    };
    let (played, score, max) = &sessions.played;
    let s = summary(played);
    assert_eq!(s["end"], "finished", "{s}");
    assert_eq!(s["sequences_played"], 10, "{s}");
    assert_eq!(s["correct"], 9, "{s}");
    assert_eq!((&s["score"], &s["max_score"]), (&json!(score), &json!(max)));
    // The therapist's own override and the two proposals replaced.
    assert_eq!(s["overrides"], 3, "{s}");
    assert_eq!(
        (
            &s["proposals"],
            &s["proposals_accepted"],
            &s["proposals_replaced"],
            &s["proposals_timed_out"]
        ),
        (&json!(9), &json!(6), &json!(2), &json!(1)),
        "{s}"
    );
    assert_eq!(s["policy_fallbacks"], 0, "{s}");
    assert_eq!(s["timeouts"], 0, "{s}");
    assert_eq!(
        s["rejected_answers"], 0,
        "nothing the bridge refused reached the game"
    );
    assert!(
        s["mean_engagement"].as_f64().is_some_and(|e| e > 0.5),
        "{s}"
    );
    let s = summary(&sessions.stopped);
    assert_eq!(s["end"], "emergency_stopped", "{s}");
    // Every refusal was logged by the bridge with its reason.
    let log = logs.read("launch.err");
    for reason in [
        "wrong PIN",
        "is not happy, disgusted, sad or angry",
        "too many messages",
        "cross-origin",
    ] {
        assert!(
            log.lines()
                .any(|l| l.starts_with("[tablet_bridge]") && l.contains(reason)),
            "bridge log lacks {reason:?}\n{}",
            logs.dump()
        );
    }
    ears.shell.stop().await;
    eprintln!("whole session: {}", axe_spent());
}

/// The two sessions the test played: the whole one (id, score, maximum score) and the one it
/// emergency-stopped.
struct Sessions {
    played: (String, i32, i32),
    stopped: String,
}

/// The phase the therapist page shows (the game's phase name).
async fn phase(page: &Page) -> String {
    let v = page
        .js(
            "return document.getElementById('phase').dataset.phase || '';",
            vec![],
        )
        .await;
    v.as_str().unwrap_or_default().to_string()
}

const RUNNING: [&str; 4] = [
    "deciding",
    "giving_feedback",
    "saying_sequence",
    "waiting_for_answer",
];

/// Starts a session from the therapist page for a child not on the list yet: its code added
/// (checked by the bridge) and chosen, the cluster only when given (under "Advanced"; none:
/// the policy's default). Clicked again if the very first command went out before DDS matched
/// the game manager's reader: commands are volatile.
async fn start_session(therapist: &Page, user: &str, cluster: Option<i32>) {
    therapist.type_into("#new-code", user).await;
    therapist.click("#add-child").await;
    therapist.wait_text("#chosen-code", user, WAIT).await;
    assert_eq!(
        therapist
            .count(&format!(
                "#children button[aria-pressed=true][data-user=\"{user}\"]"
            ))
            .await,
        1,
        "the new code is on the list, chosen"
    );
    if let Some(cluster) = cluster {
        therapist.click("#advanced summary").await;
        therapist.type_into("#cluster", &cluster.to_string()).await;
    }
    until(
        &format!("the session of {user} to start"),
        Duration::from_secs(60),
        || async {
            let running = RUNNING.contains(&phase(therapist).await.as_str());
            if running && therapist.text("#g-user").await.starts_with(user) {
                return Some(());
            }
            if therapist.count("#start:not([disabled])").await == 1 {
                therapist.click("#start").await;
                tokio::time::sleep(Duration::from_secs(2)).await;
            }
            None
        },
    )
    .await;
}

/// After both sessions: the list shows the two children the robot now knows (one session
/// each); the therapist picks the first, opens their progress (the whole session's score as
/// the page counted it, what the robot believes now: not available yet), prints it to A4 and
/// goes back to the session.
async fn progress_of_the_first_child(
    therapist: &Page,
    session_id: &str,
    score: i32,
    max: i32,
    shots: &Path,
) {
    let started = std::time::Instant::now();
    for child in ["child-7", "child-8"] {
        let row = format!("#children button[data-user=\"{child}\"] .meta");
        therapist.wait_text(&row, "1 session", WAIT).await;
    }
    therapist
        .click("#children button[data-user=\"child-7\"]")
        .await;
    therapist.wait_text("#chosen-code", "child-7", WAIT).await;
    therapist.resize(1280, 800).await;
    therapist.click("#show-progress").await;
    let article = "#progress article.progress[data-user=\"child-7\"][data-sessions=\"1\"]";
    therapist.wait_count(article, 1, WAIT).await;
    let row = format!("#progress tr[data-session=\"{session_id}\"] td.score");
    assert_eq!(therapist.text(&row).await, format!("{score} / {max}"));
    assert!(
        therapist
            .text("#progress .belief")
            .await
            .contains("Not available"),
        "what the robot believes now"
    );
    assert_eq!(therapist.count("#progress figure svg[role=img]").await, 2);
    therapist
        .screenshot(shots, "therapist_progress_1_session_1280x800")
        .await;
    therapist
        .assert_accessible("therapist, a child's progress (1 session), 1280x800")
        .await;
    let pdf = therapist
        .print_pdf(shots, "therapist_progress_1_session")
        .await;
    assert!(pdf.starts_with(b"%PDF"), "a PDF");
    therapist.click("#progress-back").await;
    therapist.wait_count("#columns:not(.hidden)", 1, WAIT).await;
    eprintln!(
        "whole session: the list, the progress and its PDF took {:.1} s",
        started.elapsed().as_secs_f64()
    );
}

/// The session the therapist page shows.
async fn session_shown(therapist: &Page) -> String {
    let label = therapist.text("#session-label").await;
    let id = label.rsplit(' ').next().unwrap_or_default().to_string();
    assert!(id.starts_with("tablet-"), "session label {label:?}");
    id
}

/// Waits until the child page offers `task`.
async fn wait_for_task_on_child(child: &Page, task: &TabletTask) {
    let id = task.sequence_id.to_string();
    until(&format!("child: task {id} on screen"), WAIT, || async {
        let v = child
            .js(
                "return document.body.classList.contains('answering') \
                     ? document.body.dataset.sequence : null;",
                vec![],
            )
            .await;
        (v.as_str() == Some(id.as_str())).then_some(())
    })
    .await;
    child
        .wait_count("#slots .slot", u64::from(task.length), WAIT)
        .await;
}

/// True while `page` shows its "offline" banner (its WebSocket is closed).
async fn offline(page: &Page) -> bool {
    page.js(
        "return !document.getElementById('offline').classList.contains('hidden');",
        vec![],
    )
    .await
        == json!(true)
}

/// The tablet bridge's pid, as the launcher last (re)started it.
fn bridge_pid(logs: &Logs) -> Option<String> {
    logs.read("launch.err").lines().rev().find_map(|l| {
        let rest = l
            .strip_prefix("[launch] started tablet_bridge (pid ")
            .or_else(|| l.strip_prefix("[launch] restarted tablet_bridge (pid "))?;
        rest.split(')').next().map(str::to_string)
    })
}

/// SIGKILLs the tablet bridge while the child's `task` is on screen: both pages show they
/// are offline; the launcher respawns the bridge; both pages reconnect by themselves (the
/// therapist page logs in again with the PIN it kept in memory), get the game back from the
/// respawned bridge (durable results and decisions, the latched task and state), and the
/// child finds the same task waiting, with nothing tapped lost to the game.
async fn bridge_killed_and_back(
    child: &Page,
    therapist: &Page,
    task: &TabletTask,
    logs: &Logs,
    shots: &Path,
) {
    let results_shown = therapist.count("#results tbody tr.result").await;
    let decisions_shown = therapist.count("#decisions tbody tr").await;
    let pid = bridge_pid(logs).unwrap_or_else(|| panic!("no bridge pid\n{}", logs.dump()));
    let killed = std::time::Instant::now();
    let status = Command::new("kill")
        .args(["-KILL", &pid])
        .status()
        .expect("kill");
    assert!(status.success(), "kill -KILL {pid}");
    until("both pages offline", WAIT, || async {
        (offline(child).await && offline(therapist).await).then_some(())
    })
    .await;
    let offline_after = killed.elapsed();
    child.screenshot(shots, "child_offline_800x1280").await;
    child.assert_accessible("child offline, 800x1280").await;
    until("the launcher restarted the bridge", WAIT, || async {
        bridge_pid(logs).filter(|p| *p != pid).map(|_| ())
    })
    .await;
    until("both pages back online", WAIT, || async {
        (!offline(child).await && !offline(therapist).await).then_some(())
    })
    .await;
    let online_after = killed.elapsed();
    wait_for_task_on_child(child, task).await;
    let task_after = killed.elapsed();
    // The game manager held the session while the bridge was lost and resumed it when the
    // bridge was back: the therapist page, logged in again, shows the game as it was.
    therapist.wait_text("#phase", "child answering", WAIT).await;
    therapist
        .wait_count("#results tbody tr.result", results_shown, WAIT)
        .await;
    therapist
        .wait_count("#decisions tbody tr", decisions_shown, WAIT)
        .await;
    eprintln!(
        "tablet_bridge SIGKILLed with task {} on the child page: both pages offline after \
         {:.1} s, online again after {:.1} s, the task back on the child page after {:.1} s; \
         the therapist page logged in again with {results_shown} results and \
         {decisions_shown} decisions",
        task.sequence_id,
        offline_after.as_secs_f64(),
        online_after.as_secs_f64(),
        task_after.as_secs_f64()
    );
}

/// Taps `emotions` on the child page (appending to what is tapped already).
async fn tap(child: &Page, emotions: &[String]) {
    let filled = "#slots .slot[data-emotion]";
    let before = child.count(filled).await;
    for e in emotions {
        child.click(&format!(".face[data-emotion={e}]")).await;
    }
    child
        .wait_count(filled, before + emotions.len() as u64, WAIT)
        .await;
}

/// The newest result row on the therapist page: class, level cell, said and tapped faces.
async fn newest_result(therapist: &Page) -> Value {
    therapist
        .js(
            "const r = document.querySelector('#results tbody tr');
             const faces = [...r.querySelectorAll('.pair .faces')].map(f =>
               [...f.querySelectorAll('img')].map(i => i.src.split('/').pop().replace('.svg', '')));
             return {class: r.className, index: r.cells[0].textContent,
                     level: r.cells[1].textContent, said: faces[0], tapped: faces[1]};",
            vec![],
        )
        .await
}

/// What the therapist does with a proposal on the page.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Reply {
    Accept,
    /// Nothing: the countdown runs out and the proposal is carried out.
    RunOut,
    /// Encourage (Challenge if encouraging is what the robot proposes).
    Feedback,
    /// Another level than the proposed one.
    Level,
}

/// What the therapist does with the policy's proposal for sequence `k`, if it is proposed.
fn reply_to(k: usize) -> Option<Reply> {
    match k {
        _ if k == OVERRIDE_AT + 1 => None,
        RUN_OUT_AT => Some(Reply::RunOut),
        REPLACED_BY_FEEDBACK_AT => Some(Reply::Feedback),
        REPLACED_BY_LEVEL_AT => Some(Reply::Level),
        _ => Some(Reply::Accept),
    }
}

/// The seconds the proposal card's countdown shows.
async fn countdown_shown(therapist: &Page) -> f64 {
    let text = therapist.text("#proposal-countdown").await;
    let number = text.split_whitespace().next().unwrap_or_default();
    number
        .parse()
        .unwrap_or_else(|_| panic!("countdown {text:?}"))
}

/// The proposal card's buttons: (id, disabled).
async fn proposal_buttons(therapist: &Page) -> Vec<(String, bool)> {
    let v = therapist
        .js(
            "return [...document.querySelectorAll('#proposal button')].map(b => [b.id, b.disabled]);",
            vec![],
        )
        .await;
    serde_json::from_value(v).expect("buttons")
}

/// The policy's proposal for sequence `k` appears on the therapist page (in words, with its
/// reason and a countdown), the therapist answers it with `reply`, the page shows what became
/// of it, and the game manager says over DDS that it settled as the page did (status, what
/// plays, the command that settled it). Returns the settled message.
async fn answer_proposal(
    therapist: &Page,
    child: &Page,
    ears: &Ears,
    session: &str,
    k: usize,
    reply: Reply,
    shots: &Path,
) -> ActionProposal {
    let step = k as u8;
    let open = format!("#proposal.open[data-step=\"{k}\"][data-status=proposed]");
    therapist.wait_count(&open, 1, WAIT).await;
    let proposed = ears.proposal(session, step, ActionProposal::PROPOSED).await;
    assert_eq!(proposed.countdown, COUNTDOWN_S, "{proposed:?}");
    let what = therapist.text("#proposal-what").await;
    let repeat = if proposed.action >= 3 { " again" } else { "" };
    assert!(
        what.starts_with(&format!("Sequence {k}: Level {}{repeat}, ", proposed.level)),
        "{what} vs {proposed:?}"
    );
    let why = therapist.text("#proposal-why").await;
    assert!(
        why.contains(&proposed.reason) && why.contains("T "),
        "{why}"
    );
    // Feedback repeats the level: not offered on the first sequence.
    for (id, disabled) in proposal_buttons(therapist).await {
        let feedback = id == "proposal-encourage" || id == "proposal-challenge";
        assert_eq!(disabled, k == 1 && feedback, "{id} at sequence {k}");
    }
    if k == 1 {
        therapist
            .screenshot(shots, "therapist_proposal_1280x800")
            .await;
        therapist
            .assert_accessible("therapist, a proposal open, 1280x800")
            .await;
    }
    if k == 7 {
        therapist
            .screenshot(shots, "therapist_proposal_800x1280")
            .await;
    }
    // (button, status, what the card then says, the command it sends: code and level)
    let (button, status, outcome, command) = match reply {
        Reply::Accept => (
            Some("#proposal-accept".to_string()),
            ActionProposal::ACCEPTED,
            "Accepted: ",
            Some((TherapistCommand::ACCEPT_PROPOSAL, 0)),
        ),
        Reply::RunOut => (None, ActionProposal::TIMED_OUT, "Ran out: ", None),
        Reply::Feedback if proposed.action == 3 => (
            Some("#proposal-challenge".into()),
            ActionProposal::REPLACED,
            "Replaced by ",
            Some((TherapistCommand::OVERRIDE_CHALLENGING, 0)),
        ),
        Reply::Feedback => (
            Some("#proposal-encourage".into()),
            ActionProposal::REPLACED,
            "Replaced by ",
            Some((TherapistCommand::OVERRIDE_ENCOURAGING, 0)),
        ),
        Reply::Level => {
            let level = if proposed.level == 1 { 2 } else { 1 };
            (
                Some(format!("#proposal-level-{level}")),
                ActionProposal::REPLACED,
                "Replaced by ",
                Some((TherapistCommand::OVERRIDE_LEVEL, level)),
            )
        }
    };
    match &button {
        Some(b) => therapist.click(b).await,
        None => run_out(therapist, child, ears, &proposed).await,
    }
    let settled_card = format!(
        "#proposal:not(.open)[data-step=\"{k}\"][data-status={}]",
        status_name(status)
    );
    therapist.wait_count(&settled_card, 1, WAIT).await;
    therapist
        .wait_text("#proposal-outcome", outcome, WAIT)
        .await;
    assert!(
        proposal_buttons(therapist).await.iter().all(|(_, d)| *d),
        "every button is disabled once it is settled"
    );
    if k == REPLACED_BY_FEEDBACK_AT {
        therapist
            .screenshot(shots, "therapist_proposal_replaced_1280x800")
            .await;
    }

    let settled = ears.proposal(session, step, status).await;
    let played = (
        settled.played_action,
        settled.played_level,
        settled.played_feedback,
    );
    let response = f64::from(settled.response_time);
    match command {
        None => {
            assert_eq!(played, (proposed.action, proposed.level, proposed.feedback));
            assert_eq!(settled.command_id, 0);
            assert!(response >= 0.95 * f64::from(COUNTDOWN_S), "{settled:?}");
        }
        Some((code, level)) => {
            let sent = ears.with(|h| {
                h.commands
                    .iter()
                    .find(|c| c.session_id == session && c.command_id == settled.command_id)
                    .cloned()
            });
            let sent = sent.unwrap_or_else(|| panic!("no command {}", settled.command_id));
            assert_eq!((sent.command, sent.level), (code, level), "{settled:?}");
            assert!(response < f64::from(COUNTDOWN_S), "{settled:?}");
            let expected = match code {
                TherapistCommand::ACCEPT_PROPOSAL => {
                    (proposed.action, proposed.level, proposed.feedback)
                }
                // Feedback repeats the level the state holds.
                TherapistCommand::OVERRIDE_ENCOURAGING => (3, proposed.state.level, 1),
                TherapistCommand::OVERRIDE_CHALLENGING => (4, proposed.state.level, 2),
                _ => (level - 1, level, 0),
            };
            assert_eq!(played, expected, "{settled:?}");
        }
    }
    // The card named what plays.
    let shown = therapist.text("#proposal-outcome").await;
    assert!(
        shown.contains(&format!("Level {}", settled.played_level)),
        "{shown} vs {settled:?}"
    );
    settled
}

/// The proposal's status as the page names it.
fn status_name(status: u8) -> &'static str {
    match status {
        ActionProposal::PROPOSED => "proposed",
        ActionProposal::ACCEPTED => "accepted",
        ActionProposal::REPLACED => "replaced",
        ActionProposal::TIMED_OUT => "timed_out",
        _ => "withdrawn",
    }
}

/// Lets `proposed` run out: the page counts down on the tablet's clock; a therapist page
/// logging in meanwhile gets it with the seconds left; the child page gets nothing of it (a
/// child socket open from now until after it ran out).
async fn run_out(therapist: &Page, child: &Page, ears: &Ears, proposed: &ActionProposal) {
    let first = countdown_shown(therapist).await;
    assert!(
        first > 0.0 && first <= f64::from(COUNTDOWN_S),
        "countdown {first}"
    );
    // Open until 2.5 s after the countdown the page shows (rounded up) ran out.
    let window_ms = (first * 1000.0) as u64 + 2500;
    let child_socket = child.raw_socket("/ws/child", vec![], window_ms);
    let therapist_side = async {
        tokio::time::sleep(Duration::from_millis(2500)).await;
        let later = countdown_shown(therapist).await;
        assert!(later < first && later > 0.0, "{first} s then {later} s");
        let got = therapist
            .raw_socket(
                "/ws/therapist",
                vec![json!({"type": "login", "pin": PIN})],
                800,
            )
            .await;
        let p = got
            .iter()
            .find(|m| m["type"] == "proposal")
            .unwrap_or_else(|| panic!("no proposal after login: {got:?}"));
        assert_eq!(
            (&p["step"], &p["open"]),
            (&json!(proposed.step), &json!(true))
        );
        let left = p["remaining"].as_f64().expect("remaining");
        assert!(
            left > 0.0 && left < f64::from(COUNTDOWN_S) - 2.0,
            "{left} s left"
        );
    };
    let (child_got, ()) = tokio::join!(child_socket, therapist_side);
    let timed_out = ears.with(|h| {
        h.proposals.iter().any(|p| {
            p.session_id == proposed.session_id
                && p.step == proposed.step
                && p.status == ActionProposal::TIMED_OUT
        })
    });
    assert!(timed_out, "ran out while the child socket was open");
    assert!(
        child_got.iter().any(|m| m["type"] == "game"),
        "{child_got:?}"
    );
    assert!(
        !child_got
            .iter()
            .any(|m| m["type"] == "proposal" || m.to_string().contains(&proposed.reason)),
        "the child page got a proposal: {child_got:?}"
    );
}

/// Bad input from both pages while task `current` is open (`previous` was answered with
/// `said`): every message refused with its reason, nothing published.
async fn refuse_bad_input(
    child: &Page,
    therapist: &Page,
    previous: &TabletTask,
    said: &[String],
    current: &TabletTask,
) {
    let (old, now, n) = (
        previous.sequence_id,
        current.sequence_id,
        usize::from(current.length),
    );
    let mut unknown = vec!["happy", "joy"];
    unknown.resize(n, "sad");
    let bad = vec![
        json!({"type": "answer", "sequence_id": old, "answer": said, "response_time": 1.0}),
        json!({"type": "answer", "sequence_id": now, "answer": unknown, "response_time": 1.0}),
        json!({"type": "answer", "sequence_id": now, "answer": ["happy"], "response_time": 1.0}),
        json!("{not json"),
        json!("x".repeat(5000)),
        json!({"type": "command", "pin": PIN, "command": "stop"}),
    ];
    let got = child.raw_socket("/ws/child", bad, 1500).await;
    let reasons: Vec<String> = got
        .iter()
        .filter(|m| m["type"] == "rejected")
        .filter_map(|m| m["reason"].as_str().map(String::from))
        .collect();
    let expected = [
        format!("this answer is for sequence {old}, but the current task is sequence {now}"),
        r#"answer[1] = "joy" is not happy, disgusted, sad or angry"#.into(),
        format!("answer has 1 emotions, the task asked for {n}"),
        "not a valid message".into(),
        "message of 5000 bytes is over the limit of 4096 bytes".into(),
        "the child page cannot send commands".into(),
    ];
    assert_eq!(reasons.len(), expected.len(), "{got:?}");
    for (r, e) in reasons.iter().zip(&expected) {
        assert!(r.starts_with(e.as_str()), "{r} vs {e}");
    }

    // A WebSocket flood: dropped with a notice, then the connection is closed.
    let flood =
        vec![json!({"type": "answer", "sequence_id": now, "answer": [], "response_time": 0}); 400];
    let got = child.raw_socket("/ws/child", flood, 2000).await;
    assert!(
        got.iter().any(|m| m["reason"]
            .as_str()
            .is_some_and(|r| r.starts_with("too many messages"))),
        "{got:?}"
    );
    assert!(
        got.iter()
            .any(|m| m["type"] == "closed" && m["code"] == 1008),
        "{got:?}"
    );

    // Commands without the right PIN, from a connection that is not logged in, and after it.
    let got = therapist
        .raw_socket(
            "/ws/therapist",
            vec![
                json!({"type": "command", "pin": PIN, "command": "stop"}),
                json!({"type": "login", "pin": "0000"}),
                json!({"type": "login", "pin": PIN}),
                json!({"type": "command", "pin": "9999", "command": "stop"}),
                json!({"type": "command", "pin": PIN, "command": "override_level", "level": 9}),
            ],
            1000,
        )
        .await;
    let reasons: Vec<&str> = got
        .iter()
        .filter(|m| m["type"] == "rejected")
        .filter_map(|m| m["reason"].as_str())
        .collect();
    assert_eq!(
        reasons,
        [
            "log in with the PIN first",
            "wrong PIN",
            "wrong PIN",
            "level = 9 is outside 1..=3"
        ],
        "{got:?}"
    );
}

async fn session(shots: &Path, ears: &Ears, logs: &Logs) -> Sessions {
    let base = format!("https://{ROBOT_HOST}:{HTTP_PORT}");
    let tls = logs.dir.path().join("tls");
    // A page elsewhere, or this host over plain http, cannot open the tablets' WebSocket.
    for origin in [
        "https://evil.example".to_string(),
        format!("http://{ROBOT_HOST}:{HTTP_PORT}"),
    ] {
        let forged = raw_https(
            HTTP_PORT,
            &tls,
            &format!(
                "GET /ws/therapist HTTP/1.1\r\nHost: {ROBOT_HOST}:{HTTP_PORT}\r\nOrigin: {origin}\r\n\
                 Connection: Upgrade\r\nUpgrade: websocket\r\nSec-WebSocket-Version: 13\r\n\
                 Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n"
            ),
        )
        .await;
        assert!(forged.starts_with("HTTP/1.1 403"), "{origin}: {forged}");
    }
    for path in ["/child", "/therapist"] {
        let page = raw_https(
            HTTP_PORT,
            &tls,
            &format!("GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"),
        )
        .await;
        assert!(
            page.contains("content-security-policy: default-src 'none'")
                && page.contains("strict-transport-security: max-age="),
            "{path}: {page}"
        );
    }

    let profiles = tempfile::tempdir().expect("profiles");
    let therapist = Page::open(
        "therapist",
        DRIVER_PORT,
        &profiles.path().join("t"),
        (1280, 800),
    )
    .await;
    let child = Page::open(
        "child",
        DRIVER_PORT,
        &profiles.path().join("c"),
        (1280, 800),
    )
    .await;

    // The therapist page asks for the PIN; a wrong one is refused with the reason.
    therapist
        .client
        .goto(&format!("{base}/therapist"))
        .await
        .expect("goto");
    therapist.wait_text("#login", "Unlock", WAIT).await;
    // Over HTTPS with the CA trusted: a secure page, no warning of an unencrypted link.
    let secure = therapist
        .js(
            "return [location.protocol, window.isSecureContext];",
            vec![],
        )
        .await;
    assert_eq!(secure, json!(["https:", true]));
    assert_eq!(therapist.count("#unencrypted.hidden").await, 1);
    therapist
        .screenshot(shots, "therapist_login_1280x800")
        .await;
    therapist
        .assert_accessible("therapist login, 1280x800")
        .await;
    therapist.type_into("#pin", "1111").await;
    therapist.click("#login").await;
    therapist.wait_text("#login-error", "wrong PIN", WAIT).await;
    therapist.type_into("#pin", PIN).await;
    therapist.click("#login").await;
    // The game manager announces itself (transient-local IDLE) once the policy serves.
    therapist.wait_text("#phase", "idle", STARTUP).await;
    // A fresh install: no child is stored yet, and a session cannot start without one.
    therapist
        .wait_text(
            "#children-empty",
            "No child has played on this robot yet",
            WAIT,
        )
        .await;
    assert_eq!(therapist.count("#start[disabled]").await, 1);
    therapist
        .assert_accessible("therapist idle, no child yet, 1280x800")
        .await;

    child
        .client
        .goto(&format!("{base}/child"))
        .await
        .expect("goto");
    child.wait_text("#prompt", "Listen to QT", WAIT).await;
    child.assert_accessible("child waiting, 1280x800").await;

    // The child picked, no cluster typed: the policy's default plays (-1 in the command).
    start_session(&therapist, "child-7", None).await;
    let session_id = session_shown(&therapist).await;
    let start = ears.with(|h| {
        h.commands
            .iter()
            .find(|c| c.command == TherapistCommand::START && c.session_id == session_id)
            .cloned()
    });
    assert_eq!(
        start.map(|c| (c.user_id, c.user_model_cluster)),
        Some(("child-7".to_string(), -1))
    );
    therapist
        .wait_text("#g-user", "child-7 (default cluster)", WAIT)
        .await;
    let mut tasks: Vec<(TabletTask, Vec<String>)> = Vec::new();
    let (mut score, mut max) = (0i32, 0i32);
    for k in 1..=10 {
        let settled = match reply_to(k) {
            Some(reply) => {
                let p = answer_proposal(&therapist, &child, ears, &session_id, k, reply, shots);
                Some(p.await)
            }
            None => None,
        };
        let task = ears.task(Some(&session_id), k).await;
        if let Some(p) = &settled {
            assert_eq!(
                usize::from(task.length),
                2 * usize::from(p.played_level) + 1,
                "sequence {k} plays what the proposal settled on: {p:?}"
            );
        }
        wait_for_task_on_child(&child, &task).await;
        let said = ears.said(&task).await;
        if k == 6 {
            // The rest of the session in portrait, as a tablet held upright.
            therapist.resize(800, 1280).await;
            child.resize(800, 1280).await;
        }
        if k == OVERRIDE_AT {
            let (previous, previous_said) = &tasks[0];
            refuse_bad_input(&child, &therapist, previous, previous_said, &task).await;
            // Pause, override the next level and resume from the therapist page.
            therapist.click("#pause").await;
            therapist.wait_text("#phase", "paused", WAIT).await;
            child.wait_text("#prompt", "Pause", WAIT).await;
            child.assert_accessible("child paused, 1280x800").await;
            therapist
                .assert_accessible("therapist paused, 1280x800")
                .await;
            therapist.click("#override-3").await;
            therapist.wait_text("#g-status", "set to L3", WAIT).await;
            therapist.click("#resume").await;
            therapist.wait_text("#phase", "child answering", WAIT).await;
            wait_for_task_on_child(&child, &task).await;
        }
        if k == BRIDGE_KILLED_AT {
            bridge_killed_and_back(&child, &therapist, &task, logs, shots).await;
        }
        let tapped: Vec<String> = if k == WRONG_AT {
            // The first emotion swapped for another one: a wrong answer.
            let mut t = said.clone();
            let other = EMOTIONS.iter().find(|e| **e != said[0]).expect("another");
            t[0] = other.to_string();
            t
        } else {
            said.clone()
        };
        if k == 1 {
            tap(&child, &tapped[..2]).await;
            child.screenshot(shots, "child_task_partial_1280x800").await;
            child.assert_accessible("child answering, 1280x800").await;
            tap(&child, &tapped[2..]).await;
            child.screenshot(shots, "child_task_filled_1280x800").await;
        } else if k == 6 {
            // Back takes the last tap away.
            tap(&child, &tapped[..1]).await;
            child.click(".face[data-emotion=sad]").await;
            child.screenshot(shots, "child_task_800x1280").await;
            child.click("#undo").await;
            child
                .wait_count("#slots .slot[data-emotion]", 1, WAIT)
                .await;
            tap(&child, &tapped[1..]).await;
        } else {
            tap(&child, &tapped).await;
        }
        child.click("#done").await;

        // The therapist sees the result: what was said above what was tapped, right or wrong.
        therapist
            .wait_count("#results tbody tr.result", k as u64, WAIT)
            .await;
        let row = newest_result(&therapist).await;
        let right = k != WRONG_AT;
        let level = (usize::from(task.length) - 1) / 2;
        assert_eq!(row["index"], json!(k.to_string()), "{row}");
        assert!(
            row["class"].as_str().is_some_and(|c| c.ends_with(if right {
                " right"
            } else {
                " wrong"
            })),
            "{row}"
        );
        assert_eq!(
            (&row["said"], &row["tapped"]),
            (&json!(said), &json!(tapped))
        );
        let replaced = settled
            .as_ref()
            .is_some_and(|p| p.status == ActionProposal::REPLACED);
        let overridden = k == OVERRIDE_AT + 1 || replaced;
        let level_cell = if overridden {
            format!("{level} *")
        } else {
            level.to_string()
        };
        assert_eq!(row["level"], json!(level_cell), "{row}");
        if k == OVERRIDE_AT + 1 {
            assert_eq!(level, 3, "the therapist's override beats the policy");
        }
        let l = level as i32;
        score += if right { l } else { -l };
        max += l;
        therapist
            .wait_text("#g-total", &format!("{score} / {max}"), WAIT)
            .await;
        if k == 1 {
            therapist.screenshot(shots, "therapist_1280x800").await;
            therapist
                .assert_accessible("therapist, a session running, 1280x800")
                .await;
        }
        tasks.push((task, said));
    }
    child.wait_text("#prompt", "All done", WAIT).await;
    therapist.wait_text("#phase", "finished", WAIT).await;
    // The camera's faces reached the page through the real classifier: the trend has points.
    until("engagement points on the chart", WAIT, || async {
        (therapist.count("#chart circle.mean").await >= 2).then_some(())
    })
    .await;
    // The person looks at the robot: the sequences whose talk held a whole second of frames
    // (not all at 20x speed) show a high engagement.
    let e = therapist
        .js(
            "return [...document.querySelectorAll('#results tbody tr')].map(r => r.cells[4].textContent);",
            vec![],
        )
        .await;
    let e: Vec<String> = serde_json::from_value(e).expect("E column");
    assert!(
        e.iter().any(|v| v.parse::<f64>().is_ok_and(|v| v > 0.5)),
        "E per sequence, newest first: {e:?}"
    );
    child.screenshot(shots, "child_finished_800x1280").await;
    therapist.screenshot(shots, "therapist_800x1280").await;
    child.assert_accessible("child finished, 800x1280").await;
    therapist
        .assert_accessible("therapist, the session finished, 800x1280")
        .await;

    // Exactly the ten real answers crossed, as tapped.
    let answers = ears.with(|h| h.answers.clone());
    assert_eq!(
        answers.iter().map(|a| a.sequence_id).collect::<Vec<_>>(),
        tasks.iter().map(|(t, _)| t.sequence_id).collect::<Vec<_>>()
    );
    // Every decision of the policy is on the page with its five Q-values; the overridden
    // sequence was not decided by the policy.
    let decisions: Vec<Decision> = ears.with(|h| {
        h.decisions
            .iter()
            .filter(|d| d.session_id == session_id)
            .cloned()
            .collect()
    });
    let mut steps: Vec<u8> = decisions.iter().map(|d| d.step).collect();
    steps.sort_unstable();
    assert_eq!(steps, [1, 2, 4, 5, 6, 7, 8, 9, 10]);
    let rows = therapist
        .js(
            "return [...document.querySelectorAll('#decisions tbody tr')].map(r =>
               [Number(r.cells[0].textContent),
                [...r.querySelectorAll('.q span')].map(s => Number(s.textContent))]);",
            vec![],
        )
        .await;
    let rows: Vec<(u8, Vec<f64>)> = serde_json::from_value(rows).expect("decision rows");
    assert_eq!(rows.len(), decisions.len(), "{rows:?}");
    for (step, shown) in rows {
        let d = decisions
            .iter()
            .find(|d| d.step == step)
            .expect("a decision");
        assert_eq!(shown.len(), 5, "five Q-values per decision");
        for (s, q) in shown.iter().zip(&d.q_values) {
            assert!((s - q).abs() <= 0.0051, "step {step}: {s} vs {q}");
        }
    }

    // Every decision of the policy was proposed once and settled once; the sequence the
    // therapist had set was not proposed.
    let proposals: Vec<(u8, u8)> = ears.with(|h| {
        h.proposals
            .iter()
            .filter(|p| p.session_id == session_id)
            .map(|p| (p.step, p.status))
            .collect()
    });
    for step in 1..=10u8 {
        let of_step: Vec<u8> = proposals
            .iter()
            .filter(|(s, _)| *s == step)
            .map(|(_, status)| *status)
            .collect();
        let expected = match reply_to(usize::from(step)) {
            None => vec![],
            Some(Reply::Accept) => vec![ActionProposal::PROPOSED, ActionProposal::ACCEPTED],
            Some(Reply::RunOut) => vec![ActionProposal::PROPOSED, ActionProposal::TIMED_OUT],
            Some(_) => vec![ActionProposal::PROPOSED, ActionProposal::REPLACED],
        };
        assert_eq!(of_step, expected, "sequence {step}: {proposals:?}");
    }

    // A second session, emergency-stopped while its first proposal waits: the robot goes
    // silent at once (an empty utterance, then nothing), the proposal is withdrawn, and the
    // page shows both.
    // Another child with a cluster chosen under "Advanced".
    start_session(&therapist, "child-8", Some(1)).await;
    let stopped = session_shown(&therapist).await;
    assert_ne!(stopped, session_id);
    therapist
        .wait_count("#proposal.open[data-step=\"1\"]", 1, WAIT)
        .await;
    ears.proposal(&stopped, 1, ActionProposal::PROPOSED).await;
    let before = ears.with(|h| h.utterances.len());
    therapist.click("#estop").await;
    therapist
        .wait_text("#phase", "EMERGENCY STOPPED", WAIT)
        .await;
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let after: Vec<String> = ears.with(|h| h.utterances[before..].to_vec());
    let silent = after.iter().position(String::is_empty);
    assert!(
        silent.is_some_and(|i| i + 1 == after.len()),
        "after the emergency stop: {after:?}"
    );
    ears.proposal(&stopped, 1, ActionProposal::WITHDRAWN).await;
    therapist
        .wait_count("#proposal[data-step=\"1\"][data-status=withdrawn]", 1, WAIT)
        .await;
    therapist
        .wait_text("#proposal-outcome", "Withdrawn", WAIT)
        .await;
    therapist
        .screenshot(shots, "therapist_emergency_stopped_800x1280")
        .await;
    therapist
        .assert_accessible("therapist emergency-stopped, proposal withdrawn, 800x1280")
        .await;
    progress_of_the_first_child(&therapist, &session_id, score, max, shots).await;

    for page in [therapist, child] {
        let _ = page.client.close().await;
    }
    Sessions {
        played: (session_id, score, max),
        stopped,
    }
}
