//! The main job as a test: every node of the suite as its own process over DDS in one loopback
//! namespace, a simulated child, the recorder; the session must run its 10 sequences, the bag
//! must hold them in order with their decisions and per-second engagement, and the report must
//! be written.

use qt_therapy_msgs::topics::{DECISION, EXPECTED_ENGAGEMENT, SEQUENCE_RESULT};
use qt_therapy_msgs::{Decision, ExpectedEngagement, SequenceResult};
use std::time::Duration;
use suite_tests::{run_in_loopback_netns, workspace_bin};

#[test]
fn a_whole_simulated_session_over_dds() {
    let launch = workspace_bin("launch");
    let bin = launch.parent().expect("target dir").display().to_string();
    let out = std::env::temp_dir().join(format!("simulated_session_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).expect("out dir");
    let o = out.display();
    let script = format!(
        "{} launch_scripts/simulated_session.launch.yaml bin:={bin} out:={o} time_scale:=0.05 cluster:=0 > {o}/stdout.log 2> {o}/stderr.log; echo \"launch_exit=$?\"",
        launch.display()
    );
    let Some(result) = run_in_loopback_netns(&script, Duration::from_secs(240)) else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(out.join(f)).unwrap_or_default();
    let context = format!(
        "{}\nstdout:\n{}\nstderr (tail):\n{}",
        String::from_utf8_lossy(&result.stdout),
        read("stdout.log"),
        {
            let e = read("stderr.log");
            e.lines()
                .rev()
                .take(40)
                .collect::<Vec<_>>()
                .into_iter()
                .rev()
                .collect::<Vec<_>>()
                .join("\n")
        }
    );
    assert!(
        String::from_utf8_lossy(&result.stdout).contains("launch_exit=0"),
        "{context}"
    );
    let stdout = read("stdout.log");
    assert_eq!(
        stdout
            .lines()
            .filter(|l| l.starts_with("[therapist] seq "))
            .count(),
        10,
        "{context}"
    );
    assert!(stdout.contains("finished: 10 sequences"), "{context}");

    let reader =
        bag::BagReader::open(&out.join("session.mcap")).expect("the recorder wrote a readable bag");
    let results: Vec<SequenceResult> = reader
        .messages(SEQUENCE_RESULT.name)
        .expect("results")
        .into_iter()
        .map(|s| s.message)
        .collect();
    assert_eq!(
        results.iter().map(|r| r.sequence_index).collect::<Vec<_>>(),
        (1..=10).collect::<Vec<u8>>(),
        "{context}"
    );
    let session = &results[0].session_id;
    assert!(
        results
            .iter()
            .all(|r| &r.session_id == session && r.sequence.len() == 2 * usize::from(r.level) + 1)
    );
    // The simulated child answered (no timeouts) and its face was seen by the classifier.
    assert!(
        results.iter().filter(|r| !r.timed_out).count() >= 8,
        "{context}"
    );
    let engagement: Vec<ExpectedEngagement> = reader
        .messages(EXPECTED_ENGAGEMENT.name)
        .expect("engagement")
        .into_iter()
        .map(|s| s.message)
        .collect();
    assert!(
        engagement.iter().filter(|e| e.has_faces).count() >= 10,
        "{} seconds with faces",
        engagement.len()
    );
    assert!(
        results
            .iter()
            .filter(|r| !r.engagement_per_second.is_empty())
            .count()
            >= 8,
        "{context}"
    );
    // Every sequence but fallbacks was set up by a decision of the policy.
    let decisions: Vec<Decision> = reader
        .messages(DECISION.name)
        .expect("decisions")
        .into_iter()
        .map(|s| s.message)
        .collect();
    assert!(
        decisions
            .iter()
            .filter(|d| &d.session_id == session)
            .count()
            >= 9,
        "{context}"
    );
    assert!(
        decisions.iter().all(|d| d.step != 1 || d.feedback == 0),
        "no feedback on the first sequence"
    );

    // The report the main job writes next to the bag.
    let report = std::process::Command::new(workspace_bin("session_report"))
        .arg(out.join("session.mcap"))
        .output()
        .expect("session_report runs");
    assert!(
        report.status.success(),
        "{}",
        String::from_utf8_lossy(&report.stderr)
    );
    let html = read("report.html");
    assert_eq!(
        html.matches("<svg").count(),
        2,
        "level and engagement figures"
    );
    assert_eq!(
        html.matches("<tr").count(),
        11,
        "a header and a row per sequence"
    );
    let _ = std::fs::remove_dir_all(&out);
}
