//! The whole suite in one process: the nodes' own run loops (`node::run` of each crate) on one
//! in-process bus (`node_shell::in_process`) on a virtual clock (tokio's paused time in a
//! current-thread runtime), set up as the main job's launch file sets them up
//! (`launch_scripts/simulated_session.launch.yaml`): the bag recorder, the user model, the
//! behaviour policy, the engagement classifier, the game manager, the tablet bridge's core (its
//! pages as `PageEvent`s a test sends, as a tablet's page would), the simulated child and the
//! therapist console's `run-session`. A node can be stopped (SIGINT), killed (its task
//! dropped: it leaves at once, as a SIGKILLed process) and started again (a new instance, as a
//! respawn is a new pid).

use node_shell::ShellOptions;
use node_shell::clock::Clock;
use node_shell::in_process::{InProcessBus, InProcessNode, NodeStop};
use node_shell::instance_lock::InstanceLock;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tablet_bridge::node::{EVENT_QUEUE, PageEvent, ToPage};
use tablet_bridge::protocol::Role;
use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;

/// 2026-03-02 09:00:00 UTC: the virtual clock's start, the same every run.
pub const T0_NS: i64 = 1_772_442_000_000_000_000;

/// The nodes of the suite.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Node {
    Recorder,
    UserModel,
    Policy,
    Classifier,
    GameManager,
    Bridge,
    Child,
}

impl Node {
    pub const ALL: [Node; 7] = [
        Node::Recorder,
        Node::UserModel,
        Node::Policy,
        Node::Classifier,
        Node::GameManager,
        Node::Bridge,
        Node::Child,
    ];

    /// Its name on the graph (what heartbeats and the game manager's watch say).
    pub fn name(self) -> &'static str {
        match self {
            Node::Recorder => bag::recorder::NODE,
            Node::UserModel => user_model::node::NODE,
            Node::Policy => qt_therapy_msgs::topics::BEHAVIOUR_POLICY_NODE,
            Node::Classifier => engagement_classifier::node::NODE,
            Node::GameManager => game_manager::node::NODE,
            Node::Bridge => tablet_bridge::node::NODE,
            Node::Child => simulated_child::node::NODE,
        }
    }
}

/// How the suite is set up: the main job's arguments.
#[derive(Debug, Clone)]
pub struct Setup {
    /// `time_scale` of the game manager and the child (the main job's default is 0.2).
    pub time_scale: f64,
    /// `seed` of the game manager and the child.
    pub seed: i64,
    /// The child's user-model cluster.
    pub cluster: i64,
    /// The user the console starts sessions for (`--user`).
    pub user: String,
    /// More `--param` overrides per node, as `game_args:=...` in the launch file.
    pub more: BTreeMap<Node, Vec<String>>,
    /// Start the policy with the Q-tables it pretrains when it has none (`bags/q_tables`,
    /// made by the node with the shipped parameters), as on a robot after its first start,
    /// instead of pretraining them (0.9 s of a debug build's time: the DDS main job does).
    pub robot_tables: bool,
}

impl Default for Setup {
    fn default() -> Self {
        Setup {
            time_scale: 0.2,
            seed: 7,
            cluster: 0,
            user: "sim-child-1".into(),
            more: BTreeMap::new(),
            robot_tables: true,
        }
    }
}

struct Running {
    stop: NodeStop,
    task: JoinHandle<anyhow::Result<()>>,
}

/// A suite running on one in-process bus.
pub struct Suite {
    pub bus: InProcessBus,
    /// Where the Q-tables go, and the run directory unless another is set (the launch file's
    /// `out`).
    pub out: PathBuf,
    /// The run directory: the bag and the session files (`out` until [`Suite::set_run`]), as
    /// the robot's service makes one per start.
    pub run: PathBuf,
    pub setup: Setup,
    running: BTreeMap<Node, Running>,
    /// The tablet bridge's pages, while it runs.
    pages: Option<mpsc::Sender<PageEvent>>,
}

/// The workspace's parameter file of `node` with the main job's overrides and `more`.
fn options(node: &str, overrides: Vec<String>) -> ShellOptions {
    ShellOptions {
        params_file: Some(
            suite_tests::workspace_root()
                .join("params")
                .join(format!("{node}.yaml")),
        ),
        namespace: "/".into(),
        param_overrides: overrides,
        ..Default::default()
    }
}

/// A path of the workspace, absolute: the nodes read their files relative to the working
/// directory, which for a test is its package's.
fn workspace_file(relative: &str) -> String {
    suite_tests::workspace_root()
        .join(relative)
        .display()
        .to_string()
}

const USER_MODELS: &str = "nodes/user_model/models/migrave_study_c2.json";
const CHILD_BELIEF_PRIOR: &str = "nodes/behaviour_policy/models/child_belief_prior_c2.json";

impl Suite {
    /// An empty bus on a virtual clock (call inside a runtime whose time is paused), writing
    /// into `out` (made empty).
    pub fn new(out: &Path, setup: Setup) -> Suite {
        let _ = std::fs::remove_dir_all(out);
        std::fs::create_dir_all(out.join("q_tables")).expect("the output directory");
        if setup.robot_tables {
            for k in 0..2 {
                let name = format!("cluster_{k}.json");
                std::fs::copy(
                    suite_tests::workspace_root()
                        .join("bags/q_tables")
                        .join(&name),
                    out.join("q_tables").join(&name),
                )
                .expect("the robot's Q-tables");
            }
        }
        Suite {
            bus: InProcessBus::new(Clock::starting_at(T0_NS)),
            out: out.to_path_buf(),
            run: out.to_path_buf(),
            setup,
            running: BTreeMap::new(),
            pages: None,
        }
    }

    /// Bags and session files go into `run` (made) from the next start of the recorder and
    /// the game manager on.
    pub fn set_run(&mut self, run: &Path) {
        std::fs::create_dir_all(run).expect("the run directory");
        self.run = run.to_path_buf();
    }

    fn overrides(&self, node: Node) -> Vec<String> {
        let s = &self.setup;
        let out = self.out.display();
        let run = self.run.display();
        let mut o: Vec<String> = match node {
            Node::Recorder => vec![],
            Node::UserModel => vec![format!("model_file:={}", workspace_file(USER_MODELS))],
            // As the launch file: the child's decisions planned on a belief about them.
            Node::Policy => vec![
                format!("user_model_file:={}", workspace_file(USER_MODELS)),
                format!("q_table_dir:={out}/q_tables"),
                "child_belief:=true".into(),
                format!(
                    "child_belief_prior_file:={}",
                    workspace_file(CHILD_BELIEF_PRIOR)
                ),
            ],
            Node::Classifier => vec![format!(
                "model_file:={}",
                workspace_file("nodes/engagement_classifier/models/synthetic_engagement.json")
            )],
            Node::GameManager => vec![
                format!("sessions_dir:={run}"),
                format!("time_scale:={}", s.time_scale),
                format!("seed:={}", s.seed),
                format!("user_model_file:={}", workspace_file(USER_MODELS)),
            ],
            Node::Bridge => vec![],
            Node::Child => vec![
                format!("user_model_file:={}", workspace_file(USER_MODELS)),
                format!("cluster:={}", s.cluster),
                format!("time_scale:={}", s.time_scale),
                format!("seed:={}", s.seed),
            ],
        };
        o.extend(s.more.get(&node).cloned().unwrap_or_default());
        o
    }

    /// Starts `node` (again, if it ran before: a new instance).
    pub fn start(&mut self, node: Node) {
        assert!(!self.running.contains_key(&node), "{node:?} runs already");
        let (mut bus, stop) = self.bus.join(node.name()).expect("joins the bus");
        let options = options(node.name(), self.overrides(node));
        let task: JoinHandle<anyhow::Result<()>> = match node {
            Node::Recorder => {
                let (params, _) = options
                    .parameters(node.name())
                    .expect("recorder parameters");
                let what = bag::recorder::Recording {
                    output: self.run.join("session.mcap"),
                    topics: Vec::new(),
                    compression: None,
                };
                tokio::spawn(async move {
                    let r =
                        bag::recorder::run(&mut bus, params, what, bag::recorder::SuiteOnly, None)
                            .await;
                    bus.stop().await;
                    r.map(|_| ())
                })
            }
            Node::UserModel => {
                let (params, path) = options.parameters(node.name()).expect("parameters");
                tokio::spawn(async move {
                    let r = user_model::node::run(&mut bus, params, &path).await;
                    bus.stop().await;
                    r
                })
            }
            Node::Policy => {
                let (params, path): (behaviour_policy::BehaviourPolicyParams, _) =
                    options.parameters(node.name()).expect("parameters");
                let lock =
                    InstanceLock::acquire(Path::new(&params.q_table_dir), node.name(), "Q-tables")
                        .expect("q_table_dir free");
                tokio::spawn(async move {
                    let _lock = lock;
                    let r = behaviour_policy::node::run(&mut bus, params, &path).await;
                    bus.stop().await;
                    r
                })
            }
            Node::Classifier => {
                let (params, path) = options.parameters(node.name()).expect("parameters");
                let estimator =
                    engagement_classifier::node::estimator(&params, &path).expect("the model");
                tokio::spawn(async move {
                    let r = engagement_classifier::node::run(&mut bus, params, estimator).await;
                    bus.stop().await;
                    r
                })
            }
            Node::GameManager => {
                let (params, path): (game_manager::GameManagerParams, _) =
                    options.parameters(node.name()).expect("parameters");
                let lock =
                    InstanceLock::acquire(&self.run, node.name(), "session files").expect("free");
                tokio::spawn(async move {
                    let _lock = lock;
                    let r = game_manager::node::run(&mut bus, params, &path).await;
                    bus.stop().await;
                    r
                })
            }
            Node::Bridge => {
                let (params, _): (tablet_bridge::TabletBridgeParams, _) =
                    options.parameters(node.name()).expect("parameters");
                params.validate().expect("valid bridge parameters");
                let (events, pages) = mpsc::channel(EVENT_QUEUE);
                self.pages = Some(events);
                tokio::spawn(async move {
                    let r = tablet_bridge::node::run(&mut bus, params, pages).await;
                    bus.stop().await;
                    r
                })
            }
            Node::Child => {
                let (params, _) = options.parameters(node.name()).expect("parameters");
                tokio::spawn(async move {
                    let r = simulated_child::node::run(&mut bus, params).await;
                    bus.stop().await;
                    r
                })
            }
        };
        self.running.insert(node, Running { stop, task });
    }

    /// Starts every node, in the launch file's order.
    pub fn start_all(&mut self) {
        for node in Node::ALL {
            self.start(node);
        }
    }

    /// Kills `node`: its task is dropped where it is, as SIGKILL ends a process; it leaves the
    /// bus at once, its writers' histories with it.
    pub async fn kill(&mut self, node: Node) {
        let r = self.running.remove(&node).expect("it runs");
        r.task.abort();
        let _ = r.task.await;
        if node == Node::Bridge {
            self.pages = None;
        }
    }

    /// Stops `node` as SIGINT does; it must end cleanly.
    pub async fn stop(&mut self, node: Node) {
        let r = self.running.remove(&node).expect("it runs");
        r.stop.stop();
        r.task
            .await
            .expect("the node's task")
            .unwrap_or_else(|e| panic!("{node:?} ended with an error: {e:#}"));
        if node == Node::Bridge {
            self.pages = None;
        }
    }

    /// Stops every node still running, as the launcher does when the console exits; each
    /// must end cleanly.
    pub async fn stop_all(&mut self) {
        let nodes: Vec<Node> = self.running.keys().copied().collect();
        for n in &nodes {
            self.running[n].stop.stop();
        }
        for n in nodes {
            let r = self.running.remove(&n).expect("it runs");
            r.task
                .await
                .expect("the node's task")
                .unwrap_or_else(|e| panic!("{n:?} ended with an error: {e:#}"));
        }
        self.pages = None;
    }

    /// A node of our own on the bus (a test's probe, or the therapist console).
    pub fn join(&self, name: &str) -> (InProcessNode, NodeStop) {
        self.bus.join(name).expect("joins the bus")
    }

    /// A page of the tablet bridge, as a tablet's browser connects one.
    pub async fn page(&self, role: Role) -> Page {
        let events = self.pages.clone().expect("the tablet bridge runs");
        let (out, rx) = mpsc::channel(256);
        let (reply, id) = oneshot::channel();
        events
            .send(PageEvent::Connect { role, out, reply })
            .await
            .expect("the bridge takes pages");
        let id = id
            .await
            .expect("the bridge answers")
            .expect("the page is let in");
        Page {
            id,
            events,
            rx,
            seen: Vec::new(),
        }
    }
}

/// A tablet page connected to the bridge's core: what it sends and what it was sent.
pub struct Page {
    id: u64,
    events: mpsc::Sender<PageEvent>,
    rx: mpsc::Receiver<ToPage>,
    /// Everything the page has been sent so far, as JSON.
    pub seen: Vec<Value>,
}

impl Page {
    /// Sends `message` (a ClientMessage as the page's script writes it).
    pub async fn send(&mut self, message: Value) {
        self.events
            .send(PageEvent::Text(self.id, message.to_string()))
            .await
            .expect("the bridge takes page messages");
    }

    /// Takes what the page has been sent by now into `seen`; the new ones.
    pub fn read(&mut self) -> Vec<Value> {
        let mut new = Vec::new();
        while let Ok(m) = self.rx.try_recv() {
            match m {
                ToPage::Text(t) => new.push(serde_json::from_str(&t).expect("JSON to a page")),
                ToPage::Close(reason) => new.push(serde_json::json!({"closed": reason})),
            }
        }
        self.seen.extend(new.iter().cloned());
        new
    }

    /// Waits (on the virtual clock) until the page is sent a message `matching`, at most
    /// `within`; it, or None.
    pub async fn wait_for(
        &mut self,
        within: Duration,
        matching: impl Fn(&Value) -> bool,
    ) -> Option<Value> {
        let deadline = tokio::time::Instant::now() + within;
        loop {
            if let Some(v) = self.read().into_iter().find(|v| matching(v)) {
                return Some(v);
            }
            match tokio::time::timeout_at(deadline, self.rx.recv()).await {
                Ok(Some(ToPage::Text(t))) => {
                    let v: Value = serde_json::from_str(&t).expect("JSON to a page");
                    self.seen.push(v.clone());
                    if matching(&v) {
                        return Some(v);
                    }
                }
                Ok(Some(ToPage::Close(reason))) => {
                    self.seen.push(serde_json::json!({"closed": reason}));
                }
                _ => return None,
            }
        }
    }
}

/// The therapist console's `run-session` on the bus, its lines collected.
pub struct Therapist {
    lines: Arc<Mutex<Vec<String>>>,
    task: JoinHandle<anyhow::Result<i32>>,
}

impl Suite {
    /// The console's `run-session --user <user> --cluster <cluster>` (and
    /// `--accept-proposals`), as the main job's therapist.
    pub fn run_session(
        &self,
        session: Option<&str>,
        accept_proposals: bool,
        sessions: u32,
    ) -> Therapist {
        let (mut bus, _) = self.join(therapist_console::console::NODE);
        let lines = Arc::new(Mutex::new(Vec::new()));
        let said = lines.clone();
        let start = therapist_console::console::Start {
            user: self.setup.user.clone(),
            cluster: self.setup.cluster as i32,
            session: session.map(String::from),
            wait: Duration::from_secs(60),
        };
        let follow = therapist_console::console::Follow {
            timeout: Duration::from_secs(1800),
            sessions,
            accept_proposals,
        };
        let task = tokio::spawn(async move {
            let code = {
                let mut console =
                    therapist_console::console::Console::new(&mut bus, move |line: &str| {
                        said.lock()
                            .unwrap_or_else(|e| e.into_inner())
                            .push(line.to_string())
                    })?;
                console.run_session(&start, follow).await
            };
            bus.stop().await;
            code
        });
        Therapist { lines, task }
    }
}

impl Therapist {
    /// The console's lines so far.
    pub fn lines(&self) -> Vec<String> {
        self.lines.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Waits for the console to exit: its exit code and its lines (an error is a panic,
    /// with the lines).
    pub async fn exit(self) -> (i32, Vec<String>) {
        let outcome = self.task.await.expect("the console's task");
        let lines = self.lines.lock().unwrap_or_else(|e| e.into_inner()).clone();
        match outcome {
            Ok(code) => (code, lines),
            Err(e) => panic!("the console failed: {e:#}\n{}", lines.join("\n")),
        }
    }
}

/// A current-thread runtime whose time is paused: it jumps to the next timer whenever every
/// task waits, so a session takes as long as its work.
pub fn virtual_time<F: std::future::Future>(f: F) -> F::Output {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .expect("a runtime")
        .block_on(f)
}

impl Therapist {
    /// Waits (on the virtual clock) until the console has said a line starting with
    /// `start`, at most `within`.
    pub async fn wait_for_line(&self, start: &str, within: Duration) {
        let deadline = tokio::time::Instant::now() + within;
        while !self.lines().iter().any(|l| l.starts_with(start)) {
            assert!(
                tokio::time::Instant::now() < deadline,
                "no console line {start:?} within {within:?}:\n{}",
                self.lines().join("\n")
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }
}
