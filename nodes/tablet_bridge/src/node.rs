//! The tablet bridge node's run loop, on any bus (`node_shell::Bus`: DDS on the robot, in
//! process in the cross-node tests): the game's topics in, therapist commands and child
//! answers out, through the sans-IO core (`Bridge`), with the pages' messages as
//! [`PageEvent`]s. Over DDS the HTTPS + WebSocket server (`server`) makes those events from
//! the tablets; in process a test sends them itself, as a tablet's page would.

use crate::bridge::Bridge;
use crate::io::{ClientId, DdsInput, Now, Output, StoredRead};
use crate::params::TabletBridgeParams;
use crate::protocol::Role;
use node_shell::{Bus, Clock};
use qt_therapy_msgs::topics::{
    ACTION_PROPOSAL, DECISION, EXPECTED_ENGAGEMENT, GAME_STATE, HEARTBEAT, SEQUENCE_RESULT,
    TABLET_ANSWER, TABLET_TASK, THERAPIST_COMMAND,
};
use qt_therapy_msgs::{TabletAnswer, TherapistCommand};
use std::collections::BTreeMap;
use tokio::sync::{mpsc, oneshot};
use tokio::time::Instant;

/// The node's name on the graph (and its parameter file's).
pub const NODE: &str = "tablet_bridge";

/// Page events waiting for the core; a flooding page waits here (backpressure).
pub const EVENT_QUEUE: usize = 1024;

/// What a page's connection tells the core.
pub enum PageEvent {
    /// A page connected as `role`: the core answers on `reply` with its id (or why it is
    /// refused) and sends it its messages on `out`.
    Connect {
        role: Role,
        out: mpsc::Sender<ToPage>,
        reply: oneshot::Sender<Result<ClientId, String>>,
    },
    /// A text message from the page.
    Text(ClientId, String),
    /// A binary message of this many bytes (the pages never send one).
    Binary(ClientId, usize),
    Disconnect(ClientId),
}

/// Messages queued for one page before it counts as too slow and is dropped.
pub(crate) const OUTGOING_QUEUE: usize = 256;

/// What the bridge publishes on the bus; the node hands these to its outboxes.
#[derive(Debug, Clone)]
pub enum Publish {
    Command(TherapistCommand),
    Answer(TabletAnswer),
}

/// What the core sends a page.
#[derive(Debug, Clone, PartialEq)]
pub enum ToPage {
    /// A `ServerMessage` as JSON.
    Text(String),
    /// Close the connection, with the reason.
    Close(String),
}

/// Runs the bridge with validated `params` (`TabletBridgeParams::validate`) until the node
/// is asked to stop, its pages' messages coming from `pages`.
pub async fn run(
    bus: &mut impl Bus,
    params: TabletBridgeParams,
    pages: mpsc::Receiver<PageEvent>,
) -> anyhow::Result<()> {
    // A parameter file kept from before `sessions_root` existed (a conffile changed on the
    // robot) leaves the default, where no session is stored: said once here, not left as an
    // empty child list on the therapist page with no reason anywhere.
    if !std::path::Path::new(&params.sessions_root).is_dir() {
        tracing::warn!(
            sessions_root = %params.sessions_root,
            "no such directory: the therapist page lists no children until a session is stored \
             there (set tablet_bridge.sessions_root to the game manager's sessions directory; \
             installed: /var/lib/qt-therapy/sessions)"
        );
    }
    let commands = bus.publisher(THERAPIST_COMMAND)?;
    let answers = bus.publisher(TABLET_ANSWER)?;
    let (dds_tx, dds_rx) = mpsc::channel(256);
    forward(bus.subscribe(GAME_STATE, 16)?, &dds_tx, DdsInput::GameState);
    forward(bus.subscribe(TABLET_TASK, 16)?, &dds_tx, DdsInput::Task);
    forward(bus.subscribe(DECISION, 64)?, &dds_tx, DdsInput::Decision);
    forward(
        bus.subscribe(SEQUENCE_RESULT, 64)?,
        &dds_tx,
        DdsInput::Result,
    );
    forward(
        bus.subscribe(ACTION_PROPOSAL, 64)?,
        &dds_tx,
        DdsInput::Proposal,
    );
    forward(
        bus.subscribe(EXPECTED_ENGAGEMENT, 64)?,
        &dds_tx,
        DdsInput::Engagement,
    );
    // Every node's heartbeat; the core watches the game manager's.
    forward(bus.subscribe(HEARTBEAT, 64)?, &dds_tx, DdsInput::Heartbeat);
    drop(dds_tx);
    let (publish_tx, mut publish_rx) = mpsc::channel(256);
    let core = tokio::spawn(run_core(
        params,
        bus.clock(),
        pages,
        dds_rx,
        publish_tx,
        bus.shutdown_signal(),
    ));
    // The core holds the only sender: this loop ends when the core does.
    while let Some(p) = publish_rx.recv().await {
        match p {
            Publish::Command(c) => commands.send(c),
            Publish::Answer(a) => answers.send(a),
        };
    }
    core.await?;
    Ok(())
}

/// Moves one subscription's messages into the core's single input channel.
fn forward<M: Send + 'static>(
    mut rx: mpsc::Receiver<M>,
    tx: &mpsc::Sender<DdsInput>,
    wrap: fn(M) -> DdsInput,
) {
    let tx = tx.clone();
    tokio::spawn(async move {
        while let Some(m) = rx.recv().await {
            if tx.send(wrap(m)).await.is_err() {
                break;
            }
        }
    });
}

/// The time as the core takes it: monotonic since `start`, and the clock's.
pub(crate) fn now(clock: Clock, start: Instant) -> Now {
    Now {
        monotonic: start.elapsed(),
        wall_nanos: clock.now_nanos(),
    }
}

/// Answers page `id`'s `read` from the stored sessions on a blocking thread, so the core's
/// loop goes on meanwhile; the answer joins the page's queue like any other message.
fn answer_from_storage(
    params: &TabletBridgeParams,
    clock: Clock,
    id: ClientId,
    read: StoredRead,
    page: mpsc::Sender<ToPage>,
) {
    let root = std::path::PathBuf::from(&params.sessions_root);
    let language = child_sessions::Language::from_code(&params.language)
        .unwrap_or(child_sessions::Language::En);
    let now_ns = clock.now_nanos();
    tokio::spawn(async move {
        let what = match &read {
            StoredRead::Children => "the list of children",
            StoredRead::Progress(_) => "a child's progress",
        };
        let read = tokio::task::spawn_blocking(move || {
            crate::stored::answer(&read, &root, language, now_ns)
        });
        let message = match read.await {
            Ok(m) => m,
            Err(e) => {
                tracing::error!(client = id, "reading {what} failed: {e}");
                return;
            }
        };
        match serde_json::to_string(&message) {
            Ok(text) => {
                tracing::info!(client = id, bytes = text.len(), "sent {what}");
                let _ = page.send(ToPage::Text(text)).await;
            }
            Err(e) => tracing::error!(client = id, "could not encode {what}: {e}"),
        }
    });
}

/// The core's loop: page events, what the node takes from the bus (`dds_in`) and the core's
/// deadlines through the core, in the order they come; its outputs to the pages' queues,
/// `publish` and the log; until `stop` resolves.
pub(crate) async fn run_core(
    params: TabletBridgeParams,
    clock: Clock,
    mut events: mpsc::Receiver<PageEvent>,
    mut dds_in: mpsc::Receiver<DdsInput>,
    publish: mpsc::Sender<Publish>,
    stop: impl Future<Output = ()>,
) {
    let start = Instant::now();
    let mut core = Bridge::new(params.clone(), now(clock, start));
    let mut pages: BTreeMap<ClientId, mpsc::Sender<ToPage>> = BTreeMap::new();
    tokio::pin!(stop);
    loop {
        // The core's next deadline (the game manager's heartbeat timeout), on its clock.
        let deadline = core.next_deadline();
        let due = start + deadline.unwrap_or_default();
        // Biased: what is ready is taken in this order, never by tokio's random pick, so a
        // run on the in-process bus is the same every time.
        let outputs = tokio::select! {
            biased;
            _ = &mut stop => break,
            _ = tokio::time::sleep_until(due), if deadline.is_some() => core.tick(now(clock, start)),
            Some(event) = events.recv() => match event {
                PageEvent::Connect { role, out, reply } => match core.connect(role, now(clock, start)) {
                    Ok((id, outputs)) => {
                        pages.insert(id, out);
                        let _ = reply.send(Ok(id));
                        outputs
                    }
                    Err(reason) => {
                        tracing::warn!(?role, "connection refused: {reason}");
                        let _ = reply.send(Err(reason));
                        continue;
                    }
                },
                PageEvent::Text(id, text) => core.ws_text(id, &text, now(clock, start)),
                PageEvent::Binary(id, len) => core.ws_binary(id, len, now(clock, start)),
                PageEvent::Disconnect(id) => {
                    pages.remove(&id);
                    core.disconnect(id)
                }
            },
            Some(input) = dds_in.recv() => core.dds(input, now(clock, start)),
            else => break,
        };
        let mut outputs = std::collections::VecDeque::from(outputs);
        while let Some(output) = outputs.pop_front() {
            match output {
                Output::Send(id, message) => {
                    let Some(page) = pages.get(&id) else { continue };
                    let text = match serde_json::to_string(&message) {
                        Ok(t) => t,
                        Err(e) => {
                            tracing::error!(client = id, "could not encode a page message: {e}");
                            continue;
                        }
                    };
                    if page.try_send(ToPage::Text(text)).is_err() {
                        // Dropping its queue ends the connection task.
                        tracing::warn!(
                            client = id,
                            "page too slow or gone: {OUTGOING_QUEUE} messages queued; disconnected"
                        );
                        pages.remove(&id);
                        outputs.extend(core.disconnect(id));
                    }
                }
                Output::Close(id, reason) => {
                    if let Some(page) = pages.remove(&id) {
                        let _ = page.try_send(ToPage::Close(reason));
                    }
                }
                Output::Command(c) => {
                    let _ = publish.send(Publish::Command(c)).await;
                }
                Output::Answer(a) => {
                    let _ = publish.send(Publish::Answer(a)).await;
                }
                Output::Log(level, message) => node_shell::logging::log_at(level, &message),
                Output::Read(id, read) => {
                    if let Some(page) = pages.get(&id).cloned() {
                        answer_from_storage(&params, clock, id, read, page);
                    }
                }
            }
        }
    }
    tracing::info!("bridge core stopped; closing the pages' connections");
}
