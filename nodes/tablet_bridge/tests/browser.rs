//! The two tablets in a real headless Chromium, against the real `tablet_bridge` binary over
//! real DDS. The game side is `tablet_game_peer`, a TEST TOOL of this crate (fixed sequences,
//! fixed Q-values) standing in for the game manager. Everything runs inside one private
//! loopback-only network namespace: the test re-runs itself in there.
//!
//! Needs Debian's `chromium` and `chromium-driver`; skips with a message where they are absent.
//! Screenshots land in target/tablet_bridge_screenshots/ (or $TABLET_SCREENSHOT_DIR).

mod support;

use serde_json::json;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;
use support::*;

const INNER: &str = "TABLET_BROWSER_TEST_INNER";
const HTTP_PORT: u16 = 18080;
const DRIVER_PORT: u16 = 19515;
const PIN: &str = "2468";
const WAIT: Duration = Duration::from_secs(30);

#[test]
fn therapist_starts_a_session_the_child_answers_and_bad_input_is_refused() {
    if std::env::var_os(INNER).is_some() {
        let runtime = tokio::runtime::Runtime::new().expect("tokio runtime");
        runtime.block_on(inner());
        return;
    }
    if which("chromium").is_none() || which("chromedriver").is_none() {
        eprintln!(
            "skipping: chromium and chromedriver are not installed \
             (apt-get update && apt-get install -y chromium chromium-driver)"
        );
        return;
    }
    if !can_make_network_namespace() {
        eprintln!("skipping: this machine cannot create a network namespace");
        return;
    }
    let shots = std::env::var_os("TABLET_SCREENSHOT_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("target/tablet_bridge_screenshots"));
    std::fs::create_dir_all(&shots).expect("screenshot dir");
    let exe = std::env::current_exe().expect("test binary");
    let out = Command::new(workspace_root().join("tests/loopback-netns"))
        .args(["timeout", "--signal=KILL", "300"])
        .arg(exe)
        .args([
            "--exact",
            "therapist_starts_a_session_the_child_answers_and_bad_input_is_refused",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(INNER, "1")
        .env("TABLET_SCREENSHOT_DIR", &shots)
        .current_dir(workspace_root())
        .output()
        .expect("running the test inside tests/loopback-netns");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "inside the namespace:\n{stdout}\n{stderr}"
    );
    eprintln!("browser test passed; screenshots in {}", shots.display());
}

async fn inner() {
    let shots = PathBuf::from(std::env::var_os("TABLET_SCREENSHOT_DIR").expect("dir"));
    let logs = Logs {
        dir: tempfile::tempdir().expect("temp dir"),
    };
    let params = logs.dir.path().join("tablet_bridge.yaml");
    std::fs::write(
        &params,
        format!(
            "tablet_bridge:\n  ros__parameters:\n    http_bind: \"127.0.0.1:{HTTP_PORT}\"\n    \
             pin: \"{PIN}\"\n    language: \"en\"\n    ws_max_dropped_before_close: 100\n"
        ),
    )
    .expect("params");
    let peer = Guard::spawn(
        "tablet_game_peer",
        Command::new(env!("CARGO_BIN_EXE_tablet_game_peer"))
            .args([
                "--params-file",
                "nodes/tablet_bridge/tests/params/tablet_game_peer.yaml",
            ])
            .env("ROS_LOCALHOST_ONLY", "1")
            .stdout(logs.file("peer.out"))
            .stderr(logs.file("peer.err")),
    );
    let bridge = Guard::spawn(
        "tablet_bridge",
        Command::new(env!("CARGO_BIN_EXE_tablet_bridge"))
            .arg("--params-file")
            .arg(&params)
            .env("ROS_LOCALHOST_ONLY", "1")
            .env_remove("QT_TABLET_PIN")
            .stdout(Stdio::null())
            .stderr(logs.file("bridge.err")),
    );
    let driver = Guard::spawn(
        "chromedriver",
        Command::new("chromedriver")
            .args([
                format!("--port={DRIVER_PORT}"),
                "--allowed-ips=127.0.0.1".into(),
            ])
            .stdout(logs.file("chromedriver.log"))
            .stderr(Stdio::null()),
    );
    until("the bridge's HTTP port", WAIT, || async {
        port_open(HTTP_PORT).then_some(())
    })
    .await;
    until("chromedriver", WAIT, || async {
        port_open(DRIVER_PORT).then_some(())
    })
    .await;

    let run = std::panic::AssertUnwindSafe(session(&shots, &logs));
    let result = futures::FutureExt::catch_unwind(run).await;
    if let Err(panic) = result {
        eprintln!("{}", logs.dump());
        std::panic::resume_unwind(panic);
    }
    drop(driver);
    assert_eq!(
        bridge.interrupt(Duration::from_secs(10)),
        Some(0),
        "bridge exit\n{}",
        logs.dump()
    );
    assert_eq!(
        peer.interrupt(Duration::from_secs(10)),
        Some(0),
        "peer exit\n{}",
        logs.dump()
    );
    // Every refusal was logged by the bridge with its reason.
    let log = logs.read("bridge.err");
    for reason in [
        "wrong PIN",
        "is not one of happy",
        "too many messages",
        "cross-origin",
    ] {
        assert!(log.contains(reason), "bridge log lacks {reason:?}\n{log}");
    }
}

async fn session(shots: &std::path::Path, logs: &Logs) {
    let base = format!("http://127.0.0.1:{HTTP_PORT}");
    // A page elsewhere cannot open the tablets' WebSocket.
    let forged = raw_http(
        HTTP_PORT,
        &format!(
            "GET /ws/therapist HTTP/1.1\r\nHost: 127.0.0.1:{HTTP_PORT}\r\nOrigin: http://evil.example\r\n\
             Connection: Upgrade\r\nUpgrade: websocket\r\nSec-WebSocket-Version: 13\r\n\
             Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n"
        ),
    );
    assert!(forged.starts_with("HTTP/1.1 403"), "{forged}");
    let page = raw_http(
        HTTP_PORT,
        "GET /child HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n",
    );
    assert!(
        page.contains("content-security-policy: default-src 'none'"),
        "{page}"
    );

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
    therapist
        .screenshot(shots, "therapist_login_1280x800")
        .await;
    therapist.type_into("#pin", "1111").await;
    therapist.click("#login").await;
    therapist.wait_text("#login-error", "wrong PIN", WAIT).await;
    therapist.type_into("#pin", PIN).await;
    therapist.click("#login").await;
    // The peer's transient-local IDLE state reaches the page once DDS discovery is done.
    therapist.wait_text("#phase", "idle", WAIT).await;

    child
        .client
        .goto(&format!("{base}/child"))
        .await
        .expect("goto");
    child.wait_text("#prompt", "Listen to QT", WAIT).await;

    // Start a session from the therapist page (clicked again if the very first command went
    // out before DDS matched the peer's reader: commands are volatile).
    therapist.type_into("#user-id", "child-7").await;
    therapist.type_into("#cluster", "0").await;
    until("the session to start", Duration::from_secs(60), || async {
        if therapist.text("#phase").await.contains("child answering") {
            return Some(());
        }
        if therapist.count("#start:not([disabled])").await == 1 {
            therapist.click("#start").await;
        }
        tokio::time::sleep(Duration::from_secs(2)).await;
        None
    })
    .await;
    assert!(therapist.text("#toast").await.contains("start"));
    let starts = logs.events("peer.out", "command");
    let session_id = starts
        .last()
        .map(|c| c["session_id"].clone())
        .expect("a start");
    assert_eq!(
        starts
            .last()
            .map(|c| (c["user_id"].clone(), c["cluster"].clone())),
        Some((json!("child-7"), json!(0)))
    );

    // The child taps the sequence the "robot" said and submits it.
    child.wait_count("#slots .slot", 3, WAIT).await;
    let said = logs.events("peer.out", "task");
    let said: Vec<String> = serde_json::from_value(said[0]["sequence"].clone()).expect("sequence");
    child
        .click(&format!(".face[data-emotion={}]", said[0]))
        .await;
    child
        .click(&format!(".face[data-emotion={}]", said[1]))
        .await;
    child.screenshot(shots, "child_task_partial_1280x800").await;
    child
        .click(&format!(".face[data-emotion={}]", said[2]))
        .await;
    child
        .wait_count("#slots .slot[data-emotion]", 3, WAIT)
        .await;
    child.screenshot(shots, "child_task_filled_1280x800").await;
    child.click("#done").await;

    // The therapist sees the result, the decisions with their Q-values, and the next task
    // opens on the child page.
    therapist
        .wait_count("#results tbody tr.result.right", 1, WAIT)
        .await;
    therapist.wait_count("#decisions tbody tr", 2, WAIT).await;
    assert_eq!(
        therapist.count("#decisions tbody tr .q").await,
        10,
        "five Q-values per decision"
    );
    assert!(therapist.text("#decisions tbody tr").await.contains("0.61"));
    child.wait_count("#slots .slot", 5, WAIT).await;
    until("engagement points on the chart", WAIT, || async {
        (therapist.count("#chart circle.mean").await >= 2).then_some(())
    })
    .await;
    therapist.screenshot(shots, "therapist_1280x800").await;
    child.screenshot(shots, "child_next_task_1280x800").await;
    therapist.resize(800, 1280).await;
    child.resize(800, 1280).await;
    child.click(".face[data-emotion=sad]").await;
    therapist.screenshot(shots, "therapist_800x1280").await;
    child.screenshot(shots, "child_task_800x1280").await;
    child.click("#undo").await;

    // Bad input from a child tablet: all refused with a reason, none published.
    let good1: Vec<&str> = said.iter().map(String::as_str).collect();
    let bad = vec![
        json!({"type": "answer", "sequence_id": 1, "answer": good1, "response_time": 1.0}),
        json!({"type": "answer", "sequence_id": 2, "answer": ["happy", "joy", "sad", "sad", "sad"], "response_time": 1.0}),
        json!({"type": "answer", "sequence_id": 2, "answer": ["happy"], "response_time": 1.0}),
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
        "this answer is for sequence 1, but the current task is sequence 2",
        r#"answer[1] = "joy" is not one of happy, disgusted, sad, angry"#,
        "the answer has 1 emotions, the task asks for 5",
        "not a valid message",
        "message of 5000 bytes is over the limit of 4096 bytes",
        "the child page cannot send commands",
    ];
    assert_eq!(reasons.len(), expected.len(), "{got:?}");
    for (r, e) in reasons.iter().zip(expected) {
        assert!(r.starts_with(e), "{r} vs {e}");
    }

    // A WebSocket flood: dropped with a notice, then the connection is closed.
    let flood =
        vec![json!({"type": "answer", "sequence_id": 2, "answer": [], "response_time": 0}); 400];
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

    // Pause, override the next level and resume from the therapist page.
    therapist.click("#pause").await;
    therapist.wait_text("#phase", "paused", WAIT).await;
    child.wait_text("#prompt", "Pause", WAIT).await;
    therapist.click("#override-3").await;
    therapist
        .wait_text("#g-status", "next level overridden to 3", WAIT)
        .await;
    therapist.click("#resume").await;
    therapist.wait_text("#phase", "child answering", WAIT).await;

    // The session went on: the real child page answers sequence 2 (wrongly, on purpose).
    for e in ["happy", "happy", "sad", "sad", "angry"] {
        child.click(&format!(".face[data-emotion={e}]")).await;
    }
    child.click("#done").await;
    therapist
        .wait_count("#results tbody tr.result.wrong", 1, WAIT)
        .await;
    child.wait_text("#prompt", "All done", WAIT).await;
    child.screenshot(shots, "child_finished_800x1280").await;

    // The emergency stop reaches the game.
    therapist.click("#estop").await;
    therapist
        .wait_text("#phase", "EMERGENCY STOPPED", WAIT)
        .await;
    therapist
        .screenshot(shots, "therapist_emergency_stopped_800x1280")
        .await;

    let answers = logs.events("peer.out", "answer");
    let ids: Vec<u64> = answers
        .iter()
        .filter_map(|a| a["sequence_id"].as_u64())
        .collect();
    assert_eq!(
        ids,
        vec![1, 2],
        "exactly the two real answers crossed: {answers:?}"
    );
    assert!(logs.events("peer.out", "unexpected_answer").is_empty());
    assert_eq!(answers[0]["answer"], json!(said));
    let commands = logs.events("peer.out", "command");
    let in_session: Vec<u64> = commands
        .iter()
        .filter(|c| c["session_id"] == session_id)
        .filter_map(|c| c["command_id"].as_u64())
        .collect();
    assert!(
        in_session.len() >= 2 && in_session.windows(2).all(|w| w[1] > w[0]),
        "{commands:?}"
    );
    assert!(logs.events("peer.out", "stale_command").is_empty());
    assert_eq!(
        commands.last().map(|c| c["command"].clone()),
        Some(json!(5)),
        "emergency stop"
    );

    for page in [therapist, child] {
        let _ = page.client.close().await;
    }
}
