//! A DDS node's start-up: logging, its parameters, the RustDDS participant (domain and
//! localhost-only from the ROS 2 environment, DDS Security when enabled), the ros2-client node
//! and its spinner, its `/rosout` writer, its heartbeat, the SIGINT/SIGTERM listener and the
//! watch on RustDDS's threads (`dds_watch`). [`NodeShell`] is the running node.

use crate::clock::Clock;
use crate::drops::DropLog;
use crate::environment::{domain_id_from_env, localhost_only_from_env};
use crate::logging::init_logging;
use crate::options::ShellOptions;
use crate::parameters::{NodeParameters, ParameterTable};
use crate::security::{SecurityError, SecurityMode, with_security};
use anyhow::{Context as _, bail};
use futures::FutureExt as _;
use ros2_client::{Context, Node, NodeName, NodeOptions, ServiceMapping};
use std::any::Any;
use std::net::{IpAddr, Ipv4Addr};
use std::path::Path;
use std::sync::Arc;
use tokio::sync::watch;

/// A running DDS node: its ros2-client node, shutdown signal and the helpers that move
/// messages. Its messages, services and clock are the node's [`Bus`](crate::Bus).
pub struct NodeShell {
    pub(crate) node: Node,
    pub(crate) name: String,
    pub(crate) service_mapping: ServiceMapping,
    pub(crate) drops: Arc<DropLog>,
    pub(crate) shutdown: watch::Receiver<bool>,
    pub(crate) clock: Clock,
    // The nodes every participant announces (ros_discovery_info).
    pub(crate) graph: crate::graph::Graph,
    // Tasks that own DDS entities: stopped before the participant goes, so RustDDS can
    // remove them cleanly.
    pub(crate) tasks: Vec<tokio::task::JoinHandle<()>>,
    // The changes the parameter services accepted, for the node's run loop: an
    // mpsc::Receiver<ParameterChange<P>> of the node's parameter type, until it takes it.
    pub(crate) parameter_changes: Option<Box<dyn Any + Send>>,
    // Ends the process if RustDDS's threads end; dropped (stopped) before the participant,
    // whose threads end at a clean stop too.
    _dds_watch: Option<crate::dds_watch::ThreadWatch>,
    // Kept so the DDS participant outlives every entity created from it; its participant
    // holds the type hashes endpoints announce (`type_hashes`).
    pub(crate) context: Context,
}

impl NodeShell {
    /// Sets up logging, reads the node's parameter file into `P`, joins the ROS 2 graph, and
    /// serves `P`'s parameters through the standard parameter services (`parameters`).
    /// Must run inside a tokio runtime.
    pub fn start<P: NodeParameters>(
        default_name: &str,
        options: &ShellOptions,
    ) -> anyhow::Result<(NodeShell, P)> {
        let name = options.node_name_or(default_name);
        let sink = init_logging(&name);
        let (params, params_path): (P, _) = options.parameters(default_name)?;
        let parameter_table = ParameterTable::new(&params)
            .with_context(|| format!("describing the parameters of {}", params_path.display()))?;
        let service_mapping = match options.service_mapping.to_ascii_lowercase().as_str() {
            "enhanced" => ServiceMapping::Enhanced,
            "cyclone" => ServiceMapping::Cyclone,
            "basic" => ServiceMapping::Basic,
            other => bail!("--service-mapping {other:?} is not enhanced, cyclone or basic"),
        };
        let domain = domain_id_from_env()?;
        let mut builder = rustdds::DomainParticipantBuilder::new(domain);
        let localhost = localhost_only_from_env();
        if localhost {
            builder = builder.with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)]);
        }
        let enclave = match SecurityMode::from_env(options.enclave_arg())
            .context("reading the DDS security settings")?
        {
            SecurityMode::Off => None,
            _ if !cfg!(feature = "security") => return Err(SecurityError::NotBuilt.into()),
            SecurityMode::PermissiveFallback { reason } => {
                tracing::warn!(
                    "ROS_SECURITY_ENABLE=true, strategy Permissive: running WITHOUT DDS \
                     security because {reason}"
                );
                None
            }
            SecurityMode::Enclave { enclave, dir } => {
                builder = with_security(builder, &dir)?;
                Some(enclave)
            }
        };
        // RustDDS's threads before the participant, so that its own are told apart.
        let rustdds_threads_before =
            crate::dds_watch::rustdds_threads(Path::new(crate::dds_watch::TASK_DIR))
                .unwrap_or_default();
        let participant = builder.build().with_context(|| match &enclave {
            Some(e) => {
                format!("creating the secured DDS participant (enclave {e}) in domain {domain}")
            }
            None => format!("creating the DDS participant in domain {domain}"),
        })?;
        // Before the context makes its first endpoint (its ros_discovery_info writer).
        crate::type_hashes::announce_builtin_types(&participant)
            .context("describing ROS 2's builtin types")?;
        let context = Context::from_domain_participant(participant)
            .context("creating the ros2-client context")?;
        let node_name = NodeName::new(&options.namespace, &name).map_err(|e| {
            anyhow::anyhow!(
                "{name:?} in {:?} is not a node name: {e:?}",
                options.namespace
            )
        })?;
        let mut node = context
            .new_node(
                node_name,
                // Our own parameter services (`parameter_services`): ros2-client's offer only
                // use_sim_time.
                NodeOptions::new()
                    .enable_rosout(false)
                    .start_parameter_services(false),
            )
            .with_context(|| format!("creating node {name}"))?;
        let (changes_tx, changes_rx) =
            tokio::sync::mpsc::channel::<crate::parameters::ParameterChange<P>>(4);
        let parameter_tasks = crate::parameter_services::serve(
            &mut node,
            service_mapping,
            parameter_table,
            changes_tx,
        )?;
        let (rosout, rosout_drain) = rosout(&context, &mut node)?;
        let (graph, graph_task) = crate::graph::follow(&context, &mut node)?;
        let spinner = node.spinner().context("starting the node's spinner")?;
        // RustDDS 0.15.1 deadlocks a secured participant when one thread creates a reader or
        // writer (security-plugins lock, then participant lock) while another creates a topic
        // (participant lock, then plugins lock): seen once as a node hung at start-up
        // (tests/dds_security.rs `rustdds_deadlocks_creating_readers_and_topics_at_once`).
        // The spinner creates its two readers in its first poll, before its first await; poll
        // it once here, so they are made on this thread in turn with the node's own entities,
        // never beside them on a tokio worker.
        let mut spin = Box::pin(spinner.spin());
        let spun_out = (&mut spin).now_or_never();
        let spinner_task = tokio::spawn(async move {
            let result = match spun_out {
                Some(result) => result,
                None => spin.await,
            };
            if let Err(e) = result {
                tracing::error!("ros2-client spinner stopped: {e:?}");
            }
        });
        sink.attach(rosout);
        let shutdown = crate::shutdown::spawn_signal_listener()?;
        tracing::info!(
            node = %name,
            domain,
            localhost_only = localhost,
            enclave = enclave.as_deref().unwrap_or("none (DDS security off)"),
            params = %params_path.display(),
            "node started"
        );
        // Last before the shell owns it: an error above drops the participant, whose threads
        // then end, and that is no reason to exit 70.
        let dds_watch = crate::dds_watch::watch_participant(&name, &rustdds_threads_before);
        let mut tasks = vec![spinner_task, rosout_drain, graph_task];
        tasks.extend(parameter_tasks);
        let mut shell = NodeShell {
            node,
            name,
            service_mapping,
            drops: Arc::new(DropLog::default()),
            shutdown,
            clock: Clock::wall(),
            graph,
            tasks,
            parameter_changes: Some(Box::new(changes_rx)),
            _dds_watch: dds_watch,
            context,
        };
        let heartbeat = crate::heartbeat::start(&mut shell)?;
        shell.tasks.push(heartbeat);
        Ok((shell, params))
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// Counts of dropped input, per topic and reason.
    pub fn drops(&self) -> Arc<DropLog> {
        self.drops.clone()
    }

    /// The changes to the node's writable parameters that the parameter services accepted
    /// (`ros2 param set`), for the node's run loop to hand to its core; `P` is the node's
    /// parameter type, as given to [`NodeShell::start`]. Taken once: a second call, or
    /// another `P`, gets a channel that never yields.
    pub fn parameter_changes<P: NodeParameters>(
        &mut self,
    ) -> tokio::sync::mpsc::Receiver<crate::parameters::ParameterChange<P>> {
        let taken = self.parameter_changes.take().and_then(|rx| {
            rx.downcast::<tokio::sync::mpsc::Receiver<crate::parameters::ParameterChange<P>>>()
                .ok()
        });
        match taken {
            Some(rx) => *rx,
            None => {
                tracing::warn!(
                    "parameter changes asked for twice, or of another type than the node's \
                     parameters: none will come"
                );
                tokio::sync::mpsc::channel(1).1
            }
        }
    }

    /// The ROS 2 graph's nodes, as their participants announce them.
    pub fn graph(&self) -> &crate::graph::Graph {
        &self.graph
    }

    /// The underlying ros2-client node, for what the shell does not wrap (the DDS benchmarks'
    /// raw publishers, a test's untyped subscriptions).
    pub fn node_mut(&mut self) -> &mut Node {
        &mut self.node
    }
}

/// Backstop on the `/rosout` records a node's writer holds (ROS 2's rosout depth).
const ROSOUT_BACKSTOP: i32 = 1000;

/// The node's `/rosout` publisher, and a task that reads the node's own records back.
///
/// Why the reader: RustDDS 0.15.1 trims a reliable writer's history to its depth only after
/// every matched reader has acknowledged; with no reader at all it trims nothing and keeps
/// every sample up to its 8,192-sample backstop. `/rosout` is
/// transient-local and usually unread, so each node kept every line it ever logged: the
/// soak's steady memory growth (heaptrack: ~6 kB per session in the tablet bridge, all in
/// the rosout writer). With our own reader acknowledging, the writer keeps its depth (the
/// newest record, for a late rqt_console), and [`ROSOUT_BACKSTOP`] caps it if that reader
/// ever falls behind. QoS otherwise as ros2-client's rosout writer.
fn rosout(
    context: &Context,
    node: &mut Node,
) -> anyhow::Result<(
    ros2_client::Publisher<ros2_client::log::Log>,
    tokio::task::JoinHandle<()>,
)> {
    use futures::StreamExt as _;
    use ros2_client::builtin_topics::rosout;
    let limits = rustdds::policy::ResourceLimits {
        max_samples: ROSOUT_BACKSTOP,
        max_instances: 1,
        max_samples_per_instance: ROSOUT_BACKSTOP,
    };
    let qos = rustdds::QosPolicyBuilder::new()
        .resource_limits(limits)
        .build()
        .modify_by(&rosout::QOS);
    let topic = context
        .domain_participant()
        .create_topic(
            rosout::TOPIC_NAME.to_string(),
            rosout::TYPE_NAME.to_string(),
            &qos,
            rustdds::TopicKind::NoKey,
        )
        .context("creating the /rosout topic")?;
    let publisher = node
        .create_publisher(&topic, None)
        .context("creating the /rosout publisher")?;
    let own_records = node
        .create_subscription::<ros2_client::log::Log>(&topic, None)
        .context("creating the /rosout reader")?;
    let drain = tokio::spawn(async move {
        let records = own_records.async_stream();
        tokio::pin!(records);
        while records.next().await.is_some() {}
    });
    Ok((publisher, drain))
}
