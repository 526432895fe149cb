//! The fuzz targets' bodies: one function per input format the suite reads from outside
//! (DDS messages, model files, parameter and launch files, tablet WebSocket messages), each
//! driving the same entry point the nodes use and checking what must hold for any input.
//! The libFuzzer targets in `fuzz_targets/` call these, and the workspace test
//! `tests/fuzz_corpora.rs` includes this file to replay the kept corpora without nightly.
//! Any panic here is a finding; errors returned by the parsers are the expected outcome.

use qt_therapy_msgs::std_msgs::StringMsg;
use qt_therapy_msgs::*;
use rustdds::RepresentationIdentifier;
use rustdds::no_key::DeserializerAdapter;
use serde::Serialize;
use serde::de::DeserializeOwned;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

/// A fuzz target's body: any bytes in, a panic on a finding.
pub type Target = fn(&[u8]);

/// The fuzz targets, by name, with their bodies.
pub const TARGETS: [(&str, Target); 8] = [
    ("msg_decode", msg_decode),
    ("user_model_file", user_model_file),
    ("q_table_file", q_table_file),
    ("xgboost_model", xgboost_model),
    ("params_file", params_file),
    ("launch_file", launch_file),
    ("tablet_ws", tablet_ws),
    ("read_bag", read_bag),
];

// ---------------------------------------------------------------------------------------
// msg_decode

/// One message or service type: decodes a payload, validates it, checks the round trip.
type Decoder = fn(&[u8]);

/// Every message and service type of `qt_therapy_msgs`, in a fixed order: the first input
/// byte picks one (modulo the count), so the corpus files stay valid when types are added
/// at the end.
pub const MESSAGE_TYPES: [(&str, Decoder); 20] = [
    ("BehaviourState", decode_one::<BehaviourState>),
    ("OpenFaceFeatures", decode_one::<OpenFaceFeatures>),
    ("EngagementEstimate", decode_one::<EngagementEstimate>),
    ("ExpectedEngagement", decode_one::<ExpectedEngagement>),
    ("TherapistCommand", decode_one::<TherapistCommand>),
    ("GameState", decode_one::<GameState>),
    ("SequenceResult", decode_one::<SequenceResult>),
    ("TabletTask", decode_one::<TabletTask>),
    ("TabletAnswer", decode_one::<TabletAnswer>),
    ("Decision", decode_one::<Decision>),
    ("UserModelInfo", decode_one::<UserModelInfo>),
    ("Heartbeat", decode_one::<Heartbeat>),
    ("String", decode_one::<StringMsg>),
    ("PredictUser_Request", decode_one::<PredictUserRequest>),
    ("PredictUser_Response", decode_one::<PredictUserResponse>),
    ("AssignCluster_Request", decode_one::<AssignClusterRequest>),
    (
        "AssignCluster_Response",
        decode_one::<AssignClusterResponse>,
    ),
    ("DecideAction_Request", decode_one::<DecideActionRequest>),
    ("DecideAction_Response", decode_one::<DecideActionResponse>),
    ("ActionProposal", decode_one::<ActionProposal>),
];

/// Input: one type byte, then a DDS serialized payload (2-byte representation identifier,
/// 2 option bytes, CDR body), decoded the way RustDDS decodes a sample for a subscription,
/// and the way the bag reader decodes a stored message.
pub fn msg_decode(data: &[u8]) {
    let Some((&kind, payload)) = data.split_first() else {
        return;
    };
    let (_, decode) = MESSAGE_TYPES[usize::from(kind) % MESSAGE_TYPES.len()];
    decode(payload);
}

fn decode_one<M>(payload: &[u8])
where
    M: DeserializeOwned + Serialize + Validate + std::fmt::Debug + 'static,
{
    // RustDDS: the representation identifier picks the byte order, the options are ignored.
    if let Some((header, body)) = payload.split_first_chunk::<4>()
        && let Ok(rep) = RepresentationIdentifier::from_bytes(&header[..2])
        && let Ok(m) = rustdds::CDRDeserializerAdapter::<M>::from_bytes(body, rep)
    {
        let _ = m.validate();
        round_trip(&m);
    }
    // The bag reader: the same header, stricter about trailing bytes.
    if let Ok(m) = bag_file::cdr::decode::<M>(payload) {
        let _ = m.validate();
        round_trip(&m);
    }
}

/// Whatever decodes must encode again, and decode to a message that encodes the same
/// (bytes, not values: NaN fields are not equal to themselves).
fn round_trip<M: DeserializeOwned + Serialize + std::fmt::Debug>(m: &M) {
    let bytes = match bag_file::cdr::encode(m) {
        Ok(b) => b,
        Err(e) => panic!("decoded {m:?} does not encode: {e}"),
    };
    let again: M = match bag_file::cdr::decode(&bytes) {
        Ok(a) => a,
        Err(e) => panic!("re-encoded {m:?} does not decode: {e}"),
    };
    match bag_file::cdr::encode(&again) {
        Ok(b) => assert_eq!(b, bytes, "{m:?} changes in a round trip"),
        Err(e) => panic!("{again:?} does not encode: {e}"),
    }
}

// ---------------------------------------------------------------------------------------
// model files

/// A user-model file as `UserModelSet::load` reads it, then every query the user-model
/// node answers.
pub fn user_model_file(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(set) = user_models::UserModelSet::from_json_str(text, Path::new("fuzz.json")) else {
        return;
    };
    for cluster in [-1, 0, 1, 2, i64::MAX] {
        if let Ok(table) = set.table(cluster) {
            let _ = table.validate();
        }
    }
    for v in [
        [0.5, 0.0, 0.5, 0.0, 0.5, 0.0],
        [1.0, 1.0, 0.0, -1.0, 1.0, 1.0],
        [0.0; 6],
    ] {
        let _ = set.assign_cluster(&v);
        let _ = set.project(&v);
    }
    assert!(set.cluster_count() >= 1, "a loaded model has a cluster");
}

/// A Q-table file as the behaviour policy loads it.
pub fn q_table_file(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = Path::new("fuzz.json");
    let Ok(file) = q_learning::q_table_file::QTableFile::from_json_str(text, path) else {
        return;
    };
    let _ = file.owner.file_name();
    assert!(
        file.table.q.iter().flatten().all(|q| q.is_finite()),
        "a loaded Q-table holds only finite values"
    );
}

/// An XGBoost JSON model as the engagement classifier loads it, then predictions.
pub fn xgboost_model(data: &[u8]) {
    use engagement_classifier::features::FEATURE_COUNT;
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = Path::new("fuzz.json");
    let Ok(model) = engagement_classifier::model::EngagementModel::from_json(text, path) else {
        return;
    };
    for raw in [
        [0.0f64; FEATURE_COUNT],
        [1.0; FEATURE_COUNT],
        [f64::NAN; FEATURE_COUNT],
        [-1e30; FEATURE_COUNT],
    ] {
        let p = model.predict(&raw);
        assert!(
            p.probability.is_nan() || (0.0..=1.0).contains(&p.probability),
            "probability {} of {raw:?}",
            p.probability
        );
    }
}

// ---------------------------------------------------------------------------------------
// parameter and launch files

/// Reads one node's section into its parameter struct and runs the node's own checks.
type ParamsReader = fn(serde_json::Map<String, serde_json::Value>);

fn typed<P: DeserializeOwned>(map: serde_json::Map<String, serde_json::Value>) -> Option<P> {
    node_shell::params::parameters_from_map(map, Path::new("fuzz.yaml"), "fuzz").ok()
}

/// Each node with parameters, with the checks it runs at startup.
pub const PARAMETER_NODES: [(&str, ParamsReader); 9] = [
    ("bag_recorder", |m| {
        let _ = typed::<bag::params::RecorderParams>(m);
    }),
    ("bag_player", |m| {
        let _ = typed::<bag::params::PlayerParams>(m);
    }),
    ("behaviour_policy", |m| {
        if let Some(p) = typed::<behaviour_policy::params::BehaviourPolicyParams>(m) {
            let _ = p.learning();
            let _ = p.pretraining();
            let _ = p.mode();
            let _ = p.seed();
        }
    }),
    ("engagement_classifier", |m| {
        if let Some(p) = typed::<engagement_classifier::params::EngagementClassifierParams>(m) {
            if p.validate().is_ok() {
                let _ = p.aggregator_config();
                let _ = p.train_params();
            }
            let _ = p.load_options();
        }
    }),
    ("game_manager", |m| {
        if let Some(p) = typed::<game_manager::params::GameManagerParams>(m)
            && p.validate().is_ok()
        {
            for emotions in 0..=7 {
                let _ = p.timing.speaking_time_s(emotions);
            }
        }
    }),
    ("simulated_child", |m| {
        if let Some(p) = typed::<simulated_child::ChildParams>(m) {
            let _ = p.validate();
        }
    }),
    ("tablet_bridge", |m| {
        if let Some(p) = typed::<tablet_bridge::TabletBridgeParams>(m) {
            let _ = p.validate();
        }
    }),
    ("user_model", |m| {
        let _ = typed::<user_model::UserModelParams>(m);
    }),
    ("therapist_console", |m| {
        let _ = typed::<node_shell::NoParameters>(m);
    }),
];

/// A ROS 2 parameter file as every node reads its section of it (the generic YAML reader,
/// then the node's typed struct and checks), plus command-line overrides from its last line.
pub fn params_file(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = Path::new("fuzz.yaml");
    let overrides: Vec<String> = text
        .lines()
        .last()
        .filter(|l| l.contains(":="))
        .map(|l| l.split(' ').map(String::from).collect())
        .unwrap_or_default();
    // A node's section key holds its name or `/**`; skipping the other nodes' parses (a YAML
    // parse each) keeps the fuzzer's rate up. Only a key spelled with YAML escapes is missed.
    let every_node = text.contains("/**");
    for (node, read) in PARAMETER_NODES {
        if !every_node && !text.contains(node) {
            continue;
        }
        let Ok(mut map) = node_shell::params::parameter_map_from_str(text, path, node) else {
            continue;
        };
        let _ = node_shell::params::apply_overrides(&mut map, &overrides, path, node);
        read(map);
    }
}

/// A launch file as `launch` parses it, with and without argument overrides.
pub fn launch_file(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = Path::new("launch_scripts/fuzz.launch.yaml");
    let mut overrides = BTreeMap::new();
    let _ = launcher::description::parse_launch(text, path, &overrides);
    overrides.insert("seed".to_string(), "$(var out)".to_string());
    overrides.insert("out".to_string(), "o u t".to_string());
    if let Ok(specs) = launcher::description::parse_launch(text, path, &overrides) {
        for s in specs {
            assert!(!s.program.is_empty(), "a process has a program: {s:?}");
        }
    }
}

// ---------------------------------------------------------------------------------------
// tablet WebSocket

/// The PIN of the fuzzed bridge (the default one, as in `params/tablet_bridge.yaml`).
pub const TABLET_PIN: &str = "1234";

/// Tablet WebSocket traffic through the bridge's sans-IO core. Input: lines; a line starting
/// with `T` is a text message from the therapist page, `B` a binary frame from the child
/// page, `G` a new game state (phase = next byte) from DDS, anything else a text message from
/// the child page. The child page waits for a 3-emotion task when the traffic starts; 50 ms
/// pass per line. Whatever the bridge publishes must pass the message checks, and every
/// reply must serialise for the page.
pub fn tablet_ws(data: &[u8]) {
    use tablet_bridge::{Bridge, DdsInput, Now, Output, Role, TabletBridgeParams};
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let at = |step: u64| Now {
        monotonic: Duration::from_millis(50 * step),
        wall_nanos: 1_700_000_000_000_000_000 + 50_000_000 * step as i64,
    };
    let params = TabletBridgeParams {
        pin: TABLET_PIN.into(),
        ..Default::default()
    };
    let mut bridge = Bridge::new(params, at(0));
    let mut outputs = Vec::new();
    let (Ok((child, out_c)), Ok((therapist, out_t))) = (
        bridge.connect(Role::Child, at(0)),
        bridge.connect(Role::Therapist, at(0)),
    ) else {
        panic!("a fresh bridge takes two pages");
    };
    outputs.extend(out_c);
    outputs.extend(out_t);
    let game = |phase: u8| GameState {
        phase,
        session_id: "s1".into(),
        ..Default::default()
    };
    outputs.extend(bridge.dds(
        DdsInput::GameState(game(GameState::WAITING_FOR_ANSWER)),
        at(0),
    ));
    let task = TabletTask {
        session_id: "s1".into(),
        sequence_id: 7,
        sequence_index: 1,
        length: 3,
        choices: ["happy", "disgusted", "sad", "angry"]
            .map(String::from)
            .to_vec(),
        timeout: 30.0,
        ..Default::default()
    };
    outputs.extend(bridge.dds(DdsInput::Task(task), at(0)));
    for (i, line) in text.split('\n').enumerate() {
        let now = at(i as u64 + 1);
        let out = match line.as_bytes().first() {
            Some(b'T') => bridge.ws_text(therapist, &line[1..], now),
            Some(b'B') => bridge.ws_binary(child, line.len(), now),
            Some(b'G') => {
                let phase = line.as_bytes().get(1).copied().unwrap_or(0);
                bridge.dds(DdsInput::GameState(game(phase)), now)
            }
            _ => bridge.ws_text(child, line, now),
        };
        outputs.extend(out);
    }
    for o in outputs {
        match o {
            Output::Send(_, m) => {
                if let Err(e) = serde_json::to_string(&m) {
                    panic!("reply {m:?} does not serialise: {e}");
                }
            }
            Output::Command(c) => {
                if let Err(e) = c.validate() {
                    panic!("the bridge published an invalid command {c:?}: {e}");
                }
            }
            Output::Answer(a) => {
                if let Err(e) = a.validate() {
                    panic!("the bridge published an invalid answer {a:?}: {e}");
                }
            }
            Output::Close(..) | Output::Log(..) | Output::Read(..) => {}
        }
    }
}

// ---------------------------------------------------------------------------------------
// read_bag

/// Any bytes through the bag reader and everything built on it (summary, typed CDR decoding
/// of every suite topic, the player's plan). Nothing may panic, abort or hang.
pub fn read_bag(data: &[u8]) {
    use bag_file::schedule::{PlayOptions, plan};
    use bag_file::{BagInfo, BagReader, ReadOptions};

    // A small chunk limit keeps each run's memory bounded the same way production's does.
    let options = ReadOptions {
        max_chunk_bytes: 4 << 20,
    };
    let Ok(reader) = BagReader::from_bytes(data, "fuzz", &options) else {
        return;
    };
    let _ = BagInfo::of(&reader).to_text();
    for channel in reader.channels() {
        if let Some(t) = bag_file::suite::suite_type(channel.type_name()) {
            for m in reader
                .raw_messages()
                .iter()
                .filter(|m| m.channel_id == channel.id)
            {
                let _ = t.check_cdr(&m.data);
            }
        }
    }
    for rate in [Some(1.0), Some(1e-300), None] {
        let o = PlayOptions {
            rate,
            start_offset: Duration::from_millis(5),
            topics: vec![],
            remap: vec![],
        };
        let _ = plan(&reader, &o, |_| Ok(()));
    }
}
