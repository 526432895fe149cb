//! The replay harness: a sample bag's recorded inputs of one node are played into that node's
//! own run loop (`node::run`, the code that runs over DDS) on the in-process bus
//! (`node_shell::in_process`), on a virtual clock that reads the bag's times; what the node
//! publishes is recorded by the real bag recorder (`bag::recorder::run`) on the same bus, into a
//! bag that the test reads back and compares with what the live node published.
//!
//! - Each input is published at its log time (when the live recorder received it, within
//!   milliseconds of when the live node did) by one player node, `bag_player`, with a writer
//!   per topic and the QoS its channel offered, through the player's own typed publishers
//!   (`bag::dds_types`); so a node that starts later gets a transient-local topic's kept
//!   history, as it got it from the live writers.
//! - The clock is tokio's paused time: a timer fires on the whole millisecond after it is due,
//!   so an input reaches the node at most 1 ms after its log time, and what the node does is
//!   stamped on that clock.
//! - A node starts at the time its test gives, to the nanosecond (e.g. the game manager at its
//!   first state's stamp): the start is not in a bag, and some outputs carry it (the child's
//!   frame clock, the console's command ids).
//! - Services are not in a bag: a test adds peers of its own on the bus (a stand-in server
//!   answering with recorded decisions, a caller making the recorded requests).
//! - The run ends at a time the test gives (or when its nodes end by themselves): every node
//!   is asked to stop, as SIGINT asks a process, then the player and the recorder; a node that
//!   ends with an error fails the test.

use bag_file::{BagReader, cdr};
use futures::future::LocalBoxFuture;
use node_shell::ShellOptions;
use node_shell::clock::Clock;
use node_shell::in_process::{InProcessBus, InProcessNode, NodeStop};
use qt_therapy_msgs::MessageDefinition;
use qt_therapy_msgs::topics::{QosKind, all_topics};
use std::path::{Path, PathBuf};
use std::time::Duration;
use suite_tests::workspace_root;
use tokio::task::JoinHandle;

/// A millisecond in nanoseconds.
pub const MS: i64 = 1_000_000;

/// One recorded message to play: when, on which topic, its bytes.
#[derive(Clone, Debug)]
pub struct Input {
    pub at_ns: i64,
    pub topic: &'static str,
    pub type_name: String,
    pub qos: QosKind,
    pub payload: Vec<u8>,
}

impl Input {
    /// The message it carries.
    pub fn message<M: MessageDefinition>(&self) -> M {
        cdr::decode(&self.payload).unwrap_or_else(|e| panic!("{}: {e}", self.topic))
    }
}

/// A topic's name as the suite's table spells it (a `&'static str`, as the bus wants).
fn static_topic(name: &str) -> &'static str {
    all_topics()
        .into_iter()
        .find(|t| t.name == name)
        .map(|t| t.name)
        .unwrap_or_else(|| panic!("{name} is not a topic of the suite"))
}

/// The recorded messages of `topics` in `bag`, each to be played at its log time, in the
/// bag's order.
pub fn recorded_inputs(bag: &BagReader, topics: &[&str]) -> Vec<Input> {
    let mut inputs = Vec::new();
    for (channel, m) in bag.iter() {
        if !topics.contains(&channel.topic.as_str()) {
            continue;
        }
        let topic = static_topic(&channel.topic);
        let qos = channel.offered_qos().unwrap_or_else(|| {
            all_topics()
                .into_iter()
                .find(|t| t.name == topic)
                .map_or(QosKind::Reliable, |t| t.qos)
        });
        inputs.push(Input {
            at_ns: m.log_time as i64,
            topic,
            type_name: channel.type_name().to_string(),
            qos,
            payload: m.data.clone(),
        });
    }
    inputs
}

/// The recorded messages of one topic with their log times, decoded (none for a topic the bag
/// has no channel of).
pub fn recorded<M: MessageDefinition>(bag: &BagReader, topic: &str) -> Vec<(i64, M)> {
    if bag.topic_channels(topic).is_empty() {
        return Vec::new();
    }
    bag.messages::<M>(topic)
        .unwrap_or_else(|e| panic!("{topic}: {e}"))
        .into_iter()
        .map(|s| (s.log_time as i64, s.message))
        .collect()
}

/// `params/<node>.yaml` of the workspace with `overrides` (`key:=value`), as a launch file's
/// `--param` gives them.
pub fn parameters<P: serde::de::DeserializeOwned>(
    node: &str,
    overrides: &[String],
) -> (P, PathBuf) {
    let options = ShellOptions {
        params_file: Some(workspace_root().join("params").join(format!("{node}.yaml"))),
        namespace: "/".into(),
        param_overrides: overrides.to_vec(),
        ..Default::default()
    };
    options
        .parameters(node)
        .unwrap_or_else(|e| panic!("{node}'s parameters: {e:#}"))
}

/// A file of the workspace by its absolute path (the nodes read files relative to the working
/// directory, which for a test is its package's).
pub fn workspace_file(relative: &str) -> String {
    workspace_root().join(relative).display().to_string()
}

/// What a node's task is given to run: its place on the bus; it returns the run loop's end.
pub type NodeRun =
    Box<dyn for<'a> FnOnce(&'a mut InProcessNode) -> LocalBoxFuture<'a, anyhow::Result<()>>>;

struct Running {
    name: String,
    stop: NodeStop,
    task: JoinHandle<anyhow::Result<()>>,
}

/// One replay: a bus on a virtual clock, the player, the recorder and the nodes started.
pub struct Replay {
    bus: InProcessBus,
    dir: tempfile::TempDir,
    player: Running,
    recorder: Running,
    nodes: Vec<Running>,
}

/// How long before the first input the clock starts (the player and the recorder join then).
const LEAD: i64 = 1_000 * MS;

impl Replay {
    /// A replay of `inputs` whose recorder records `outputs` (topics of the suite, all when
    /// empty): call it inside [`virtual_time`]. The clock starts at least a second before the
    /// first input and before `from`, a whole number of milliseconds before `from`: a timer set
    /// at `from` (the start of the node under test) fires on time to the nanosecond.
    pub fn new(inputs: Vec<Input>, outputs: &[&str], from: i64) -> Replay {
        let first = inputs
            .iter()
            .map(|i| i.at_ns)
            .min()
            .unwrap_or(from)
            .min(from);
        let before = (from - first + LEAD + MS - 1) / MS * MS;
        let bus = InProcessBus::new(Clock::starting_at(from - before));
        let dir = tempfile::tempdir().expect("a temporary directory");
        let output = dir.path().join("replay.mcap");
        let (params, _) = parameters::<bag::params::RecorderParams>(bag::recorder::NODE, &[]);
        let what = bag::recorder::Recording {
            output,
            topics: outputs.iter().map(|t| t.to_string()).collect(),
            compression: None,
        };
        let recorder = spawn(
            &bus,
            bag::recorder::NODE,
            None,
            Box::new(move |bus| {
                Box::pin(async move {
                    bag::recorder::run(bus, params, what, bag::recorder::SuiteOnly, None)
                        .await
                        .map(|_| ())
                })
            }),
        );
        let player = spawn(
            &bus,
            "bag_player",
            None,
            Box::new(move |bus| Box::pin(play(bus, inputs))),
        );
        Replay {
            bus,
            dir,
            player,
            recorder,
            nodes: Vec::new(),
        }
    }

    /// The bus's clock.
    pub fn clock(&self) -> Clock {
        self.bus.clock()
    }

    /// A directory of this replay's own (parameters, Q-tables, session files).
    pub fn dir(&self) -> &Path {
        self.dir.path()
    }

    /// Starts `run` as node `name` at `at_ns` exactly (a test's peer or the node under test).
    pub fn start(&mut self, name: &str, at_ns: i64, run: NodeRun) {
        let node = spawn(&self.bus, name, Some(at_ns), run);
        self.nodes.push(node);
    }

    /// Runs until `end_ns` (None: until every started node has ended by itself), then stops
    /// the nodes, the player and the recorder; the bag the recorder wrote, and the replay's
    /// directory.
    pub async fn finish(self, end_ns: Option<i64>) -> Replayed {
        let Replay {
            bus,
            dir,
            player,
            recorder,
            nodes,
        } = self;
        if let Some(end) = end_ns {
            bus.clock().sleep_until(end).await;
            for n in &nodes {
                n.stop.stop();
            }
        }
        for n in nodes {
            end(n).await;
        }
        player.stop.stop();
        end(player).await;
        recorder.stop.stop();
        end(recorder).await;
        let path = dir.path().join("replay.mcap");
        let bag = BagReader::open(&path)
            .and_then(BagReader::strict)
            .unwrap_or_else(|e| panic!("the replay's bag {}: {e}", path.display()));
        Replayed { bag, dir }
    }
}

/// What a replay left: the bag its recorder wrote, and its directory (removed when dropped).
pub struct Replayed {
    pub bag: BagReader,
    pub dir: tempfile::TempDir,
}

/// Waits for a node's task; its error or panic fails the test, naming it.
async fn end(n: Running) {
    match n.task.await {
        Ok(Ok(())) => {}
        Ok(Err(e)) => panic!("{} ended with an error: {e:#}", n.name),
        Err(e) => panic!("{}'s task: {e}", n.name),
    }
}

/// Joins `name` to the bus and runs it from `at_ns` or at once. Exactly: a time off the
/// clock's millisecond grid (see [`Replay::new`]) is reached by moving the paused clock on by
/// the part of a millisecond its timers cannot; the clock then stays that far off the grid.
fn spawn(bus: &InProcessBus, name: &str, at_ns: Option<i64>, run: NodeRun) -> Running {
    let (mut node, stop) = bus.join(name).expect("joins the bus");
    let clock = bus.clock();
    let task = tokio::task::spawn_local(async move {
        if let Some(at) = at_ns {
            // A timer fires on the first millisecond tick at or after its time, and a clock
            // already moved off the grid reads up to 1 ms more: 2 ms early is never late.
            clock.sleep_until(at - 2 * MS).await;
            let now = clock.now_nanos();
            if at > now {
                tokio::time::advance(Duration::from_nanos((at - now) as u64)).await;
            }
        }
        let outcome = run(&mut node).await;
        node.stop().await;
        outcome
    });
    Running {
        name: name.to_string(),
        stop,
        task,
    }
}

/// The player: a writer per topic (with its channel's QoS), each input published at its time;
/// then it stays, so its writers keep their transient-local histories, until it is stopped.
async fn play(bus: &mut InProcessNode, mut inputs: Vec<Input>) -> anyhow::Result<()> {
    use node_shell::Bus;
    inputs.sort_by_key(|i| i.at_ns);
    let mut publishers = std::collections::BTreeMap::new();
    for i in &inputs {
        if !publishers.contains_key(i.topic) {
            let ty = bag::dds_types::bus_type::<InProcessNode>(&i.type_name)
                .ok_or_else(|| anyhow::anyhow!("{}: unknown type {}", i.topic, i.type_name))?;
            publishers.insert(i.topic, ty.publisher(bus, i.topic, i.qos)?);
        }
    }
    let clock = bus.clock();
    let stop = bus.shutdown_signal();
    tokio::pin!(stop);
    for i in &inputs {
        tokio::select! {
            biased;
            _ = &mut stop => return Ok(()),
            _ = clock.sleep_until(i.at_ns) => {}
        }
        publishers[i.topic]
            .publish_cdr(&i.payload)
            .map_err(anyhow::Error::msg)?;
    }
    stop.await;
    Ok(())
}

/// A current-thread runtime whose time is paused: it jumps to the next timer whenever every
/// task waits, so a replay takes as long as its work. Nodes run as local tasks (the player's
/// publishers stay on this thread).
pub fn virtual_time<F: std::future::Future>(f: F) -> F::Output {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .expect("a runtime");
    tokio::task::LocalSet::new().block_on(&runtime, f)
}
