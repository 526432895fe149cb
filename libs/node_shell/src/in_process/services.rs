//! Services on the in-process bus: each server takes its requests one at a time, validated
//! as over DDS; a call goes to every server of the name and the first answer wins.

use super::{Entity, Inbox, Leave, Shared};
use crate::bus::{Handed, ServiceCall, hand_to_node};
use crate::drops::DropLog;
use qt_therapy_msgs::services::ServiceDefinition;
use qt_therapy_msgs::topics::Service;
use qt_therapy_msgs::{InvalidMessage, MessageDefinition, Validate};
use std::any::Any;
use std::collections::BTreeMap;
use std::sync::Arc;
use tokio::sync::mpsc;

pub(crate) struct ServiceEntry {
    type_name: String,
    pub(super) typed: Box<dyn AnyService>,
}

/// A service whose types are known only to its servers and clients.
pub(super) trait AnyService: Send {
    fn as_any(&mut self) -> &mut dyn Any;
    fn remove(&mut self, id: u64);
    fn servers(&self) -> usize;
}

/// One request and where its answer goes.
struct Request<S: ServiceDefinition> {
    request: S::Request,
    reply: mpsc::Sender<S::Response>,
}

struct TypedService<S: ServiceDefinition> {
    servers: BTreeMap<u64, Arc<Inbox<Request<S>>>>,
}

impl<S: ServiceDefinition + 'static> AnyService for TypedService<S> {
    fn as_any(&mut self) -> &mut dyn Any {
        self
    }

    fn remove(&mut self, id: u64) {
        self.servers.remove(&id);
    }

    fn servers(&self) -> usize {
        self.servers.len()
    }
}

fn type_name<S: ServiceDefinition>() -> String {
    format!("{}/srv/{}", S::PACKAGE, S::NAME)
}

/// The typed service `service`, made on first use; another type under its name is an error.
fn typed<'g, S: ServiceDefinition + 'static>(
    services: &'g mut BTreeMap<&'static str, ServiceEntry>,
    service: Service<S>,
) -> anyhow::Result<&'g mut TypedService<S>> {
    let entry = services
        .entry(service.name)
        .or_insert_with(|| ServiceEntry {
            type_name: type_name::<S>(),
            typed: Box::new(TypedService::<S> {
                servers: BTreeMap::new(),
            }),
        });
    if entry.type_name != type_name::<S>() {
        anyhow::bail!(
            "{} is a {} on this bus, not a {}",
            service.name,
            entry.type_name,
            type_name::<S>()
        );
    }
    entry
        .typed
        .as_any()
        .downcast_mut::<TypedService<S>>()
        .ok_or_else(|| anyhow::anyhow!("{}: two Rust types for one service", service.name))
}

/// Serves `service`: the node's channel, and the task that takes the requests (one at a time,
/// each validated first) until the node drops the channel or the task is aborted.
pub(super) fn serve<S>(
    shared: &Arc<Shared>,
    service: Service<S>,
    invalid: fn(&InvalidMessage) -> S::Response,
    drops: Arc<DropLog>,
) -> anyhow::Result<(mpsc::Receiver<ServiceCall<S>>, tokio::task::JoinHandle<()>)>
where
    S: ServiceDefinition + 'static,
    S::Request: Validate,
{
    let inbox = Inbox::new(None);
    let id = {
        let mut graph = shared.graph();
        let id = graph.new_entity();
        typed(&mut graph.services, service)?
            .servers
            .insert(id, inbox.clone());
        id
    };
    shared.changed();
    let leave = Leave {
        shared: shared.clone(),
        what: Entity::Server(service.name, id),
    };
    let (tx, rx) = mpsc::channel(16);
    let name = service.name;
    let task = tokio::spawn(async move {
        let _leave = leave;
        loop {
            let Request::<S> { request, reply } = inbox.pop().await;
            let response = match hand_to_node(request, &tx, &drops, name, invalid).await {
                Handed::Answer(response) => response,
                Handed::Unanswered => continue,
                Handed::NodeGone => break,
            };
            // The caller may have stopped waiting.
            let _ = reply.try_send(response);
        }
    });
    Ok((rx, task))
}

/// How a client reaches the servers of its service.
pub(crate) struct Caller<S: ServiceDefinition> {
    shared: Arc<Shared>,
    service: Service<S>,
}

impl<S: ServiceDefinition> Clone for Caller<S> {
    fn clone(&self) -> Self {
        Caller {
            shared: self.shared.clone(),
            service: self.service,
        }
    }
}

impl<S: ServiceDefinition + 'static> Caller<S> {
    pub(super) fn new(shared: &Arc<Shared>, service: Service<S>) -> Caller<S> {
        Caller {
            shared: shared.clone(),
            service,
        }
    }

    /// Sends `request` to every server there now; the first answer. Never resolves when no
    /// server answers (none there, or gone first): the caller's timeout ends it.
    pub(crate) async fn call(&self, request: S::Request) -> Result<S::Response, String>
    where
        S::Request: MessageDefinition,
    {
        let (reply, mut answers) = mpsc::channel(8);
        {
            let mut graph = self.shared.graph();
            let t = typed(&mut graph.services, self.service).map_err(|e| e.to_string())?;
            for inbox in t.servers.values() {
                inbox.push(Request::<S> {
                    request: request.clone(),
                    reply: reply.clone(),
                });
            }
        }
        drop(reply);
        match answers.recv().await {
            Some(response) => Ok(response),
            None => std::future::pending().await,
        }
    }
}
