//! Writes the generated seeds of every fuzz target under SEEDS_DIR/<target>/: valid encoded
//! messages of every type (hand-made, and real ones from the sample bags), Q-tables as the
//! policy writes them, shrunk copies of the shipped model files, tablet conversations, and the
//! shipped parameter and launch files with one value at a time set to an edge value, and small
//! bags of every compression. run.sh
//! adds the repository's own files next to them.
//!   make_seeds SEEDS_DIR

use q_learning::learning::QTable;
use q_learning::q_table_file::{QTableFile, QTableOwner};
use qt_therapy_msgs::std_msgs::{Header, StringMsg};
use qt_therapy_msgs::*;
use serde::Serialize;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use suite_fuzz::{MESSAGE_TYPES, TABLET_PIN};

fn main() -> anyhow::Result<()> {
    let root = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "seeds".into()));
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    messages(&root.join("msg_decode"))?;
    recorded_messages(&repo, &root.join("msg_decode"))?;
    q_tables(&root.join("q_table_file"))?;
    user_models(&repo, &root.join("user_model_file"))?;
    xgboost(&repo, &root.join("xgboost_model"))?;
    tablet(&root.join("tablet_ws"))?;
    parameter_edges(&repo, &root.join("params_file"))?;
    launch_edges(&repo, &root.join("launch_file"))?;
    bags(&root.join("read_bag"))?;
    Ok(())
}

/// Small bags of every compression, one message of several suite types each, so the bag
/// reader's fuzzing starts from valid files.
fn bags(dir: &Path) -> anyhow::Result<()> {
    use bag_file::{BagWriter, Compression, WriterOptions};
    use qt_therapy_msgs::topics::{GAME_STATE, OPENFACE_FEATURES, ROBOT_SPEECH};
    use std::io::Cursor;
    std::fs::create_dir_all(dir)?;
    for (name, compression) in [
        ("zstd", Compression::Zstd),
        ("lz4", Compression::Lz4),
        ("none", Compression::None),
    ] {
        let options = WriterOptions {
            compression,
            chunk_size: 256,
            compression_threads: 0,
        };
        let mut w = BagWriter::new(Cursor::new(Vec::new()), "seed", &options)?;
        let speech = w.add_topic(ROBOT_SPEECH)?;
        let state = w.add_topic(GAME_STATE)?;
        let face = w.add_topic(OPENFACE_FEATURES)?;
        w.write(
            speech,
            10,
            &StringMsg {
                data: "happy".into(),
            },
        )?;
        w.write(
            state,
            20,
            &GameState {
                phase: 3,
                status: "saying".into(),
                ..Default::default()
            },
        )?;
        w.write(
            face,
            30,
            &OpenFaceFeatures {
                features: vec![0.5; 32],
                success: true,
                ..Default::default()
            },
        )?;
        w.write(speech, 5, &StringMsg { data: "sad".into() })?;
        let bytes = w.finish()?.into_inner();
        std::fs::write(dir.join(format!("seed_{name}.mcap")), bytes)?;
    }
    Ok(())
}

/// Each shipped launch file with its first executable given, one at a time, a key the
/// repository's files never use or a value its checks refuse (`fuzz/coverage.sh launch_file`
/// showed `args`, `cwd`, per-process `env` and a wrong `output` unreached after hours).
fn launch_edges(repo: &Path, dir: &Path) -> anyhow::Result<()> {
    const EXTRA: [&str; 10] = [
        "    args: \"--x 1 --note 'two words'\"",
        "    args: \"--note 'unbalanced\"",
        "    cwd: $(var out)",
        "    output: nowhere",
        "    output: both",
        "    env: [{name: A, value: $(var out)}, {name: B, value: \"$(env HOME)\"}]",
        "    on_exit: restart",
        "    respawn: maybe",
        "    respawn_delay: soon",
        "    cmd: \"''\"",
    ];
    let mut files = files_in(&repo.join("launch_scripts"), ".launch.yaml")?;
    files.extend(files_in(&repo.join("tests/launch"), ".launch.yaml")?);
    for path in files {
        let stem = path
            .file_name()
            .map(|s| s.to_string_lossy().replace(".launch.yaml", ""));
        let text = std::fs::read_to_string(&path)?;
        let lines = uncommented_lines(&text);
        // The `cmd:` line of the first executable; a replacement `cmd:` takes its place.
        let Some(cmd) = lines.iter().position(|l| l.starts_with("    cmd:")) else {
            continue;
        };
        for (n, extra) in EXTRA.iter().enumerate() {
            let mut changed = lines.clone();
            if extra.trim_start().starts_with("cmd:") {
                changed[cmd] = extra;
            } else {
                changed.insert(cmd + 1, extra);
            }
            let name = format!("edge_{}_{n}", stem.as_deref().unwrap_or("launch"));
            write(dir, &name, (changed.join("\n") + "\n").as_bytes())?;
        }
    }
    Ok(())
}

/// Each shipped parameter file (comments dropped) once per parameter and edge value, that one
/// parameter changed: every node's checks start reached. Mutating YAML text rarely turns a
/// valid file into a well-typed wrong value; the first hours of fuzzing never tried
/// `exploitation_only: false` or a `reward` it does not know (`fuzz/coverage.sh params_file`).
fn parameter_edges(repo: &Path, dir: &Path) -> anyhow::Result<()> {
    // The two lists: a blank element, and one named twice (list parameters such as the game
    // manager's watched_nodes refuse both; a later fuzz run found those checks unseeded).
    const EDGES: [&str; 15] = [
        "0",
        "-1",
        "0.5",
        "1e309",
        ".nan",
        "-.inf",
        "true",
        "false",
        "\"\"",
        "x",
        "[]",
        "[\"\"]",
        "[x, x]",
        "9223372036854775807",
        "-9223372036854775808",
    ];
    for path in files_in(&repo.join("params"), ".yaml")? {
        let node = path.file_stem().map(|s| s.to_string_lossy().into_owned());
        let node = node.as_deref().unwrap_or("params");
        let text = std::fs::read_to_string(&path)?;
        let lines = uncommented_lines(&text);
        for (i, line) in lines.iter().enumerate() {
            // A parameter: indented under `ros__parameters:`, `key: value`.
            let indent = line.len() - line.trim_start().len();
            let Some((key, _)) = line.trim_start().split_once(": ") else {
                continue;
            };
            if indent < 4 {
                continue;
            }
            for (n, edge) in EDGES.iter().enumerate() {
                let mut changed = lines.clone();
                let replaced = format!("{}{key}: {edge}", &line[..indent]);
                changed[i] = &replaced;
                let name = format!("edge_{node}_{key}_{n}");
                write(dir, &name, (changed.join("\n") + "\n").as_bytes())?;
            }
        }
    }
    Ok(())
}

/// The files of `dir` whose names end with `suffix`, sorted (seeds named alike every run).
fn files_in(dir: &Path, suffix: &str) -> anyhow::Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.to_string_lossy().ends_with(suffix))
        .collect();
    files.sort();
    Ok(files)
}

/// A YAML file's lines without its comment lines (smaller seeds, the same meaning).
fn uncommented_lines(text: &str) -> Vec<&str> {
    text.lines()
        .filter(|l| !l.trim_start().starts_with('#'))
        .collect()
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    std::fs::write(dir.join(name), bytes)?;
    Ok(())
}

/// The type byte of `name` in `MESSAGE_TYPES`.
fn kind(name: &str) -> anyhow::Result<u8> {
    let i = MESSAGE_TYPES
        .iter()
        .position(|(n, _)| *n == name)
        .ok_or_else(|| anyhow::anyhow!("{name} is not a fuzzed type"))?;
    Ok(u8::try_from(i)?)
}

/// A seed message. Every seed but the all-default one (`tag` "0") must pass the checks, so
/// the fuzzer starts past them: an invalid seed once kept every SequenceResult check after the
/// first failing one unreached (`fuzz/coverage.sh msg_decode`).
fn message<M: Serialize + Validate>(
    dir: &Path,
    name: &str,
    tag: &str,
    m: &M,
) -> anyhow::Result<()> {
    if tag != "0" {
        m.validate()
            .map_err(|e| anyhow::anyhow!("seed {name} {tag} is not a valid message: {e}"))?;
    }
    let mut bytes = vec![kind(name)?];
    bytes.extend(bag_file::cdr::encode(m)?);
    write(dir, &format!("seed_{name}_{tag}"), &bytes)
}

/// Real messages: the first few of each fuzzed type in each sample bag (`bags/*.mcap`), as
/// the live nodes encoded them.
fn recorded_messages(repo: &Path, dir: &Path) -> anyhow::Result<()> {
    const PER_TYPE: usize = 3;
    for path in files_in(&repo.join("bags"), ".mcap")? {
        let reader = bag_file::BagReader::open(&path)?;
        let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned());
        let mut taken = std::collections::BTreeMap::<u8, usize>::new();
        for (channel, raw) in reader.iter() {
            // `qt_therapy_msgs/msg/GameState`, `std_msgs/msg/String`, `.../srv/X_Request`.
            let Some(name) = channel.type_name().rsplit('/').next() else {
                continue;
            };
            let Ok(k) = kind(name) else { continue };
            let n = taken.entry(k).or_default();
            if *n == PER_TYPE {
                continue;
            }
            *n += 1;
            let mut bytes = vec![k];
            bytes.extend(&raw.data);
            let tag = format!("{}_{n}", stem.as_deref().unwrap_or("bag"));
            write(dir, &format!("recorded_{name}_{tag}"), &bytes)?;
        }
    }
    Ok(())
}

fn messages(dir: &Path) -> anyhow::Result<()> {
    let header = Header {
        stamp: builtin_interfaces::Time {
            sec: 1_700_000_000,
            nanosec: 5,
        },
        frame_id: "camera".into(),
    };
    let words = |w: &[&str]| w.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let state = BehaviourState {
        level: 2,
        feedback: 1,
        previous_score: -1,
    };
    message(dir, "BehaviourState", "0", &BehaviourState::default())?;
    message(dir, "BehaviourState", "1", &state)?;
    message(dir, "OpenFaceFeatures", "0", &OpenFaceFeatures::default())?;
    let face = OpenFaceFeatures {
        header: header.clone(),
        face_id: "face0".into(),
        confidence: 0.9,
        success: true,
        features: vec![0.25; 32],
    };
    message(dir, "OpenFaceFeatures", "1", &face)?;
    message(
        dir,
        "EngagementEstimate",
        "0",
        &EngagementEstimate::default(),
    )?;
    let estimate = EngagementEstimate {
        header: header.clone(),
        face_id: "face0".into(),
        label: 1,
        probability: 0.8,
    };
    message(dir, "EngagementEstimate", "1", &estimate)?;
    message(
        dir,
        "ExpectedEngagement",
        "0",
        &ExpectedEngagement::default(),
    )?;
    let expected = ExpectedEngagement {
        header: header.clone(),
        source: "camera".into(),
        has_faces: true,
        mean: 0.5,
        smoothed: 0.4,
        frame_count: 30,
        missing_count: 2,
        ..Default::default()
    };
    message(dir, "ExpectedEngagement", "1", &expected)?;
    message(dir, "TherapistCommand", "0", &TherapistCommand::default())?;
    let command = TherapistCommand {
        header: header.clone(),
        command: TherapistCommand::OVERRIDE_LEVEL,
        session_id: "s1".into(),
        command_id: 3,
        user_id: "u1".into(),
        user_model_cluster: 1,
        level: 2,
    };
    message(dir, "TherapistCommand", "1", &command)?;
    message(dir, "GameState", "0", &GameState::default())?;
    let game = GameState {
        header: header.clone(),
        phase: GameState::WAITING_FOR_ANSWER,
        session_id: "s1".into(),
        user_id: "u1".into(),
        user_model_cluster: 0,
        sequence_index: 3,
        level: 2,
        feedback: 1,
        last_score: 1,
        policy_fallback: false,
        status: "waiting".into(),
        sequences_planned: 10,
        command_session_id: "s1".into(),
        command_id: 3,
        command_outcome: GameState::COMMAND_REFUSED,
        command_refusal: "already paused".into(),
    };
    message(dir, "GameState", "1", &game)?;
    message(dir, "SequenceResult", "0", &SequenceResult::default())?;
    let result = SequenceResult {
        header: header.clone(),
        session_id: "s1".into(),
        user_id: "u1".into(),
        sequence_index: 2,
        state: state.clone(),
        action: 1,
        level: 2,
        feedback: 1,
        sequence: words(&["happy", "sad", "angry", "happy", "disgusted"]),
        answer: words(&["happy", "sad", "angry", "sad", "disgusted"]),
        outcome: -1,
        activity_result: -0.5,
        engagement: 0.3,
        engagement_per_second: vec![0.1, 0.5],
        response_time: 3.5,
        sequences_planned: 10,
        ..Default::default()
    };
    message(dir, "SequenceResult", "1", &result)?;
    message(dir, "TabletTask", "0", &TabletTask::default())?;
    let task = TabletTask {
        header: header.clone(),
        session_id: "s1".into(),
        sequence_id: 7,
        sequence_index: 1,
        length: 3,
        choices: words(&["happy", "disgusted", "sad", "angry"]),
        timeout: 30.0,
    };
    message(dir, "TabletTask", "1", &task)?;
    message(dir, "TabletAnswer", "0", &TabletAnswer::default())?;
    let answer = TabletAnswer {
        header: header.clone(),
        session_id: "s1".into(),
        sequence_id: 7,
        answer: words(&["sad", "sad", "happy"]),
        response_time: 2.5,
    };
    message(dir, "TabletAnswer", "1", &answer)?;
    message(dir, "Decision", "0", &Decision::default())?;
    let decision = Decision {
        header: header.clone(),
        session_id: "s1".into(),
        step: 2,
        state: state.clone(),
        action: 3,
        level: 2,
        feedback: 1,
        q_values: vec![1.0, 2.0, 0.5, 0.0, -1.0],
        probabilities: vec![0.2; 5],
        temperature: 0.5,
        explored: true,
        exploitation_only: false,
        model_used: "cluster 0".into(),
    };
    message(dir, "Decision", "1", &decision)?;
    message(dir, "UserModelInfo", "0", &UserModelInfo::default())?;
    let info = UserModelInfo {
        header: header.clone(),
        model_file: "models/m.json".into(),
        format_version: 2,
        clusters: vec![0, 1],
        cluster_sizes: vec![5, 7],
        kernel: "rbf".into(),
    };
    message(dir, "UserModelInfo", "1", &info)?;
    message(dir, "Heartbeat", "0", &Heartbeat::default())?;
    let beat = Heartbeat {
        header: header.clone(),
        node_name: "game_manager".into(),
        pid: 4242,
        sequence: 17,
    };
    message(dir, "Heartbeat", "1", &beat)?;
    message(dir, "String", "0", &StringMsg::default())?;
    message(
        dir,
        "String",
        "1",
        &StringMsg {
            data: "QT/happy".into(),
        },
    )?;
    let predict = PredictUserRequest {
        cluster: 1,
        level: 2,
        feedback: 1,
        previous_score: 0,
        outcome: 1,
    };
    message(dir, "PredictUser_Request", "1", &predict)?;
    let predicted = PredictUserResponse {
        ok: true,
        error: String::new(),
        success_probability: 0.7,
        success_std: 0.1,
        engagement: 0.2,
        engagement_std: 0.3,
    };
    message(dir, "PredictUser_Response", "1", &predicted)?;
    let assign = AssignClusterRequest {
        user_vector: vec![0.5, 0.1, 0.6, 0.2, 0.4, -0.1],
    };
    message(dir, "AssignCluster_Request", "1", &assign)?;
    let assigned = AssignClusterResponse {
        ok: true,
        error: String::new(),
        cluster: 1,
        projection: vec![0.3, -0.2],
    };
    message(dir, "AssignCluster_Response", "1", &assigned)?;
    let decide = DecideActionRequest {
        session_id: "s1".into(),
        user_id: "u1".into(),
        user_model_cluster: 0,
        state,
        step: 2,
        after_sequence: 1,
    };
    message(dir, "DecideAction_Request", "1", &decide)?;
    let decided = DecideActionResponse {
        ok: true,
        error: String::new(),
        decision,
    };
    message(dir, "DecideAction_Response", "1", &decided)?;
    message(dir, "ActionProposal", "0", &ActionProposal::default())?;
    let proposed = ActionProposal {
        header: header.clone(),
        session_id: "s1".into(),
        step: 4,
        state: BehaviourState {
            level: 2,
            feedback: 0,
            previous_score: -2,
        },
        action: 3,
        level: 2,
        feedback: 1,
        temperature: 235.0,
        success_std: 0.31,
        reason: "state visited 3 times (T 235 > 100)".into(),
        countdown: 5.0,
        deadline: builtin_interfaces::Time {
            sec: 1_700_000_005,
            nanosec: 5,
        },
        status: ActionProposal::PROPOSED,
        ..Default::default()
    };
    message(dir, "ActionProposal", "1", &proposed)?;
    // Settled: the played fields are checked too.
    let replaced = ActionProposal {
        status: ActionProposal::REPLACED,
        played_action: 2,
        played_level: 3,
        played_feedback: 0,
        command_id: 9,
        response_time: 1.25,
        success_std: -1.0,
        ..proposed
    };
    message(dir, "ActionProposal", "2", &replaced)?;
    Ok(())
}

fn q_tables(dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut table = QTable::default();
    table.q[3] = [1.5, -2.0, 0.25, 0.0, 1e300];
    table.visits[3] = 9;
    for (name, owner) in [
        ("seed_cluster.json", QTableOwner::Cluster(1)),
        ("seed_user.json", QTableOwner::User("u1".into())),
    ] {
        let file = QTableFile {
            owner,
            provenance: "seed".into(),
            updates: 12,
            table: table.clone(),
            learned: [("s1".to_string(), 3)].into_iter().collect(),
        };
        file.save(&dir.join(name))?;
    }
    Ok(())
}

/// The shipped user models without their plot-only user list, so the seed is small.
fn user_models(repo: &Path, dir: &Path) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(repo.join("nodes/user_model/models/migrave_study_c2.json"))?;
    let mut v: Value = serde_json::from_str(&text)?;
    v["users"] = json!([]);
    write(
        dir,
        "seed_no_users.json",
        serde_json::to_string(&v)?.as_bytes(),
    )?;
    Ok(())
}

/// The shipped engagement model cut to its first two trees.
fn xgboost(repo: &Path, dir: &Path) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(
        repo.join("nodes/engagement_classifier/models/synthetic_engagement.json"),
    )?;
    let mut v: Value = serde_json::from_str(&text)?;
    let model = &mut v["learner"]["gradient_booster"]["model"];
    for key in ["trees", "tree_info"] {
        if let Some(a) = model[key].as_array_mut() {
            a.truncate(2);
        }
    }
    model["iteration_indptr"] = json!([0, 1, 2]);
    model["gbtree_model_param"]["num_trees"] = json!("2");
    let small = serde_json::to_string(&v)?;
    engagement_classifier::model::EngagementModel::from_json(&small, Path::new("seed"))?;
    write(dir, "seed_two_trees.json", small.as_bytes())
}

fn tablet(dir: &Path) -> anyhow::Result<()> {
    let answer =
        r#"{"type":"answer","sequence_id":7,"answer":["happy","sad","angry"],"response_time":2.5}"#;
    let login = format!(r#"T{{"type":"login","pin":"{TABLET_PIN}"}}"#);
    let command = |c: &str, extra: &str| {
        format!(r#"T{{"type":"command","pin":"{TABLET_PIN}","command":"{c}"{extra}}}"#)
    };
    let conversations = [
        ("answer", vec![answer.to_string()]),
        (
            "therapist",
            vec![
                login.clone(),
                command("start", r#","user_id":"u1","cluster":1"#),
                command("pause", ""),
                command("resume", ""),
                command("override_level", r#","level":2"#),
                command("stop", ""),
                command("emergency_stop", ""),
            ],
        ),
        (
            "wrong_pin",
            vec![
                r#"T{"type":"login","pin":"0000"}"#.to_string(),
                r#"T{"type":"command","pin":"9999","command":"start"}"#.to_string(),
            ],
        ),
        (
            "game",
            vec![
                "G\u{1}".to_string(),
                answer.to_string(),
                "G\u{4}".to_string(),
                "B".to_string(),
                answer.to_string(),
            ],
        ),
    ];
    for (name, lines) in conversations {
        write(dir, &format!("seed_{name}"), lines.join("\n").as_bytes())?;
    }
    Ok(())
}
