//! The parameters' tests: the shipped file is the default, the file stays flat and strict,
//! and every bad value is named by its key.

use super::*;
use std::path::Path;

/// The defaults with `change` made.
fn with(change: impl FnOnce(&mut GameManagerParams)) -> GameManagerParams {
    let mut p = GameManagerParams::default();
    change(&mut p);
    p
}

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
const KEYS: [&str; 57] = [
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
    "disk_warning_free_mb",
    "disk_floor_free_mb",
    "disk_check_interval_s",
    "retention_dir",
    "retention_budget_mb",
    "retention_removes",
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
    "robot_speech_node",
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
        p.session.seed,
        p.timing.time_scale,
        p.files.sessions_dir.as_str(),
        p.lines.goodbye_de.as_str(),
        p.reliability.recovery_max_age_s,
        p.robot.robot_gesture_speed,
        p.supervision.proposal_countdown_s,
    );
    assert_eq!(set, (7, 0.5, "s", "ciao", 60.0, 2.0, 9.0));
    let rest = with(|p| {
        p.session.seed = 7;
        p.timing.time_scale = 0.5;
        p.files.sessions_dir = "s".into();
        p.lines.goodbye_de = "ciao".into();
        p.reliability.recovery_max_age_s = 60.0;
        p.robot.robot_gesture_speed = 2.0;
        p.supervision.proposal_countdown_s = 9.0;
    });
    assert_eq!(p, rest, "the keys not given keep their defaults");
}

#[test]
fn default_speaking_times_are_the_authors() {
    let p = GameManagerParams::default();
    let times: Vec<f64> = [3, 5, 7]
        .iter()
        .map(|n| p.timing.speaking_time_s(*n))
        .collect();
    assert_eq!(times, vec![8.0, 14.0, 20.0]);
}

#[test]
fn bad_values_name_their_key() {
    let cases: Vec<(GameManagerParams, &str)> = vec![
        (
            with(|p| p.session.sequences_per_session = 11),
            "sequences_per_session",
        ),
        (with(|p| p.timing.time_scale = 0.0), "time_scale"),
        (with(|p| p.lines.language = "fr".into()), "language"),
        (
            with(|p| p.disk.disk_floor_free_mb = 600.0),
            "disk_floor_free_mb",
        ),
        (
            with(|p| p.disk.retention_removes = strings(&["q_tables"])),
            "retention_removes",
        ),
        (
            with(|p| p.disk.disk_check_interval_s = 0.0),
            "disk_check_interval_s",
        ),
        (
            with(|p| p.timing.speaking_time_base_s = -9.0),
            "speaking_time_base_s",
        ),
        (with(|p| p.lines.encouraging_de = vec![]), "encouraging_de"),
        (
            with(|p| p.lines.emotion_words_en = strings(&["a"])),
            "emotion_words_en",
        ),
        (
            with(|p| p.timing.policy_deadline_s = f64::NAN),
            "policy_deadline_s",
        ),
        (
            with(|p| p.reliability.recovery_max_age_s = -1.0),
            "recovery_max_age_s",
        ),
        (
            with(|p| p.reliability.node_loss_timeout_s = 0.0),
            "node_loss_timeout_s",
        ),
        (
            with(|p| {
                p.reliability.watched_nodes = strings(&["behaviour_policy", "behaviour_policy"])
            }),
            "watched_nodes",
        ),
        (
            with(|p| p.reliability.watched_nodes = strings(&["game_manager"])),
            "watched_nodes",
        ),
        (
            with(|p| p.supervision.propose_above_temperature = -1.0),
            "propose_above_temperature",
        ),
        (
            with(|p| p.supervision.propose_above_success_std = f64::INFINITY),
            "propose_above_success_std",
        ),
        (
            with(|p| p.supervision.proposal_countdown_s = 0.0),
            "proposal_countdown_s",
        ),
        (
            with(|p| p.robot.qtrobot_ros2_stop_namespace = "qtrobot_stop".into()),
            "qtrobot_ros2_stop_namespace",
        ),
        (
            with(|p| p.robot.qtrobot_ros2_stop_namespace = "/qtrobot stop/".into()),
            "qtrobot_ros2_stop_namespace",
        ),
    ];
    for ns in ["", "/qtrobot_stop", "/robot/stop_2"] {
        let p = with(|p| p.robot.qtrobot_ros2_stop_namespace = ns.into());
        assert_eq!(p.validate(), Ok(()), "{ns:?}");
    }
    for (p, key) in cases {
        assert_eq!(p.validate().map_err(|e| e.key), Err(key));
    }
}
