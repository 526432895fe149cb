//! The game manager's parameters (`params/game_manager.yaml`), grouped by what changes
//! together: the session's shape, the timing, the files, the robot's lines, the watch of the
//! other nodes with the restart, the robot, and supervised autonomy. The file stays flat (every
//! key at the top level, as ROS 2 has them): it is read into a flat struct with the same keys,
//! which refuses an unknown key and names a bad one, and from it into the groups. Both come
//! from one list below (key, type, default, what it is). `Default` is the shipped yaml;
//! `validate` (`validate.rs`) names the key at fault.

mod validate;

pub use validate::ParamError;

use node_shell::parameters::{Declared, DescribedParameters};
use serde::{Deserialize, Serialize};

/// Declares the parameter groups once: each group a struct with its keys (the file's keys),
/// types, doc comments and defaults; `GameManagerParams` holding one of each; and the file's
/// flat form, a struct with every key that `deny_unknown_fields` guards, read into the groups.
/// Flat keys through `#[serde(flatten)]` would lose the key of a bad value (serde reads a
/// flattened struct from a buffer, past serde_path_to_error's sight), so the flat form is a
/// struct of its own.
macro_rules! parameter_groups {
    (
        $(
            $(#[$group_meta:meta])*
            $group:ident: $Group:ident {
                $( $(#[$meta:meta])* $([$writable:ident])? $key:ident: $ty:ty = $default:expr, )*
            }
        )*
    ) => {
        $(
            $(#[$group_meta])*
            #[derive(Debug, Clone, PartialEq)]
            pub struct $Group {
                $( $(#[$meta])* pub $key: $ty, )*
            }

            impl Default for $Group {
                fn default() -> Self {
                    $Group { $( $key: $default, )* }
                }
            }
        )*

        /// Parameters of the game manager node, by concern; the file's keys are flat.
        #[derive(Debug, Clone, PartialEq, Default, Deserialize, Serialize)]
        #[serde(from = "FlatParams", into = "FlatParams")]
        pub struct GameManagerParams {
            $( $(#[$group_meta])* pub $group: $Group, )*
        }

        /// The parameter file's form: every key at the top level, described for the ROS 2
        /// parameter services (its doc comments; `[writable]` keys change while the node
        /// runs: `GameManager::change_parameters`).
        #[derive(Deserialize, Serialize, DescribedParameters)]
        #[serde(deny_unknown_fields, default)]
        struct FlatParams {
            $( $( $(#[$meta])* $(#[parameter($writable)])? $key: $ty, )* )*
        }

        impl Default for FlatParams {
            fn default() -> Self {
                let p = GameManagerParams::default();
                FlatParams { $( $( $key: p.$group.$key, )* )* }
            }
        }

        impl From<FlatParams> for GameManagerParams {
            fn from(f: FlatParams) -> Self {
                GameManagerParams { $( $group: $Group { $( $key: f.$key, )* }, )* }
            }
        }

        impl From<GameManagerParams> for FlatParams {
            fn from(p: GameManagerParams) -> Self {
                FlatParams { $( $( $key: p.$group.$key, )* )* }
            }
        }
    };
}

impl DescribedParameters for GameManagerParams {
    fn declared() -> Vec<Declared> {
        FlatParams::declared()
    }
}

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

parameter_groups! {
    /// The session's shape and its random draws.
    session: SessionParams {
        /// Seed of the emotion sequences and of the choice among feedback lines (each
        /// session draws from its own stream, from this seed and the session id).
        seed: i64 = 42,
        /// Sequences per session (the paper's omega = 10).
        sequences_per_session: i64 = 10,
        /// Longest run of one emotion in a sequence (the authors: no three identical in a
        /// row).
        max_identical_in_a_row: i64 = 2,
    }

    /// How long the robot takes and how long the game waits.
    timing: TimingParams {
        /// Robot speaking time for a sequence of n emotions: base + n * per_emotion seconds.
        speaking_time_base_s: f64 = -1.0,
        /// Seconds per emotion word: one word every this many seconds.
        speaking_time_per_emotion_s: f64 = 3.0,
        /// Seconds the robot needs for the introduction.
        intro_time_s: f64 = 6.0,
        /// Seconds the robot needs for a feedback line.
        feedback_time_s: f64 = 4.0,
        /// Seconds the robot needs for "well done" / "let's try again".
        reaction_time_s: f64 = 2.0,
        /// Multiplies every robot timing and the answer timeout (0.1 = ten times faster).
        time_scale: f64 = 1.0,
        /// Seconds (before time_scale) the child has to answer; a timeout is a wrong answer.
        answer_timeout_s: f64 = 60.0,
        /// Seconds the policy has to answer DecideAction before the safe fallback is used.
        policy_deadline_s: f64 = 2.0,
        /// At startup, seconds to wait for the DecideAction service before announcing the
        /// game (a request sent before the service is matched is lost); 0 = do not wait.
        policy_startup_wait_s: f64 = 10.0,
        /// Seconds after the robot stopped talking that late ExpectedEngagement windows may
        /// still arrive (the classifier closes a second after its end plus its lateness).
        engagement_wait_s: f64 = 1.5,
    }

    /// Where the session files go.
    files: FileParams {
        /// Directory of the session files (JSON lines + summary).
        sessions_dir: String = "sessions".into(),
    }

    /// The disk the session files and the bag go to: the warning, the floor, the budget and
    /// what retention may delete to keep within it (`retention.rs`).
    disk: DiskParams {
        /// Below this much free space (MB) on the sessions' disk, GameState.status (the
        /// therapist page) warns.
        disk_warning_free_mb: f64 = 500.0,
        /// Below this much free space (MB) a START is refused, with the reason.
        disk_floor_free_mb: f64 = 100.0,
        /// Seconds (real) between two looks at the free space; it is also looked at before
        /// every therapist command.
        disk_check_interval_s: f64 = 10.0,
        /// Directory of the run directories the budget covers (the service's sessions/);
        /// "" turns retention off.
        retention_dir: String = String::new(),
        /// Most the run directories under retention_dir may hold (MB).
        retention_budget_mb: f64 = 20000.0,
        /// What retention deletes, kind by kind in this order, oldest run first, while the
        /// runs are over the budget or the disk is below disk_warning_free_mb: "bags",
        /// "reports", "logs". Session files, Q-tables and the running session's run
        /// directory are never deleted.
        retention_removes: Vec<String> = strings(&["bags", "reports", "logs"]),
    }

    /// What the robot says, and the faces and gestures that go with it.
    lines: LineParams {
        /// Language of the robot's lines: "en" or "de".
        [writable] language: String = "en".into(),
        /// The introduction, in English.
        intro_en: String = "Hello! Let's play a memory game. I will say some emotions. \
                            Listen carefully and then tap them on the tablet in the same order."
            .into(),
        /// The introduction, in German.
        intro_de: String = "Hallo! Lass uns ein Gedächtnisspiel spielen. Ich sage dir ein paar \
                            Gefühle. Hör gut zu und tippe sie dann in der gleichen Reihenfolge \
                            auf dem Tablet an."
            .into(),
        /// Encouraging feedback (action a4), one line drawn per feedback, in English.
        encouraging_en: Vec<String> = strings(&[
            "You are doing great, keep going!",
            "I know you can do it. Let's try another one!",
        ]),
        /// Encouraging feedback, in German.
        encouraging_de: Vec<String> = strings(&[
            "Das machst du toll, weiter so!",
            "Ich weiß, dass du das kannst. Noch eine!",
        ]),
        /// Challenging feedback (action a5), one line drawn per feedback, in English.
        challenging_en: Vec<String> = strings(&[
            "Now concentrate, this one is harder!",
            "Let's see if you can remember this one. Pay attention!",
        ]),
        /// Challenging feedback, in German.
        challenging_de: Vec<String> = strings(&[
            "Jetzt konzentrier dich, die nächste ist schwerer!",
            "Mal sehen, ob du dir diese merken kannst. Pass gut auf!",
        ]),
        /// Said after a right answer, in English.
        well_done_en: String = "Well done!".into(),
        /// Said after a right answer, in German.
        well_done_de: String = "Gut gemacht!".into(),
        /// Said after a wrong (or timed-out) answer, in English.
        try_again_en: String = "Let's try again.".into(),
        /// Said after a wrong (or timed-out) answer, in German.
        try_again_de: String = "Versuchen wir es noch einmal.".into(),
        /// Said after the last sequence and on a therapist stop, in English.
        goodbye_en: String =
            "That was the last one. Thank you for playing with me, goodbye!".into(),
        /// Said after the last sequence and on a therapist stop, in German.
        goodbye_de: String =
            "Das war die letzte. Danke, dass du mit mir gespielt hast, tschüss!".into(),
        /// The emotion words the robot says, in the order happy, disgusted, sad, angry.
        emotion_words_en: Vec<String> = strings(&["happy", "disgusted", "sad", "angry"]),
        /// The emotion words in German, in the same order.
        emotion_words_de: Vec<String> = strings(&["fröhlich", "angeekelt", "traurig", "wütend"]),
        /// QTrobot gesture with the introduction.
        intro_gesture: String = "QT/hi".into(),
        /// QTrobot face with encouraging feedback.
        encouraging_emotion: String = "QT/happy".into(),
        /// QTrobot gesture with encouraging feedback.
        encouraging_gesture: String = "QT/clapping".into(),
        /// QTrobot face with challenging feedback.
        challenging_emotion: String = "QT/showing_smile".into(),
        /// QTrobot gesture with challenging feedback.
        challenging_gesture: String = "QT/challenge".into(),
        /// QTrobot face with "well done".
        well_done_emotion: String = "QT/happy".into(),
        /// QTrobot face with "let's try again".
        try_again_emotion: String = "QT/showing_smile".into(),
        /// QTrobot gesture with the goodbye.
        goodbye_gesture: String = "QT/bye".into(),
    }

    /// What the node does when another node or it itself fails: the heartbeats it watches
    /// and the session it takes over after a restart.
    reliability: ReliabilityParams {
        /// Nodes whose heartbeat the game manager watches (their `NodeShell` names). A node
        /// silent for longer than `node_loss_timeout_s` is lost: the robot goes silent and
        /// the session is held (paused, not lost) until it is back. Empty: watch nothing.
        watched_nodes: Vec<String> = strings(&[
            "behaviour_policy",
            "engagement_classifier",
            "tablet_bridge",
            "bag_recorder",
        ]),
        /// Seconds without a heartbeat after which a watched node is lost (real time: not
        /// multiplied by `time_scale`).
        node_loss_timeout_s: f64 = 4.0,
        /// True: a session held for a lost node resumes by itself when every watched node is
        /// back. False: it stays paused until the therapist's resume.
        auto_resume_after_node_loss: bool = true,
        /// At start-up, a session left unfinished in `sessions_dir` (files without a
        /// summary: the node was killed) and active at most this many seconds ago is taken
        /// over, paused, and goes on at the therapist's resume; older ones are left as they
        /// are. 0: never.
        recovery_max_age_s: f64 = 3600.0,
    }

    /// How the robot is driven.
    robot: RobotParams {
        /// How the robot is driven: `topics` (QTrobot's std_msgs/String topics; the game
        /// waits the estimated speaking times), `qtrobot` (QTrobot V2's services through
        /// ros1_bridge) or `qtrobot_ros2` (QTrobot V3's ROS 2 gateway): each service returns
        /// when the robot has finished, and the game waits for them.
        robot_backend: String = "topics".into(),
        /// `topics`: the node of the robot's speech subscriber. At start-up the game manager
        /// waits (at most `robot_call_timeout_s`) until that node subscribes to the speech
        /// topic, so the robot hears the first line; if it never does, the reason is the game
        /// state's status (the therapist's page). "": no wait.
        robot_speech_node: String = String::new(),
        /// `qtrobot`, `qtrobot_ros2`: a call not answered within this many seconds (real
        /// time) fails; the session is then paused with the reason.
        robot_call_timeout_s: f64 = 60.0,
        /// `qtrobot`, `qtrobot_ros2`: the gesture speed factor sent with every gesture.
        robot_gesture_speed: f64 = 1.0,
        /// `qtrobot_ros2`: the namespace of a second gateway process kept for stopping the
        /// robot (the gateway serves one call at a time, so its own cancel waits for the
        /// sentence under way); the emergency stop's cancel goes there. "": through the
        /// robot's gateway.
        qtrobot_ros2_stop_namespace: String = "/qtrobot_stop".into(),
    }

    /// Supervised autonomy: which decisions are proposed to the therapist first.
    supervision: SupervisionParams {
        /// Supervised autonomy: a decision the policy is unsure of is proposed to the
        /// therapist (ActionProposal) and played when accepted, replaced, or when its
        /// countdown runs out.
        [writable] supervised_autonomy: bool = false,
        /// A decision whose state's softmax temperature is above this is proposed (the
        /// temperature falls with the state's visits: 300 unvisited, 0.5 after 60 visits).
        [writable] propose_above_temperature: f64 = 100.0,
        /// A decision whose user-model σ of P(success) for the sequence it sets up is above
        /// this is proposed (needs `user_model_file`). What σ means is the file's: with the
        /// paper's fit (noise 1e-10, the shipped models) it is about 0 at every (L, F, PS) the
        /// study saw even once and 0.25-0.39 where it saw none, so the rule means "never
        /// seen in the study" for any limit between; with a model fitted with
        /// `user_model fit --noise fitted` it is 0.06-0.22 on the study and says how well the
        /// data pin P(success) down.
        [writable] propose_above_success_std: f64 = 0.3,
        /// Seconds (before time_scale) the therapist has to answer a proposal.
        [writable] proposal_countdown_s: f64 = 5.0,
        /// The user models the σ rule reads ("" turns it off): the behaviour policy's file,
        /// or the same study fitted with `--noise fitted` (the same clusters) for a σ that
        /// means uncertainty.
        user_model_file: String = "nodes/user_model/models/migrave_study_c2.json".into(),
    }
}

/// How the robot is driven (`robot_backend`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RobotBackend {
    Topics,
    /// QTrobot V2 (ROS 1 `qt_robot_interface`, reached through ros1_bridge).
    QtRobot,
    /// QTrobot V3 (LuxAI's ROS 2 gateway, `qtrobot_interfaces`).
    QtRobotRos2,
}

impl RobotBackend {
    /// Whether the robot answers when it has finished (services), so the game waits for it
    /// rather than for estimated speaking times.
    pub fn answers_when_done(self) -> bool {
        self != RobotBackend::Topics
    }

    /// Whether the robot serves one call at a time, so the game must ask for one at a time:
    /// LuxAI's V3 gateway does (every service in one rclpy mutually exclusive callback group).
    pub fn serves_one_call_at_a_time(self) -> bool {
        self == RobotBackend::QtRobotRos2
    }
}

impl RobotParams {
    /// The backend `robot_backend` names.
    pub fn backend(&self) -> Result<RobotBackend, ParamError> {
        match self.robot_backend.as_str() {
            "topics" => Ok(RobotBackend::Topics),
            "qtrobot" => Ok(RobotBackend::QtRobot),
            "qtrobot_ros2" => Ok(RobotBackend::QtRobotRos2),
            other => Err(ParamError {
                key: "robot_backend",
                reason: format!("{other:?} is not topics, qtrobot or qtrobot_ros2"),
            }),
        }
    }
}

impl TimingParams {
    /// Robot speaking time for a sequence of `emotions` words, in unscaled seconds.
    pub fn speaking_time_s(&self, emotions: usize) -> f64 {
        self.speaking_time_base_s + emotions as f64 * self.speaking_time_per_emotion_s
    }
}

#[cfg(test)]
mod tests;
