//! Proves the Rust mirror matches the interface files: every `.msg`/`.srv` is parsed here,
//! independently of the crate, and compared field by field (name, ROS type, order) and constant
//! by constant with the Rust types; every type round-trips through CDR exactly.

use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::definition::{Constant, Field};
use qt_therapy_msgs::std_msgs::{BoolMsg, Header, StringMsg};
use qt_therapy_msgs::*;
use std::collections::BTreeSet;
use std::path::Path;

/// A `.msg` (or half a `.srv`) as parsed from its text.
#[derive(Debug, Default, PartialEq)]
struct Parsed {
    fields: Vec<(String, String)>,
    constants: Vec<(String, String, String)>,
}

fn parse_definition(text: &str) -> Parsed {
    let mut parsed = Parsed::default();
    for raw in text.lines() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let (ty, rest) = line.split_once(char::is_whitespace).expect("type and name");
        let rest = rest.trim();
        if let Some((name, value)) = rest.split_once('=') {
            parsed.constants.push((
                name.trim().to_string(),
                ty.to_string(),
                value.trim().to_string(),
            ));
        } else {
            let name = rest.split_whitespace().next().expect("field name");
            // Inside a package, `Type` means `this_package/Type`; `Header` is std_msgs/Header.
            let ty = if ty == "Header" {
                "std_msgs/Header".to_string()
            } else {
                ty.to_string()
            };
            parsed.fields.push((name.to_string(), ty));
        }
    }
    parsed
}

/// `ty` as a full ROS type name, a bare message type being in `package`.
fn qualify_in(ty: &str, package: &str) -> String {
    let q = qualify(ty);
    match q.strip_prefix("qt_therapy_msgs/") {
        Some(rest) if !ty.starts_with("qt_therapy_msgs/") => format!("{package}/{rest}"),
        _ => q,
    }
}

fn qualify(ty: &str) -> String {
    let (base, array) = match ty.find('[') {
        Some(i) => (&ty[..i], &ty[i..]),
        None => (ty, ""),
    };
    const PRIMITIVES: [&str; 12] = [
        "bool", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
        "float32", "float64", "string",
    ];
    if base.contains('/') || PRIMITIVES.contains(&base) {
        ty.to_string()
    } else {
        format!("qt_therapy_msgs/{base}{array}")
    }
}

fn rust_side(fields: Vec<Field>, constants: Vec<Constant>) -> Parsed {
    Parsed {
        fields: fields
            .into_iter()
            .map(|f| (f.name.to_string(), f.ros_type))
            .collect(),
        constants: constants
            .into_iter()
            .map(|c| (c.name.to_string(), c.ros_type, c.value))
            .collect(),
    }
}

fn check<M: MessageDefinition>(text: &str) {
    let mut from_file = parse_definition(text);
    // rosidl gives a message without fields one byte, under this name.
    if from_file.fields.is_empty() {
        from_file
            .fields
            .push(("structure_needs_at_least_one_member".into(), "uint8".into()));
    }
    for f in &mut from_file.fields {
        f.1 = qualify_in(&f.1, M::PACKAGE);
    }
    let from_rust = rust_side(M::fields(), M::constants());
    assert_eq!(
        from_rust,
        from_file,
        "{}/{} differs from its interface file",
        M::PACKAGE,
        M::NAME
    );
}

fn package_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(package_dir().join(rel))
        .unwrap_or_else(|e| panic!("reading {rel}: {e}"))
}

#[test]
fn every_message_file_matches_its_rust_type() {
    let mut checked = BTreeSet::new();
    macro_rules! msg {
        ($($t:ty),*) => {$(
            check::<$t>(&read(&format!("msg/{}.msg", <$t>::NAME)));
            checked.insert(format!("msg/{}.msg", <$t>::NAME));
        )*};
    }
    msg!(
        BehaviourState,
        OpenFaceFeatures,
        EngagementEstimate,
        ExpectedEngagement,
        TherapistCommand,
        GameState,
        SequenceResult,
        TabletTask,
        TabletAnswer,
        Decision,
        UserModelInfo,
        Heartbeat,
        ActionProposal
    );
    macro_rules! srv {
        ($($s:ty),*) => {$(
            let text = read(&format!("srv/{}.srv", <$s>::NAME));
            let (request, response) = text.split_once("\n---\n").expect("a .srv has a --- line");
            check::<<$s as ServiceDefinition>::Request>(request);
            check::<<$s as ServiceDefinition>::Response>(response);
            assert_eq!(<$s>::definition_text(), text);
            checked.insert(format!("srv/{}.srv", <$s>::NAME));
        )*};
    }
    srv!(PredictUser, AssignCluster, DecideAction);

    // Nothing in msg/ or srv/ lacks a Rust type.
    let mut on_disk = BTreeSet::new();
    for dir in ["msg", "srv"] {
        for entry in std::fs::read_dir(package_dir().join(dir)).expect("interface dir") {
            let name = entry
                .expect("entry")
                .file_name()
                .to_string_lossy()
                .to_string();
            on_disk.insert(format!("{dir}/{name}"));
        }
    }
    assert_eq!(
        on_disk, checked,
        "interface files without a Rust mirror (or the reverse)"
    );

    // The ROS4HRI types the classifier publishes, against their restatement.
    check::<hri_msgs::EngagementLevel>(&read("../interfaces/hri_msgs/msg/EngagementLevel.msg"));
    check::<hri_msgs::IdsList>(&read("../interfaces/hri_msgs/msg/IdsList.msg"));
    assert_eq!(
        dds_type_name::<hri_msgs::EngagementLevel>().dds_msg_type(),
        "hri_msgs::msg::dds_::EngagementLevel_"
    );

    // QTrobot's services, against the package the robot side builds.
    macro_rules! robot_srv {
        ($($s:ty),*) => {$(
            let rel = format!("../interfaces/qt_robot_interface/srv/{}.srv", <$s>::NAME);
            let text = read(&rel);
            let (request, response) = text.split_once("---\n").expect("a .srv has a --- line");
            check::<<$s as ServiceDefinition>::Request>(request);
            check::<<$s as ServiceDefinition>::Response>(response);
            let cmake = read("../interfaces/qt_robot_interface/CMakeLists.txt");
            assert!(cmake.contains(&format!("\"srv/{}.srv\"", <$s>::NAME)));
            let rules = read("../interfaces/qt_robot_interface/mapping_rules.yaml");
            assert!(rules.contains(&format!("ros2_service_name: '{}'", <$s>::NAME)));
        )*};
    }
    {
        use qt_robot_interface::*;
        robot_srv!(SpeechSay, SpeechStop, EmotionShow, GesturePlay);
    }
    // QTrobot V3's, against their restatement.
    for (text, request, response) in [
        (
            read("../interfaces/qtrobot_interfaces/srv/TtsEngineSayText.srv"),
            <qtrobot_interfaces::TtsEngineSayTextRequest as MessageDefinition>::fields
                as fn() -> Vec<Field>,
            <qtrobot_interfaces::TtsEngineSayTextResponse as MessageDefinition>::fields
                as fn() -> Vec<Field>,
        ),
        (
            read("../interfaces/qtrobot_interfaces/srv/TtsEngineCancel.srv"),
            <qtrobot_interfaces::TtsEngineCancelRequest as MessageDefinition>::fields,
            <qtrobot_interfaces::TtsEngineCancelResponse as MessageDefinition>::fields,
        ),
        (
            read("../interfaces/qtrobot_interfaces/srv/FaceEmotionShow.srv"),
            <qtrobot_interfaces::FaceEmotionShowRequest as MessageDefinition>::fields,
            <qtrobot_interfaces::FaceEmotionShowResponse as MessageDefinition>::fields,
        ),
        (
            read("../interfaces/qtrobot_interfaces/srv/GestureFilePlay.srv"),
            <qtrobot_interfaces::GestureFilePlayRequest as MessageDefinition>::fields,
            <qtrobot_interfaces::GestureFilePlayResponse as MessageDefinition>::fields,
        ),
    ] {
        let (req, resp) = text.split_once("---\n").expect("a .srv has a --- line");
        for (half, fields) in [(req, request), (resp, response)] {
            let file: Vec<(String, String)> = parse_definition(half).fields;
            let rust: Vec<(String, String)> = fields()
                .into_iter()
                .map(|f| (f.name.to_string(), f.ros_type))
                .collect();
            assert_eq!(rust, file);
        }
    }

    // And the CMakeLists lists every one of them for rosidl.
    let cmake = read("CMakeLists.txt");
    for file in &on_disk {
        assert!(
            cmake.contains(&format!("\"{file}\"")),
            "CMakeLists.txt does not list {file}"
        );
    }
}

#[test]
fn standard_types_match_ros2() {
    // As in ros2/common_interfaces and rcl_interfaces (comments dropped).
    check::<Time>("int32 sec\nuint32 nanosec");
    check::<Header>("builtin_interfaces/Time stamp\nstring frame_id");
    check::<StringMsg>("string data");
    check::<BoolMsg>("bool data");
    assert_eq!(
        dds_type_name::<BoolMsg>().dds_msg_type(),
        "std_msgs::msg::dds_::Bool_"
    );
    assert_eq!(
        dds_type_name::<GameState>().dds_msg_type(),
        "qt_therapy_msgs::msg::dds_::GameState_"
    );
    assert_eq!(
        dds_type_name::<Header>().dds_msg_type(),
        "std_msgs::msg::dds_::Header_"
    );
}

#[test]
fn schema_text_appends_dependencies_once_in_rosbag2_form() {
    let schema = SequenceResult::schema_text();
    let separator = "=".repeat(80);
    assert!(schema.starts_with(SequenceResult::definition_text().trim_end()));
    for dep in [
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "qt_therapy_msgs/BehaviourState",
    ] {
        let marker = format!("{separator}\nMSG: {dep}\n");
        assert_eq!(schema.matches(&marker).count(), 1, "{dep} in\n{schema}");
    }
    assert_eq!(schema.matches(&separator).count(), 3);
}

fn stamp() -> Header {
    Header {
        stamp: Time {
            sec: 1_648_134_409,
            nanosec: 123_456_789,
        },
        frame_id: "camera_color_optical_frame".into(),
    }
}

fn state() -> BehaviourState {
    BehaviourState {
        level: 2,
        feedback: 1,
        previous_score: -3,
    }
}

fn round_trip<M: MessageDefinition + PartialEq + std::fmt::Debug>(value: M) {
    use cdr_encoding::{from_bytes, to_vec};
    let le = to_vec::<M, byteorder::LittleEndian>(&value).expect("serialises");
    let (back, used) = from_bytes::<M, byteorder::LittleEndian>(&le).expect("deserialises");
    assert_eq!(back, value, "{} changed in a CDR round trip", M::NAME);
    assert_eq!(used, le.len(), "{} left bytes unread", M::NAME);
    assert_eq!(
        to_vec::<M, byteorder::LittleEndian>(&back).expect("serialises"),
        le
    );
    let be = to_vec::<M, byteorder::BigEndian>(&value).expect("serialises");
    let (back_be, _) = from_bytes::<M, byteorder::BigEndian>(&be).expect("deserialises");
    assert_eq!(back_be, value);
}

#[test]
fn every_type_round_trips_through_cdr_exactly() {
    round_trip(hri_msgs::EngagementLevel {
        header: stamp(),
        level: hri_msgs::EngagementLevel::DISENGAGING,
    });
    round_trip(hri_msgs::IdsList {
        header: stamp(),
        ids: vec![
            "anonymous_person_1a2b3c4d".into(),
            "anonymous_person_0e9f8a7b".into(),
        ],
    });
    let features: Vec<f32> = (0..32).map(|i| i as f32 * 0.37 - 5.0).collect();
    round_trip(Time {
        sec: -3,
        nanosec: 999_999_999,
    });
    round_trip(stamp());
    round_trip(StringMsg {
        data: "Super gemacht! Ünïcode ✓".into(),
    });
    round_trip(BoolMsg { data: true });
    round_trip(state());
    round_trip(OpenFaceFeatures {
        header: stamp(),
        face_id: "0".into(),
        confidence: 0.98,
        success: true,
        features,
    });
    round_trip(EngagementEstimate {
        header: stamp(),
        face_id: "1".into(),
        label: -1,
        probability: 0.125,
    });
    round_trip(ExpectedEngagement {
        header: stamp(),
        source: "camera_color_optical_frame/0".into(),
        window_start: Time {
            sec: 10,
            nanosec: 0,
        },
        window_end: Time {
            sec: 11,
            nanosec: 0,
        },
        has_faces: true,
        mean: 0.5,
        smoothed: 0.25,
        frame_count: 29,
        missing_count: 1,
    });
    round_trip(TherapistCommand {
        header: stamp(),
        command: TherapistCommand::OVERRIDE_LEVEL,
        session_id: "s-1".into(),
        command_id: u64::MAX - 1,
        user_id: "03DEQR1O".into(),
        user_model_cluster: -1,
        level: 3,
    });
    round_trip(ActionProposal {
        header: stamp(),
        session_id: "s".into(),
        proposal_id: 1_700_000_000_123_456_789,
        step: 4,
        state: state(),
        action: 3,
        level: 2,
        feedback: 1,
        temperature: 235.0,
        success_std: 0.31,
        reason: "state visited 13 times (T 235 > 100)".into(),
        countdown: 5.0,
        deadline: Time::from_nanos(1_700_000_005_000_000_000),
        status: ActionProposal::REPLACED,
        played_action: 2,
        played_level: 3,
        played_feedback: 0,
        command_id: 9,
        response_time: 2.5,
    });
    round_trip(GameState {
        header: stamp(),
        phase: GameState::WAITING_FOR_ANSWER,
        session_id: "s".into(),
        user_id: "u".into(),
        user_model_cluster: 1,
        sequence_index: 10,
        level: 3,
        feedback: 2,
        last_score: -3,
        policy_fallback: true,
        status: "policy did not answer in 2 s".into(),
        sequences_planned: 10,
        command_session_id: "s".into(),
        command_id: u64::MAX - 1,
        command_outcome: GameState::COMMAND_REFUSED,
        command_refusal: "already paused".into(),
    });
    round_trip(SequenceResult {
        header: stamp(),
        session_id: "s".into(),
        user_id: "u".into(),
        user_model_cluster: 0,
        sequence_index: 4,
        state: state(),
        action: 3,
        level: 2,
        feedback: 1,
        overridden: false,
        sequence: ["happy", "sad", "angry", "disgusted", "happy"]
            .map(String::from)
            .to_vec(),
        answer: ["happy", "sad", "angry"].map(String::from).to_vec(),
        outcome: -1,
        timed_out: false,
        activity_result: -1.0,
        engagement: 0.3,
        engagement_per_second: vec![0.1, -0.2, 1.0],
        engagement_period_start: Time {
            sec: 1_700_000_000,
            nanosec: 5,
        },
        engagement_period_end: Time {
            sec: 1_700_000_009,
            nanosec: 999_999_999,
        },
        response_time: 8.25,
        sequences_planned: 5,
    });
    round_trip(TabletTask {
        header: stamp(),
        session_id: "s".into(),
        sequence_id: 7,
        sequence_index: 7,
        length: 7,
        choices: ["happy", "disgusted", "sad", "angry"]
            .map(String::from)
            .to_vec(),
        timeout: 60.0,
    });
    round_trip(TabletAnswer {
        header: stamp(),
        session_id: "s".into(),
        sequence_id: 7,
        answer: vec!["sad".into()],
        response_time: 3.5,
    });
    let decision = Decision {
        header: stamp(),
        session_id: "s".into(),
        step: 2,
        state: state(),
        action: 4,
        level: 2,
        feedback: 2,
        q_values: vec![0.5, -1.25, 3.0, 2.0, f64::MIN_POSITIVE],
        probabilities: vec![0.1, 0.2, 0.3, 0.2, 0.2],
        temperature: 0.5,
        explored: true,
        exploitation_only: false,
        model_used: "cluster 1".into(),
        planned_on_belief: true,
        belief_observations: 12,
        belief_success: vec![0.9, 0.6, 0.25],
        belief_success_sd: vec![0.05, 0.1, 0.2],
        belief_engagement: vec![0.5, 0.25, -0.125],
        belief_engagement_sd: vec![0.1, 0.2, 0.3],
        baseline_action: 2,
    };
    round_trip(decision.clone());
    round_trip(UserModelInfo {
        header: stamp(),
        model_file: "m.json".into(),
        format_version: 1,
        clusters: vec![0, 1],
        cluster_sizes: vec![11, 9],
        kernel: "RationalQuadratic".into(),
    });
    round_trip(Heartbeat {
        header: stamp(),
        node_name: "game_manager".into(),
        pid: 4242,
        sequence: 17,
    });
    round_trip(PredictUserRequest {
        cluster: 1,
        level: 3,
        feedback: 2,
        previous_score: -3,
        outcome: -1,
    });
    round_trip(PredictUserResponse {
        ok: true,
        error: String::new(),
        success_probability: 0.5,
        success_std: 0.01,
        engagement: -0.6,
        engagement_std: 0.2,
    });
    round_trip(AssignClusterRequest {
        user_vector: vec![0.9, 0.5, 0.8, 0.6, 0.5, 0.5],
    });
    round_trip(AssignClusterResponse {
        ok: false,
        error: "x".into(),
        cluster: -1,
        projection: vec![1.0, -2.0],
    });
    round_trip(DecideActionRequest {
        session_id: "s".into(),
        user_id: "u".into(),
        user_model_cluster: 0,
        state: state(),
        step: 2,
        after_sequence: 1,
    });
    round_trip(DecideActionResponse {
        ok: true,
        error: String::new(),
        decision,
    });
}

#[test]
fn cdr_layout_is_what_a_ros2_peer_writes() {
    // Hand-computed little-endian CDR: int32 sec, uint32 nanosec, then the string as a
    // uint32 length including the NUL, bytes, NUL.
    let header = Header {
        stamp: Time { sec: 1, nanosec: 2 },
        frame_id: "ab".into(),
    };
    let bytes = cdr_encoding::to_vec::<_, byteorder::LittleEndian>(&header).expect("serialises");
    assert_eq!(bytes, [1, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, b'a', b'b', 0]);
    // int8 after uint8s needs no padding; a following uint32 aligns to 4.
    let s = BehaviourState {
        level: 1,
        feedback: 2,
        previous_score: -3,
    };
    assert_eq!(
        cdr_encoding::to_vec::<_, byteorder::LittleEndian>(&s).expect("serialises"),
        [1, 2, 0xfd]
    );
}
