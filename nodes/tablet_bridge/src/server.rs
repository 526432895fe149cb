//! The HTTPS + WebSocket side of the bridge (axum): serves the pages (over TLS when the
//! parameters name a certificate, `tls`), upgrades `/ws/child` and `/ws/therapist`
//! (same-origin only), and hands each connection's messages to the core's loop as
//! [`PageEvent`]s (`node`), which answers each page on its own queue. No decision is taken
//! here. [`serve_on`] runs the pages with the core's loop on channels instead of a bus (the
//! HTTP tests).

use crate::io::DdsInput;
use crate::node::{EVENT_QUEUE, OUTGOING_QUEUE, PageEvent, Publish, ToPage, run_core};
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
use std::sync::Arc;
use tokio::net::TcpListener;
use tokio::sync::{mpsc, oneshot, watch};

/// WebSocket close code "policy violation".
const CLOSE_POLICY: u16 = 1008;

const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; \
                   connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";
/// Over HTTPS: a browser that has been here once asks only for HTTPS for a year (a forged
/// plain-HTTP page on the clinic's network cannot catch the PIN).
const HSTS: &str = "max-age=31536000";

struct Shared {
    events: mpsc::Sender<PageEvent>,
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

/// Binds `params.http_bind` for [`serve_pages`].
pub async fn bind(params: &TabletBridgeParams) -> anyhow::Result<TcpListener> {
    let addr = params.validate()?;
    TcpListener::bind(addr)
        .await
        .with_context(|| format!("binding the tablet pages' address {addr} (http_bind)"))
}

/// The TLS configuration the parameters name (None: plain HTTP), for `--check` and
/// [`serve_pages`].
pub fn tls_config(
    params: &TabletBridgeParams,
) -> Result<Option<Arc<rustls::ServerConfig>>, crate::tls::TlsError> {
    params
        .tls_files()
        .map(|(cert, key)| crate::tls::server_config(&cert, &key))
        .transpose()
}

/// The pages and their core's loop on channels, without a bus, on a listener the caller bound
/// (tests bind port 0), on the wall clock, until `shutdown` resolves: `dds_in` is what the
/// node would take from the bus, `publish` what it would send.
pub async fn serve_on(
    listener: TcpListener,
    params: TabletBridgeParams,
    dds_in: mpsc::Receiver<DdsInput>,
    publish: mpsc::Sender<Publish>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let clock = node_shell::Clock::wall();
    let (events, events_rx) = mpsc::channel(EVENT_QUEUE);
    let (stop_tx, stop_rx) = watch::channel(false);
    let stopped = |rx: &watch::Receiver<bool>| {
        let mut rx = rx.clone();
        async move {
            let _ = rx.wait_for(|stop| *stop).await;
        }
    };
    let core_task = tokio::spawn(run_core(
        params.clone(),
        clock,
        events_rx,
        dds_in,
        publish,
        stopped(&stop_rx),
    ));
    tokio::spawn(async move {
        shutdown.await;
        let _ = stop_tx.send(true);
    });
    let served = serve_pages(listener, params, events, stopped(&stop_rx)).await;
    core_task.await.context("the bridge core task")?;
    served
}

/// Serves the pages on `listener` (over HTTPS when the parameters name a certificate), each
/// connection's messages to `events`, until `shutdown` resolves and the connections have
/// closed (the core's loop closes them when it stops).
pub async fn serve_pages(
    listener: TcpListener,
    params: TabletBridgeParams,
    events: mpsc::Sender<PageEvent>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let tls = tls_config(&params)?;
    let shared = Arc::new(Shared {
        events,
        pages: Pages::new(&params.language),
        scheme: if tls.is_some() { "https" } else { "http" },
        max_frame: params
            .ws_max_message_bytes
            .saturating_mul(16)
            .max(64 * 1024),
    });
    let addr = listener.local_addr()?;
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
    Ok(())
}

async fn hsts(mut response: Response) -> Response {
    response.headers_mut().insert(
        header::STRICT_TRANSPORT_SECURITY,
        HeaderValue::from_static(HSTS),
    );
    response
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
        .send(PageEvent::Connect { role, out, reply })
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
                    Some(Ok(Message::Text(t))) => PageEvent::Text(id, t.to_string()),
                    Some(Ok(Message::Binary(b))) => PageEvent::Binary(id, b.len()),
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
                Some(ToPage::Text(t)) => {
                    if socket.send(Message::Text(t.into())).await.is_err() {
                        break;
                    }
                }
                Some(ToPage::Close(reason)) => {
                    close(&mut socket, &reason).await;
                    break;
                }
                None => break,
            }
        }
    }
    let _ = s.events.send(PageEvent::Disconnect(id)).await;
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
