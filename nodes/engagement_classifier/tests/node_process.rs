//! `engagement_classifier run` as a process: a bad model stops it at start-up, before it joins
//! the ROS graph; over DDS, bad frames are dropped and named in its log while it goes on
//! classifying the good ones exactly as the model does in process.

use engagement_classifier::synthetic::{SyntheticSpec, generate};
use engagement_classifier::{EngagementClassifierParams, EngagementModel, OPENFACE_FEATURES};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{EngagementEstimate, ExpectedEngagement, OpenFaceFeatures};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::time::{Duration, Instant};

mod common;
use common::{classifier, workspace};

/// A model file that is not XGBoost JSON, and an XGBoost model with another objective: the node
/// exits with an error naming the file and the problem, and never says it started on the graph.
#[test]
fn a_bad_model_stops_the_node_before_it_joins_the_graph() {
    let dir = tempfile::tempdir().expect("temp dir");
    let not_json = dir.path().join("frames_not_a_model.json");
    std::fs::write(&not_json, "frame,pose_Tx\n0,1.5\n").expect("writes");
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/xgb_plain.json");
    let mut regression: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixture).expect("fixture")).expect("JSON");
    regression["learner"]["objective"]["name"] = "reg:squarederror".into();
    let other_objective = dir.path().join("regression_model.json");
    std::fs::write(&other_objective, regression.to_string()).expect("writes");

    for (model, problem) in [
        (&not_json, "not an XGBoost JSON model"),
        (&other_objective, "objective \"reg:squarederror\""),
    ] {
        let params = dir.path().join("engagement_classifier.yaml");
        std::fs::write(
            &params,
            format!(
                "engagement_classifier:\n  ros__parameters:\n    model_file: {:?}\n",
                model.to_str().expect("UTF-8 path")
            ),
        )
        .expect("writes");
        let mut node = classifier(&params, dir.path(), &[]);
        let status = node
            .wait_for_exit(Duration::from_secs(30))
            .expect("the node exits at start-up");
        let stderr = std::fs::read_to_string(dir.path().join("node.err")).unwrap_or_default();
        assert!(!status.success(), "{stderr}");
        assert!(
            stderr.contains(&model.display().to_string()) && stderr.contains(problem),
            "the error names {} and {problem:?}:\n{stderr}",
            model.display()
        );
        assert!(
            !stderr.contains("node started"),
            "joined the graph before loading the model:\n{stderr}"
        );
    }
}

/// Set in the copy of the test that runs inside the network namespace.
const IN_NAMESPACE: &str = "ENGAGEMENT_CLASSIFIER_TEST_IN_LOOPBACK_NETNS";

/// The real node over DDS, fed OpenFace frames of one camera by a probe node: good frames with,
/// in between, frames with a NaN feature and with 31 or 33 features. Every estimate it
/// publishes is for a good frame and equals the in-process model's (label and probability,
/// bit for bit); none is for a bad frame; its seconds count no bad frame (as a face or as
/// "no face"); it logs each kind of bad frame; it still classifies frames sent after them and
/// exits cleanly on SIGINT. DDS multicasts, so this test runs itself again inside a private
/// loopback-only namespace (tests/loopback-netns).
#[test]
fn bad_frames_over_dds_are_dropped_and_the_node_goes_on_classifying() {
    let Some(stdout) = loopback_netns::test_inside_namespace(
        "bad_frames_over_dds_are_dropped_and_the_node_goes_on_classifying",
        IN_NAMESPACE,
        Duration::from_secs(120),
        bad_frames_inside_the_namespace,
    ) else {
        return;
    };
    assert!(stdout.contains("over DDS:"), "{stdout}");
    println!("{stdout}");
}

const FRAME_NS: i64 = 33_333_333;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Good,
    NotFinite,
    FeatureCount(usize),
}

/// Frame `i` of the mixed stretch: 3 in 10 are bad.
fn kind_of(i: usize) -> Kind {
    match i % 10 {
        3 => Kind::NotFinite,
        7 => Kind::FeatureCount(31),
        9 => Kind::FeatureCount(33),
        _ => Kind::Good,
    }
}

fn bad_frames_inside_the_namespace() {
    use node_shell::{NoParameters, NodeShell, ShellOptions};
    use qt_therapy_msgs::topics;

    let params_file = workspace().join("params/engagement_classifier.yaml");
    let params = EngagementClassifierParams::from_yaml_file(&params_file).expect("params");
    let model = EngagementModel::load(&workspace().join(&params.model_file)).expect("model");
    let rows = generate(&SyntheticSpec {
        participants: 1,
        frames_per_participant: 600,
        label_noise: 0.0,
        seed: 11,
        ..Default::default()
    })
    .rows;
    let good_features = |k: usize| -> Vec<f32> { rows[k % rows.len()].map(|v| v as f32).to_vec() };
    let labels: BTreeSet<i8> = (0..rows.len())
        .map(|k| {
            let f: [f32; 32] = good_features(k).try_into().expect("32");
            model.predict_f32(&f).label
        })
        .collect();
    assert_eq!(
        labels.len(),
        2,
        "the frames are both engaged and disengaged"
    );

    let dir = tempfile::tempdir().expect("temp dir");
    let probe_params = dir.path().join("probe.yaml");
    std::fs::write(&probe_params, "engagement_probe:\n  ros__parameters: {}\n").expect("writes");
    let mut node = classifier(&params_file, dir.path(), &[]);

    let t0 = node_shell::now_nanos();
    let frame = |k: usize, features: Vec<f32>| OpenFaceFeatures {
        header: Header {
            stamp: Time::from_nanos(t0 + k as i64 * FRAME_NS),
            frame_id: "camera".into(),
        },
        face_id: "0".into(),
        confidence: 0.98,
        success: true,
        features,
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .expect("runtime");
    // (stamp -> expected (label, probability bits)) of every good frame sent, stamps of bad ones
    let mut good: BTreeMap<i64, (i8, u32)> = BTreeMap::new();
    let mut bad: BTreeMap<i64, Kind> = BTreeMap::new();
    let (estimates, seconds, mixed) = runtime.block_on(async {
        let options = ShellOptions {
            params_file: Some(probe_params.clone()),
            namespace: "/".into(),
            service_mapping: "enhanced".into(),
            ..Default::default()
        };
        let (mut shell, NoParameters {}) =
            NodeShell::start("engagement_probe", &options).expect("probe node");
        let features = shell
            .publisher(topics::OPENFACE_FEATURES)
            .expect("publisher");
        let mut estimates_rx = shell
            .subscribe(topics::ENGAGEMENT_ESTIMATE, 8192)
            .expect("reader");
        let mut seconds_rx = shell
            .subscribe(topics::EXPECTED_ENGAGEMENT, 1024)
            .expect("reader");
        assert!(
            features
                .wait_for_subscribers(&shell, Duration::from_secs(30))
                .await,
            "the classifier never subscribed to the frames"
        );
        let mut estimates: Vec<EngagementEstimate> = Vec::new();
        let mut seconds: Vec<ExpectedEngagement> = Vec::new();
        let mut k = 0usize;
        let send_good = |k: usize, good: &mut BTreeMap<i64, (i8, u32)>| {
            let f = good_features(k);
            let p = model.predict_f32(&f.clone().try_into().expect("32"));
            let message = frame(k, f);
            good.insert(
                message.header.stamp.to_nanos(),
                (p.label, p.probability.to_bits()),
            );
            features.send(message);
        };
        let mut tick = tokio::time::interval(Duration::from_nanos(FRAME_NS as u64));

        // Warm-up: good frames until the first estimate comes back (both ways matched).
        let deadline = Instant::now() + Duration::from_secs(30);
        while estimates.is_empty() {
            assert!(Instant::now() < deadline, "no estimate within 30 s");
            tick.tick().await;
            send_good(k, &mut good);
            k += 1;
            while let Ok(e) = estimates_rx.try_recv() {
                estimates.push(e);
            }
        }
        // The mixed stretch.
        let mixed = k..k + 120;
        for i in mixed.clone() {
            tick.tick().await;
            match kind_of(i - mixed.start) {
                Kind::Good => send_good(i, &mut good),
                kind => {
                    let mut f = good_features(i);
                    match kind {
                        Kind::NotFinite => f[(i - mixed.start) % 32] = f32::NAN,
                        Kind::FeatureCount(n) => f.resize(n, 0.5),
                        Kind::Good => {}
                    }
                    let message = frame(i, f);
                    bad.insert(message.header.stamp.to_nanos(), kind);
                    features.send(message);
                }
            }
        }
        k = mixed.end;
        // Good frames after it, until one of them is classified: the node goes on.
        let after = t0 + mixed.end as i64 * FRAME_NS;
        let deadline = Instant::now() + Duration::from_secs(30);
        while !estimates.iter().any(|e| e.header.stamp.to_nanos() >= after) {
            assert!(
                Instant::now() < deadline,
                "no estimate for a frame after the bad ones within 30 s"
            );
            tick.tick().await;
            send_good(k, &mut good);
            k += 1;
            while let Ok(e) = estimates_rx.try_recv() {
                estimates.push(e);
            }
        }
        // The seconds of the mixed stretch close 1.2 s of message time after their end.
        let last_sent = t0 + (k as i64 - 1) * FRAME_NS;
        let deadline = Instant::now() + Duration::from_secs(30);
        while !seconds.iter().any(|s| s.window_end.to_nanos() > last_sent) {
            let left = deadline.saturating_duration_since(Instant::now());
            match tokio::time::timeout(left, seconds_rx.recv()).await {
                Ok(Some(s)) => seconds.push(s),
                _ => panic!("no second closed after the last frame within 30 s"),
            }
        }
        while let Ok(e) = estimates_rx.try_recv() {
            estimates.push(e);
        }
        drop((features, estimates_rx, seconds_rx));
        shell.stop().await;
        let mixed_ns = t0 + mixed.start as i64 * FRAME_NS..t0 + mixed.end as i64 * FRAME_NS;
        (estimates, seconds, mixed_ns)
    });

    // Every estimate is for a good frame, as the model gives it in process.
    for e in &estimates {
        let stamp = e.header.stamp.to_nanos();
        assert!(
            !bad.contains_key(&stamp),
            "estimate for a bad frame ({:?}): {e:?}",
            bad.get(&stamp)
        );
        assert_eq!(
            good.get(&stamp),
            Some(&(e.label, e.probability.to_bits())),
            "estimate {e:?}"
        );
        assert_eq!(
            (e.header.frame_id.as_str(), e.face_id.as_str()),
            ("camera", "0")
        );
    }
    let classified_in_mixed = estimates
        .iter()
        .filter(|e| mixed.contains(&e.header.stamp.to_nanos()))
        .count();
    let good_in_mixed = good.keys().filter(|s| mixed.contains(s)).count();
    assert_eq!(good_in_mixed + bad.len(), 120);
    // Frames travel best effort: a busy machine may lose a few, not most.
    assert!(
        2 * classified_in_mixed >= good_in_mixed,
        "{classified_in_mixed} of {good_in_mixed} good frames between bad ones classified"
    );

    // Seconds count good frames only: none as "no face", never more than were sent.
    let mut checked_seconds = 0;
    for s in seconds.iter().filter(|s| s.source == "camera/0") {
        let window = s.window_start.to_nanos()..s.window_end.to_nanos();
        let sent = good.keys().filter(|t| window.contains(t)).count();
        assert_eq!(s.missing_count, 0, "{s:?}");
        assert!(
            s.frame_count as usize <= sent,
            "{s:?}: {sent} good frames sent"
        );
        if window.start >= mixed.start && window.end <= mixed.end {
            assert!(s.has_faces && s.frame_count > 0, "{s:?}");
            checked_seconds += 1;
        }
    }
    assert!(
        checked_seconds >= 3,
        "{checked_seconds} whole seconds of the mixed stretch"
    );

    // Still running after all of it; then a clean exit.
    assert!(
        matches!(node.0.try_wait(), Ok(None)),
        "the classifier stopped"
    );
    node.interrupt();
    let status = node.wait_for_exit(Duration::from_secs(20));
    let log = std::fs::read_to_string(dir.path().join("node.err")).unwrap_or_default();
    assert!(
        status.is_some_and(|s| s.success()),
        "exit {status:?}\n{log}"
    );
    // Each kind of bad frame is named in the log.
    let first_nan = format!("feature 3 ({}) is NaN", OPENFACE_FEATURES[3]);
    for reason in [
        first_nan.as_str(),
        "has 31 features, expected 32",
        "has 33 features, expected 32",
    ] {
        assert!(log.contains(reason), "{reason:?} not in the log:\n{log}");
    }
    println!(
        "over DDS: {classified_in_mixed} of {good_in_mixed} good frames between {} bad ones \
         classified as in process, no bad frame classified or counted; {} estimates, {} \
         seconds; clean exit on SIGINT",
        bad.len(),
        estimates.len(),
        seconds.len()
    );
}
