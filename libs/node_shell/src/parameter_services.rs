//! The six standard parameter services of a node over DDS (`~/list_parameters`,
//! `~/get_parameters`, `~/get_parameter_types`, `~/describe_parameters`, `~/set_parameters`,
//! `~/set_parameters_atomically`), answered from the node's [`ParameterTable`] as rclcpp's
//! `ParameterService` answers (jazzy, `rclcpp/src/rclcpp/parameter_service.cpp`), and
//! `/parameter_events` when a change is taken. ros2-client's own parameter services are off:
//! they knew only `use_sim_time`.
//!
//! A set that passes the table's checks goes to the node's run loop as a
//! [`ParameterChange`] (the node's core decides); the services answer one request at a time
//! per service, and a set holds the table until the node has answered.

use crate::parameters::{NodeParameters, ParameterChange, ParameterTable, Refusal};
use anyhow::Context as _;
use ros2_client::names::Name;
use ros2_client::parameters::raw;
use ros2_client::qos::{Durability, History, Reliability};
use ros2_client::rcl_interfaces::*;
use ros2_client::{Node, Publisher, QosProfile, Server, ServiceMapping, ServiceTypeName};
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{Mutex, mpsc};

/// How long a set waits for the node's run loop to answer before it is refused.
const NODE_ANSWER_TIMEOUT: Duration = Duration::from_secs(10);

/// rclcpp's `rmw_qos_profile_parameters`: reliable, volatile, keep last 1000.
fn parameters_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability(Reliability::Reliable {
            when_full: ros2_client::qos::WhenFull::Wait(Duration::from_millis(100)),
        })
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 1000 })
}

/// Serves `table` for `node` (its fully qualified name `node_name`): one task per service.
/// Changes the table accepts go to `changes`.
pub(crate) fn serve<P: NodeParameters>(
    node: &mut Node,
    mapping: ServiceMapping,
    table: ParameterTable,
    changes: mpsc::Sender<ParameterChange<P>>,
) -> anyhow::Result<Vec<tokio::task::JoinHandle<()>>> {
    let node_name = node.fully_qualified_name();
    let events = node.parameter_events_publisher();
    let table = Arc::new(Mutex::new(table));
    let mut tasks = Vec::new();

    let list = server::<ListParametersRequest, ListParametersResponse>(
        node,
        mapping,
        &node_name,
        "list_parameters",
        "ListParameters",
    )?;
    let t = table.clone();
    tasks.push(answer(list, "list_parameters", move |req| {
        let t = t.clone();
        async move {
            ListParametersResponse {
                result: t.lock().await.list(&req.prefixes, req.depth),
            }
        }
    }));

    let get = server::<GetParametersRequest, GetParametersResponse>(
        node,
        mapping,
        &node_name,
        "get_parameters",
        "GetParameters",
    )?;
    let t = table.clone();
    tasks.push(answer(get, "get_parameters", move |req| {
        let t = t.clone();
        async move {
            GetParametersResponse {
                values: t.lock().await.get(&req.names),
            }
        }
    }));

    let types = server::<GetParameterTypesRequest, GetParameterTypesResponse>(
        node,
        mapping,
        &node_name,
        "get_parameter_types",
        "GetParameterTypes",
    )?;
    let t = table.clone();
    tasks.push(answer(types, "get_parameter_types", move |req| {
        let t = t.clone();
        async move {
            GetParameterTypesResponse {
                values: t.lock().await.types(&req.names),
            }
        }
    }));

    let describe = server::<DescribeParametersRequest, DescribeParametersResponse>(
        node,
        mapping,
        &node_name,
        "describe_parameters",
        "DescribeParameters",
    )?;
    let t = table.clone();
    tasks.push(answer(describe, "describe_parameters", move |req| {
        let t = t.clone();
        async move {
            DescribeParametersResponse {
                values: t.lock().await.describe(&req.names),
            }
        }
    }));

    let setter = Arc::new(Setter {
        table: table.clone(),
        changes,
        events,
        node_name: node_name.clone(),
    });

    let set = server::<SetParametersRequest, SetParametersResponse>(
        node,
        mapping,
        &node_name,
        "set_parameters",
        "SetParameters",
    )?;
    let s = setter.clone();
    tasks.push(answer(set, "set_parameters", move |req| {
        let s = s.clone();
        async move {
            // As rclcpp: one at a time, each as its own atomic set.
            let mut results = Vec::new();
            for p in req.parameter {
                let result = match s.set(vec![p]).await {
                    Err(Refusal::NotDeclared(name)) => Err(format!(
                        "parameter '{name}' cannot be set because it was not declared"
                    )),
                    Err(Refusal::Reason(reason)) => Err(reason),
                    Ok(()) => Ok(()),
                };
                results.push(result_message(result));
            }
            SetParametersResponse { results }
        }
    }));

    let atomically = server::<SetParametersRequest, SetParametersAtomicallyResponse>(
        node,
        mapping,
        &node_name,
        "set_parameters_atomically",
        "SetParametersAtomically",
    )?;
    let s = setter;
    tasks.push(answer(
        atomically,
        "set_parameters_atomically",
        move |req| {
            let s = s.clone();
            async move {
                let result = match s.set(req.parameter).await {
                    Err(Refusal::NotDeclared(_)) => {
                        Err("One or more parameters were not declared before setting".to_string())
                    }
                    Err(Refusal::Reason(reason)) => Err(reason),
                    Ok(()) => Ok(()),
                };
                SetParametersAtomicallyResponse {
                    result: result_message(result),
                }
            }
        },
    ));
    Ok(tasks)
}

fn result_message(result: Result<(), String>) -> raw::SetParametersResult {
    match result {
        Ok(()) => raw::SetParametersResult {
            successful: true,
            reason: String::new(),
        },
        Err(reason) => raw::SetParametersResult {
            successful: false,
            reason,
        },
    }
}

fn server<Req, Resp>(
    node: &mut Node,
    mapping: ServiceMapping,
    node_name: &str,
    service: &str,
    type_name: &str,
) -> anyhow::Result<Server<Req, Resp>>
where
    Req: ros2_client::Message + Clone + 'static,
    Resp: ros2_client::Message + 'static,
{
    let name = Name::new(node_name, service)
        .map_err(|e| anyhow::anyhow!("{node_name}/{service} is not a service name: {e:?}"))?;
    node.create_server::<Req, Resp>(
        mapping,
        &name,
        &ServiceTypeName::new("rcl_interfaces", type_name),
        parameters_qos(),
        parameters_qos(),
    )
    .with_context(|| format!("creating the parameter service {node_name}/{service}"))
}

/// Answers every request of `server` with `respond(request)`, one at a time.
fn answer<Req, Resp, F, Fut>(
    server: Server<Req, Resp>,
    service: &'static str,
    respond: F,
) -> tokio::task::JoinHandle<()>
where
    Req: ros2_client::Message + Send + Sync + 'static,
    Resp: ros2_client::Message + Send + Sync + 'static,
    F: Fn(Req) -> Fut + Send + 'static,
    Fut: Future<Output = Resp> + Send,
{
    tokio::spawn(async move {
        loop {
            let (id, request) = match server.async_receive_request().await {
                Ok(r) => r,
                Err(e) => {
                    tracing::warn!(service, "undecodable parameter request: {e:?}");
                    continue;
                }
            };
            let response = respond(request).await;
            if let Err(e) = server.async_send_response(id, response).await {
                tracing::warn!(service, "could not send a response: {e:?}");
            }
        }
    })
}

/// Sets parameters: the table's checks, the node's answer, then the store and the event.
struct Setter<P> {
    table: Arc<Mutex<ParameterTable>>,
    changes: mpsc::Sender<ParameterChange<P>>,
    events: Arc<Publisher<raw::ParameterEvent>>,
    node_name: String,
}

impl<P: NodeParameters> Setter<P> {
    async fn set(&self, parameters: Vec<raw::Parameter>) -> Result<(), Refusal> {
        // Held until the node has answered: one change at a time.
        let mut table = self.table.lock().await;
        table.check(&parameters)?;
        let proposed: P = table.proposed(&parameters).map_err(Refusal::Reason)?;
        let names: Vec<String> = parameters.iter().map(|p| p.name.clone()).collect();
        let (change, answer) = ParameterChange::new(proposed, names.clone());
        if self.changes.send(change).await.is_err() {
            return Err(Refusal::Reason(
                "the node takes no parameter changes now (it is stopping)".into(),
            ));
        }
        match tokio::time::timeout(NODE_ANSWER_TIMEOUT, answer).await {
            Ok(Ok(Ok(()))) => {}
            Ok(Ok(Err(reason))) => {
                tracing::info!(parameters = ?names, "parameter change refused: {reason}");
                return Err(Refusal::Reason(reason));
            }
            Ok(Err(_)) => {
                return Err(Refusal::Reason(
                    "the node dropped the change without an answer".into(),
                ));
            }
            Err(_) => {
                return Err(Refusal::Reason(format!(
                    "the node did not answer within {NODE_ANSWER_TIMEOUT:?}"
                )));
            }
        }
        let changed = table.apply(&parameters);
        tracing::info!(parameters = ?names, "parameters changed");
        let event = raw::ParameterEvent {
            stamp: ros2_client::builtin_interfaces::Time::now(),
            node: self.node_name.clone(),
            new_parameters: vec![],
            changed_parameters: changed,
            deleted_parameters: vec![],
        };
        if let Err(e) = self.events.publish(event) {
            tracing::warn!("could not publish /parameter_events: {e:?}");
        }
        Ok(())
    }
}
