//! The game manager's parameters (`params/game_manager.yaml`): session shape, robot timings,
//! deadlines, where session files go, and the robot's lines in English and German.
//! `Default` is the shipped yaml; `validate` names the key at fault.

use serde::Deserialize;

/// Parameters of the game manager node (flat ROS 2 keys).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GameManagerParams {
    /// Seed of the emotion sequences and of the choice among feedback lines.
    pub seed: i64,
    /// Sequences per session (the paper's omega = 10).
    pub sequences_per_session: i64,
    /// Longest run of one emotion in a sequence (the authors: no three identical in a row).
    pub max_identical_in_a_row: i64,
    /// Robot speaking time for a sequence of n emotions: base + n * per_emotion seconds.
    pub speaking_time_base_s: f64,
    pub speaking_time_per_emotion_s: f64,
    /// Seconds the robot needs for the introduction, a feedback line, and "well done" /
    /// "let's try again".
    pub intro_time_s: f64,
    pub feedback_time_s: f64,
    pub reaction_time_s: f64,
    /// Multiplies every robot timing and the answer timeout (0.1 = ten times faster).
    pub time_scale: f64,
    /// Seconds (before time_scale) the child has to answer; a timeout is a wrong answer.
    pub answer_timeout_s: f64,
    /// Seconds the policy has to answer DecideAction before the safe fallback is used.
    pub policy_deadline_s: f64,
    /// At startup, seconds to wait for the DecideAction service before announcing the game
    /// (a request sent before the service is matched is lost); 0 = do not wait.
    pub policy_startup_wait_s: f64,
    /// Seconds after the robot stopped talking that late ExpectedEngagement windows may still
    /// arrive (the classifier closes a second after its end plus its lateness).
    pub engagement_wait_s: f64,
    /// Directory of the session files (JSON lines + summary).
    pub sessions_dir: String,
    /// Language of the robot's lines: "en" or "de".
    pub language: String,
    pub intro_en: String,
    pub intro_de: String,
    pub encouraging_en: Vec<String>,
    pub encouraging_de: Vec<String>,
    pub challenging_en: Vec<String>,
    pub challenging_de: Vec<String>,
    pub well_done_en: String,
    pub well_done_de: String,
    pub try_again_en: String,
    pub try_again_de: String,
    pub goodbye_en: String,
    pub goodbye_de: String,
    /// The emotion words the robot says, in the order happy, disgusted, sad, angry.
    pub emotion_words_en: Vec<String>,
    pub emotion_words_de: Vec<String>,
    /// QTrobot face animations and gestures that go with the lines.
    pub intro_gesture: String,
    pub encouraging_emotion: String,
    pub encouraging_gesture: String,
    pub challenging_emotion: String,
    pub challenging_gesture: String,
    pub well_done_emotion: String,
    pub try_again_emotion: String,
    pub goodbye_gesture: String,
    /// Nodes whose heartbeat the game manager watches (their `NodeShell` names). A node
    /// silent for longer than `node_loss_timeout_s` is lost: the robot goes silent and the
    /// session is held (paused, not lost) until it is back. Empty: watch nothing.
    pub watched_nodes: Vec<String>,
    /// Seconds without a heartbeat after which a watched node is lost (real time: not
    /// multiplied by `time_scale`).
    pub node_loss_timeout_s: f64,
    /// True: a session held for a lost node resumes by itself when every watched node is back.
    /// False: it stays paused until the therapist's resume.
    pub auto_resume_after_node_loss: bool,
    /// At start-up, a session left unfinished in `sessions_dir` (files without a summary: the
    /// node was killed) and active at most this many seconds ago is taken over, paused, and
    /// goes on at the therapist's resume; older ones are left as they are. 0: never.
    pub recovery_max_age_s: f64,
    /// How the robot is driven: `topics` (QTrobot's std_msgs/String topics; the game waits
    /// the estimated speaking times), `qtrobot` (QTrobot V2's services through ros1_bridge)
    /// or `qtrobot_ros2` (QTrobot V3's ROS 2 gateway): each service returns when the robot
    /// has finished, and the game waits for them.
    pub robot_backend: String,
    /// `qtrobot`, `qtrobot_ros2`: a call not answered within this many seconds (real time) fails; the
    /// session is then paused with the reason.
    pub robot_call_timeout_s: f64,
    /// `qtrobot`, `qtrobot_ros2`: the gesture speed factor sent with every gesture.
    pub robot_gesture_speed: f64,
    /// `qtrobot_ros2`: the namespace of a second gateway process kept for stopping the robot
    /// (the gateway serves one call at a time, so its own cancel waits for the sentence under
    /// way); the emergency stop's cancel goes there. "": through the robot's gateway.
    pub qtrobot_ros2_stop_namespace: String,
    /// Supervised autonomy: a decision the policy is unsure of is proposed to the therapist
    /// (ActionProposal) and played when accepted, replaced, or when its countdown runs out.
    pub supervised_autonomy: bool,
    /// A decision whose state's softmax temperature is above this is proposed (the
    /// temperature falls with the state's visits: 300 unvisited, 0.5 after 60 visits).
    pub propose_above_temperature: f64,
    /// A decision whose user-model σ of P(success) for the sequence it sets up is above this
    /// is proposed (needs `user_model_file`). What σ means is the file's: with the paper's
    /// fit (noise 1e-10, the shipped models) it is about 0 at every (L, F, PS) the study saw
    /// even once and 0.25-0.39 where it saw none, so the rule means "never seen in the study"
    /// for any limit between; with a model fitted with `user_model fit --noise fitted` it is
    /// 0.06-0.22 on the study and says how well the data pin P(success) down.
    pub propose_above_success_std: f64,
    /// Seconds (before time_scale) the therapist has to answer a proposal.
    pub proposal_countdown_s: f64,
    /// The user models the σ rule reads ("" turns it off): the behaviour policy's file, or
    /// the same study fitted with `--noise fitted` (the same clusters) for a σ that means
    /// uncertainty.
    pub user_model_file: String,
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

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

impl Default for GameManagerParams {
    fn default() -> Self {
        GameManagerParams {
            seed: 42,
            sequences_per_session: 10,
            max_identical_in_a_row: 2,
            speaking_time_base_s: -1.0,
            speaking_time_per_emotion_s: 3.0,
            intro_time_s: 6.0,
            feedback_time_s: 4.0,
            reaction_time_s: 2.0,
            time_scale: 1.0,
            answer_timeout_s: 60.0,
            policy_deadline_s: 2.0,
            policy_startup_wait_s: 10.0,
            engagement_wait_s: 1.5,
            sessions_dir: "sessions".into(),
            language: "en".into(),
            intro_en: "Hello! Let's play a memory game. I will say some emotions. \
                       Listen carefully and then tap them on the tablet in the same order."
                .into(),
            intro_de: "Hallo! Lass uns ein Gedächtnisspiel spielen. Ich sage dir ein paar \
                       Gefühle. Hör gut zu und tippe sie dann in der gleichen Reihenfolge \
                       auf dem Tablet an."
                .into(),
            encouraging_en: strings(&[
                "You are doing great, keep going!",
                "I know you can do it. Let's try another one!",
            ]),
            encouraging_de: strings(&[
                "Das machst du toll, weiter so!",
                "Ich weiß, dass du das kannst. Noch eine!",
            ]),
            challenging_en: strings(&[
                "Now concentrate, this one is harder!",
                "Let's see if you can remember this one. Pay attention!",
            ]),
            challenging_de: strings(&[
                "Jetzt konzentrier dich, die nächste ist schwerer!",
                "Mal sehen, ob du dir diese merken kannst. Pass gut auf!",
            ]),
            well_done_en: "Well done!".into(),
            well_done_de: "Gut gemacht!".into(),
            try_again_en: "Let's try again.".into(),
            try_again_de: "Versuchen wir es noch einmal.".into(),
            goodbye_en: "That was the last one. Thank you for playing with me, goodbye!".into(),
            goodbye_de: "Das war die letzte. Danke, dass du mit mir gespielt hast, tschüss!".into(),
            emotion_words_en: strings(&["happy", "disgusted", "sad", "angry"]),
            emotion_words_de: strings(&["fröhlich", "angeekelt", "traurig", "wütend"]),
            intro_gesture: "QT/hi".into(),
            encouraging_emotion: "QT/happy".into(),
            encouraging_gesture: "QT/clapping".into(),
            challenging_emotion: "QT/showing_smile".into(),
            challenging_gesture: "QT/challenge".into(),
            well_done_emotion: "QT/happy".into(),
            try_again_emotion: "QT/showing_smile".into(),
            goodbye_gesture: "QT/bye".into(),
            watched_nodes: strings(&[
                "behaviour_policy",
                "engagement_classifier",
                "tablet_bridge",
                "bag_recorder",
            ]),
            node_loss_timeout_s: 4.0,
            auto_resume_after_node_loss: true,
            recovery_max_age_s: 3600.0,
            robot_backend: "topics".into(),
            robot_call_timeout_s: 60.0,
            robot_gesture_speed: 1.0,
            qtrobot_ros2_stop_namespace: "/qtrobot_stop".into(),
            supervised_autonomy: false,
            propose_above_temperature: 100.0,
            propose_above_success_std: 0.3,
            proposal_countdown_s: 5.0,
            user_model_file: "nodes/user_model/models/migrave_study_c2.json".into(),
        }
    }
}

/// A parameter the game manager cannot work with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("game_manager parameter {key}: {reason}")]
pub struct ParamError {
    pub key: &'static str,
    pub reason: String,
}

fn bad(key: &'static str, reason: impl Into<String>) -> Result<(), ParamError> {
    Err(ParamError {
        key,
        reason: reason.into(),
    })
}

fn seconds(key: &'static str, v: f64, low: f64, high: f64) -> Result<(), ParamError> {
    if !(v.is_finite() && v >= low && v <= high) {
        return bad(
            key,
            format!("{v} is not a number of seconds in [{low}, {high}]"),
        );
    }
    Ok(())
}

impl GameManagerParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        if !(1..=10).contains(&self.sequences_per_session) {
            return bad("sequences_per_session", "must be in 1..=10");
        }
        if !(1..=7).contains(&self.max_identical_in_a_row) {
            return bad("max_identical_in_a_row", "must be in 1..=7");
        }
        seconds(
            "speaking_time_per_emotion_s",
            self.speaking_time_per_emotion_s,
            0.0,
            60.0,
        )?;
        seconds(
            "speaking_time_base_s",
            self.speaking_time_base_s,
            -60.0,
            60.0,
        )?;
        if self.speaking_time_base_s + 3.0 * self.speaking_time_per_emotion_s <= 0.0 {
            return bad(
                "speaking_time_base_s",
                "base + 3 * per_emotion must be positive (the shortest sequence takes time)",
            );
        }
        seconds("intro_time_s", self.intro_time_s, 0.0, 600.0)?;
        seconds("feedback_time_s", self.feedback_time_s, 0.0, 600.0)?;
        seconds("reaction_time_s", self.reaction_time_s, 0.0, 600.0)?;
        if !(self.time_scale.is_finite() && self.time_scale > 0.0 && self.time_scale <= 10.0) {
            return bad(
                "time_scale",
                format!("{} is not in (0, 10]", self.time_scale),
            );
        }
        // The task's timeout is checked with the answer rules' limit by every reader.
        let max = sequence_game::answer::MAX_RESPONSE_TIME_S;
        seconds("answer_timeout_s", self.answer_timeout_s, 0.001, max)?;
        if self.answer_timeout_s * self.time_scale > max {
            return bad(
                "answer_timeout_s",
                "times time_scale must be at most 3600 s",
            );
        }
        seconds("policy_deadline_s", self.policy_deadline_s, 0.001, 60.0)?;
        seconds(
            "policy_startup_wait_s",
            self.policy_startup_wait_s,
            0.0,
            600.0,
        )?;
        seconds("engagement_wait_s", self.engagement_wait_s, 0.0, 10.0)?;
        if self.sessions_dir.trim().is_empty() {
            return bad("sessions_dir", "is empty");
        }
        if !matches!(self.language.as_str(), "en" | "de") {
            return bad(
                "language",
                format!("{:?} is not \"en\" or \"de\"", self.language),
            );
        }
        let lines: [(&'static str, &[String]); 4] = [
            ("encouraging_en", &self.encouraging_en),
            ("encouraging_de", &self.encouraging_de),
            ("challenging_en", &self.challenging_en),
            ("challenging_de", &self.challenging_de),
        ];
        for (key, list) in lines {
            if list.is_empty() || list.iter().any(|l| l.trim().is_empty()) {
                return bad(key, "needs at least one line and no empty lines");
            }
        }
        for (key, words) in [
            ("emotion_words_en", &self.emotion_words_en),
            ("emotion_words_de", &self.emotion_words_de),
        ] {
            if words.len() != 4 || words.iter().any(|w| w.trim().is_empty()) {
                return bad(key, "needs 4 words: happy, disgusted, sad, angry");
            }
        }
        seconds("node_loss_timeout_s", self.node_loss_timeout_s, 0.2, 600.0)?;
        seconds(
            "recovery_max_age_s",
            self.recovery_max_age_s,
            0.0,
            30.0 * 86_400.0,
        )?;
        for (i, name) in self.watched_nodes.iter().enumerate() {
            if name.trim().is_empty() || name == "game_manager" {
                return bad(
                    "watched_nodes",
                    format!("{name:?} is not a node the game manager can watch"),
                );
            }
            if self.watched_nodes[..i].contains(name) {
                return bad("watched_nodes", format!("{name:?} is listed twice"));
            }
        }
        self.robot_backend()?;
        seconds(
            "robot_call_timeout_s",
            self.robot_call_timeout_s,
            0.1,
            3600.0,
        )?;
        seconds("robot_gesture_speed", self.robot_gesture_speed, 0.0, 10.0)?;
        let ns = &self.qtrobot_ros2_stop_namespace;
        // "" or /name[/name...], each name a ROS name token.
        let namespace = ns.starts_with('/')
            && ns.split('/').skip(1).all(|part| {
                part.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
                    && part.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            });
        if !(ns.is_empty() || namespace) {
            return bad(
                "qtrobot_ros2_stop_namespace",
                format!(
                    "{ns:?} is not a ROS namespace such as \"/qtrobot_stop\" (or \"\" for none)"
                ),
            );
        }
        if !(self.propose_above_temperature.is_finite() && self.propose_above_temperature >= 0.0) {
            return bad(
                "propose_above_temperature",
                format!(
                    "{} is not a temperature >= 0",
                    self.propose_above_temperature
                ),
            );
        }
        if !(self.propose_above_success_std.is_finite() && self.propose_above_success_std >= 0.0) {
            return bad(
                "propose_above_success_std",
                format!(
                    "{} is not a standard deviation >= 0",
                    self.propose_above_success_std
                ),
            );
        }
        seconds(
            "proposal_countdown_s",
            self.proposal_countdown_s,
            0.1,
            3600.0,
        )?;
        Ok(())
    }

    pub fn robot_backend(&self) -> Result<RobotBackend, ParamError> {
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

    /// Robot speaking time for a sequence of `emotions` words, in unscaled seconds.
    pub fn speaking_time_s(&self, emotions: usize) -> f64 {
        self.speaking_time_base_s + emotions as f64 * self.speaking_time_per_emotion_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn shipped_yaml_is_the_default_and_valid() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../params/game_manager.yaml");
        let map = node_shell::params::read_parameter_map(&path, "game_manager")
            .expect("params/game_manager.yaml readable");
        let params: GameManagerParams =
            node_shell::params::parameters_from_map(map, &path, "game_manager")
                .expect("params/game_manager.yaml fits GameManagerParams");
        assert_eq!(params, GameManagerParams::default());
        params.validate().expect("shipped parameters are valid");
    }

    /// Every key of the parameter file, in the order an unknown key's error lists them.
    const KEYS: [&str; 50] = [
        "seed",
        "sequences_per_session",
        "max_identical_in_a_row",
        "speaking_time_base_s",
        "speaking_time_per_emotion_s",
        "intro_time_s",
        "feedback_time_s",
        "reaction_time_s",
        "time_scale",
        "answer_timeout_s",
        "policy_deadline_s",
        "policy_startup_wait_s",
        "engagement_wait_s",
        "sessions_dir",
        "language",
        "intro_en",
        "intro_de",
        "encouraging_en",
        "encouraging_de",
        "challenging_en",
        "challenging_de",
        "well_done_en",
        "well_done_de",
        "try_again_en",
        "try_again_de",
        "goodbye_en",
        "goodbye_de",
        "emotion_words_en",
        "emotion_words_de",
        "intro_gesture",
        "encouraging_emotion",
        "encouraging_gesture",
        "challenging_emotion",
        "challenging_gesture",
        "well_done_emotion",
        "try_again_emotion",
        "goodbye_gesture",
        "watched_nodes",
        "node_loss_timeout_s",
        "auto_resume_after_node_loss",
        "recovery_max_age_s",
        "robot_backend",
        "robot_call_timeout_s",
        "robot_gesture_speed",
        "qtrobot_ros2_stop_namespace",
        "supervised_autonomy",
        "propose_above_temperature",
        "propose_above_success_std",
        "proposal_countdown_s",
        "user_model_file",
    ];

    fn load(body: &str) -> Result<GameManagerParams, node_shell::params::ParamsError> {
        let path = Path::new("game_manager.yaml");
        let yaml = format!("game_manager:\n  ros__parameters:\n{body}");
        let map = node_shell::params::parameter_map_from_str(&yaml, path, "game_manager")
            .expect("YAML with the node's section");
        node_shell::params::parameters_from_map(map, path, "game_manager")
    }

    /// The file stays flat and strict: an unknown key is refused naming it and every key
    /// the node takes, a value of the wrong type is refused naming its key, and each key
    /// sets its own parameter.
    #[test]
    fn the_file_is_flat_and_a_bad_key_is_named() {
        let listed: Vec<String> = KEYS.iter().map(|k| format!("`{k}`")).collect();
        let err = load("    time_scael: 0.1\n").expect_err("an unknown key");
        assert_eq!(
            err.to_string(),
            format!(
                "parameter file game_manager.yaml: game_manager.ros__parameters.time_scael: \
                 unknown field `time_scael`, expected one of {}",
                listed.join(", ")
            )
        );
        for key in KEYS {
            // No parameter takes null.
            let err = load(&format!("    {key}: null\n")).expect_err(key);
            match err {
                node_shell::params::ParamsError::Key { key: named, .. } => {
                    assert_eq!(named, key)
                }
                other => panic!("{key}: {other}"),
            }
        }
        let err = load("    time_scale: \"fast\"\n").expect_err("a word for a number");
        assert_eq!(
            err.to_string(),
            "parameter file game_manager.yaml: game_manager.ros__parameters.time_scale: \
             invalid type: string \"fast\", expected f64"
        );
        let p = load(
            "    seed: 7\n    time_scale: 0.5\n    sessions_dir: \"s\"\n    goodbye_de: \"ciao\"\n    \
             recovery_max_age_s: 60.0\n    robot_gesture_speed: 2.0\n    proposal_countdown_s: 9.0\n",
        )
        .expect("valid keys");
        let set = (
            p.seed,
            p.time_scale,
            p.sessions_dir.as_str(),
            p.goodbye_de.as_str(),
            p.recovery_max_age_s,
            p.robot_gesture_speed,
            p.proposal_countdown_s,
        );
        assert_eq!(set, (7, 0.5, "s", "ciao", 60.0, 2.0, 9.0));
        let rest = GameManagerParams {
            seed: 7,
            time_scale: 0.5,
            sessions_dir: "s".into(),
            goodbye_de: "ciao".into(),
            recovery_max_age_s: 60.0,
            robot_gesture_speed: 2.0,
            proposal_countdown_s: 9.0,
            ..Default::default()
        };
        assert_eq!(p, rest, "the keys not given keep their defaults");
    }

    #[test]
    fn default_speaking_times_are_the_authors() {
        let p = GameManagerParams::default();
        let times: Vec<f64> = [3, 5, 7].iter().map(|n| p.speaking_time_s(*n)).collect();
        assert_eq!(times, vec![8.0, 14.0, 20.0]);
    }

    #[test]
    fn bad_values_name_their_key() {
        let cases: Vec<(GameManagerParams, &str)> = vec![
            (
                GameManagerParams {
                    sequences_per_session: 11,
                    ..Default::default()
                },
                "sequences_per_session",
            ),
            (
                GameManagerParams {
                    time_scale: 0.0,
                    ..Default::default()
                },
                "time_scale",
            ),
            (
                GameManagerParams {
                    language: "fr".into(),
                    ..Default::default()
                },
                "language",
            ),
            (
                GameManagerParams {
                    speaking_time_base_s: -9.0,
                    ..Default::default()
                },
                "speaking_time_base_s",
            ),
            (
                GameManagerParams {
                    encouraging_de: vec![],
                    ..Default::default()
                },
                "encouraging_de",
            ),
            (
                GameManagerParams {
                    emotion_words_en: strings(&["a"]),
                    ..Default::default()
                },
                "emotion_words_en",
            ),
            (
                GameManagerParams {
                    policy_deadline_s: f64::NAN,
                    ..Default::default()
                },
                "policy_deadline_s",
            ),
            (
                GameManagerParams {
                    recovery_max_age_s: -1.0,
                    ..Default::default()
                },
                "recovery_max_age_s",
            ),
            (
                GameManagerParams {
                    node_loss_timeout_s: 0.0,
                    ..Default::default()
                },
                "node_loss_timeout_s",
            ),
            (
                GameManagerParams {
                    watched_nodes: strings(&["behaviour_policy", "behaviour_policy"]),
                    ..Default::default()
                },
                "watched_nodes",
            ),
            (
                GameManagerParams {
                    watched_nodes: strings(&["game_manager"]),
                    ..Default::default()
                },
                "watched_nodes",
            ),
            (
                GameManagerParams {
                    propose_above_temperature: -1.0,
                    ..Default::default()
                },
                "propose_above_temperature",
            ),
            (
                GameManagerParams {
                    propose_above_success_std: f64::INFINITY,
                    ..Default::default()
                },
                "propose_above_success_std",
            ),
            (
                GameManagerParams {
                    proposal_countdown_s: 0.0,
                    ..Default::default()
                },
                "proposal_countdown_s",
            ),
            (
                GameManagerParams {
                    qtrobot_ros2_stop_namespace: "qtrobot_stop".into(),
                    ..Default::default()
                },
                "qtrobot_ros2_stop_namespace",
            ),
            (
                GameManagerParams {
                    qtrobot_ros2_stop_namespace: "/qtrobot stop/".into(),
                    ..Default::default()
                },
                "qtrobot_ros2_stop_namespace",
            ),
        ];
        for ns in ["", "/qtrobot_stop", "/robot/stop_2"] {
            let p = GameManagerParams {
                qtrobot_ros2_stop_namespace: ns.into(),
                ..Default::default()
            };
            assert_eq!(p.validate(), Ok(()), "{ns:?}");
        }
        for (p, key) in cases {
            assert_eq!(p.validate().map_err(|e| e.key), Err(key));
        }
    }
}
