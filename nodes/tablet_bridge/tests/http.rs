//! The HTTP + WebSocket server with its core, without DDS or a browser: pages and headers,
//! the same-origin rule, and one answer crossing from a WebSocket to the publish channel.
//! A minimal WebSocket client (RFC 6455 framing) is written here so nothing else is needed.

use serde_json::{Value, json};
use std::time::Duration;
use tablet_bridge::server::{Publish, serve_on};
use tablet_bridge::{DdsInput, TabletBridgeParams};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;

const DEADLINE: Duration = Duration::from_secs(10);

struct Server {
    port: u16,
    dds: mpsc::Sender<DdsInput>,
    published: mpsc::Receiver<Publish>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<anyhow::Result<()>>,
}

async fn start() -> Server {
    let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let port = listener.local_addr().expect("addr").port();
    let (dds, dds_rx) = mpsc::channel(16);
    let (publish, published) = mpsc::channel(16);
    let (stop, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let params = TabletBridgeParams {
        pin: "2468".into(),
        ..Default::default()
    };
    let shutdown = async move {
        let _ = stop_rx.await;
    };
    let task = tokio::spawn(serve_on(listener, params, dds_rx, publish, shutdown));
    Server {
        port,
        dds,
        published,
        stop: Some(stop),
        task,
    }
}

async fn request(port: u16, text: &str) -> String {
    let mut s = TcpStream::connect(("127.0.0.1", port))
        .await
        .expect("connect");
    s.write_all(text.as_bytes()).await.expect("write");
    let mut out = Vec::new();
    let _ = tokio::time::timeout(DEADLINE, s.read_to_end(&mut out)).await;
    String::from_utf8_lossy(&out).into_owned()
}

fn upgrade(path: &str, port: u16, origin: &str) -> String {
    format!(
        "GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nOrigin: {origin}\r\nConnection: Upgrade\r\n\
         Upgrade: websocket\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n"
    )
}

/// A WebSocket client connection after a successful handshake.
struct Ws(TcpStream);

impl Ws {
    async fn open(port: u16, path: &str) -> Ws {
        let mut s = TcpStream::connect(("127.0.0.1", port))
            .await
            .expect("connect");
        let origin = format!("http://127.0.0.1:{port}");
        s.write_all(upgrade(path, port, &origin).as_bytes())
            .await
            .expect("write");
        let mut head = Vec::new();
        while !head.ends_with(b"\r\n\r\n") {
            let mut b = [0u8; 1];
            s.read_exact(&mut b).await.expect("handshake");
            head.push(b[0]);
        }
        let head = String::from_utf8_lossy(&head);
        assert!(head.starts_with("HTTP/1.1 101"), "{head}");
        Ws(s)
    }

    /// Sends one masked text frame (clients must mask).
    async fn send(&mut self, text: &str) {
        let payload = text.as_bytes();
        let mask = [0x12u8, 0x34, 0x56, 0x78];
        let mut frame = vec![0x81u8];
        match payload.len() {
            n if n < 126 => frame.push(0x80 | n as u8),
            n if n < 65536 => {
                frame.push(0x80 | 126);
                frame.extend_from_slice(&(n as u16).to_be_bytes());
            }
            n => {
                frame.push(0x80 | 127);
                frame.extend_from_slice(&(n as u64).to_be_bytes());
            }
        }
        frame.extend_from_slice(&mask);
        frame.extend(payload.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
        self.0.write_all(&frame).await.expect("send");
    }

    /// The next text message from the server, as JSON.
    async fn recv(&mut self) -> Value {
        let read = async {
            let mut h = [0u8; 2];
            self.0.read_exact(&mut h).await.expect("frame");
            let mut len = u64::from(h[1] & 0x7f);
            if len == 126 {
                let mut b = [0u8; 2];
                self.0.read_exact(&mut b).await.expect("len");
                len = u64::from(u16::from_be_bytes(b));
            } else if len == 127 {
                let mut b = [0u8; 8];
                self.0.read_exact(&mut b).await.expect("len");
                len = u64::from_be_bytes(b);
            }
            let mut payload = vec![0u8; len as usize];
            self.0.read_exact(&mut payload).await.expect("payload");
            assert_eq!(h[0], 0x81, "a final text frame");
            serde_json::from_slice(&payload).expect("JSON")
        };
        tokio::time::timeout(DEADLINE, read)
            .await
            .expect("a message in time")
    }
}

#[tokio::test]
async fn pages_are_served_with_a_strict_policy_and_unknown_paths_are_not() {
    let mut server = start().await;
    let port = server.port;
    let child = request(
        port,
        "GET /child HTTP/1.1\r\nHost: a\r\nConnection: close\r\n\r\n",
    )
    .await;
    assert!(child.starts_with("HTTP/1.1 200"), "{child}");
    assert!(child.contains("content-type: text/html; charset=utf-8"));
    assert!(child.contains("content-security-policy: default-src 'none'; script-src 'self'"));
    assert!(child.contains("x-content-type-options: nosniff"));
    assert!(child.contains(r#"<html lang="en">"#));
    let face = request(
        port,
        "GET /assets/faces/sad.svg HTTP/1.1\r\nHost: a\r\nConnection: close\r\n\r\n",
    )
    .await;
    assert!(
        face.contains("content-type: image/svg+xml") && face.contains("<svg"),
        "{face}"
    );
    let missing = request(
        port,
        "GET /etc/passwd HTTP/1.1\r\nHost: a\r\nConnection: close\r\n\r\n",
    )
    .await;
    assert!(missing.starts_with("HTTP/1.1 404"), "{missing}");
    let post = request(
        port,
        "POST /child HTTP/1.1\r\nHost: a\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
    )
    .await;
    assert!(post.starts_with("HTTP/1.1 405"), "{post}");
    // The refused upgrade keeps the connection open: read its head only.
    let mut s = TcpStream::connect(("127.0.0.1", port))
        .await
        .expect("connect");
    s.write_all(upgrade("/ws/child", port, "http://evil.example").as_bytes())
        .await
        .expect("write");
    let mut head = [0u8; 256];
    let n = tokio::time::timeout(DEADLINE, s.read(&mut head))
        .await
        .expect("in time")
        .expect("read");
    let forged = String::from_utf8_lossy(&head[..n]);
    assert!(forged.starts_with("HTTP/1.1 403"), "{forged}");
    if let Some(stop) = server.stop.take() {
        let _ = stop.send(());
    }
    let done = tokio::time::timeout(DEADLINE, &mut server.task).await;
    assert!(
        matches!(done, Ok(Ok(Ok(())))),
        "the server stops cleanly: {done:?}"
    );
}

#[tokio::test]
async fn an_answer_crosses_from_the_child_socket_to_the_publish_channel() {
    let mut server = start().await;
    let mut child = Ws::open(server.port, "/ws/child").await;
    assert_eq!(
        child.recv().await,
        json!({"type": "no_task", "reason": "waiting"})
    );
    let task = qt_therapy_msgs::TabletTask {
        session_id: "s1".into(),
        sequence_id: 4,
        sequence_index: 2,
        length: 3,
        choices: ["happy", "disgusted", "sad", "angry"]
            .map(String::from)
            .to_vec(),
        timeout: 60.0,
        ..Default::default()
    };
    server.dds.send(DdsInput::Task(task)).await.expect("dds");
    let shown = child.recv().await;
    assert_eq!(
        (shown["type"].clone(), shown["sequence_id"].clone()),
        (json!("task"), json!(4))
    );

    child
        .send(r#"{"type":"answer","sequence_id":4,"answer":["sad","joy","sad"],"response_time":3}"#)
        .await;
    let refused = child.recv().await;
    assert_eq!(refused["type"], "rejected");
    assert!(
        refused["reason"]
            .as_str()
            .unwrap_or("")
            .contains(r#""joy""#),
        "{refused}"
    );

    child
        .send(
            r#"{"type":"answer","sequence_id":4,"answer":["sad","angry","sad"],"response_time":3}"#,
        )
        .await;
    assert_eq!(
        child.recv().await,
        json!({"type": "accepted", "what": "answer"})
    );
    let published = tokio::time::timeout(DEADLINE, server.published.recv()).await;
    match published {
        Ok(Some(Publish::Answer(a))) => {
            assert_eq!((a.session_id.as_str(), a.sequence_id), ("s1", 4));
            assert_eq!(a.answer, vec!["sad", "angry", "sad"]);
        }
        other => panic!("expected the answer on the publish channel, got {other:?}"),
    }

    let mut therapist = Ws::open(server.port, "/ws/therapist").await;
    assert_eq!(therapist.recv().await, json!({"type": "login_required"}));
    therapist
        .send(r#"{"type":"command","pin":"2468","command":"emergency_stop"}"#)
        .await;
    assert_eq!(
        therapist.recv().await["reason"],
        "log in with the PIN first"
    );
    assert!(
        server.published.try_recv().is_err(),
        "nothing else was published"
    );

    // Shutting down with both pages still connected ends their connections and the server.
    if let Some(stop) = server.stop.take() {
        let _ = stop.send(());
    }
    let done = tokio::time::timeout(DEADLINE, &mut server.task).await;
    assert!(matches!(done, Ok(Ok(Ok(())))), "the server stops: {done:?}");
    let mut rest = Vec::new();
    let closed = tokio::time::timeout(DEADLINE, child.0.read_to_end(&mut rest)).await;
    assert!(closed.is_ok(), "the child's connection was closed");
}
