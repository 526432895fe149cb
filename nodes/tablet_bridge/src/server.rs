//! The HTTPS + WebSocket shell around the core (axum): serves the pages (over TLS when the
//! parameters name a certificate, `tls`), upgrades `/ws/child` and `/ws/therapist`
//! (same-origin only), and runs one task that owns the core and moves page messages, DDS
//! messages and the clock through it. No decision is taken here.

use crate::bridge::{Bridge, ClientId, DdsInput, Now, Output};
use crate::pages::Pages;
use crate::params::TabletBridgeParams;
use crate::protocol::{Role, ServerMessage};
use anyhow::Context as _;
use axum::Router;
use axum::extract::State;
use axum::extract::ws::{CloseFrame, Message, WebSocket, WebSocketUpgrade};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, Uri, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use qt_therapy_msgs::{TabletAnswer, TherapistCommand};
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;
use tokio::net::TcpListener;
use tokio::sync::{mpsc, oneshot, watch};

/// What the bridge publishes on DDS; the binary hands these to its outboxes.
#[derive(Debug, Clone)]
pub enum Publish {
    Command(TherapistCommand),
    Answer(TabletAnswer),
}

/// Messages queued for one page before it counts as too slow and is dropped.
const OUTGOING_QUEUE: usize = 256;
/// Page events waiting for the core; a flooding page waits here (backpressure).
const EVENT_QUEUE: usize = 1024;
/// WebSocket close code "policy violation".
const CLOSE_POLICY: u16 = 1008;

const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; \
                   connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";
/// Over HTTPS: a browser that has been here once asks only for HTTPS for a year (a forged
/// plain-HTTP page on the clinic's network cannot catch the PIN).
const HSTS: &str = "max-age=31536000";

enum Event {
    Connect {
        role: Role,
        out: mpsc::Sender<Outgoing>,
        reply: oneshot::Sender<Result<ClientId, String>>,
    },
    Text(ClientId, String),
    Binary(ClientId, usize),
    Disconnect(ClientId),
}

enum Outgoing {
    Text(String),
    Close(String),
}

struct Shared {
    events: mpsc::Sender<Event>,
    pages: Pages,
    /// `https` or `http`: what a page's origin must say.
    scheme: &'static str,
    /// Transport limit: above the core's limit, so an oversized message gets a reason first.
    max_frame: usize,
}

/// Whether a WebSocket upgrade comes from a page of this server (`scheme`: `https` or
/// `http`, as served). Browsers always send `Origin`; a page elsewhere, or this host's name
/// over the other scheme, must not drive the tablets (cross-site WebSocket hijacking).
pub fn origin_allowed(origin: Option<&str>, host: Option<&str>, scheme: &str) -> bool {
    let Some(origin) = origin else {
        return true;
    };
    let (Some(host), Some((origin_scheme, rest))) = (host, origin.split_once("://")) else {
        return false;
    };
    origin_scheme.eq_ignore_ascii_case(scheme)
        && rest.trim_end_matches('/').eq_ignore_ascii_case(host)
}

/// Binds `params.http_bind` and serves until `shutdown` resolves.
pub async fn serve(
    params: TabletBridgeParams,
    dds_in: mpsc::Receiver<DdsInput>,
    publish: mpsc::Sender<Publish>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let addr = params.validate()?;
    let listener = TcpListener::bind(addr)
        .await
        .with_context(|| format!("binding the tablet pages' address {addr} (http_bind)"))?;
    serve_on(listener, params, dds_in, publish, shutdown).await
}

/// The TLS configuration the parameters name (None: plain HTTP), for `--check` and [`serve`].
pub fn tls_config(
    params: &TabletBridgeParams,
) -> Result<Option<Arc<rustls::ServerConfig>>, crate::tls::TlsError> {
    params
        .tls_files()
        .map(|(cert, key)| crate::tls::server_config(&cert, &key))
        .transpose()
}

/// As [`serve`], on a listener the caller bound (tests bind port 0).
pub async fn serve_on(
    listener: TcpListener,
    params: TabletBridgeParams,
    dds_in: mpsc::Receiver<DdsInput>,
    publish: mpsc::Sender<Publish>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let tls = tls_config(&params)?;
    let clock = Instant::now();
    let core = Bridge::new(params.clone(), now(clock));
    let (events, events_rx) = mpsc::channel(EVENT_QUEUE);
    let shared = Arc::new(Shared {
        events,
        pages: Pages::new(&params.language),
        scheme: if tls.is_some() { "https" } else { "http" },
        max_frame: params
            .ws_max_message_bytes
            .saturating_mul(16)
            .max(64 * 1024),
    });
    let (stop_tx, stop_rx) = watch::channel(false);
    let core_task = tokio::spawn(run_core(core, clock, events_rx, dds_in, publish, stop_rx));
    let addr = listener.local_addr()?;
    let shutdown = async move {
        shutdown.await;
        let _ = stop_tx.send(true);
    };
    match tls {
        Some(config) => {
            tracing::info!(
                %addr,
                certificate = %params.tls_cert_file,
                "serving the tablet pages over HTTPS: /child and /therapist"
            );
            let app = router(shared).layer(axum::middleware::map_response(hsts));
            let listener = crate::tls::TlsListener::new(listener, config)?;
            axum::serve(listener, app)
                .with_graceful_shutdown(shutdown)
                .await
                .context("serving HTTPS")?;
        }
        None => {
            if addr.ip().is_loopback() {
                tracing::info!(%addr, "serving the tablet pages over plain HTTP on loopback: /child and /therapist");
            } else {
                tracing::warn!(
                    %addr,
                    "serving the tablet pages UNENCRYPTED (allow_plain_http): the PIN and the \
                     child's results cross the network in plain text"
                );
            }
            axum::serve(listener, router(shared))
                .with_graceful_shutdown(shutdown)
                .await
                .context("serving HTTP")?;
        }
    }
    core_task.await.context("the bridge core task")?;
    Ok(())
}

async fn hsts(mut response: Response) -> Response {
    response.headers_mut().insert(
        header::STRICT_TRANSPORT_SECURITY,
        HeaderValue::from_static(HSTS),
    );
    response
}

fn now(clock: Instant) -> Now {
    Now {
        monotonic: clock.elapsed(),
        wall_nanos: node_shell::now_nanos(),
    }
}

fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/ws/child", get(ws_child))
        .route("/ws/therapist", get(ws_therapist))
        .route("/healthz", get(|| async { "ok" }))
        .fallback(static_file)
        .with_state(shared)
}

async fn static_file(State(s): State<Arc<Shared>>, method: Method, uri: Uri) -> Response {
    if method != Method::GET && method != Method::HEAD {
        return StatusCode::METHOD_NOT_ALLOWED.into_response();
    }
    let Some(asset) = s.pages.get(uri.path()) else {
        return (StatusCode::NOT_FOUND, "not found").into_response();
    };
    let mut response = asset.body.clone().into_response();
    let h = response.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(asset.content_type),
    );
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CSP),
    );
    response
}

async fn ws_child(s: State<Arc<Shared>>, headers: HeaderMap, ws: WebSocketUpgrade) -> Response {
    upgrade(s.0, &headers, ws, Role::Child)
}

async fn ws_therapist(s: State<Arc<Shared>>, headers: HeaderMap, ws: WebSocketUpgrade) -> Response {
    upgrade(s.0, &headers, ws, Role::Therapist)
}

fn upgrade(s: Arc<Shared>, headers: &HeaderMap, ws: WebSocketUpgrade, role: Role) -> Response {
    let text = |name| {
        headers
            .get(name)
            .and_then(|v: &HeaderValue| v.to_str().ok())
    };
    let (origin, host) = (text(header::ORIGIN), text(header::HOST));
    if !origin_allowed(origin, host, s.scheme) {
        tracing::warn!(?role, ?origin, ?host, "cross-origin WebSocket refused");
        return (StatusCode::FORBIDDEN, "cross-origin WebSocket refused").into_response();
    }
    let max = s.max_frame;
    ws.max_message_size(max)
        .max_frame_size(max)
        .on_upgrade(move |socket| connection(s, socket, role))
}

async fn connection(s: Arc<Shared>, mut socket: WebSocket, role: Role) {
    let (out, mut out_rx) = mpsc::channel(OUTGOING_QUEUE);
    let (reply, reply_rx) = oneshot::channel();
    if s.events
        .send(Event::Connect { role, out, reply })
        .await
        .is_err()
    {
        return;
    }
    let id = match reply_rx.await {
        Ok(Ok(id)) => id,
        Ok(Err(reason)) => {
            let rejected = ServerMessage::Rejected {
                reason: reason.clone(),
            };
            if let Ok(text) = serde_json::to_string(&rejected) {
                let _ = socket.send(Message::Text(text.into())).await;
            }
            close(&mut socket, &reason).await;
            return;
        }
        Err(_) => return,
    };
    loop {
        tokio::select! {
            incoming = socket.recv() => {
                let event = match incoming {
                    Some(Ok(Message::Text(t))) => Event::Text(id, t.to_string()),
                    Some(Ok(Message::Binary(b))) => Event::Binary(id, b.len()),
                    Some(Ok(Message::Ping(_) | Message::Pong(_))) => continue,
                    Some(Ok(Message::Close(_))) => {
                        // Flushes the close reply tungstenite queued, so the page sees a clean close.
                        let _ = futures::SinkExt::close(&mut socket).await;
                        break;
                    }
                    None => break,
                    Some(Err(e)) => {
                        tracing::warn!(client = id, ?role, "connection dropped: {e}");
                        break;
                    }
                };
                if s.events.send(event).await.is_err() {
                    break;
                }
            }
            outgoing = out_rx.recv() => match outgoing {
                Some(Outgoing::Text(t)) => {
                    if socket.send(Message::Text(t.into())).await.is_err() {
                        break;
                    }
                }
                Some(Outgoing::Close(reason)) => {
                    close(&mut socket, &reason).await;
                    break;
                }
                None => break,
            }
        }
    }
    let _ = s.events.send(Event::Disconnect(id)).await;
}

async fn close(socket: &mut WebSocket, reason: &str) {
    // A close frame's reason holds at most 123 bytes.
    let mut end = reason.len().min(123);
    while !reason.is_char_boundary(end) {
        end -= 1;
    }
    let frame = CloseFrame {
        code: CLOSE_POLICY,
        reason: reason[..end].to_string().into(),
    };
    if socket.send(Message::Close(Some(frame))).await.is_err() {
        return;
    }
    // Wait (briefly) for the page's close reply, discarding what it still sends: closing the
    // TCP connection with unread data would reset it and lose the close frame and its reason.
    let drain = async {
        while let Some(Ok(m)) = socket.recv().await {
            if let Message::Close(_) = m {
                break;
            }
        }
    };
    let _ = tokio::time::timeout(std::time::Duration::from_secs(2), drain).await;
}

async fn run_core(
    mut core: Bridge,
    clock: Instant,
    mut events: mpsc::Receiver<Event>,
    mut dds_in: mpsc::Receiver<DdsInput>,
    publish: mpsc::Sender<Publish>,
    mut stop: watch::Receiver<bool>,
) {
    let mut pages: HashMap<ClientId, mpsc::Sender<Outgoing>> = HashMap::new();
    loop {
        // The core's next deadline (the game manager's heartbeat timeout), on its clock.
        let deadline = core.next_deadline();
        let due = tokio::time::Instant::from_std(clock + deadline.unwrap_or_default());
        let outputs = tokio::select! {
            _ = stop.wait_for(|stop| *stop) => break,
            _ = tokio::time::sleep_until(due), if deadline.is_some() => core.tick(now(clock)),
            Some(event) = events.recv() => match event {
                Event::Connect { role, out, reply } => match core.connect(role, now(clock)) {
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
                Event::Text(id, text) => core.ws_text(id, &text, now(clock)),
                Event::Binary(id, len) => core.ws_binary(id, len, now(clock)),
                Event::Disconnect(id) => {
                    pages.remove(&id);
                    core.disconnect(id)
                }
            },
            Some(input) = dds_in.recv() => core.dds(input, now(clock)),
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
                    if page.try_send(Outgoing::Text(text)).is_err() {
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
                        let _ = page.try_send(Outgoing::Close(reason));
                    }
                }
                Output::Command(c) => {
                    let _ = publish.send(Publish::Command(c)).await;
                }
                Output::Answer(a) => {
                    let _ = publish.send(Publish::Answer(a)).await;
                }
                Output::Log(level, message) => node_shell::logging::log_at(level, &message),
            }
        }
    }
    tracing::info!("bridge core stopped; closing the pages' connections");
}

#[cfg(test)]
mod tests {
    use super::origin_allowed;

    #[test]
    fn only_same_origin_pages_may_open_a_websocket() {
        let host = Some("10.0.0.5:8080");
        assert!(origin_allowed(Some("http://10.0.0.5:8080"), host, "http"));
        assert!(origin_allowed(Some("HTTP://10.0.0.5:8080/"), host, "http"));
        assert!(origin_allowed(Some("https://10.0.0.5:8080"), host, "https"));
        assert!(
            origin_allowed(None, host, "https"),
            "non-browser clients send no Origin"
        );
        assert!(!origin_allowed(Some("http://evil.example"), host, "http"));
        assert!(!origin_allowed(Some("https://evil.example"), host, "https"));
        assert!(!origin_allowed(Some("http://10.0.0.5:8081"), host, "http"));
        assert!(!origin_allowed(Some("null"), host, "http"));
        assert!(!origin_allowed(Some("http://10.0.0.5:8080"), None, "http"));
        // The same host over the other scheme is another origin: a plain-HTTP page
        // (forged on the network) may not drive an HTTPS bridge.
        assert!(!origin_allowed(Some("http://10.0.0.5:8080"), host, "https"));
        assert!(!origin_allowed(Some("https://10.0.0.5:8080"), host, "http"));
    }
}
