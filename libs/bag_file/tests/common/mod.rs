//! A short synthetic session on every topic of the suite (3 s: OpenFace frames at 30 Hz, their
//! engagement labels, one sequence of the game with its decision, task, answer and result,
//! heartbeats, robot speech), written with the in-process writer, for the bag tests and the
//! Python readability check. Its content is made up; only its shape matters here.
#![allow(dead_code)]

use bag_file::{BagWriter, Stamp};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::{Header, StringMsg};
use qt_therapy_msgs::topics::OPENFACE_FEATURES;
use qt_therapy_msgs::topics::*;
use qt_therapy_msgs::*;
use std::io::{Seek, Write};

/// 2023-11-14 22:13:20 UTC, in ns.
pub const START_NS: u64 = 1_700_000_000_000_000_000;
const MS: u64 = 1_000_000;

/// One written message, as the readers should see it.
#[derive(Debug, Clone)]
pub struct Expected {
    pub topic: String,
    pub type_name: String,
    pub log_time: u64,
    pub publish_time: u64,
    pub message: serde_json::Value,
}

struct Session<'a, W: Write + Seek> {
    w: &'a mut BagWriter<W>,
    expected: Vec<Expected>,
}

impl<W: Write + Seek> Session<'_, W> {
    fn put<M: MessageDefinition>(&mut self, topic: Topic<M>, offset_ms: u64, message: M) {
        let channel = self.w.add_topic(topic).expect("channel");
        let log_time = START_NS + offset_ms * MS;
        // Published a little before it was logged, as over DDS.
        let publish_time = log_time - 250_000;
        let stamp = Stamp {
            log_time,
            publish_time,
            sequence: self.expected.len() as u32,
        };
        self.w
            .write_stamped(channel, stamp, &message)
            .expect("write");
        self.expected.push(Expected {
            topic: topic.name.to_string(),
            type_name: M::full_type_name(),
            log_time,
            publish_time,
            message: serde_json::to_value(&message).expect("json"),
        });
    }
}

fn header(offset_ms: u64) -> Header {
    Header {
        stamp: Time::from_nanos((START_NS + offset_ms * MS) as i64),
        frame_id: "qt_camera".into(),
    }
}

fn words(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| s.to_string()).collect()
}

/// Writes the session into `w` (not finished) and returns what was written, in write order.
pub fn write_session<W: Write + Seek>(w: &mut BagWriter<W>) -> Vec<Expected> {
    let mut s = Session {
        w,
        expected: Vec::new(),
    };
    let session_id = "demo-session".to_string();
    s.put(
        USER_MODEL_INFO,
        0,
        UserModelInfo {
            header: header(0),
            model_file: "user_models.json".into(),
            format_version: 1,
            clusters: vec![0, 1],
            cluster_sizes: vec![12, 8],
            kernel: "RBF + White".into(),
        },
    );
    s.put(
        PERSONS_TRACKED,
        5,
        qt_therapy_msgs::hri_msgs::IdsList {
            header: header(5),
            ids: vec!["user_child_07".into()],
        },
    );
    s.put(
        THERAPIST_COMMAND,
        10,
        TherapistCommand {
            header: header(10),
            command: TherapistCommand::START,
            session_id: session_id.clone(),
            command_id: 1,
            user_id: "child-07".into(),
            user_model_cluster: 1,
            level: 1,
        },
    );
    for frame in 0..90u64 {
        let t = 20 + frame * 1000 / 30;
        let phase = frame as f32 * 0.2;
        let features: Vec<f32> = (0..32)
            .map(|j| (phase + j as f32 * 0.37).sin() * 0.8)
            .collect();
        s.put(
            OPENFACE_FEATURES,
            t,
            OpenFaceFeatures {
                header: header(t),
                face_id: "0".into(),
                confidence: 0.9 + 0.001 * (frame % 50) as f32,
                success: true,
                features,
            },
        );
        let engaged = frame % 7 != 0;
        s.put(
            ENGAGEMENT_ESTIMATE,
            t + 3,
            EngagementEstimate {
                header: header(t),
                face_id: "0".into(),
                label: if engaged { 1 } else { -1 },
                probability: if engaged { 0.82 } else { 0.31 },
            },
        );
    }
    for second in 0..3u64 {
        let t = 1000 * (second + 1);
        s.put(
            EXPECTED_ENGAGEMENT,
            t + 5,
            ExpectedEngagement {
                header: header(t),
                source: "0".into(),
                window_start: Time::from_nanos((START_NS + (t - 1000) * MS) as i64),
                window_end: Time::from_nanos((START_NS + t * MS) as i64),
                has_faces: true,
                mean: 0.7142857,
                smoothed: 0.69 + 0.01 * second as f32,
                frame_count: 30,
                missing_count: 0,
            },
        );
    }
    for tick in 0..30u64 {
        for (k, node) in ["game_manager", "engagement_classifier"].iter().enumerate() {
            s.put(
                HEARTBEAT,
                tick * 100 + 7 + k as u64,
                Heartbeat {
                    header: header(tick * 100),
                    node_name: node.to_string(),
                    pid: 4242 + k as u32,
                    sequence: tick,
                },
            );
        }
    }
    let state = BehaviourState {
        level: 1,
        feedback: 0,
        previous_score: 0,
    };
    let game = |phase: u8, status: &str| GameState {
        header: header(0),
        phase,
        session_id: session_id.clone(),
        user_id: "child-07".into(),
        user_model_cluster: 1,
        sequence_index: 1,
        level: 1,
        feedback: 0,
        last_score: 0,
        policy_fallback: false,
        status: status.into(),
        sequences_planned: 10,
        command_session_id: session_id.clone(),
        command_id: 1,
        command_outcome: GameState::COMMAND_CARRIED_OUT,
        command_refusal: String::new(),
    };
    s.put(
        GAME_STATE,
        15,
        game(GameState::DECIDING, "asking the policy"),
    );
    s.put(
        DECISION,
        40,
        Decision {
            header: header(40),
            session_id: session_id.clone(),
            step: 1,
            state: state.clone(),
            action: 1,
            level: 1,
            feedback: 1,
            q_values: vec![0.12, 0.48, -0.05, 0.3, 0.0],
            probabilities: vec![0.17, 0.36, 0.12, 0.26, 0.09],
            temperature: 0.25,
            explored: false,
            exploitation_only: false,
            model_used: "q_table".into(),
            ..Default::default()
        },
    );
    s.put(
        ACTION_PROPOSAL,
        50,
        ActionProposal {
            header: header(50),
            session_id: session_id.clone(),
            // The game manager's clock when it proposed: the header's stamp here.
            proposal_id: START_NS + 50 * MS,
            step: 1,
            state: state.clone(),
            action: 0,
            level: 1,
            feedback: 0,
            temperature: 300.0,
            success_std: 0.34,
            reason: "the state is little visited (temperature 300.0 > 100)".into(),
            countdown: 5.0,
            deadline: Time::from_nanos(5_050_000_000),
            status: ActionProposal::ACCEPTED,
            played_action: 0,
            played_level: 1,
            played_feedback: 0,
            command_id: 2,
            response_time: 1.5,
        },
    );
    s.put(
        GAME_STATE,
        60,
        game(GameState::SAYING_SEQUENCE, "saying the sequence"),
    );
    s.put(
        ROBOT_SPEECH,
        70,
        StringMsg {
            data: "Listen carefully: happy, sad, angry.".into(),
        },
    );
    s.put(
        ROBOT_EMOTION,
        75,
        StringMsg {
            data: "QT/happy".into(),
        },
    );
    s.put(
        ROBOT_GESTURE,
        80,
        StringMsg {
            data: "QT/happy".into(),
        },
    );
    s.put(
        TABLET_TASK,
        1200,
        TabletTask {
            header: header(1200),
            session_id: session_id.clone(),
            sequence_id: 1,
            sequence_index: 1,
            length: 3,
            choices: words(&["happy", "disgusted", "sad", "angry"]),
            timeout: 30.0,
        },
    );
    s.put(
        GAME_STATE,
        1210,
        game(GameState::WAITING_FOR_ANSWER, "waiting for the answer"),
    );
    s.put(
        TABLET_ANSWER,
        2400,
        TabletAnswer {
            header: header(2400),
            session_id: session_id.clone(),
            sequence_id: 1,
            answer: words(&["happy", "sad", "angry"]),
            response_time: 1.19,
        },
    );
    s.put(
        SEQUENCE_RESULT,
        2450,
        SequenceResult {
            header: header(2450),
            session_id: session_id.clone(),
            user_id: "child-07".into(),
            user_model_cluster: 1,
            sequence_index: 1,
            state,
            action: 1,
            level: 1,
            feedback: 1,
            overridden: false,
            sequence: words(&["happy", "sad", "angry"]),
            answer: words(&["happy", "sad", "angry"]),
            outcome: 1,
            timed_out: false,
            activity_result: 1.0,
            engagement: 0.71,
            engagement_per_second: vec![0.7, 0.71, 0.72],
            engagement_period_start: Time::from_nanos((START_NS + 15 * MS) as i64),
            engagement_period_end: Time::from_nanos((START_NS + 1200 * MS) as i64),
            response_time: 1.19,
            sequences_planned: 10,
        },
    );
    s.put(
        GAME_STATE,
        2460,
        game(GameState::GIVING_FEEDBACK, "giving feedback"),
    );
    s.expected
}

/// The session, written and finished in memory.
pub fn session_bytes(options: &bag_file::WriterOptions) -> (Vec<u8>, Vec<Expected>) {
    let mut w =
        BagWriter::new(std::io::Cursor::new(Vec::new()), "session", options).expect("writer");
    let expected = write_session(&mut w);
    (w.finish().expect("finish").into_inner(), expected)
}

/// The expected messages sorted as a reader returns them (log time, then write order).
pub fn in_log_time_order(expected: &[Expected]) -> Vec<Expected> {
    let mut sorted = expected.to_vec();
    sorted.sort_by_key(|e| e.log_time);
    sorted
}
