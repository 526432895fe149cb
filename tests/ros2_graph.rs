//! The suite as a citizen of a real ROS 2 graph: a Jazzy rclpy peer (rmw_fastrtps_cpp, from the
//! `ros-jazzy-*` wheels, tests/ros2/requirements.txt) is up before a whole simulated session
//! starts in the same loopback namespace and looks at it as `ros2 node list`,
//! `ros2 topic info -v`, `ros2 topic echo` and rqt do (tests/ros2/peer.py): every node listed,
//! every endpoint attributed to its node, every type hash equal to rosidl's, every line the
//! robot says heard, /rosout lines from every node; it publishes a topic of its own, which the
//! recorder's `--all` must record; and it works every node's parameters as `ros2 param` does
//! (list, get, describe, a set taken and seen on /parameter_events, sets refused with
//! rclcpp's reasons, and `ros2 param dump`, which this test loads back through each node's
//! parameter reader). Then `bag play --clock` of that bag must publish /clock.
//!
//! The wheels' venv: `QT_ROS2_VENV` (tests/run.sh installs it while the workspace builds and
//! writes `<venv>/.installed` when done), else `target/ros2-venv`. Without one the test skips,
//! and fails under tests/run.sh (QT_REQUIRE_ALL_TESTS), as the browser test does.

use bag_file::BagReader;
use node_shell::parameters::NodeParameters;
use qt_therapy_msgs::std_msgs::StringMsg;
use qt_therapy_msgs::topics::ROBOT_SPEECH;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use suite_tests::{run_in_loopback_netns, workspace_bin, workspace_root};

/// The suite's nodes in launch_scripts/simulated_session.launch.yaml.
const NODES: [&str; 8] = [
    "bag_recorder",
    "behaviour_policy",
    "engagement_classifier",
    "game_manager",
    "simulated_child",
    "tablet_bridge",
    "therapist_console",
    "user_model",
];

/// The venv with the ROS 2 wheels, waiting (bounded) for tests/run.sh's install to finish.
fn ros2_venv() -> Option<PathBuf> {
    let given = std::env::var_os("QT_ROS2_VENV").map(PathBuf::from);
    let venv = given
        .clone()
        .unwrap_or_else(|| workspace_root().join("target/ros2-venv"));
    if given.is_some() {
        // tests/run.sh installs the wheels while the workspace builds: wait for it.
        let started = Instant::now();
        while !venv.join(".installed").exists() && !venv.join(".failed").exists() {
            if started.elapsed() > Duration::from_secs(900) {
                break;
            }
            std::thread::sleep(Duration::from_secs(2));
        }
    }
    if venv.join(".installed").exists() && venv.join("bin/python").exists() {
        return Some(venv);
    }
    let why = format!(
        "the ROS 2 Jazzy wheels are not installed in {} (tests/ros2/requirements.txt; \
         tests/run.sh installs them: see target/test-logs/ros2-venv.log)",
        venv.display()
    );
    loopback_netns::skip_or_fail(&why);
    None
}

/// `ros2 param dump`'s file of `node` (the peer's), read as the node reads its parameter file:
/// every key it holds comes back with its value, and it holds every parameter the node shows
/// on the graph.
fn dump_loads_back<P: NodeParameters>(dump_dir: &Path, node: &str) -> Result<P, String> {
    let path = dump_dir.join(format!("{node}.yaml"));
    let params: P = node_shell::params::load_parameters(&path, node).map_err(|e| e.to_string())?;
    let mut dumped =
        node_shell::params::read_parameter_map(&path, node).map_err(|e| e.to_string())?;
    dumped.remove(node_shell::parameters::USE_SIM_TIME);
    let Ok(Value::Object(read)) = serde_json::to_value(&params) else {
        return Err(format!("{node}'s parameters do not serialise to a map"));
    };
    for (key, value) in &dumped {
        if read.get(key) != Some(value) {
            return Err(format!(
                "{node}: {key} is {value} in the dump, {:?} as read back",
                read.get(key)
            ));
        }
    }
    let shown = P::declared().iter().filter(|d| !d.hidden).count();
    if dumped.len() != shown {
        return Err(format!(
            "{node}: the dump holds {} parameters, the node shows {shown}",
            dumped.len()
        ));
    }
    Ok(params)
}

fn report(path: &Path) -> Value {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or(Value::Null)
}

fn failed_checks(report: &Value) -> Vec<String> {
    report["checks"]
        .as_array()
        .map(|checks| {
            checks
                .iter()
                .filter(|c| c["ok"] != Value::Bool(true))
                .map(|c| format!("{}: {}", c["check"], c["detail"]))
                .collect()
        })
        .unwrap_or_else(|| vec!["no report".to_string()])
}

#[test]
fn a_real_ros2_peer_sees_the_whole_session() {
    let Some(venv) = ros2_venv() else {
        return;
    };
    let launch = workspace_bin("launch");
    let bin = launch.parent().expect("target dir").display().to_string();
    let out = std::env::temp_dir().join(format!("ros2_graph_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).expect("out dir");
    let (o, v) = (out.display(), venv.display());
    let python = format!("( . tests/ros2/env.sh {v}; exec {v}/bin/python tests/ros2/peer.py");
    let script = format!(
        "{python} session --report {o}/session.json --expect-nodes {nodes} --dump-dir {o}/dump ) \
  > {o}/peer.log 2>&1 &
peer=$!
# The peer is up before the session: it must hear the robot's first line too.
sleep 4
{bin}/launch launch_scripts/simulated_session.launch.yaml --log-dir {o}/logs bin:={bin} \
  out:={o} time_scale:=0.05 cluster:=0 seed:=7 game_args:='--param robot_speech_node:=ros2_peer' \
  > {o}/stdout.log 2> {o}/stderr.log
echo launch_exit=$?
kill -INT $peer; wait $peer
{python} play --report {o}/play.json --seconds 14 ) > {o}/play_peer.log 2>&1 &
clock_peer=$!
sleep 3
{bin}/bag play {o}/session.mcap --clock --rate 4 > {o}/play.log 2>&1
echo play_exit=$?
wait $clock_peer
",
        nodes = NODES.join(","),
    );
    let Some(result) = run_in_loopback_netns(&script, Duration::from_secs(300)) else {
        return;
    };
    let read = |f: &str| std::fs::read_to_string(out.join(f)).unwrap_or_default();
    let stdout = String::from_utf8_lossy(&result.stdout).to_string();
    let context = format!(
        "{stdout}\npeer log:\n{}\nclock peer log:\n{}\nplay log:\n{}\n(files in {o})",
        read("peer.log"),
        read("play_peer.log"),
        read("play.log"),
    );
    assert!(stdout.contains("launch_exit=0"), "{context}");

    // Every endpoint of the suite offers or asks what rclpy's match: no ROS 2 tool warns.
    assert!(
        !read("peer.log").contains("incompatible QoS"),
        "a QoS incompatibility with the real peer:\n{context}"
    );

    let session = report(&out.join("session.json"));
    let failed = failed_checks(&session);
    assert!(failed.is_empty(), "{failed:#?}\n{context}");

    // Every line the robot said reached the peer, which was up before the session.
    let bag = BagReader::open(&out.join("session.mcap")).expect("the session's bag");
    let said: Vec<String> = bag
        .messages::<StringMsg>(ROBOT_SPEECH.name)
        .expect("speech in the bag")
        .into_iter()
        .map(|m| m.message.data)
        .collect();
    let heard: Vec<String> = session["facts"]["utterances"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|u| u.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default();
    assert!(!said.is_empty(), "{context}");
    assert_eq!(heard, said, "the peer heard other lines than the bag holds");

    // /rosout: lines, with its name and level, from every node that logged (rqt_console's
    // view). The launcher keeps each node's log in logs/<node>.log; the console logs only
    // warnings, to the terminal, and had none.
    let levels = &session["facts"]["rosout_levels"];
    let logged: Vec<&str> = NODES
        .iter()
        .copied()
        .filter(|n| !read(&format!("logs/{n}.log")).trim().is_empty())
        .collect();
    assert!(logged.len() >= 7, "{logged:?}\n{context}");
    let silent: Vec<&str> = logged
        .iter()
        .copied()
        .filter(|n| levels[*n].as_array().is_none_or(|l| l.is_empty()))
        .collect();
    assert!(
        silent.is_empty(),
        "no /rosout line from {silent:?}; got {levels}\n{context}"
    );

    // The recorder's --all recorded the peer's own topics too, with their definitions: one of
    // a type the suite does not know, described by the peer's ~/get_type_description.
    let counts = bag.counts();
    let channels: Vec<String> = bag.channels().map(|c| c.topic.clone()).collect();
    for (topic, type_name, definition) in [
        ("/ros2_peer/chatter", "std_msgs/msg/String", "string data"),
        ("/ros2_peer/count", "std_msgs/msg/Int32", "int32 data"),
    ] {
        let channel = bag.channels().find(|c| c.topic == topic);
        let Some(channel) = channel else {
            panic!("{topic} (from rclpy) is not in the bag; channels: {channels:?}\n{context}");
        };
        assert_eq!(channel.type_name(), type_name);
        assert!(
            counts.get(&channel.id).copied().unwrap_or(0) > 0,
            "{topic}: no messages"
        );
        let schema = channel
            .schema
            .as_ref()
            .map(|s| String::from_utf8_lossy(&s.data).to_string())
            .unwrap_or_default();
        assert!(
            schema.lines().any(|l| l.trim() == definition),
            "{topic}'s definition in the bag is {schema:?}"
        );
    }

    // `ros2 param dump` of every node loads back as its parameter file (the peer dumped the
    // classifier again after its min_confidence was set to 0.7).
    let dump = out.join("dump");
    let loaded: Vec<(&str, Result<(), String>)> = vec![
        (
            "bag_recorder",
            dump_loads_back::<bag::params::RecorderParams>(&dump, "bag_recorder").map(drop),
        ),
        (
            "behaviour_policy",
            dump_loads_back::<behaviour_policy::BehaviourPolicyParams>(&dump, "behaviour_policy")
                .map(drop),
        ),
        (
            "engagement_classifier",
            dump_loads_back::<engagement_classifier::EngagementClassifierParams>(
                &dump,
                "engagement_classifier",
            )
            .and_then(|p| {
                p.validate().map_err(|e| e.to_string())?;
                (p.min_confidence == 0.7).then_some(()).ok_or(format!(
                    "min_confidence {} in the dump, not 0.7",
                    p.min_confidence
                ))
            }),
        ),
        (
            "game_manager",
            dump_loads_back::<game_manager::GameManagerParams>(&dump, "game_manager")
                .and_then(|p| p.validate().map_err(|e| e.to_string())),
        ),
        (
            "simulated_child",
            dump_loads_back::<simulated_child::ChildParams>(&dump, "simulated_child").map(drop),
        ),
        (
            "tablet_bridge",
            dump_loads_back::<tablet_bridge::TabletBridgeParams>(&dump, "tablet_bridge").map(drop),
        ),
        (
            "therapist_console",
            dump_loads_back::<node_shell::NoParameters>(&dump, "therapist_console").map(drop),
        ),
        (
            "user_model",
            dump_loads_back::<user_model::UserModelParams>(&dump, "user_model").map(drop),
        ),
    ];
    let failed: Vec<String> = loaded
        .into_iter()
        .filter_map(|(node, r)| r.err().map(|e| format!("{node}: {e}")))
        .collect();
    assert!(failed.is_empty(), "{failed:#?}\n{context}");
    // The change the peer made reached the classifier's core.
    let classifier_log = read("logs/engagement_classifier.log");
    assert!(
        classifier_log
            .lines()
            .any(|l| l.contains("parameters changed") && l.contains("min_confidence=0.7")),
        "the classifier did not log the change\n{context}"
    );

    // bag play --clock.
    assert!(stdout.contains("play_exit=0"), "{context}");
    let play = report(&out.join("play.json"));
    let failed = failed_checks(&play);
    assert!(failed.is_empty(), "{failed:#?}\n{context}");
}
