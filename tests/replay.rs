//! Replay tests: the sample sessions in bags/ (recorded from the simulated suite, every node a
//! process over DDS) go through the nodes' sans-IO cores in-process, with message time as the
//! clock, and what comes out is compared with what the live nodes published in that session:
//! the engagement classifier (recorded faces -> per-frame estimates and per-second
//! engagement), the behaviour policy (recorded states -> decisions, from the Q-tables it
//! started with and the same seed) and the game manager (recorded therapist commands,
//! decisions, answers and engagement -> results, game states, tablet tasks and robot acts).
//! The last test replays the faces over real DDS into a real `engagement_classifier run`.

use bag_file::BagReader;
use behaviour_policy::BehaviourPolicyParams;
use engagement_classifier::messages::{Sources, source_name};
use engagement_classifier::{
    EngagementClassifierParams, EngagementEstimator, EngagementSecond, FrameOutcome,
};
use game_manager::{GameManager, GameManagerParams, Input, Output};
use q_learning::messages::transition;
use q_learning::{PolicyCore, QTableFile};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::{Header, StringMsg};
use qt_therapy_msgs::topics::{
    DECISION, ENGAGEMENT_ESTIMATE, EXPECTED_ENGAGEMENT, GAME_STATE, OPENFACE_FEATURES,
    ROBOT_EMOTION, ROBOT_GESTURE, ROBOT_SPEECH, SEQUENCE_RESULT, TABLET_ANSWER, TABLET_TASK,
    THERAPIST_COMMAND,
};
use qt_therapy_msgs::{
    DecideActionRequest, DecideActionResponse, Decision, EngagementEstimate, ExpectedEngagement,
    GameState, OpenFaceFeatures, SequenceResult, TabletAnswer, TabletTask, TherapistCommand,
};
use sequence_game::SEQUENCES_PER_SESSION;
use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::time::Duration;
use suite_tests::{run_in_loopback_netns, workspace_bin, workspace_root};

/// A sample bag and the launch arguments it was recorded with (bags/README.md,
/// bags/record_samples.sh); every other parameter is the repository's params/ default.
struct Sample {
    file: &'static str,
    /// `seed:=` of the launch: the game manager's (and the simulated child's) seed.
    game_seed: i64,
    /// `time_scale:=` of the launch (0.2 by default).
    time_scale: f64,
    cluster: i32,
    /// Sequences played (10 unless the therapist stopped the session).
    sequences: usize,
}

const SAMPLES: [Sample; 3] = [
    Sample {
        file: "cluster0_seed7.mcap",
        game_seed: 7,
        time_scale: 0.2,
        cluster: 0,
        sequences: 10,
    },
    Sample {
        file: "cluster1_seed11_pause_override.mcap",
        game_seed: 11,
        time_scale: 0.2,
        cluster: 1,
        sequences: 10,
    },
    Sample {
        file: "cluster0_seed3_stopped.mcap",
        game_seed: 3,
        time_scale: 0.2,
        cluster: 0,
        sequences: 4,
    },
];

fn bag_path(sample: &Sample) -> PathBuf {
    workspace_root().join("bags").join(sample.file)
}

/// The sample, which must be complete and undamaged.
fn open(sample: &Sample) -> BagReader {
    let path = bag_path(sample);
    BagReader::open(&path)
        .and_then(BagReader::strict)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A node's parameters as the launch gave them: the file in params/.
fn params<P: serde::de::DeserializeOwned>(node: &str) -> P {
    let path = workspace_root().join(format!("params/{node}.yaml"));
    node_shell::params::load_parameters(&path, node)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// (log time, message) of one topic.
fn recorded<M: qt_therapy_msgs::MessageDefinition>(
    reader: &BagReader,
    topic: &str,
) -> Vec<(i64, M)> {
    reader
        .messages::<M>(topic)
        .unwrap_or_else(|e| panic!("{topic}: {e}"))
        .into_iter()
        .map(|s| (s.log_time as i64, s.message))
        .collect()
}

// ---------------------------------------------------------------------------------------
// (a) Engagement classifier

/// What the classifier core gives for a stream of frames, converted as `engagement_classifier
/// run` converts it.
struct Classified {
    /// (frame stamp, "<camera>/<face>") -> (label, probability bits); NaN for a missing face.
    estimates: BTreeMap<(i64, String), (i8, u32)>,
    /// (source, window start) -> the second as the node publishes it.
    seconds: BTreeMap<(String, i64), ExpectedEngagement>,
    refused: usize,
}

/// Frames in the order given, message time = their stamps, then the end of the stream.
fn classify<'a>(frames: impl IntoIterator<Item = &'a OpenFaceFeatures>) -> Classified {
    let p: EngagementClassifierParams = params("engagement_classifier");
    let mut estimator =
        EngagementEstimator::from_params(&p, &workspace_root()).expect("the launch's model loads");
    // The node's own conversion of messages (engagement_classifier::messages).
    let mut sources = Sources::default();
    let mut closed: Vec<EngagementSecond> = Vec::new();
    let mut out = Classified {
        estimates: BTreeMap::new(),
        seconds: BTreeMap::new(),
        refused: 0,
    };
    for frame in frames {
        let name = source_name(frame);
        let face = sources.face_frame(frame);
        let stamp_ns = face.stamp_ns;
        match estimator.on_frame(&face, &mut |s| closed.push(*s)) {
            Ok(FrameOutcome::Classified(p)) => {
                out.estimates
                    .insert((stamp_ns, name), (p.label, p.probability.to_bits()));
            }
            Ok(FrameOutcome::Missing(_)) => {
                out.estimates.insert(
                    (stamp_ns, name),
                    (EngagementEstimate::MISSING, f32::NAN.to_bits()),
                );
            }
            Err(_) => out.refused += 1,
        }
    }
    estimator.flush(&mut |s| closed.push(*s));
    for s in closed {
        let e = sources.expected_engagement(&s);
        out.seconds.insert((e.source.clone(), s.window_start_ns), e);
    }
    out
}

/// The recorded seconds by (source, window start).
fn recorded_seconds(reader: &BagReader) -> BTreeMap<(String, i64), ExpectedEngagement> {
    recorded::<ExpectedEngagement>(reader, EXPECTED_ENGAGEMENT.name)
        .into_iter()
        .map(|(_, e)| ((e.source.clone(), e.window_start.to_nanos()), e))
        .collect()
}

/// The recorded frames the live classifier saw: those it published an estimate for. A frame
/// the bag holds without one did not reach the classifier: at startup, before its reader had
/// matched the child's writer (best-effort, volatile: a reader gets only what is published
/// after it matched), or later, dropped on the best-effort topic while the machine was busy.
/// (Were an estimate lost instead, between the classifier and the recorder, that second's
/// counts would differ from the replay's and the test fail.) Returns them and how many were
/// left out.
fn frames_the_classifier_saw(reader: &BagReader) -> (Vec<OpenFaceFeatures>, usize) {
    let seen: BTreeSet<(i64, String)> =
        recorded::<EngagementEstimate>(reader, ENGAGEMENT_ESTIMATE.name)
            .into_iter()
            .map(|(_, e)| {
                (
                    e.header.stamp.to_nanos(),
                    format!("{}/{}", e.header.frame_id, e.face_id),
                )
            })
            .collect();
    let all = recorded::<OpenFaceFeatures>(reader, OPENFACE_FEATURES.name);
    let total = all.len();
    let frames: Vec<OpenFaceFeatures> = all
        .into_iter()
        .map(|(_, f)| f)
        .filter(|f| seen.contains(&(f.header.stamp.to_nanos(), source_name(f))))
        .collect();
    let unseen = total - frames.len();
    (frames, unseen)
}

#[test]
fn recorded_faces_give_the_recorded_estimates_and_engagement_per_second() {
    for sample in &SAMPLES {
        let f = sample.file;
        let reader = open(sample);
        let (frames, unseen) = frames_the_classifier_saw(&reader);
        // A few: at most 2 % of the frames.
        assert!(
            unseen * 50 <= frames.len(),
            "{f}: {unseen} recorded frames the classifier never saw"
        );
        let replay = classify(&frames);
        assert_eq!(replay.refused, 0, "{f}");

        // Per frame: every estimate the live node published has the same label and a
        // bit-identical probability; all but a few were for frames the bag holds (the recorder
        // too may match late or drop a best-effort sample).
        let estimates = recorded::<EngagementEstimate>(&reader, ENGAGEMENT_ESTIMATE.name);
        let mut compared = 0;
        for (_, e) in &estimates {
            let key = (
                e.header.stamp.to_nanos(),
                format!("{}/{}", e.header.frame_id, e.face_id),
            );
            let Some(&(label, bits)) = replay.estimates.get(&key) else {
                continue;
            };
            compared += 1;
            assert_eq!(
                (e.label, e.probability.to_bits()),
                (label, bits),
                "{f}: frame {key:?}: recorded {} p={}, replayed {label} p={}",
                e.label,
                e.probability,
                f32::from_bits(bits)
            );
        }
        assert_eq!(compared, frames.len(), "{f}");
        assert!(
            compared + 5 >= estimates.len(),
            "{f}: {compared} of {} estimates compared",
            estimates.len()
        );

        // Per second: every second the live node published is the replayed one, field for
        // field (counts, mean, smoothed mean, window, stamp), but for seconds whose frame
        // counts differ and the smoothed means right after them (by a factor 1 - alpha per
        // second). Those the bag cannot resolve: a frame or its estimate lost on the
        // best-effort topics between the child, the classifier and the recorder (mostly in
        // the first second, while they still match each other's writers; later on a busy
        // machine). At most 5 % of the seconds; nothing else may differ.
        let live = recorded_seconds(&reader);
        assert!(live.len() >= 20, "{f}: {} seconds", live.len());
        for key in live.keys() {
            assert!(
                replay.seconds.contains_key(key),
                "{f}: second {key:?} not replayed"
            );
        }
        let c = compare_seconds(&replay.seconds, &live);
        let other_counts = c.fewer_frames.len() + c.more_frames.len();
        assert!(
            c.unexplained.is_empty() && other_counts * 20 <= live.len().max(40),
            "{f}: replayed vs live seconds: {}; {c:?}",
            c.summary()
        );
        // The replay says nothing the live node did not, but for the seconds after the
        // recorder stopped: the launch ends with the session, the live node closes its last
        // seconds a little later, the replay flushes them at the end of the frames.
        let last_live = live.keys().map(|(_, w)| *w).max().unwrap_or(i64::MIN);
        let extra: Vec<_> = replay
            .seconds
            .keys()
            .filter(|k| !live.contains_key(*k))
            .collect();
        assert!(
            extra.iter().all(|(_, w)| *w > last_live) && extra.len() <= 3,
            "{f}: replayed seconds the live node did not publish: {extra:?}"
        );
        eprintln!(
            "{f}: {compared} frame estimates equal; seconds: {} ({unseen} recorded frames never reached the classifier; {} seconds after the recorder stopped)",
            c.summary(),
            extra.len()
        );
    }
}

// ---------------------------------------------------------------------------------------
// (b) Behaviour policy

/// "cluster 1 (out/.../cluster_1.json, 4 updates)" -> (1, 4).
fn cluster_and_updates(model_used: &str) -> (usize, u64) {
    let cluster = model_used
        .strip_prefix("cluster ")
        .and_then(|s| s.split(' ').next())
        .and_then(|k| k.parse().ok())
        .unwrap_or_else(|| panic!("model_used {model_used:?}"));
    let updates = model_used
        .rsplit(", ")
        .next()
        .and_then(|s| s.strip_suffix(" updates)"))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("model_used {model_used:?}"));
    (cluster, updates)
}

#[test]
fn recorded_states_give_the_recorded_decisions_under_the_same_seed_and_q_tables() {
    let p: BehaviourPolicyParams = params("behaviour_policy");
    let learning = p.learning().expect("learning constants");
    for sample in &SAMPLES {
        let reader = open(sample);
        let decisions = recorded::<Decision>(&reader, DECISION.name);
        let results = recorded::<SequenceResult>(&reader, SEQUENCE_RESULT.name);
        // The node's policies, one per cluster, as `behaviour_policy run` opens them: the
        // Q-tables it pretrained at startup (bags/q_tables), seed ^ cluster.
        let mut cores: BTreeMap<usize, PolicyCore> = BTreeMap::new();
        let mut learned: BTreeMap<usize, usize> = BTreeMap::new();
        // Decisions the live node made before it had learned from every result already in
        // the bag (the recorder got the result first).
        let mut ahead_of_learning = 0;
        for (t, d) in &decisions {
            let (k, updates) = cluster_and_updates(&d.model_used);
            let core = cores.entry(k).or_insert_with(|| {
                let path = workspace_root().join(format!("bags/q_tables/cluster_{k}.json"));
                let file = QTableFile::load(&path).expect("initial Q-table");
                PolicyCore::new(
                    file.table,
                    learning,
                    p.mode(),
                    p.seed() ^ k as u64,
                    file.updates,
                )
            });
            // DDS does not order the result topic and the decision service against each other:
            // the live node decided after exactly `updates` updates, so learn up to there.
            let of_cluster: Vec<&SequenceResult> = results
                .iter()
                .map(|(_, r)| r)
                .filter(|r| r.user_model_cluster == k as i32)
                .collect();
            let logged_before = of_cluster
                .iter()
                .zip(
                    results
                        .iter()
                        .filter(|(_, r)| r.user_model_cluster == k as i32),
                )
                .filter(|(_, (rt, _))| rt < t)
                .count() as u64;
            if logged_before > updates {
                ahead_of_learning += 1;
            }
            let done = learned.entry(k).or_default();
            while core.updates() < updates {
                let r = of_cluster.get(*done).unwrap_or_else(|| {
                    panic!(
                        "{}: decision after {updates} updates, too few results",
                        sample.file
                    )
                });
                core.learn(&transition(r).expect("a valid result"))
                    .expect("learns");
                *done += 1;
            }
            let state = d.state.to_state().expect("recorded state");
            let got = core.decide(state, d.step).expect("decides");
            let context = format!("{}: step {} in {state}", sample.file, d.step);
            assert_eq!(got.action.index() as u8, d.action, "{context}");
            assert_eq!(
                (got.level.get(), got.feedback as u8),
                (d.level, d.feedback),
                "{context}"
            );
            assert_eq!(got.q_values.to_vec(), d.q_values, "{context}: Q-values");
            assert_eq!(got.probabilities.to_vec(), d.probabilities, "{context}");
            assert_eq!(got.temperature, d.temperature, "{context}");
            assert_eq!(got.explored, d.explored, "{context}");
            assert_eq!(
                got.mode == q_learning::Mode::Exploit,
                d.exploitation_only,
                "{context}"
            );
        }
        // One decision per sequence the policy set (not the overridden ones), and in a stopped
        // session perhaps one more, for the sequence being set up when the therapist stopped.
        let steps: Vec<u8> = decisions.iter().map(|(_, d)| d.step).collect();
        let mut expected_steps: Vec<u8> = results
            .iter()
            .filter(|(_, r)| !r.overridden)
            .map(|(_, r)| r.sequence_index)
            .collect();
        if results.len() < SEQUENCES_PER_SESSION && steps.len() == expected_steps.len() + 1 {
            expected_steps.push(results.len() as u8 + 1);
        }
        assert_eq!(results.len(), sample.sequences, "{}", sample.file);
        assert_eq!(
            steps, expected_steps,
            "{}: one decision per policy-set sequence",
            sample.file
        );
        for (_, r) in &results {
            assert_eq!(r.user_model_cluster, sample.cluster, "{}", sample.file);
        }
        eprintln!(
            "{}: {} decisions equal in action, Q-values, probabilities, temperature; {ahead_of_learning} \
             made before the node had learned the result logged before them",
            sample.file,
            decisions.len()
        );
    }
}

// ---------------------------------------------------------------------------------------
// (c) Game manager

/// Everything the game manager core put out, with the message time it did it at.
#[derive(Default)]
struct GameReplay {
    states: Vec<(i64, GameState)>,
    tasks: Vec<(i64, TabletTask)>,
    results: Vec<(i64, SequenceResult)>,
    speech: Vec<(i64, String)>,
    emotions: Vec<(i64, String)>,
    gestures: Vec<(i64, String)>,
    /// (request id, request, already answered).
    requests: Vec<(u64, DecideActionRequest, bool)>,
}

enum Recorded {
    Command(TherapistCommand),
    Answer(TabletAnswer),
    Engagement(ExpectedEngagement),
    Decision(Decision),
}

/// The game manager core with the timers it asked for, and what it put out.
struct GameDriver {
    core: GameManager,
    timers: BTreeSet<(i64, u64)>,
    out: GameReplay,
}

impl GameDriver {
    fn handle(&mut self, input: Input, now: i64) {
        for o in self.core.handle(input, now) {
            self.take(o, now);
        }
    }

    fn take(&mut self, o: Output, now: i64) {
        let out = &mut self.out;
        match o {
            Output::Say(s) => out.speech.push((now, s)),
            // As the topics backend puts it on the wire (the bags were recorded with it).
            Output::Silence => out.speech.push((
                now,
                game_manager::node::robot::SILENCE_ON_SPEECH_TOPIC.into(),
            )),
            Output::ShowEmotion(s) => out.emotions.push((now, s)),
            Output::PlayGesture(s) => out.gestures.push((now, s)),
            Output::Task(t) => out.tasks.push((now, t)),
            Output::State(s) => out.states.push((now, s)),
            Output::Result(r) => out.results.push((now, r)),
            Output::Decide {
                request_id,
                request,
                ..
            } => out.requests.push((request_id, request, false)),
            Output::SetTimer { id, at_ns } => {
                self.timers.insert((at_ns, id));
            }
            // The sample sessions were recorded with the topics backend (no robot steps) and
            // without supervised autonomy (no proposals).
            Output::AwaitRobot { .. }
            | Output::Proposal(_)
            | Output::Record(_)
            | Output::Journal(_)
            | Output::Summary(_)
            | Output::LiveLine(_)
            | Output::Alarm(_)
            | Output::Log { .. } => {}
        }
    }

    /// Fires the timers due by `until`, each at the time it was asked for.
    fn fire_until(&mut self, until: i64) {
        while let Some(&(at, id)) = self.timers.first() {
            if at > until {
                break;
            }
            self.timers.pop_first();
            self.handle(Input::TimerFired { id }, at);
        }
    }

    /// The open request a recorded decision answers: same session and step, and the decision
    /// was made for the state the core asked about.
    fn request_for(&mut self, d: &Decision) -> Option<u64> {
        let (id, request, answered) = self
            .out
            .requests
            .iter_mut()
            .rev()
            .find(|(_, r, _)| r.session_id == d.session_id && r.step == d.step)?;
        assert!(!*answered, "two decisions for step {}", d.step);
        assert_eq!(
            request.state, d.state,
            "step {}: decided for another state",
            d.step
        );
        *answered = true;
        Some(*id)
    }
}

/// Drives the core with the recorded inputs at their log times (when the recorder received
/// them: within milliseconds of when the live node did), firing its timers at the times it
/// asked for, up to the end of the bag. Heartbeats are not fed: a core that hears none
/// watches none, and the bag lacks the recorder's own (it leaves them out), which the live
/// node watched; the test checks that no node was lost in the recorded session instead.
fn replay_game(sample: &Sample, reader: &BagReader) -> GameReplay {
    let mut p: GameManagerParams = params("game_manager");
    p.session.seed = sample.game_seed;
    p.timing.time_scale = sample.time_scale;
    let mut inputs: Vec<(i64, Recorded)> = Vec::new();
    inputs.extend(
        recorded::<TherapistCommand>(reader, THERAPIST_COMMAND.name)
            .into_iter()
            .map(|(t, m)| (t, Recorded::Command(m))),
    );
    inputs.extend(
        recorded::<TabletAnswer>(reader, TABLET_ANSWER.name)
            .into_iter()
            .map(|(t, m)| (t, Recorded::Answer(m))),
    );
    inputs.extend(
        recorded::<ExpectedEngagement>(reader, EXPECTED_ENGAGEMENT.name)
            .into_iter()
            .map(|(t, m)| (t, Recorded::Engagement(m))),
    );
    inputs.extend(
        recorded::<Decision>(reader, DECISION.name)
            .into_iter()
            .map(|(t, m)| (t, Recorded::Decision(m))),
    );
    inputs.sort_by_key(|(t, _)| *t);
    // The node published its first (idle) state when it started.
    let states = recorded::<GameState>(reader, GAME_STATE.name);
    let start = states.first().map_or(0, |(_, s)| s.header.stamp.to_nanos());
    let end = reader.time_range().map_or(0, |(_, e)| e as i64);

    let mut g = GameDriver {
        core: GameManager::new(p).expect("parameters"),
        timers: BTreeSet::new(),
        out: GameReplay::default(),
    };
    for o in g.core.initial_outputs(start) {
        g.take(o, start);
    }
    for (t, input) in inputs {
        g.fire_until(t);
        let input = match input {
            Recorded::Command(c) => Input::Command(c),
            Recorded::Answer(a) => Input::Answer(a),
            Recorded::Engagement(e) => Input::Engagement(e),
            Recorded::Decision(d) => {
                let Some(request_id) = g.request_for(&d) else {
                    panic!(
                        "{}: decision for step {} nobody asked for",
                        sample.file, d.step
                    );
                };
                // The published Decision is the service response's decision.
                Input::Decision {
                    request_id,
                    response: DecideActionResponse {
                        ok: true,
                        error: String::new(),
                        decision: d,
                    },
                }
            }
        };
        g.handle(input, t);
    }
    g.fire_until(end);
    g.out
}

/// How far the replay's message times may be from the live node's: the live node reads the
/// wall clock when an input arrives or a timer fires (a few ms after it was due, on a busy
/// machine), the replay uses the recorder's receipt times and the exact due times.
const GAME_TIME_TOLERANCE_NS: i64 = 100_000_000;

/// Largest |replayed - recorded| time over pairs, after checking the contents are equal.
fn compare_stamped<M: PartialEq + std::fmt::Debug>(
    what: &str,
    replayed: &[(i64, M)],
    recorded: &[(i64, M)],
) -> i64 {
    if let Some(i) = (0..replayed.len().max(recorded.len()))
        .find(|&i| replayed.get(i).map(|(_, m)| m) != recorded.get(i).map(|(_, m)| m))
    {
        panic!(
            "{what}: {} replayed, {} recorded; they differ first at #{i}:\n replayed: {:?}\n recorded: {:?}",
            replayed.len(),
            recorded.len(),
            replayed.get(i).map(|(_, m)| m),
            recorded.get(i).map(|(_, m)| m)
        );
    }
    replayed
        .iter()
        .zip(recorded)
        .map(|((a, _), (b, _))| (a - b).abs())
        .max()
        .unwrap_or(0)
}

/// (header stamp, message with a zero stamp), so contents compare exactly and times apart.
fn by_stamp<M: Clone>(items: &[(i64, M)], header: impl Fn(&mut M) -> &mut Header) -> Vec<(i64, M)> {
    items
        .iter()
        .map(|(_, m)| {
            let mut m = m.clone();
            let h = header(&mut m);
            let t = h.stamp.to_nanos();
            h.stamp = Time::default();
            (t, m)
        })
        .collect()
}

/// (stamp, result) pairs, as `by_stamp` makes them.
type StampedResults = Vec<(i64, SequenceResult)>;

/// Results with their engagement periods (message times, like their stamps) taken out, and
/// the periods, so contents compare exactly and times within the tolerance.
fn without_periods(items: StampedResults) -> (StampedResults, Vec<(i64, i64)>) {
    items
        .into_iter()
        .map(|(t, mut r)| {
            let period = (
                r.engagement_period_start.to_nanos(),
                r.engagement_period_end.to_nanos(),
            );
            r.engagement_period_start = Time::default();
            r.engagement_period_end = Time::default();
            ((t, r), period)
        })
        .unzip()
}

fn strings(reader: &BagReader, topic: &str) -> Vec<(i64, String)> {
    recorded::<StringMsg>(reader, topic)
        .into_iter()
        .map(|(t, m)| (t, m.data))
        .collect()
}

#[test]
fn recorded_commands_decisions_and_answers_give_the_recorded_game() {
    for sample in &SAMPLES {
        let reader = open(sample);
        let g = replay_game(sample, &reader);
        let f = sample.file;
        let mut worst = 0;
        let mut check = |what: &str, d: i64| {
            worst = worst.max(d);
            assert!(
                d <= GAME_TIME_TOLERANCE_NS,
                "{f}: {what} {:.1} ms from the live node's",
                d as f64 * 1e-6
            );
        };
        let live_states = recorded::<GameState>(&reader, GAME_STATE.name);
        assert!(
            live_states
                .iter()
                .all(|(_, s)| !s.status.contains("node lost")),
            "{f}: a node was lost in the recorded session"
        );
        let results = by_stamp(
            &recorded(&reader, SEQUENCE_RESULT.name),
            |m: &mut SequenceResult| &mut m.header,
        );
        assert_eq!(results.len(), sample.sequences, "{f}");
        let (replayed, replayed_periods) = without_periods(by_stamp(&g.results, |m| &mut m.header));
        let (results, periods) = without_periods(results);
        let d = compare_stamped(&format!("{f}: sequence results"), &replayed, &results);
        check("results", d);
        let d = replayed_periods
            .iter()
            .zip(&periods)
            .map(|(a, b)| (a.0 - b.0).abs().max((a.1 - b.1).abs()))
            .max()
            .unwrap_or(0);
        check("results' engagement periods", d);
        let d = compare_stamped(
            &format!("{f}: tablet tasks"),
            &by_stamp(&g.tasks, |m: &mut TabletTask| &mut m.header),
            &by_stamp(
                &recorded(&reader, TABLET_TASK.name),
                |m: &mut TabletTask| &mut m.header,
            ),
        );
        check("tasks", d);
        let d = compare_stamped(
            &format!("{f}: game states"),
            &by_stamp(&g.states, |m: &mut GameState| &mut m.header),
            &by_stamp(&recorded(&reader, GAME_STATE.name), |m: &mut GameState| {
                &mut m.header
            }),
        );
        check("game states", d);
        for (topic, replayed) in [
            (ROBOT_SPEECH.name, &g.speech),
            (ROBOT_EMOTION.name, &g.emotions),
            (ROBOT_GESTURE.name, &g.gestures),
        ] {
            let d = compare_stamped(&format!("{f}: {topic}"), replayed, &strings(&reader, topic));
            check(topic, d);
        }
        assert!(
            g.requests.iter().all(|(_, _, answered)| *answered),
            "{f}: a request the policy did not answer"
        );
        eprintln!(
            "{f}: game replayed; message times within {:.1} ms of the live node's",
            worst as f64 * 1e-6
        );
    }
}

// ---------------------------------------------------------------------------------------
// (d) The same replay over real DDS processes

/// The recorded faces of the first sample are played by `bag play` (rate 2) into a real
/// `engagement_classifier run`, whose estimates and per-second engagement `bag record` records,
/// all inside one loopback-only network namespace. Compared with (1) the in-process core on
/// every frame played: every recorded estimate bit-identical; every second equal in every
/// field, except seconds in which the DDS classifier counted fewer frames (it did not receive
/// some: the topic is best effort, and this machine is shared) and, after such a second, the
/// smoothed mean of seconds with the same frames; never more frames, nothing else different,
/// at least half the seconds equal; besides those, only empty seconds after the last frame
/// (the node lets message time run on until it is stopped); (2) the live classifier of the
/// recorded session: the same, with losses possible on either side.
#[test]
fn played_faces_over_dds_give_the_recorded_engagement() {
    let sample = &SAMPLES[0];
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    // Discovery on a busy machine can take seconds: the player waits for the classifier.
    std::fs::write(
        d.join("bag_player.yaml"),
        "bag_player:\n  ros__parameters:\n    wait_for_subscribers_s: 30.0\n    linger_s: 1.0\n",
    )
    .expect("player params");
    let script = format!(
        r#"
        export ROS_LOCALHOST_ONLY=1 QT_PARAMS_DIR=params; D={d}
        {classifier} run >$D/clf.out 2>$D/clf.err & C=$!
        {bag} record -o $D/out.mcap --topics {expected} {estimate} >$D/rec.out 2>$D/rec.err & R=$!
        sleep 1
        {bag} play {bagfile} --topics {features} --rate 2 --params-file $D/bag_player.yaml \
            >$D/play.out 2>$D/play.err; P=$?
        # The classifier closes its last seconds 1.2 s (message time at the wall clock's pace)
        # after the last frame, and the rest when it stops.
        sleep 2.5
        kill -INT $C; wait $C; CE=$?
        sleep 1
        kill -INT $R; wait $R; RE=$?
        echo "{{\"play\":$P,\"classifier\":$CE,\"recorder\":$RE}}"
        "#,
        d = d.display(),
        classifier = workspace_bin("engagement_classifier").display(),
        bag = workspace_bin("bag").display(),
        bagfile = bag_path(sample).display(),
        expected = EXPECTED_ENGAGEMENT.name,
        estimate = ENGAGEMENT_ESTIMATE.name,
        features = OPENFACE_FEATURES.name,
    );
    let Some(out) = run_in_loopback_netns(&script, Duration::from_secs(180)) else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
    let context = format!(
        "stdout: {}\nstderr: {}\nplay: {}{}\nclassifier: {}\nrecorder: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
        read("play.out"),
        read("play.err"),
        read("clf.err"),
        read("rec.err"),
    );
    let status = suite_tests::json_lines(&String::from_utf8_lossy(&out.stdout))
        .pop()
        .unwrap_or_else(|| panic!("no status line\n{context}"));
    for key in ["play", "classifier", "recorder"] {
        assert_eq!(status[key], 0, "{key}\n{context}");
    }
    let original = open(sample);
    let replayed = BagReader::open(&d.join("out.mcap"))
        .and_then(BagReader::strict)
        .unwrap_or_else(|e| panic!("{e}\n{context}"));

    // (1) The DDS classifier against the in-process core on the frames played.
    let frames: Vec<OpenFaceFeatures> = recorded(&original, OPENFACE_FEATURES.name)
        .into_iter()
        .map(|(_, f)| f)
        .collect();
    let core = classify(&frames);
    let estimates = recorded::<EngagementEstimate>(&replayed, ENGAGEMENT_ESTIMATE.name);
    for (_, e) in &estimates {
        let key = (
            e.header.stamp.to_nanos(),
            format!("{}/{}", e.header.frame_id, e.face_id),
        );
        assert_eq!(
            core.estimates.get(&key),
            Some(&(e.label, e.probability.to_bits())),
            "frame {key:?}"
        );
    }
    let over_dds = recorded_seconds(&replayed);
    assert!(
        over_dds.len() >= 60,
        "{} seconds\n{context}",
        over_dds.len()
    );
    // After the last frame the node lets message time run on at the wall clock's pace, so
    // it also reports empty seconds (the face is not yet timed out) until it is stopped; the
    // in-process replay ends at the last frame.
    let last_frame = frames.last().map_or(0, |f| f.header.stamp.to_nanos());
    let mut run_on = 0;
    for (key, got) in &over_dds {
        if !core.seconds.contains_key(key) {
            assert!(
                key.1 > last_frame
                    && !got.has_faces
                    && got.frame_count == 0
                    && got.missing_count == 0,
                "second {key:?} is not the core's: {got:?}"
            );
            run_on += 1;
        }
    }
    assert!(run_on <= 4, "{run_on} empty seconds after the last frame");
    // Frames the DDS classifier did not receive (best effort, on a busy machine) make fewer
    // frames in their second, never more, and nothing else may differ.
    let vs_core = compare_seconds(&over_dds, &core.seconds);
    assert!(
        vs_core.unexplained.is_empty()
            && vs_core.more_frames.is_empty()
            && 2 * vs_core.equal >= over_dds.len(),
        "over DDS vs the in-process core: {vs_core:?}\n{context}"
    );
    assert_eq!(
        vs_core.equal + run_on + vs_core.fewer_frames.len() + vs_core.smoothed_after.len(),
        over_dds.len()
    );

    // (2) The DDS classifier against the live one of the recorded session: either may have
    // missed frames.
    let live = recorded_seconds(&original);
    let vs_live = compare_seconds(&over_dds, &live);
    assert!(
        vs_live.unexplained.is_empty() && 2 * vs_live.equal >= live.len(),
        "over DDS vs the live session: {vs_live:?}\n{context}"
    );
    eprintln!(
        "over DDS: {} seconds, {} estimates recorded (of {} frames played); vs the in-process \
         core: {}; vs the live session ({} seconds): {}; {run_on} empty seconds after the last \
         frame",
        over_dds.len(),
        estimates.len(),
        frames.len(),
        vs_core.summary(),
        live.len(),
        vs_live.summary(),
    );
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
