//! The DDS side of every node: builds the RustDDS participant (domain id and localhost-only
//! from the ROS 2 environment variables), the ros2-client node and its spinner, typed
//! publishers, validated subscriptions and services over channels, a heartbeat, a clean
//! exit on SIGINT/SIGTERM, and an exit (code 70) if RustDDS's threads end (`dds_watch`).
//! Node logic never sees any of this: it gets messages from channels.

use crate::drops::DropLog;
use crate::logging::init_logging;
use crate::params::{apply_overrides, parameters_from_map, read_parameter_map};
use crate::security::{SecurityError, SecurityMode};
use anyhow::{Context as _, bail};
use futures::FutureExt as _;
use qt_therapy_msgs::services::ServiceDefinition;
use qt_therapy_msgs::topics::{HEARTBEAT, QosKind, Service, Topic};
use qt_therapy_msgs::{Heartbeat, InvalidMessage, MessageDefinition, Validate, dds_type_name};
use ros2_client::qos::{Durability, History, Reliability, WhenFull};
use ros2_client::{
    Context, Message, Name, Node, NodeName, NodeOptions, QosProfile, ServiceMapping,
    ServiceTypeName,
};
use serde::de::DeserializeOwned;
use std::net::{IpAddr, Ipv4Addr};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{mpsc, oneshot, watch};

/// Command-line options every node accepts (flatten into the node's clap struct).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ShellOptions {
    /// ROS 2 parameter file [default: $QT_PARAMS_DIR/<node>.yaml, else params/<node>.yaml,
    /// else /etc/qt-therapy/<node>.yaml where the package installed it]
    #[arg(long)]
    pub params_file: Option<PathBuf>,
    /// Node name on the ROS graph; also the section read from the parameter file.
    #[arg(long)]
    pub node_name: Option<String>,
    /// Node namespace.
    #[arg(long, default_value = "/")]
    pub namespace: String,
    /// Service mapping: `enhanced` talks to rmw_fastrtps peers, `cyclone` to rmw_cyclonedds.
    #[arg(long, env = "QT_SERVICE_MAPPING", default_value = "enhanced")]
    pub service_mapping: String,
    /// Override one parameter of the file, as ROS 2's `-p`: `--param time_scale:=0.2`.
    #[arg(long = "param", value_name = "KEY:=VALUE")]
    pub param_overrides: Vec<String>,
    /// SROS2 enclave of this node, e.g. /qt_therapy/tablet_bridge (used when
    /// ROS_SECURITY_ENABLE=true; ROS_SECURITY_ENCLAVE_OVERRIDE wins over it, as in rcl).
    /// Always accepted, so launch files need no per-build variant; a build without the
    /// `security` feature refuses to start when security is enabled.
    #[arg(long)]
    pub enclave: Option<String>,
}

impl ShellOptions {
    /// The `--enclave` argument.
    pub fn enclave_arg(&self) -> Option<&str> {
        self.enclave.as_deref()
    }

    /// The parameter file this node reads.
    pub fn params_path(&self, node_name: &str) -> PathBuf {
        if let Some(p) = &self.params_file {
            return p.clone();
        }
        let dir = params_dir(
            std::env::var_os("QT_PARAMS_DIR").filter(|d| !d.is_empty()),
            |d| d.is_dir(),
        );
        dir.join(format!("{node_name}.yaml"))
    }

    /// The node's name: `--node-name`, else `default_name`.
    pub fn node_name_or(&self, default_name: &str) -> String {
        self.node_name
            .clone()
            .unwrap_or_else(|| default_name.to_string())
    }

    /// The node's parameters as `NodeShell::start` reads them (its file, then the `--param`
    /// overrides, into `P`), and the file's path: for a node that must check them before it
    /// joins the graph.
    pub fn parameters<P: DeserializeOwned>(
        &self,
        default_name: &str,
    ) -> anyhow::Result<(P, PathBuf)> {
        let name = self.node_name_or(default_name);
        let path = self.params_path(&name);
        let mut map = read_parameter_map(&path, &name)?;
        apply_overrides(&mut map, &self.param_overrides, &path, &name)?;
        let params = parameters_from_map(map, &path, &name)?;
        Ok((params, path))
    }
}

/// Where the qt-therapy package installs the parameter files (conffiles).
pub const INSTALLED_PARAMS_DIR: &str = "/etc/qt-therapy";

/// The directory the parameter files are read from: `QT_PARAMS_DIR`, else `params/` (in the
/// workspace), else the package's `/etc/qt-therapy` when it is there, so an installed program
/// started from anywhere finds its files; else `params/`, which the error then names.
fn params_dir(env: Option<std::ffi::OsString>, is_dir: impl Fn(&Path) -> bool) -> PathBuf {
    if let Some(dir) = env {
        return PathBuf::from(dir);
    }
    let workspace = Path::new("params");
    if !is_dir(workspace) && is_dir(Path::new(INSTALLED_PARAMS_DIR)) {
        return PathBuf::from(INSTALLED_PARAMS_DIR);
    }
    workspace.to_path_buf()
}

/// ROS_DOMAIN_ID, 0 when unset; values outside 0..=232 are an error.
pub fn domain_id_from_env() -> anyhow::Result<u16> {
    domain_id_from(std::env::var("ROS_DOMAIN_ID").ok().as_deref())
}

/// The domain id a `ROS_DOMAIN_ID` value names: unset or empty is 0, as in ROS 2.
fn domain_id_from(value: Option<&str>) -> anyhow::Result<u16> {
    match value.map(str::trim) {
        None | Some("") => Ok(0),
        Some(s) => match s.parse::<u16>() {
            Ok(d) if d <= 232 => Ok(d),
            _ => bail!("ROS_DOMAIN_ID={s:?} is not a domain id in 0..=232"),
        },
    }
}

/// True when ROS_LOCALHOST_ONLY=1 or ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST.
pub fn localhost_only_from_env() -> bool {
    localhost_only_from(
        std::env::var("ROS_LOCALHOST_ONLY").ok().as_deref(),
        std::env::var("ROS_AUTOMATIC_DISCOVERY_RANGE")
            .ok()
            .as_deref(),
    )
}

/// Whether `ROS_LOCALHOST_ONLY` (Humble) or `ROS_AUTOMATIC_DISCOVERY_RANGE` (Jazzy) keep
/// discovery on this machine.
fn localhost_only_from(localhost_only: Option<&str>, discovery_range: Option<&str>) -> bool {
    localhost_only.is_some_and(|v| v.trim() == "1")
        || discovery_range.is_some_and(|v| v.trim().eq_ignore_ascii_case("LOCALHOST"))
}

/// The QoS a topic class gets, the same on both sides.
pub fn qos_profile(kind: QosKind) -> QosProfile {
    let reliable = Reliability::Reliable {
        when_full: WhenFull::Wait(Duration::from_millis(100)),
    };
    match kind {
        QosKind::Reliable => QosProfile::publisher_default()
            .reliability(reliable)
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth: 100 }),
        QosKind::State => QosProfile::publisher_default()
            .reliability(reliable)
            .durability(Durability::TransientLocal)
            .history(History::KeepLast { depth: 1 }),
        QosKind::Durable => QosProfile::publisher_default()
            .reliability(reliable)
            .durability(Durability::TransientLocal)
            .history(History::KeepLast { depth: 100 }),
        QosKind::Features => QosProfile::subscription_default()
            .reliability(Reliability::BestEffort)
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth: 10 }),
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

/// The QoS of the suite's services' request and response topics, the same on both sides.
pub fn service_qos() -> QosProfile {
    qos_profile(QosKind::Reliable).history(History::KeepLast { depth: 10 })
}

/// A full topic or service name (`/qt_therapy/x`) as ros2-client's namespace and base name.
pub fn ros_name(full: &str) -> anyhow::Result<Name> {
    let (ns, base) = match full.rsplit_once('/') {
        Some(("", base)) => ("/", base),
        Some((ns, base)) => (ns, base),
        None => ("/", full),
    };
    Name::new(ns, base).map_err(|e| anyhow::anyhow!("{full:?} is not a ROS name: {e:?}"))
}

/// A running node: its ros2-client node, shutdown signal and the helpers that move messages.
pub struct NodeShell {
    node: Node,
    name: String,
    service_mapping: ServiceMapping,
    drops: Arc<DropLog>,
    shutdown: watch::Receiver<bool>,
    // Tasks that own DDS entities: stopped before the participant goes, so RustDDS can
    // remove them cleanly.
    tasks: Vec<tokio::task::JoinHandle<()>>,
    // Ends the process if RustDDS's threads end; dropped (stopped) before the participant,
    // whose threads end at a clean stop too.
    _dds_watch: Option<crate::dds_watch::ThreadWatch>,
    // Kept so the DDS participant outlives every entity created from it.
    _context: Context,
}

impl NodeShell {
    /// Sets up logging, reads the node's parameter file into `P`, and joins the ROS 2 graph.
    /// Must run inside a tokio runtime.
    pub fn start<P: DeserializeOwned>(
        default_name: &str,
        options: &ShellOptions,
    ) -> anyhow::Result<(NodeShell, P)> {
        let name = options.node_name_or(default_name);
        let sink = init_logging(&name);
        let (params, params_path): (P, _) = options.parameters(default_name)?;
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
        let context = Context::from_domain_participant(participant)
            .context("creating the ros2-client context")?;
        let node_name = NodeName::new(&options.namespace, &name).map_err(|e| {
            anyhow::anyhow!(
                "{name:?} in {:?} is not a node name: {e:?}",
                options.namespace
            )
        })?;
        let mut node = context
            .new_node(node_name, NodeOptions::new().enable_rosout(false))
            .with_context(|| format!("creating node {name}"))?;
        let (rosout, rosout_drain) = rosout(&context, &mut node)?;
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
        let shutdown = spawn_signal_listener()?;
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
        let mut shell = NodeShell {
            node,
            name,
            service_mapping,
            drops: Arc::new(DropLog::default()),
            shutdown,
            tasks: vec![spinner_task, rosout_drain],
            _dds_watch: dds_watch,
            _context: context,
        };
        shell.start_heartbeat()?;
        Ok((shell, params))
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// The underlying ros2-client node, for what the shell does not wrap (the bag recorder's
    /// untyped subscriptions).
    pub fn node_mut(&mut self) -> &mut Node {
        &mut self.node
    }

    /// Counts of dropped input, per topic and reason.
    pub fn drops(&self) -> Arc<DropLog> {
        self.drops.clone()
    }

    /// A publisher on one of the suite's topics.
    pub fn publisher<M: MessageDefinition + Message>(
        &mut self,
        topic: Topic<M>,
    ) -> anyhow::Result<Outbox<M>> {
        let qos = qos_profile(topic.qos);
        let dds_topic = self
            .node
            .create_topic(&ros_name(topic.name)?, dds_type_name::<M>(), &qos)
            .with_context(|| format!("creating topic {}", topic.name))?;
        let publisher = self
            .node
            .create_publisher::<M>(&dds_topic, Some(qos))
            .with_context(|| format!("creating a publisher on {}", topic.name))?;
        Ok(Outbox {
            publisher,
            topic: topic.name,
        })
    }

    /// A subscription whose decoded, validated messages arrive on the returned channel.
    /// Undecodable or invalid messages are logged once per topic and reason, and dropped.
    pub fn subscribe<M>(
        &mut self,
        topic: Topic<M>,
        capacity: usize,
    ) -> anyhow::Result<mpsc::Receiver<M>>
    where
        M: MessageDefinition + Message + Validate,
    {
        let qos = qos_profile(topic.qos);
        let dds_topic = self
            .node
            .create_topic(&ros_name(topic.name)?, dds_type_name::<M>(), &qos)
            .with_context(|| format!("creating topic {}", topic.name))?;
        let subscription = self
            .node
            .create_subscription::<M>(&dds_topic, Some(qos))
            .with_context(|| format!("subscribing to {}", topic.name))?;
        let (tx, rx) = mpsc::channel(capacity.max(1));
        let drops = self.drops.clone();
        let name = topic.name;
        self.tasks.push(tokio::spawn(async move {
            loop {
                match subscription.async_take().await {
                    Ok((message, _info)) => match message.validate() {
                        Ok(()) => {
                            if tx.send(message).await.is_err() {
                                break;
                            }
                        }
                        Err(e) => {
                            drops.record(name, &e.to_string());
                        }
                    },
                    Err(e) => {
                        drops.record(name, &format!("undecodable payload: {e:?}"));
                    }
                }
            }
        }));
        Ok(rx)
    }

    /// Serves a service: validated requests arrive on the channel with a responder; invalid
    /// ones get `invalid(reason)` as their response without reaching the node.
    pub fn serve<S>(
        &mut self,
        service: Service<S>,
        invalid: fn(&InvalidMessage) -> S::Response,
    ) -> anyhow::Result<mpsc::Receiver<ServiceCall<S>>>
    where
        S: ServiceDefinition + 'static,
        S::Request: Validate,
    {
        let server = self
            .node
            .create_server::<S::Request, S::Response>(
                self.service_mapping,
                &ros_name(service.name)?,
                &ServiceTypeName::new(S::PACKAGE, S::NAME),
                service_qos(),
                service_qos(),
            )
            .with_context(|| format!("creating service {}", service.name))?;
        let (tx, rx) = mpsc::channel(16);
        let drops = self.drops.clone();
        let name = service.name;
        self.tasks.push(tokio::spawn(async move {
            loop {
                let (id, request) = match server.async_receive_request().await {
                    Ok(r) => r,
                    Err(e) => {
                        drops.record(name, &format!("undecodable request: {e:?}"));
                        continue;
                    }
                };
                let response = match request.validate() {
                    Err(e) => {
                        drops.record(name, &e.to_string());
                        invalid(&e)
                    }
                    Ok(()) => {
                        let (responder, answer) = oneshot::channel();
                        if tx.send(ServiceCall { request, responder }).await.is_err() {
                            break;
                        }
                        match answer.await {
                            Ok(response) => response,
                            Err(_) => continue,
                        }
                    }
                };
                if let Err(e) = server.async_send_response(id, response).await {
                    tracing::warn!(service = name, "could not send a response: {e:?}");
                }
            }
        }));
        Ok(rx)
    }

    /// A client for one of the suite's services.
    pub fn client<S: ServiceDefinition>(
        &mut self,
        service: Service<S>,
    ) -> anyhow::Result<ServiceClient<S>> {
        let client = self
            .node
            .create_client::<S::Request, S::Response>(
                self.service_mapping,
                &ros_name(service.name)?,
                &ServiceTypeName::new(S::PACKAGE, S::NAME),
                service_qos(),
                service_qos(),
            )
            .with_context(|| format!("creating a client for {}", service.name))?;
        Ok(ServiceClient {
            client: Arc::new(client),
            name: service.name,
        })
    }

    /// Waits until a server for `client` is matched, or `timeout` passes; true if matched.
    pub async fn wait_for_service<S: ServiceDefinition>(
        &self,
        client: &ServiceClient<S>,
        timeout: Duration,
    ) -> bool {
        wait_rechecking(timeout, || client.client.wait_for_service(&self.node)).await
    }

    /// Resolves when SIGINT or SIGTERM arrives.
    pub fn shutdown_signal(&self) -> impl std::future::Future<Output = ()> + Send + 'static {
        let mut rx = self.shutdown.clone();
        async move {
            let _ = rx.wait_for(|stop| *stop).await;
        }
    }

    /// Publishes a [`Heartbeat`] at 10 Hz for as long as the process lives.
    fn start_heartbeat(&mut self) -> anyhow::Result<()> {
        let outbox = self.publisher(HEARTBEAT)?;
        let node_name = self.name.clone();
        self.tasks.push(tokio::spawn(async move {
            let mut tick = tokio::time::interval(Duration::from_millis(100));
            let mut sequence = 0u64;
            loop {
                tick.tick().await;
                outbox.send(Heartbeat {
                    header: crate::header_now(),
                    node_name: node_name.clone(),
                    pid: std::process::id(),
                    sequence,
                });
                sequence += 1;
            }
        }));
        Ok(())
    }

    /// Leaves the graph cleanly so peers see the participant go at once. Drop the node's own
    /// publishers, clients and receivers before calling this.
    pub async fn stop(self) {
        for task in &self.tasks {
            task.abort();
        }
        for task in self.tasks {
            let _ = task.await;
        }
        tracing::info!(node = %self.name, "node stopped");
    }
}

/// Turns on RustDDS's builtin authentication, access control and cryptography with the
/// enclave's files. SROS2 keys carry no password.
#[cfg(feature = "security")]
fn with_security(
    builder: rustdds::DomainParticipantBuilder,
    enclave_dir: &std::path::Path,
) -> anyhow::Result<rustdds::DomainParticipantBuilder> {
    Ok(builder.builtin_security(
        rustdds::DomainParticipantSecurityConfigFiles::with_ros_default_names(
            enclave_dir,
            String::new(),
        ),
    ))
}

#[cfg(not(feature = "security"))]
fn with_security(
    _builder: rustdds::DomainParticipantBuilder,
    _enclave_dir: &std::path::Path,
) -> anyhow::Result<rustdds::DomainParticipantBuilder> {
    Err(SecurityError::NotBuilt.into())
}

fn spawn_signal_listener() -> anyhow::Result<watch::Receiver<bool>> {
    use tokio::signal::unix::{SignalKind, signal};
    let mut interrupt = signal(SignalKind::interrupt()).context("installing the SIGINT handler")?;
    let mut terminate =
        signal(SignalKind::terminate()).context("installing the SIGTERM handler")?;
    let (tx, rx) = watch::channel(false);
    tokio::spawn(async move {
        tokio::select! {
            _ = interrupt.recv() => tracing::info!("SIGINT: shutting down"),
            _ = terminate.recv() => tracing::info!("SIGTERM: shutting down"),
        }
        let _ = tx.send(true);
    });
    Ok(rx)
}

/// A typed publisher that logs (never panics on) failed writes.
pub struct Outbox<M: Message> {
    publisher: ros2_client::Publisher<M>,
    topic: &'static str,
}

impl<M: Message + Serialize + std::fmt::Debug> Outbox<M> {
    /// Publishes; a failure is logged with the topic and returned as false.
    pub fn send(&self, message: M) -> bool {
        match self.publisher.publish(message) {
            Ok(()) => true,
            Err(e) => {
                tracing::warn!(topic = self.topic, "publish failed: {e:?}");
                false
            }
        }
    }

    pub fn topic(&self) -> &'static str {
        self.topic
    }

    /// Waits until a subscriber is matched (then a short settle, since the remote side may
    /// match us a moment later), or `timeout` passes; true if matched.
    pub async fn wait_for_subscribers(&self, shell: &NodeShell, timeout: Duration) -> bool {
        let matched = wait_rechecking(timeout, || {
            self.publisher.wait_for_subscription(&shell.node)
        })
        .await;
        if matched {
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
        matched
    }
}

use serde::Serialize;

/// One validated service request and the way to answer it.
pub struct ServiceCall<S: ServiceDefinition> {
    pub request: S::Request,
    responder: oneshot::Sender<S::Response>,
}

impl<S: ServiceDefinition> ServiceCall<S> {
    pub fn respond(self, response: S::Response) {
        // The caller may have gone; nothing to do then.
        let _ = self.responder.send(response);
    }
}

/// Why a service call gave no answer.
#[derive(Debug, thiserror::Error)]
pub enum CallError {
    #[error("{service} did not answer within {timeout:?}")]
    Timeout {
        service: &'static str,
        timeout: Duration,
    },
    #[error("{service}: {reason}")]
    Failed {
        service: &'static str,
        reason: String,
    },
}

/// A typed service client with a deadline on every call.
pub struct ServiceClient<S: ServiceDefinition> {
    client: Arc<ros2_client::Client<S::Request, S::Response>>,
    name: &'static str,
}

impl<S: ServiceDefinition> Clone for ServiceClient<S> {
    fn clone(&self) -> Self {
        ServiceClient {
            client: self.client.clone(),
            name: self.name,
        }
    }
}

impl<S: ServiceDefinition> ServiceClient<S> {
    /// The service's name.
    pub fn name(&self) -> &'static str {
        self.name
    }

    pub async fn call(
        &self,
        request: S::Request,
        timeout: Duration,
    ) -> Result<S::Response, CallError> {
        match tokio::time::timeout(timeout, self.client.async_call_service(request)).await {
            Err(_) => Err(CallError::Timeout {
                service: self.name,
                timeout,
            }),
            Ok(Err(e)) => Err(CallError::Failed {
                service: self.name,
                reason: format!("{e:?}"),
            }),
            Ok(Ok(response)) => Ok(response),
        }
    }
}

/// Parameters of a node that has none of its own.
#[derive(Debug, Clone, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoParameters {}

/// How often a wait for a match starts again (see [`wait_rechecking`]).
const MATCH_RECHECK: Duration = Duration::from_millis(200);

/// Runs `wait` (one of ros2-client's waits for a match) until it resolves or `timeout` passes,
/// starting it anew every [`MATCH_RECHECK`]; true if it resolved. ros2-client's waits look at
/// the match state when they start, then only when a discovery event reaches them, through a
/// channel of 8 that drops events when full. A node joining a whole graph gets a burst of
/// them, so the one that matters can be dropped and the wait then runs its whole timeout: a
/// respawned game manager waited its 10 s for a running policy in 1 of 10 kill-test runs. A
/// new wait checks the state first, so a dropped event costs at most one recheck.
async fn wait_rechecking<F, W>(timeout: Duration, mut wait: F) -> bool
where
    F: FnMut() -> W,
    W: std::future::Future<Output = ()>,
{
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        let left = deadline.saturating_duration_since(tokio::time::Instant::now());
        if left.is_zero() {
            return false;
        }
        if tokio::time::timeout(left.min(MATCH_RECHECK), wait())
            .await
            .is_ok()
        {
            return true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{INSTALLED_PARAMS_DIR, domain_id_from, localhost_only_from, params_dir};
    use std::future::Future;
    use std::pin::Pin;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::{Duration, Instant};

    #[test]
    fn parameter_files_come_from_the_env_then_the_workspace_then_the_package() {
        use std::path::{Path, PathBuf};
        let only =
            |dirs: &'static [&'static str]| move |d: &Path| dirs.iter().any(|x| d == Path::new(x));
        let env = Some(std::ffi::OsString::from("/tmp/p"));
        assert_eq!(params_dir(env, only(&["params"])), PathBuf::from("/tmp/p"));
        assert_eq!(
            params_dir(None, only(&["params", INSTALLED_PARAMS_DIR])),
            PathBuf::from("params")
        );
        assert_eq!(
            params_dir(None, only(&[INSTALLED_PARAMS_DIR])),
            PathBuf::from(INSTALLED_PARAMS_DIR)
        );
        // Neither: the workspace's, so the error names the file a developer expects.
        assert_eq!(params_dir(None, only(&[])), PathBuf::from("params"));
    }

    #[test]
    fn ros_domain_id_is_read_as_ros_2_does_and_nonsense_is_named() {
        assert_eq!(domain_id_from(None).ok(), Some(0));
        assert_eq!(domain_id_from(Some("")).ok(), Some(0));
        assert_eq!(domain_id_from(Some(" 42 ")).ok(), Some(42));
        assert_eq!(domain_id_from(Some("232")).ok(), Some(232));
        for bad in ["233", "-1", "seven", "1.5"] {
            let e = domain_id_from(Some(bad)).map_err(|e| e.to_string());
            assert_eq!(
                e,
                Err(format!(
                    "ROS_DOMAIN_ID={bad:?} is not a domain id in 0..=232"
                ))
            );
        }
    }

    #[test]
    fn either_localhost_setting_keeps_discovery_local() {
        assert!(!localhost_only_from(None, None));
        assert!(localhost_only_from(Some("1"), None));
        assert!(!localhost_only_from(Some("0"), None));
        assert!(localhost_only_from(None, Some("LOCALHOST")));
        assert!(localhost_only_from(Some("0"), Some("localhost")));
        assert!(!localhost_only_from(None, Some("SUBNET")));
    }

    /// A wait that checks the state only when it starts, as ros2-client's does once its
    /// event was dropped: it resolves if `matched` is set by then, else never.
    fn wait_missing_its_event(matched: &AtomicBool) -> Pin<Box<dyn Future<Output = ()> + Send>> {
        if matched.load(Ordering::SeqCst) {
            Box::pin(std::future::ready(()))
        } else {
            Box::pin(std::future::pending())
        }
    }

    #[tokio::test]
    async fn a_match_whose_event_was_dropped_is_seen_at_the_next_recheck() {
        let matched = Arc::new(AtomicBool::new(false));
        let set = matched.clone();
        tokio::spawn(async move {
            tokio::time::sleep(Duration::from_millis(50)).await;
            set.store(true, Ordering::SeqCst);
        });
        let started = Instant::now();
        let found =
            super::wait_rechecking(Duration::from_secs(30), || wait_missing_its_event(&matched))
                .await;
        assert!(found);
        // One recheck after the match, not the 30 s timeout.
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "{:?}",
            started.elapsed()
        );
    }

    #[tokio::test]
    async fn no_match_waits_the_whole_timeout_and_says_so() {
        let matched = AtomicBool::new(false);
        let started = Instant::now();
        let found = super::wait_rechecking(Duration::from_millis(500), || {
            wait_missing_its_event(&matched)
        })
        .await;
        assert!(!found);
        assert!(started.elapsed() >= Duration::from_millis(500));
    }
}
