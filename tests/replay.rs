//! Replay tests: the sample sessions in bags/ (recorded from the simulated suite, every node a
//! process over DDS) replayed into every node's own run loop, one node at a time, through one
//! harness (`replay/harness.rs`): the node's recorded inputs go in on the in-process bus at
//! their recorded times, what it publishes is recorded by the real recorder on that bus, and
//! compared with what the live node published in the session. Services are not in a bag: the
//! game manager's policy answers with the recorded decisions, and the policy is asked what the
//! recorded decisions answered. Each test says what it compares, exactly and within what.

#[path = "replay/harness.rs"]
mod harness;

use bag_file::BagReader;
use engagement_classifier::EngagementClassifierParams;
use engagement_classifier::messages::source_name;
use harness::{
    Input, MS, Replay, parameters, recorded, recorded_inputs, virtual_time, workspace_file,
};
use node_shell::Bus;
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::{Header, StringMsg};
use qt_therapy_msgs::topics::{
    ACTION_PROPOSAL, DECIDE_ACTION, DECISION, ENGAGEMENT_ESTIMATE, EXPECTED_ENGAGEMENT, GAME_STATE,
    HEARTBEAT, OPENFACE_FEATURES, ROBOT_EMOTION, ROBOT_GESTURE, ROBOT_SPEECH, SEQUENCE_RESULT,
    TABLET_ANSWER, TABLET_TASK, THERAPIST_COMMAND, USER_MODEL_INFO,
};
use qt_therapy_msgs::{
    DecideActionRequest, DecideActionResponse, Decision, EngagementEstimate, ExpectedEngagement,
    GameState, Heartbeat, OpenFaceFeatures, SequenceResult, TabletAnswer, TabletTask,
    TherapistCommand, UserModelInfo,
};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use suite_tests::workspace_root;

/// A sample bag and the launch arguments it was recorded with (bags/README.md,
/// bags/record_samples.sh); every other parameter is the repository's params/ default.
struct Sample {
    file: &'static str,
    /// `seed:=` of the launch: the game manager's and the simulated child's seed.
    seed: i64,
    /// `time_scale:=` of the launch (0.2 by default).
    time_scale: f64,
    cluster: i32,
    /// Sequences played (10 unless the therapist stopped the session).
    sequences: usize,
}

const SAMPLES: [Sample; 3] = [
    Sample {
        file: "cluster0_seed7.mcap",
        seed: 7,
        time_scale: 0.2,
        cluster: 0,
        sequences: 10,
    },
    Sample {
        file: "cluster1_seed11_pause_override.mcap",
        seed: 11,
        time_scale: 0.2,
        cluster: 1,
        sequences: 10,
    },
    Sample {
        file: "cluster0_seed3_stopped.mcap",
        seed: 3,
        time_scale: 0.2,
        cluster: 0,
        sequences: 4,
    },
];

/// The sample, which must be complete and undamaged.
fn open(sample: &Sample) -> BagReader {
    let path = workspace_root().join("bags").join(sample.file);
    BagReader::open(&path)
        .and_then(BagReader::strict)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The bag's first and last log times.
fn span(bag: &BagReader) -> (i64, i64) {
    let (a, b) = bag.time_range().expect("a bag with messages");
    (a as i64, b as i64)
}

/// How far a replayed node's message times may be from the live node's: the live node read
/// the wall clock when an input arrived or a timer fired (a few ms after it was due on a busy
/// machine); the replay gets each input at the recorder's receipt time (to the next ms).
const TIME_TOLERANCE_NS: i64 = 100 * MS;

/// `m` with its header's stamp taken out (to compare contents exactly and times apart), and
/// that stamp.
fn unstamped<M: Clone>(m: &M, header: impl Fn(&mut M) -> &mut Header) -> (i64, M) {
    let mut m = m.clone();
    let h = header(&mut m);
    let t = h.stamp.to_nanos();
    h.stamp = Time::default();
    (t, m)
}

/// Compares two streams of (time, message): the same messages in the same order, exactly; the
/// largest time apart, which must be within `tolerance`.
fn same_messages<M: PartialEq + std::fmt::Debug>(
    what: &str,
    replayed: &[(i64, M)],
    live: &[(i64, M)],
    tolerance: i64,
) -> i64 {
    if let Some(i) = (0..replayed.len().max(live.len()))
        .find(|&i| replayed.get(i).map(|(_, m)| m) != live.get(i).map(|(_, m)| m))
    {
        panic!(
            "{what}: {} replayed, {} live; they differ first at #{i}:\n replayed: {:?}\n live:     {:?}",
            replayed.len(),
            live.len(),
            replayed.get(i).map(|(_, m)| m),
            live.get(i).map(|(_, m)| m)
        );
    }
    let worst = replayed
        .iter()
        .zip(live)
        .map(|((a, _), (b, _))| (a - b).abs())
        .max()
        .unwrap_or(0);
    assert!(
        worst <= tolerance,
        "{what}: {:.1} ms from the live node's",
        worst as f64 * 1e-6
    );
    worst
}

/// A node's `key:=value` overrides that make the parameter file's relative paths absolute
/// (the launch ran the nodes from the workspace; a test runs in its package's directory).
fn absolute(key: &str, relative: &str) -> String {
    format!("{key}:={}", workspace_file(relative))
}

// ---------------------------------------------------------------------------------------
// The engagement classifier

/// The recorded frames the live classifier saw, as inputs: those it published an estimate
/// for. A frame the bag holds without one did not reach the classifier: at startup, before its
/// reader had matched the child's writer (best effort, volatile: a reader gets only what is
/// published after it matched), or later, dropped on the best-effort topic while the machine
/// was busy. (Were an estimate lost instead, between the classifier and the recorder, that
/// second's counts would differ from the replay's and the test fail.) Returns them and how many
/// were left out.
fn frames_the_classifier_saw(bag: &BagReader) -> (Vec<Input>, usize) {
    let seen: BTreeSet<(i64, String)> =
        recorded::<EngagementEstimate>(bag, ENGAGEMENT_ESTIMATE.name)
            .into_iter()
            .map(|(_, e)| (e.header.stamp.to_nanos(), estimate_source(&e)))
            .collect();
    let all = recorded_inputs(bag, &[OPENFACE_FEATURES.name]);
    let total = all.len();
    let frames: Vec<Input> = all
        .into_iter()
        .filter(|i| {
            let f: OpenFaceFeatures = i.message();
            seen.contains(&(f.header.stamp.to_nanos(), source_name(&f)))
        })
        .collect();
    let unseen = total - frames.len();
    (frames, unseen)
}

/// "<camera>/<face>" of an estimate, as `source_name` names a frame's.
fn estimate_source(e: &EngagementEstimate) -> String {
    format!("{}/{}", e.header.frame_id, e.face_id)
}

/// The seconds of a bag by (source, window start).
fn seconds(bag: &BagReader) -> BTreeMap<(String, i64), ExpectedEngagement> {
    recorded::<ExpectedEngagement>(bag, EXPECTED_ENGAGEMENT.name)
        .into_iter()
        .map(|(_, e)| ((e.source.clone(), e.window_start.to_nanos()), e))
        .collect()
}

/// `engagement_classifier run` with the launch's parameters, from `at_ns`.
fn start_classifier(replay: &mut Replay, at_ns: i64) {
    let (defaults, _) = parameters::<EngagementClassifierParams>("engagement_classifier", &[]);
    let (params, path) = parameters::<EngagementClassifierParams>(
        "engagement_classifier",
        &[absolute("model_file", &defaults.model_file)],
    );
    let estimator = engagement_classifier::node::estimator(&params, &path).expect("the model");
    replay.start(
        engagement_classifier::node::NODE,
        at_ns,
        Box::new(move |bus| Box::pin(engagement_classifier::node::run(bus, params, estimator))),
    );
}

/// Inputs: the frames the live classifier saw and the game states, at their log times; the
/// classifier starts before the first. Compared: every estimate the live node published, with
/// the replayed one for the same frame, exactly (header, face, label, probability's bits); one
/// replayed per frame fed, the live ones without a replayed twin at most 5 (their frames the
/// recorder lost). Every second (ExpectedEngagement) the live node published, with the
/// replayed one, exactly (counts, mean, smoothed mean, window, stamp), but for seconds whose
/// frame counts differ and the smoothed means right after them: at most 5 %, and only these.
/// The replay publishes no second the live node did not, but the last ones it closes when it
/// is stopped (the live node's came after the recorder stopped). Not compared: the ROS4HRI
/// topics (the samples were recorded without them).
#[test]
fn the_classifier_replayed_gives_the_recorded_estimates_and_engagement_per_second() {
    for sample in &SAMPLES {
        let f = sample.file;
        let bag = open(sample);
        let (first, last) = span(&bag);
        let (mut inputs, unseen) = frames_the_classifier_saw(&bag);
        let fed = inputs.len();
        // A few: at most 2 % of the frames.
        assert!(
            unseen * 50 <= fed,
            "{f}: {unseen} recorded frames the classifier never saw"
        );
        inputs.extend(recorded_inputs(&bag, &[GAME_STATE.name]));
        let replayed = virtual_time(async move {
            let mut r = Replay::new(
                inputs,
                &[ENGAGEMENT_ESTIMATE.name, EXPECTED_ENGAGEMENT.name],
                first - 100 * MS,
            );
            start_classifier(&mut r, first - 100 * MS);
            r.finish(Some(last)).await.bag
        });

        let replayed_estimates: BTreeMap<(i64, String), EngagementEstimate> =
            recorded::<EngagementEstimate>(&replayed, ENGAGEMENT_ESTIMATE.name)
                .into_iter()
                .map(|(_, e)| ((e.header.stamp.to_nanos(), estimate_source(&e)), e))
                .collect();
        assert_eq!(replayed_estimates.len(), fed, "{f}: one estimate per frame");
        let live = recorded::<EngagementEstimate>(&bag, ENGAGEMENT_ESTIMATE.name);
        let mut compared = 0;
        for (_, e) in &live {
            let key = (e.header.stamp.to_nanos(), estimate_source(e));
            let Some(r) = replayed_estimates.get(&key) else {
                continue;
            };
            compared += 1;
            assert!(
                (&r.header, &r.face_id, r.label, r.probability.to_bits())
                    == (&e.header, &e.face_id, e.label, e.probability.to_bits()),
                "{f}: frame {key:?}: live {e:?}, replayed {r:?}"
            );
        }
        assert_eq!(compared, fed, "{f}");
        assert!(
            compared + 5 >= live.len(),
            "{f}: {compared} of {} estimates compared",
            live.len()
        );

        let live = seconds(&bag);
        let replay = seconds(&replayed);
        assert!(live.len() >= 20, "{f}: {} seconds", live.len());
        for key in live.keys() {
            assert!(replay.contains_key(key), "{f}: second {key:?} not replayed");
        }
        let c = compare_seconds(&replay, &live);
        let other_counts = c.fewer_frames.len() + c.more_frames.len();
        assert!(
            c.unexplained.is_empty() && other_counts * 20 <= live.len().max(40),
            "{f}: replayed vs live seconds: {}; {c:?}",
            c.summary()
        );
        let last_live = live.keys().map(|(_, w)| *w).max().unwrap_or(i64::MIN);
        let extra: Vec<_> = replay.keys().filter(|k| !live.contains_key(*k)).collect();
        assert!(
            extra.iter().all(|(_, w)| *w > last_live) && extra.len() <= 3,
            "{f}: replayed seconds the live node did not publish: {extra:?}"
        );
        eprintln!(
            "{f}: {compared} frame estimates equal; seconds: {} ({unseen} recorded frames never \
             reached the classifier; {} seconds closed at the stop)",
            c.summary(),
            extra.len()
        );
    }
}

/// How two classifiers' seconds compare, over the seconds both reported.
#[derive(Debug, Default)]
struct SecondsComparison {
    equal: usize,
    /// Seconds counting fewer frames (this classifier did not receive some: best effort).
    fewer_frames: Vec<(String, i64)>,
    /// Seconds counting more frames (the other classifier did not receive some).
    more_frames: Vec<(String, i64)>,
    /// Same frames and mean, but the smoothed mean differs after a second with other frames of
    /// its source (by a factor 1 - alpha per second after it).
    smoothed_after: Vec<(String, i64)>,
    /// Anything else: a real difference.
    unexplained: Vec<(String, i64)>,
}

impl SecondsComparison {
    fn summary(&self) -> String {
        format!(
            "{} equal, {} with fewer frames, {} with more, {} smoothed differently after those, {} unexplained",
            self.equal,
            self.fewer_frames.len(),
            self.more_frames.len(),
            self.smoothed_after.len(),
            self.unexplained.len()
        )
    }
}

fn compare_seconds(
    got: &BTreeMap<(String, i64), ExpectedEngagement>,
    want: &BTreeMap<(String, i64), ExpectedEngagement>,
) -> SecondsComparison {
    let mut c = SecondsComparison::default();
    for (key, g) in got {
        let Some(w) = want.get(key) else {
            continue;
        };
        let (n_got, n_want) = (
            g.frame_count + g.missing_count,
            w.frame_count + w.missing_count,
        );
        let after_other = |c: &SecondsComparison| {
            c.fewer_frames
                .iter()
                .chain(&c.more_frames)
                .any(|(s, t)| *s == key.0 && *t < key.1)
        };
        if g == w {
            c.equal += 1;
        } else if n_got < n_want {
            c.fewer_frames.push(key.clone());
        } else if n_got > n_want {
            c.more_frames.push(key.clone());
        } else if (g.frame_count, g.missing_count, g.mean)
            == (w.frame_count, w.missing_count, w.mean)
            && after_other(&c)
        {
            c.smoothed_after.push(key.clone());
        } else {
            c.unexplained.push(key.clone());
        }
    }
    c
}

// ---------------------------------------------------------------------------------------
// The behaviour policy

/// "cluster 1 (out/.../cluster_1.json, 4 updates)" -> ("cluster 1", "cluster_1.json", 4); a
/// decision planned on the child's belief names the table after " near ".
fn model_used(d: &Decision) -> (String, String, u64) {
    let table = d
        .model_used
        .rsplit_once(" near ")
        .map_or(d.model_used.as_str(), |(_, t)| t);
    let parsed = table.split_once(" (").and_then(|(owner, rest)| {
        let (path, updates) = rest.strip_suffix(" updates)")?.rsplit_once(", ")?;
        let file = Path::new(path).file_name()?.to_str()?.to_string();
        Some((owner.to_string(), file, updates.parse().ok()?))
    });
    parsed.unwrap_or_else(|| panic!("model_used {:?}", d.model_used))
}

/// A decision with its stamp and its table's path taken out: what must be equal.
fn decision_contents(d: &Decision) -> (i64, Decision) {
    let (t, mut d) = unstamped(d, |d| &mut d.header);
    d.model_used = String::new();
    (t, d)
}

/// The session's START command: the user and cluster every request of the session names.
fn start_command(bag: &BagReader) -> TherapistCommand {
    recorded::<TherapistCommand>(bag, THERAPIST_COMMAND.name)
        .into_iter()
        .map(|(_, c)| c)
        .find(|c| c.command == TherapistCommand::START)
        .expect("a START command")
}

/// How the policy is replayed.
#[derive(Debug, Clone, Copy, PartialEq)]
enum PolicyRun {
    /// As the session ran: one table per cluster.
    AsRecorded,
    /// `per_user_q_tables: true`: the user's own table, made from the cluster's at their first
    /// decision, decides; it learns the same results, so it decides as the cluster's did.
    PerUserTables,
    /// Every result delivered twice (the second copy 1 ms later, as a respawned game manager's
    /// history arrives again): each learned once.
    ResultsTwice,
}

/// The policy's replay: the decisions it published and the answers its caller got.
struct PolicyReplay {
    bag: BagReader,
    answers: Vec<DecideActionResponse>,
    q_tables: BTreeMap<String, q_learning::QTableFile>,
}

/// Inputs: the results, each at its log time or, where the live table had not learned it when
/// it made a later decision, 1 ms after the last such decision (twice with `ResultsTwice`, the
/// copy 1 ms later); each recorded decision's request (its session, step, state; the session's
/// user and cluster from its START) made at the decision's stamp, when the live node decided,
/// naming as `after_sequence` the results of the session the live table had learned by then
/// (its update count in `model_used`, less step 1's). Both make the replayed node decide on
/// what the live one had learned, through its own wait, whatever order the recorder heard the
/// result and the decision in. The policy starts from the Q-tables it started from in the session (bags/q_tables)
/// with the launch's parameters.
fn replay_policy(bag_of: &BagReader, run: PolicyRun) -> PolicyReplay {
    let (first, last) = span(bag_of);
    let decisions = recorded::<Decision>(bag_of, DECISION.name);
    let base = decisions
        .iter()
        .find(|(_, d)| d.step == 1)
        .map_or(0, |(_, d)| model_used(d).2);
    // (stamp, step, results of the session its table had learned)
    let learned: Vec<(i64, u8, u64)> = decisions
        .iter()
        .map(|(_, d)| (d.header.stamp.to_nanos(), d.step, model_used(d).2 - base))
        .collect();
    let mut inputs = recorded_inputs(bag_of, &[SEQUENCE_RESULT.name]);
    for i in &mut inputs {
        let k = u64::from(i.message::<SequenceResult>().sequence_index);
        if let Some(after) = learned
            .iter()
            .filter(|(_, step, n)| u64::from(*step) > k && *n < k)
            .map(|(t, _, _)| *t)
            .max()
        {
            i.at_ns = i.at_ns.max(after + MS);
        }
    }
    if run == PolicyRun::ResultsTwice {
        let again: Vec<Input> = inputs
            .iter()
            .map(|i| Input {
                at_ns: i.at_ns + MS,
                ..i.clone()
            })
            .collect();
        inputs.extend(again);
    }
    let start = start_command(bag_of);
    let requests: Vec<(i64, DecideActionRequest)> = decisions
        .iter()
        .zip(&learned)
        .map(|((_, d), (at, _, n))| {
            (
                *at,
                DecideActionRequest {
                    session_id: d.session_id.clone(),
                    user_id: start.user_id.clone(),
                    user_model_cluster: start.user_model_cluster,
                    state: d.state.clone(),
                    step: d.step,
                    after_sequence: u8::try_from(*n).expect("at most 10 results"),
                },
            )
        })
        .collect();
    let on_belief = decisions.iter().any(|(_, d)| d.planned_on_belief);
    let answers = Arc::new(Mutex::new(Vec::new()));
    let got = answers.clone();
    let (bag, q_tables) = virtual_time(async move {
        let mut r = Replay::new(inputs, &[DECISION.name], first - 100 * MS);
        let tables = r.dir().join("q_tables");
        std::fs::create_dir_all(&tables).expect("a Q-table directory");
        for k in 0..2 {
            let name = format!("cluster_{k}.json");
            std::fs::copy(
                workspace_root().join("bags/q_tables").join(&name),
                tables.join(&name),
            )
            .expect("the session's first Q-tables");
        }
        let (defaults, _) =
            parameters::<behaviour_policy::BehaviourPolicyParams>("behaviour_policy", &[]);
        let mut overrides = vec![
            absolute("user_model_file", &defaults.user_model_file),
            format!("q_table_dir:={}", tables.display()),
        ];
        if run == PolicyRun::PerUserTables {
            overrides.push("per_user_q_tables:=true".into());
        }
        // Planned on the child's belief as the session was (the main job's launch turns it on).
        if on_belief {
            overrides.push("child_belief:=true".into());
            overrides.push(absolute(
                "child_belief_prior_file",
                &defaults.child_belief_prior_file,
            ));
        }
        let (params, path) =
            parameters::<behaviour_policy::BehaviourPolicyParams>("behaviour_policy", &overrides);
        r.start(
            qt_therapy_msgs::topics::BEHAVIOUR_POLICY_NODE,
            first - 100 * MS,
            Box::new(move |bus| {
                Box::pin(async move { behaviour_policy::node::run(bus, params, &path).await })
            }),
        );
        // The game manager's side of the calls: each recorded request at its time.
        r.start(
            "recorded_requests",
            first - 100 * MS,
            Box::new(move |bus| {
                Box::pin(async move {
                    let client = bus.client(DECIDE_ACTION)?;
                    let clock = bus.clock();
                    let mut calls = Vec::new();
                    for (at, request) in requests {
                        clock.sleep_until(at).await;
                        let client = client.clone();
                        let got = got.clone();
                        calls.push(tokio::spawn(async move {
                            let answer = client.call(request, Duration::from_secs(3)).await;
                            got.lock().unwrap_or_else(|e| e.into_inner()).push(answer);
                        }));
                    }
                    for c in calls {
                        c.await?;
                    }
                    Ok(())
                })
            }),
        );
        let replayed = r.finish(Some(last)).await;
        let tables = replayed.dir.path().join("q_tables");
        let q_tables = std::fs::read_dir(&tables)
            .expect("the Q-table directory")
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|x| x == "json"))
            // The children's belief files beside the tables are not Q-tables.
            .filter(|p| {
                !p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("belief_"))
            })
            .map(|p| {
                let name = p
                    .file_name()
                    .and_then(|n| n.to_str())
                    .unwrap_or_default()
                    .to_string();
                (
                    name,
                    q_learning::QTableFile::load(&p).expect("a Q-table file"),
                )
            })
            .collect();
        (replayed.bag, q_tables)
    });
    let answers = Arc::try_unwrap(answers)
        .map(|m| m.into_inner().unwrap_or_else(|e| e.into_inner()))
        .unwrap_or_default()
        .into_iter()
        .map(|a| a.unwrap_or_else(|e| panic!("a request went unanswered: {e}")))
        .collect();
    PolicyReplay {
        bag,
        answers,
        q_tables,
    }
}

/// Compared, for the recorded session, with per-user tables, and with every result twice:
/// every decision the live node published, with the replayed one, exactly (action, level,
/// feedback, Q-values, probabilities, temperature, explored, mode, state, step, session) but
/// its stamp (within 100 ms: the request is made at the live decision's stamp, to the next ms)
/// and which table decided (`model_used`): the cluster's as recorded, or the user's own with
/// per-user tables, after the same number of updates, each time. Every call answered ok with
/// the decision published. After the session each table the session taught has learned each
/// of its results once: the cluster's (and the user's) updates are the results of that
/// cluster, and its last learned sequence of the session is the session's last.
#[test]
fn the_policy_replayed_gives_the_recorded_decisions_with_per_user_tables_and_results_twice() {
    for sample in &SAMPLES {
        let f = sample.file;
        let bag = open(sample);
        let live = recorded::<Decision>(&bag, DECISION.name);
        let results = recorded::<SequenceResult>(&bag, SEQUENCE_RESULT.name);
        assert_eq!(results.len(), sample.sequences, "{f}");
        let user = start_command(&bag).user_id;
        for run in [
            PolicyRun::AsRecorded,
            PolicyRun::PerUserTables,
            PolicyRun::ResultsTwice,
        ] {
            let what = format!("{f} ({run:?})");
            let replay = replay_policy(&bag, run);
            let replayed = recorded::<Decision>(&replay.bag, DECISION.name);
            let contents = |ds: &[(i64, Decision)]| -> Vec<(i64, Decision)> {
                ds.iter().map(|(_, d)| decision_contents(d)).collect()
            };
            let worst = same_messages(
                &format!("{what}: decisions"),
                &contents(&replayed),
                &contents(&live),
                TIME_TOLERANCE_NS,
            );
            for ((_, r), (_, l)) in replayed.iter().zip(&live) {
                let (owner, file, updates) = model_used(l);
                let expected = match run {
                    PolicyRun::PerUserTables => {
                        (format!("user {user}"), format!("user_{user}.json"), updates)
                    }
                    _ => (owner, file, updates),
                };
                assert_eq!(model_used(r), expected, "{what}: step {}", r.step);
            }
            assert_eq!(replay.answers.len(), live.len(), "{what}");
            let published: Vec<&Decision> = replayed.iter().map(|(_, d)| d).collect();
            for a in &replay.answers {
                assert!(a.ok, "{what}: refused: {}", a.error);
                assert!(published.contains(&&a.decision), "{what}: answered {a:?}");
            }
            // Each table the session taught learned each of its results once.
            let session = &results[0].1.session_id;
            let mut taught = vec![format!("cluster_{}.json", sample.cluster)];
            if run == PolicyRun::PerUserTables {
                taught.push(format!("user_{user}.json"));
            }
            for name in &taught {
                let table = replay
                    .q_tables
                    .get(name)
                    .unwrap_or_else(|| panic!("{what}: no {name}"));
                assert_eq!(table.updates, sample.sequences as u64, "{what}: {name}");
                assert_eq!(
                    table.learned.get(session).copied(),
                    Some(sample.sequences as u8),
                    "{what}: {name}"
                );
            }
            eprintln!(
                "{what}: {} decisions equal, within {:.1} ms of the live ones",
                live.len(),
                worst as f64 * 1e-6
            );
        }
    }
}

// ---------------------------------------------------------------------------------------
// The game manager

/// Everything the game manager publishes, as the comparison takes it: messages with their
/// header stamps (and a result's engagement period) taken out; the robot's strings at their
/// log times.
struct Game {
    states: Vec<(i64, GameState)>,
    tasks: Vec<(i64, TabletTask)>,
    results: Vec<(i64, SequenceResult)>,
    periods: Vec<(i64, (i64, i64))>,
    robot: Vec<(&'static str, Vec<(i64, String)>)>,
    proposals: usize,
}

fn game(bag: &BagReader) -> Game {
    let results: Vec<(i64, SequenceResult)> = recorded(bag, SEQUENCE_RESULT.name)
        .iter()
        .map(|(_, r): &(i64, SequenceResult)| unstamped(r, |r| &mut r.header))
        .collect();
    let periods = results
        .iter()
        .map(|(t, r)| {
            (
                *t,
                (
                    r.engagement_period_start.to_nanos(),
                    r.engagement_period_end.to_nanos(),
                ),
            )
        })
        .collect();
    Game {
        states: recorded(bag, GAME_STATE.name)
            .iter()
            .map(|(_, s): &(i64, GameState)| unstamped(s, |s| &mut s.header))
            .collect(),
        tasks: recorded(bag, TABLET_TASK.name)
            .iter()
            .map(|(_, t): &(i64, TabletTask)| unstamped(t, |t| &mut t.header))
            .collect(),
        results: results
            .into_iter()
            .map(|(t, mut r)| {
                r.engagement_period_start = Time::default();
                r.engagement_period_end = Time::default();
                (t, r)
            })
            .collect(),
        periods,
        robot: [ROBOT_SPEECH.name, ROBOT_EMOTION.name, ROBOT_GESTURE.name]
            .into_iter()
            .map(|topic| {
                let strings = recorded::<StringMsg>(bag, topic)
                    .into_iter()
                    .map(|(t, m)| (t, m.data))
                    .collect();
                (topic, strings)
            })
            .collect(),
        proposals: recorded::<qt_therapy_msgs::ActionProposal>(bag, ACTION_PROPOSAL.name).len(),
    }
}

/// Inputs: the therapist's commands, the tablet's answers, the engagement per second and the
/// other nodes' heartbeats at their log times; the policy's answers from a stand-in that
/// answers each DecideAction with the recorded decision for its session and step at that
/// decision's log time (the request's state must be the recorded decision's). The game
/// manager starts at its first recorded state's stamp, with the launch's parameters (the
/// sample's seed and time scale). Compared: its game states, tablet tasks, results and the
/// robot's speech, faces and gestures, every one, in order, exactly but their stamps (and a
/// result's engagement period, its message times) within 100 ms; no proposal (the samples ran
/// without supervised autonomy); every decision asked for and answered; no node lost.
#[test]
fn the_game_manager_replayed_gives_the_recorded_game() {
    for sample in &SAMPLES {
        let f = sample.file;
        let bag = open(sample);
        let (first, last) = span(&bag);
        let live = game(&bag);
        assert!(
            live.states
                .iter()
                .all(|(_, s)| !s.status.contains("node lost")),
            "{f}: a node was lost in the recorded session"
        );
        let started = recorded::<GameState>(&bag, GAME_STATE.name)[0]
            .1
            .header
            .stamp
            .to_nanos();
        let inputs: Vec<Input> = recorded_inputs(
            &bag,
            &[
                THERAPIST_COMMAND.name,
                TABLET_ANSWER.name,
                EXPECTED_ENGAGEMENT.name,
                HEARTBEAT.name,
            ],
        )
        .into_iter()
        .filter(|i| {
            i.topic != HEARTBEAT.name
                || i.message::<Heartbeat>().node_name != game_manager::node::NODE
        })
        .collect();
        let decisions = recorded::<Decision>(&bag, DECISION.name);
        let asked = Arc::new(Mutex::new(Vec::new()));
        let asked_by = asked.clone();
        let (sample_seed, time_scale) = (sample.seed, sample.time_scale);
        let replayed = virtual_time(async move {
            let mut r = Replay::new(
                inputs,
                &[
                    GAME_STATE.name,
                    TABLET_TASK.name,
                    SEQUENCE_RESULT.name,
                    ROBOT_SPEECH.name,
                    ROBOT_EMOTION.name,
                    ROBOT_GESTURE.name,
                    ACTION_PROPOSAL.name,
                ],
                first.min(started) - 100 * MS,
            );
            r.start(
                "recorded_policy",
                first.min(started) - 100 * MS,
                Box::new(move |bus| Box::pin(recorded_policy(bus, decisions, asked_by))),
            );
            let (defaults, _) = parameters::<game_manager::GameManagerParams>("game_manager", &[]);
            let (params, path) = parameters::<game_manager::GameManagerParams>(
                "game_manager",
                &[
                    format!("sessions_dir:={}", r.dir().display()),
                    format!("seed:={sample_seed}"),
                    format!("time_scale:={time_scale}"),
                    absolute("user_model_file", &defaults.supervision.user_model_file),
                ],
            );
            r.start(
                game_manager::node::NODE,
                started,
                Box::new(move |bus| {
                    Box::pin(async move { game_manager::node::run(bus, params, &path).await })
                }),
            );
            r.finish(Some(last)).await.bag
        });
        let got = game(&replayed);
        let t = TIME_TOLERANCE_NS;
        let mut worst = same_messages(&format!("{f}: game states"), &got.states, &live.states, t);
        worst = worst.max(same_messages(
            &format!("{f}: tablet tasks"),
            &got.tasks,
            &live.tasks,
            t,
        ));
        worst = worst.max(same_messages(
            &format!("{f}: results"),
            &got.results,
            &live.results,
            t,
        ));
        assert_eq!(got.results.len(), sample.sequences, "{f}");
        let periods_apart = got
            .periods
            .iter()
            .zip(&live.periods)
            .map(|((_, a), (_, b))| (a.0 - b.0).abs().max((a.1 - b.1).abs()))
            .max()
            .unwrap_or(0);
        assert!(
            periods_apart <= t,
            "{f}: engagement periods {periods_apart} ns apart"
        );
        for ((topic, a), (_, b)) in got.robot.iter().zip(&live.robot) {
            worst = worst.max(same_messages(&format!("{f}: {topic}"), a, b, t));
        }
        assert_eq!((got.proposals, live.proposals), (0, 0), "{f}: proposals");
        let asked = asked.lock().unwrap_or_else(|e| e.into_inner()).clone();
        assert_eq!(
            asked,
            recorded::<Decision>(&bag, DECISION.name)
                .iter()
                .map(|(_, d)| d.step)
                .collect::<Vec<u8>>(),
            "{f}: the decisions asked for"
        );
        eprintln!(
            "{f}: game replayed; message times within {:.1} ms of the live node's",
            worst as f64 * 1e-6
        );
    }
}

/// The policy's part for the game manager's replay: each DecideAction is answered with the
/// recorded decision of its session and step, at the time the live one was recorded; a
/// request for a state other than the recorded decision's fails the replay. The steps asked
/// for go to `asked`.
async fn recorded_policy(
    bus: &mut node_shell::in_process::InProcessNode,
    decisions: Vec<(i64, Decision)>,
    asked: Arc<Mutex<Vec<u8>>>,
) -> anyhow::Result<()> {
    let mut calls = bus.serve(DECIDE_ACTION, |e| DecideActionResponse {
        ok: false,
        error: e.to_string(),
        ..Default::default()
    })?;
    let clock = bus.clock();
    let stop = bus.shutdown_signal();
    tokio::pin!(stop);
    loop {
        let call = tokio::select! {
            biased;
            _ = &mut stop => return Ok(()),
            Some(call) = calls.recv() => call,
        };
        let request = call.request.clone();
        asked
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(request.step);
        let Some((at, d)) = decisions
            .iter()
            .find(|(_, d)| d.session_id == request.session_id && d.step == request.step)
        else {
            anyhow::bail!("a decision for step {} nobody recorded", request.step);
        };
        anyhow::ensure!(
            d.state == request.state,
            "step {}: asked for {:?}, the recorded decision was for {:?}",
            request.step,
            request.state,
            d.state
        );
        clock.sleep_until(*at).await;
        call.respond(DecideActionResponse {
            ok: true,
            error: String::new(),
            decision: d.clone(),
        });
    }
}

// ---------------------------------------------------------------------------------------
// The user model

/// The user model has no input in a bag (nobody called PredictUser or AssignCluster in the
/// samples, and calls are not recorded): its one output is the announcement of its model
/// file. Started at the recorded announcement's stamp with the launch's parameters: equal in
/// every field (the model file named by the path the launch gave, here absolute).
#[test]
fn the_user_model_replayed_announces_the_recorded_models() {
    for sample in &SAMPLES {
        let f = sample.file;
        let bag = open(sample);
        let (first, last) = span(&bag);
        let live = recorded::<UserModelInfo>(&bag, USER_MODEL_INFO.name);
        assert_eq!(live.len(), 1, "{f}");
        let started = live[0].1.header.stamp.to_nanos();
        let replayed = virtual_time(async move {
            let mut r = Replay::new(Vec::new(), &[USER_MODEL_INFO.name], first.min(started));
            let (defaults, _) = parameters::<user_model::UserModelParams>("user_model", &[]);
            let (params, path) = parameters::<user_model::UserModelParams>(
                "user_model",
                &[absolute("model_file", &defaults.model_file)],
            );
            r.start(
                user_model::node::NODE,
                started,
                Box::new(move |bus| {
                    Box::pin(async move { user_model::node::run(bus, params, &path).await })
                }),
            );
            r.finish(Some(last)).await.bag
        });
        let got = recorded::<UserModelInfo>(&replayed, USER_MODEL_INFO.name);
        assert_eq!(got.len(), 1, "{f}");
        let (mut got, live) = (got[0].1.clone(), live[0].1.clone());
        assert_eq!(got.model_file, workspace_file(&live.model_file), "{f}");
        got.model_file = live.model_file.clone();
        assert_eq!(got, live, "{f}");
    }
}

// ---------------------------------------------------------------------------------------
// The tablet bridge

/// What the two pages were sent, as JSON.
#[derive(Default)]
struct Pages {
    child: Vec<serde_json::Value>,
    therapist: Vec<serde_json::Value>,
}

/// The bridge's DDS side: inputs are every topic it reads (game states, tasks, decisions,
/// results, proposals, engagement, heartbeats) at their log times; a child's page and a
/// therapist's page are connected at its start, and what the session's tablet and therapist
/// did is done on them at the recorded times: each recorded answer tapped on the child's page,
/// each recorded command given on the therapist's page. (In the samples the simulated child
/// and the console sent those over DDS themselves; the bridge published nothing but its
/// heartbeat.) Compared: the answers the bridge publishes with the recorded ones, exactly but
/// their stamps (the bridge stamps receipt, within 100 ms of the child's); its commands with
/// the recorded ones in kind, session, user, cluster and level (a START from the page names
/// its own session, tablet-<ms>, and ids are the bridge's own), stamps within 100 ms. The
/// child's page is shown each recorded task once, the therapist's page each recorded result,
/// and never a game manager lost.
#[test]
fn the_tablet_bridge_replayed_publishes_what_its_pages_did() {
    use tablet_bridge::node::{EVENT_QUEUE, PageEvent, ToPage};
    use tablet_bridge::protocol::Role;
    use tokio::sync::{mpsc, oneshot};
    for sample in &SAMPLES {
        let f = sample.file;
        let bag = open(sample);
        let (first, last) = span(&bag);
        let inputs = recorded_inputs(
            &bag,
            &[
                GAME_STATE.name,
                TABLET_TASK.name,
                DECISION.name,
                SEQUENCE_RESULT.name,
                ACTION_PROPOSAL.name,
                EXPECTED_ENGAGEMENT.name,
                HEARTBEAT.name,
            ],
        );
        let answers = recorded::<TabletAnswer>(&bag, TABLET_ANSWER.name);
        let commands = recorded::<TherapistCommand>(&bag, THERAPIST_COMMAND.name);
        let (page_answers, page_commands) = (answers.clone(), commands.clone());
        let started = first - 100 * MS;
        let (replayed, pages) = virtual_time(async move {
            let mut r = Replay::new(
                inputs,
                &[TABLET_ANSWER.name, THERAPIST_COMMAND.name],
                started,
            );
            let (params, _) =
                parameters::<tablet_bridge::TabletBridgeParams>(tablet_bridge::node::NODE, &[]);
            params.validate().expect("valid bridge parameters");
            let pin = params.pin.clone();
            let (events, from_pages) = mpsc::channel(EVENT_QUEUE);
            r.start(
                tablet_bridge::node::NODE,
                started,
                Box::new(move |bus| Box::pin(tablet_bridge::node::run(bus, params, from_pages))),
            );
            let clock = r.clock();
            let pages = tokio::spawn(async move {
                clock.sleep_until(started + MS).await;
                let connect = async |role| {
                    let (out, rx) = mpsc::channel::<ToPage>(1024);
                    let (reply, id) = oneshot::channel();
                    events
                        .send(PageEvent::Connect { role, out, reply })
                        .await
                        .expect("the bridge takes pages");
                    let id = id.await.expect("an answer").expect("the page is let in");
                    (id, rx)
                };
                let (child, mut child_rx) = connect(Role::Child).await;
                let (therapist, mut therapist_rx) = connect(Role::Therapist).await;
                let text = |id, v: serde_json::Value| PageEvent::Text(id, v.to_string());
                events
                    .send(text(
                        therapist,
                        serde_json::json!({"type": "login", "pin": pin}),
                    ))
                    .await
                    .expect("sent");
                let mut taps: Vec<(i64, PageEvent)> = page_answers
                    .iter()
                    .map(|(t, a)| {
                        let v = serde_json::json!({
                            "type": "answer",
                            "sequence_id": a.sequence_id,
                            "answer": a.answer,
                            "response_time": a.response_time,
                        });
                        (*t, text(child, v))
                    })
                    .collect();
                for (t, c) in &page_commands {
                    let command = match c.command {
                        TherapistCommand::START => "start",
                        TherapistCommand::PAUSE => "pause",
                        TherapistCommand::RESUME => "resume",
                        TherapistCommand::STOP => "stop",
                        TherapistCommand::OVERRIDE_LEVEL => "override_level",
                        other => panic!("a command the samples do not give: {other}"),
                    };
                    let mut v =
                        serde_json::json!({"type": "command", "pin": pin, "command": command});
                    if c.command == TherapistCommand::START {
                        v["user_id"] = c.user_id.clone().into();
                        v["cluster"] = c.user_model_cluster.into();
                    }
                    if c.command == TherapistCommand::OVERRIDE_LEVEL {
                        v["level"] = c.level.into();
                    }
                    taps.push((*t, text(therapist, v)));
                }
                taps.sort_by_key(|(t, _)| *t);
                for (t, event) in taps {
                    clock.sleep_until(t).await;
                    events
                        .send(event)
                        .await
                        .expect("the bridge takes page messages");
                }
                // What the pages were sent, until the bridge stops and drops them.
                drop(events);
                let mut pages = Pages::default();
                let read = |m: ToPage| match m {
                    ToPage::Text(t) => serde_json::from_str(&t).expect("JSON"),
                    ToPage::Close(reason) => serde_json::json!({"closed": reason}),
                };
                loop {
                    tokio::select! {
                        Some(m) = child_rx.recv() => pages.child.push(read(m)),
                        Some(m) = therapist_rx.recv() => pages.therapist.push(read(m)),
                        else => break,
                    }
                }
                pages
            });
            let bag = r.finish(Some(last)).await.bag;
            (bag, pages.await.expect("the pages' task"))
        });

        // The bridge stamps what a page sends when it takes it: the time it was tapped, the
        // recorded log time (to the next ms).
        let got = recorded::<TabletAnswer>(&replayed, TABLET_ANSWER.name);
        let stamped = |a: &[(i64, TabletAnswer)]| -> Vec<(i64, TabletAnswer)> {
            a.iter()
                .map(|(_, a)| unstamped(a, |a| &mut a.header))
                .collect()
        };
        let logged = |a: &[(i64, TabletAnswer)]| -> Vec<(i64, TabletAnswer)> {
            a.iter()
                .map(|(t, a)| (*t, unstamped(a, |a| &mut a.header).1))
                .collect()
        };
        let worst = same_messages(
            &format!("{f}: answers"),
            &stamped(&got),
            &logged(&answers),
            MS,
        );
        let got = recorded::<TherapistCommand>(&replayed, THERAPIST_COMMAND.name);
        let comparable =
            |c: &[(i64, TherapistCommand)], at_log: bool| -> Vec<(i64, TherapistCommand)> {
                c.iter()
                    .map(|(log, c)| {
                        let (t, mut c) = unstamped(c, |c| &mut c.header);
                        c.command_id = 0;
                        if c.command == TherapistCommand::START {
                            c.session_id = String::new();
                        } else {
                            // Only a START names the user (the console leaves 0, a page -1).
                            c.user_model_cluster = 0;
                        }
                        (if at_log { *log } else { t }, c)
                    })
                    .collect()
            };
        let worst = worst.max(same_messages(
            &format!("{f}: commands"),
            &comparable(&got, false),
            &comparable(&commands, true),
            MS,
        ));
        for (_, c) in got
            .iter()
            .filter(|(_, c)| c.command == TherapistCommand::START)
        {
            assert!(c.session_id.starts_with("tablet-"), "{f}: {c:?}");
        }
        // What the pages were shown.
        let tasks: Vec<u64> = pages
            .child
            .iter()
            .filter(|m| m["type"] == "task")
            .map(|m| m["sequence_id"].as_u64().unwrap_or(0))
            .collect();
        let live_tasks: Vec<u64> = recorded::<TabletTask>(&bag, TABLET_TASK.name)
            .iter()
            .map(|(_, t)| u64::from(t.sequence_id))
            .collect();
        assert_eq!(tasks, live_tasks, "{f}: the tasks on the child's page");
        let rows: Vec<(String, u64)> = pages
            .therapist
            .iter()
            .filter(|m| m["type"] == "result")
            .map(|m| {
                (
                    m["session_id"].as_str().unwrap_or("").to_string(),
                    m["sequence_index"].as_u64().unwrap_or(0),
                )
            })
            .collect();
        let live_rows: Vec<(String, u64)> = recorded::<SequenceResult>(&bag, SEQUENCE_RESULT.name)
            .iter()
            .map(|(_, r)| (r.session_id.clone(), u64::from(r.sequence_index)))
            .collect();
        assert_eq!(rows, live_rows, "{f}: the results on the therapist's page");
        assert!(
            pages.therapist.iter().all(|m| !m["status"]
                .as_str()
                .unwrap_or("")
                .starts_with("game manager lost")),
            "{f}: the game manager shown lost"
        );
        eprintln!(
            "{f}: {} answers and {} commands from the pages as recorded, within {:.1} ms",
            answers.len(),
            commands.len(),
            worst as f64 * 1e-6
        );
    }
}

// ---------------------------------------------------------------------------------------
// The simulated child

/// The child's frame period at the launch's 30 fps.
const FRAME_NS: i64 = 33_333_333;

/// The most frames the recorder may have missed before its reader matched the child's writer.
const MISSED_FRAMES: i64 = 90;

/// Inputs: the game states, tablet tasks and robot faces at their log times; the child starts
/// at its frame clock's origin (the first recorded frame's stamp, or up to [`MISSED_FRAMES`]
/// frames before it where the recorder's reader matched late: the start that draws the first
/// recorded frame alike) with the launch's parameters (the sample's seed, cluster and time scale).
///
/// Compared: the frame clock, every recorded frame on the child's 30 fps grid from its origin
/// (within 1 ms: the live child stamps a frame with its steady clock plus the wall clock's
/// offset, read anew each tick, so a stamp wanders by microseconds) and a replayed frame at
/// that grid point, the replayed frames the bag lacks at most 2 % (frames the recorder lost, or
/// the live child skipped on a stall), each with the recorded face id and camera; what the
/// child drew for each frame (its gaze, lost face, features): the same for every frame (each
/// frame's draws are keyed by its index on the frame clock); every
/// replayed answer answers a recorded task, once, with the recorded answer's emotions (the
/// child's draws for it: outcome and mistakes), for the task's session, stamped after the
/// task arrived.
#[test]
fn the_simulated_child_replayed_keeps_the_recorded_frame_clock_and_answers_its_tasks() {
    for sample in &SAMPLES {
        let f = sample.file;
        let bag = open(sample);
        let (_, last) = span(&bag);
        let frames = recorded::<OpenFaceFeatures>(&bag, OPENFACE_FEATURES.name);
        let first = frames[0].1.header.stamp.to_nanos();
        let inputs = recorded_inputs(
            &bag,
            &[GAME_STATE.name, TABLET_TASK.name, ROBOT_EMOTION.name],
        );
        let (seed, cluster, time_scale) = (sample.seed, sample.cluster, sample.time_scale);
        let replay_from = |origin: i64| {
            let inputs = inputs.clone();
            virtual_time(async move {
                let mut r = Replay::new(
                    inputs,
                    &[OPENFACE_FEATURES.name, TABLET_ANSWER.name],
                    origin,
                );
                let (defaults, _) =
                    parameters::<simulated_child::ChildParams>(simulated_child::node::NODE, &[]);
                let (params, _) = parameters::<simulated_child::ChildParams>(
                    simulated_child::node::NODE,
                    &[
                        absolute("user_model_file", &defaults.user_model_file),
                        format!("seed:={seed}"),
                        format!("cluster:={cluster}"),
                        format!("time_scale:={time_scale}"),
                    ],
                );
                r.start(
                    simulated_child::node::NODE,
                    origin,
                    Box::new(move |bus| Box::pin(simulated_child::node::run(bus, params))),
                );
                r.finish(Some(last)).await.bag
            })
        };
        let frames_of = |bag: &BagReader| -> BTreeMap<i64, OpenFaceFeatures> {
            recorded::<OpenFaceFeatures>(bag, OPENFACE_FEATURES.name)
                .into_iter()
                .map(|(_, m)| (m.header.stamp.to_nanos(), m))
                .collect()
        };
        let drawn_alike = |got: &OpenFaceFeatures, live: &OpenFaceFeatures| {
            let mut drawn = got.clone();
            drawn.header.stamp = live.header.stamp.clone();
            &drawn == live
        };
        // The child's origin, its frame 0: the recorder hears its frames only once its reader
        // has matched (best effort, volatile), so the first recorded frame may be a later one.
        // The child started then or up to `MISSED_FRAMES` frames earlier: the start whose
        // replay draws the first recorded frame as the live child did.
        let (missed, origin, replayed) = (0..=MISSED_FRAMES)
            .find_map(|k0| {
                let origin = first - k0 * FRAME_NS;
                let replayed = replay_from(origin);
                frames_of(&replayed)
                    .get(&origin.saturating_add(k0 * FRAME_NS))
                    .is_some_and(|got| drawn_alike(got, &frames[0].1))
                    .then_some((k0, origin, replayed))
            })
            .unwrap_or_else(|| {
                panic!(
                    "{f}: no start up to {MISSED_FRAMES} frames before the first recorded draws it"
                )
            });
        let replayed_frames = frames_of(&replayed);
        let mut equal = 0;
        let mut wander: i64 = 0;
        for (_, live) in &frames {
            let t = live.header.stamp.to_nanos();
            let k = ((t - origin) as f64 / FRAME_NS as f64).round() as i64;
            let off = t - origin - k * FRAME_NS;
            assert!(
                off.abs() <= MS,
                "{f}: frame {k} {off} ns off the child's frame clock"
            );
            wander = wander.max(off.abs());
            let on_grid = origin + k * FRAME_NS;
            let got = replayed_frames
                .get(&on_grid)
                .unwrap_or_else(|| panic!("{f}: frame {k} not replayed"));
            assert_eq!(
                (&got.face_id, &got.header.frame_id),
                (&live.face_id, &live.header.frame_id),
                "{f}: frame {k}"
            );
            equal += usize::from(drawn_alike(got, live));
        }
        assert_eq!(equal, frames.len(), "{f}: frames drawn the same");
        assert!(
            replayed_frames.keys().all(|t| (t - origin) % FRAME_NS == 0),
            "{f}: a replayed frame off the frame clock"
        );
        // Frames before the first recorded one are the ones the recorder missed.
        let extra = replayed_frames.range(first..).count() - frames.len();
        assert!(
            extra * 50 <= frames.len(),
            "{f}: {extra} replayed frames the bag lacks"
        );

        let tasks = recorded::<TabletTask>(&bag, TABLET_TASK.name);
        let answers = recorded::<TabletAnswer>(&replayed, TABLET_ANSWER.name);
        let mut answered = BTreeSet::new();
        for (_, a) in &answers {
            let (arrived, task) = tasks
                .iter()
                .find(|(_, t)| t.session_id == a.session_id && t.sequence_id == a.sequence_id)
                .unwrap_or_else(|| panic!("{f}: an answer to no recorded task: {a:?}"));
            assert!(
                answered.insert(a.sequence_id),
                "{f}: task {} answered twice",
                a.sequence_id
            );
            assert_eq!(a.answer.len(), usize::from(task.length), "{f}: {a:?}");
            let live = recorded::<TabletAnswer>(&bag, TABLET_ANSWER.name)
                .into_iter()
                .find(|(_, l)| l.session_id == a.session_id && l.sequence_id == a.sequence_id)
                .map(|(_, l)| l.answer);
            assert_eq!(
                Some(&a.answer),
                live.as_ref(),
                "{f}: task {}'s answer",
                a.sequence_id
            );
            assert!(
                a.header.stamp.to_nanos() > *arrived,
                "{f}: answered before the task: {a:?}"
            );
        }
        assert!(!answers.is_empty(), "{f}: no task answered");
        eprintln!(
            "{f}: {} frames on the recorded frame clock (from frame {missed}; within {wander} \
             ns; {extra} more replayed; {equal} drawn the same); {} of {} tasks answered as \
             recorded (the live child answered {})",
            frames.len(),
            answers.len(),
            tasks.len(),
            recorded::<TabletAnswer>(&bag, TABLET_ANSWER.name).len()
        );
    }
}

// ---------------------------------------------------------------------------------------
// The OpenFace bridge

/// The samples' faces came from the simulated child, not from OpenFace: the OpenFace bridge's
/// input, a CSV, is not in a bag. What can be replayed is the camera's side: the recorded
/// frames written as OpenFace's FeatureExtraction writes its CSV (its header and columns: frame
/// from 1, face_id, timestamp in seconds to the millisecond, confidence, success, then gaze,
/// pose and action units by OpenFace's names; values in full precision, where OpenFace
/// writes a few decimals, so that they can compare exactly), replayed by the bridge's loop
/// (`replay_rate: 1`) on the in-process bus. Compared: every frame with a face (a lost face,
/// success 0, is skipped by the bridge, as it is for OpenFace), in order, exactly in face,
/// camera frame, confidence, success and features; its stamp, from the first frame's, within
/// 1 ms of the recorded one's (OpenFace's timestamps have milliseconds).
#[test]
fn the_openface_bridge_replays_the_recorded_faces_from_openfaces_csv() {
    for sample in &SAMPLES {
        let f = sample.file;
        let bag = open(sample);
        let (first, _) = span(&bag);
        let frames: Vec<OpenFaceFeatures> =
            recorded::<OpenFaceFeatures>(&bag, OPENFACE_FEATURES.name)
                .into_iter()
                .map(|(_, m)| m)
                .collect();
        let dir = tempfile::tempdir().expect("a temporary directory");
        let csv = dir.path().join("webcam.csv");
        std::fs::write(&csv, openface_csv(&frames)).expect("the CSV");
        let (csv_path, frame_id) = (csv.display().to_string(), frames[0].header.frame_id.clone());
        let replayed = virtual_time(async move {
            let mut r = Replay::new(Vec::new(), &[OPENFACE_FEATURES.name], first);
            let (params, _) = parameters::<openface_bridge::OpenFaceBridgeParams>(
                openface_bridge::node::NODE,
                &[
                    format!("csv_path:={csv_path}"),
                    "replay_rate:=1.0".into(),
                    format!("frame_id:={frame_id}"),
                ],
            );
            let stamp = params.validate().expect("valid parameters");
            let bridge = openface_bridge::Bridge::new(&params, stamp);
            r.start(
                openface_bridge::node::NODE,
                first,
                Box::new(move |bus| {
                    Box::pin(async move { openface_bridge::node::run(bus, &params, bridge).await })
                }),
            );
            r.finish(None).await.bag
        });
        let got: Vec<OpenFaceFeatures> =
            recorded::<OpenFaceFeatures>(&replayed, OPENFACE_FEATURES.name)
                .into_iter()
                .map(|(_, m)| m)
                .collect();
        let faces: Vec<&OpenFaceFeatures> = frames.iter().filter(|m| m.success).collect();
        assert_eq!(got.len(), faces.len(), "{f}: frames with a face");
        let (t0, r0) = (
            faces[0].header.stamp.to_nanos(),
            got[0].header.stamp.to_nanos(),
        );
        let mut worst = 0;
        for (g, live) in got.iter().zip(&faces) {
            let apart =
                ((g.header.stamp.to_nanos() - r0) - (live.header.stamp.to_nanos() - t0)).abs();
            worst = worst.max(apart);
            let (mut g, mut live) = (g.clone(), (*live).clone());
            g.header.stamp = Time::default();
            live.header.stamp = Time::default();
            assert_eq!(g, live, "{f}");
        }
        assert!(
            worst <= MS,
            "{f}: stamps {worst} ns from the recorded spacing"
        );
        eprintln!(
            "{f}: {} frames through OpenFace's CSV equal, stamps within {:.3} ms",
            got.len(),
            worst as f64 * 1e-6
        );
    }
}

/// The frames as OpenFace 2.2's FeatureExtraction (-pose -aus -gaze) writes them, landmarks
/// left out (the bridge maps columns by name): ", "-separated, gaze first, then pose, then the
/// action units' intensities and presences.
fn openface_csv(frames: &[OpenFaceFeatures]) -> String {
    use qt_therapy_msgs::OPENFACE_FEATURES as NAMES;
    // Our feature order is pose (6), action units (18), gaze (8); OpenFace's is gaze, pose, AUs.
    let order: Vec<usize> = (24..32).chain(0..24).collect();
    let mut text = ["frame", "face_id", "timestamp", "confidence", "success"]
        .into_iter()
        .chain(order.iter().map(|&k| NAMES[k]))
        .collect::<Vec<&str>>()
        .join(", ");
    text.push('\n');
    let t0 = frames[0].header.stamp.to_nanos();
    for (n, m) in frames.iter().enumerate() {
        let t = (m.header.stamp.to_nanos() - t0) as f64 * 1e-9;
        let mut row = format!(
            "{}, {}, {t:.3}, {}, {}",
            n + 1,
            m.face_id,
            m.confidence,
            u8::from(m.success)
        );
        for &k in &order {
            row.push_str(&format!(", {}", m.features[k]));
        }
        text.push_str(&row);
        text.push('\n');
    }
    text
}

// ---------------------------------------------------------------------------------------
// The bag recorder

/// The recorder replayed: every recorded message of the suite's topics is played at its log
/// time and the recorder (whose bag every other replay reads) records all the suite's topics. Compared, topic by
/// topic: the same channels (type, schema, offered QoS), the same messages byte for byte in
/// order, each logged within 1 ms after its original log time; besides them only the player's
/// own heartbeats, and channels of topics the session did not use, empty. What a replay cannot
/// give back: the original publishers' publish times and sequence numbers (the player's are
/// recorded: its publish time is the log time).
#[test]
fn the_recorder_replayed_records_the_recorded_bag() {
    for sample in &SAMPLES {
        let f = sample.file;
        let bag = open(sample);
        let (first, last) = span(&bag);
        // The suite's own topics: `bag record --all` also took the graph's others (/rosout,
        // /parameter_events, the ROS4HRI persons), which the replay's bus does not carry.
        let suite: BTreeSet<&str> = qt_therapy_msgs::topics::all_topics()
            .into_iter()
            .map(|t| t.name)
            .collect();
        let topics: Vec<&str> = bag
            .channels()
            .map(|c| c.topic.as_str())
            .filter(|t| suite.contains(t))
            .collect();
        let inputs = recorded_inputs(&bag, &topics);
        let replayed = virtual_time(async move {
            let r = Replay::new(inputs, &[], first);
            r.finish(Some(last + 10 * MS)).await.bag
        });
        let mut compared = 0;
        for channel in bag.channels().filter(|c| suite.contains(c.topic.as_str())) {
            let topic = channel.topic.as_str();
            let got = replayed.topic_channels(topic);
            assert_eq!(got.len(), 1, "{f}: {topic}");
            let got = got[0];
            assert_eq!(
                (got.type_name(), got.metadata.get("offered_qos_profiles")),
                (
                    channel.type_name(),
                    channel.metadata.get("offered_qos_profiles")
                ),
                "{f}: {topic}'s channel"
            );
            // The schema is today's definition of the type, which may have grown since the
            // sample was recorded (constants added: the CDR is the same).
            let today = qt_therapy_msgs::topics::all_topics()
                .into_iter()
                .find(|t| t.name == topic)
                .map(|t| t.schema_text)
                .unwrap_or_else(|| panic!("{topic} is not in the topic table"));
            assert_eq!(
                got.schema
                    .as_ref()
                    .map(|s| String::from_utf8_lossy(&s.data).to_string()),
                Some(today),
                "{f}: {topic}'s schema"
            );
            let of = |b: &BagReader, id: u16| -> Vec<(u64, u64, Vec<u8>)> {
                b.raw_messages()
                    .iter()
                    .filter(|m| m.channel_id == id)
                    .map(|m| (m.log_time, m.publish_time, m.data.clone()))
                    .collect()
            };
            let mut replayed_messages = of(&replayed, got.id);
            if topic == HEARTBEAT.name {
                replayed_messages.retain(|(_, _, data)| {
                    bag_file::cdr::decode::<Heartbeat>(data)
                        .map(|h| h.node_name)
                        .unwrap_or_default()
                        != "bag_player"
                });
            }
            let original = of(&bag, channel.id);
            assert_eq!(replayed_messages.len(), original.len(), "{f}: {topic}");
            for (i, (r, o)) in replayed_messages.iter().zip(&original).enumerate() {
                assert!(r.2 == o.2, "{f}: {topic} #{i}: other bytes");
                assert!(
                    r.0 >= o.0 && r.0 - o.0 <= MS as u64 && r.1 == r.0,
                    "{f}: {topic} #{i}: logged at {} (published {}), recorded at {}",
                    r.0,
                    r.1,
                    o.0
                );
            }
            compared += original.len();
        }
        for c in replayed.channels() {
            if bag.topic_channels(&c.topic).is_empty() {
                assert!(
                    replayed.raw_messages().iter().all(|m| m.channel_id != c.id),
                    "{f}: messages on {}",
                    c.topic
                );
            }
        }
        eprintln!("{f}: {compared} messages recorded again, byte for byte");
    }
}

// ---------------------------------------------------------------------------------------
// The therapist console

/// Inputs: the game states, results, decisions and proposals at their log times. The console's
/// `run-session --user U --cluster K` starts half a second (its wait for the game's state to
/// settle) before the recorded START was sent, and each other recorded command is given as
/// the one-shot command the therapist typed (`therapist pause --session S`, ...) at the time it
/// was sent; neither start is in a bag, and both name their commands by the clock. Compared:
/// every command, exactly (kind, session, id, user, cluster, level, stamp); each answered by the
/// recorded game manager (a one-shot exits 0), and `run-session` follows the session to its
/// end: a line per result, exit 0 when it finished, 3 when the therapist stopped it.
#[test]
fn the_therapist_console_replayed_gives_the_recorded_commands() {
    use therapist_console::console::{Console, Follow, Start};
    for sample in &SAMPLES {
        let f = sample.file;
        let bag = open(sample);

        let commands = recorded::<TherapistCommand>(&bag, THERAPIST_COMMAND.name);
        let start = start_command(&bag);
        let inputs = recorded_inputs(
            &bag,
            &[
                GAME_STATE.name,
                SEQUENCE_RESULT.name,
                DECISION.name,
                ACTION_PROPOSAL.name,
            ],
        );
        let exits = Arc::new(Mutex::new(Vec::new()));
        let lines = Arc::new(Mutex::new(Vec::new()));
        let started = start.header.stamp.to_nanos() - 500 * MS;
        let (said, codes) = (lines.clone(), exits.clone());
        let one_shots: Vec<TherapistCommand> = commands
            .iter()
            .map(|(_, c)| c.clone())
            .filter(|c| c.command != TherapistCommand::START)
            .collect();
        let replayed = virtual_time(async move {
            let mut r = Replay::new(inputs, &[THERAPIST_COMMAND.name], started);
            let session_start = Start {
                user: start.user_id.clone(),
                cluster: start.user_model_cluster,
                session: None,
                wait: Duration::from_secs(60),
            };
            let follow = Follow {
                timeout: Duration::from_secs(1800),
                sessions: 1,
                accept_proposals: false,
            };
            let run_codes = codes.clone();
            r.start(
                therapist_console::console::NODE,
                started,
                Box::new(move |bus| {
                    Box::pin(async move {
                        let code = {
                            let mut console = Console::new(bus, move |line: &str| {
                                said.lock()
                                    .unwrap_or_else(|e| e.into_inner())
                                    .push(line.to_string())
                            })?;
                            console.run_session(&session_start, follow).await?
                        };
                        run_codes
                            .lock()
                            .unwrap_or_else(|e| e.into_inner())
                            .push(("run-session".to_string(), code));
                        Ok(())
                    })
                }),
            );
            for c in one_shots {
                let codes = codes.clone();
                r.start(
                    therapist_console::console::NODE,
                    c.header.stamp.to_nanos(),
                    Box::new(move |bus| {
                        Box::pin(async move {
                            let mut console = Console::new(bus, |_: &str| {})?;
                            let mut command = console.command(c.command, &c.session_id);
                            command.level = c.level;
                            let code = console.send(command).await?;
                            codes
                                .lock()
                                .unwrap_or_else(|e| e.into_inner())
                                .push((format!("command {}", c.command), code));
                            Ok(())
                        })
                    }),
                );
            }
            r.finish(None).await.bag
        });
        let got = recorded::<TherapistCommand>(&replayed, THERAPIST_COMMAND.name);
        let messages = |c: &[(i64, TherapistCommand)]| -> Vec<TherapistCommand> {
            c.iter().map(|(_, c)| c.clone()).collect()
        };
        assert_eq!(messages(&got), messages(&commands), "{f}: commands");
        let exits = exits.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let lines = lines.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let finished = sample.sequences == 10;
        let mut expected: Vec<(String, i32)> = commands
            .iter()
            .filter(|(_, c)| c.command != TherapistCommand::START)
            .map(|(_, c)| (format!("command {}", c.command), 0))
            .collect();
        expected.push(("run-session".into(), if finished { 0 } else { 3 }));
        let mut sorted = exits.clone();
        sorted.sort();
        expected.sort();
        assert_eq!(sorted, expected, "{f}: exit codes\n{}", lines.join("\n"));
        assert_eq!(
            lines.iter().filter(|l| l.starts_with("seq ")).count(),
            sample.sequences,
            "{f}: a line per result\n{}",
            lines.join("\n")
        );
        eprintln!(
            "{f}: {} commands equal; the console's lines:\n{}",
            got.len(),
            lines.join("\n")
        );
    }
}
