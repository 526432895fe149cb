//! The HTTP(S) + WebSocket server with its core, without DDS or a browser: pages and headers,
//! the same-origin rule, and one answer crossing from a WebSocket to the publish channel, in
//! plain HTTP on loopback and over TLS with the robot's own certificates (`tablet_tls`'s):
//! HSTS, a client that does not trust the CA, TLS 1.0 and 1.1, plain HTTP on the HTTPS port.
//! A minimal WebSocket client (RFC 6455 framing) is written here so nothing else is needed.

use serde_json::{Value, json};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;
use tablet_bridge::certificates::{self, InitOptions, Name};
use tablet_bridge::node::Publish;
use tablet_bridge::server::serve_on;
use tablet_bridge::{DdsInput, TabletBridgeParams};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
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
    start_with(TabletBridgeParams {
        pin: "2468".into(),
        ..Default::default()
    })
    .await
}

async fn start_with(params: TabletBridgeParams) -> Server {
    let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let port = listener.local_addr().expect("addr").port();
    let (dds, dds_rx) = mpsc::channel(16);
    let (publish, published) = mpsc::channel(16);
    let (stop, stop_rx) = tokio::sync::oneshot::channel::<()>();
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

/// A connection to the server, plain or TLS.
trait Stream: AsyncRead + AsyncWrite + Unpin + Send {}
impl<S: AsyncRead + AsyncWrite + Unpin + Send> Stream for S {}

/// A WebSocket client connection after a successful handshake.
struct Ws(Box<dyn Stream>);

impl Ws {
    async fn open(port: u16, path: &str) -> Ws {
        let s = TcpStream::connect(("127.0.0.1", port))
            .await
            .expect("connect");
        Ws::handshake(Box::new(s), port, path, "http").await
    }

    async fn handshake(mut s: Box<dyn Stream>, port: u16, path: &str, scheme: &str) -> Ws {
        let origin = format!("{scheme}://127.0.0.1:{port}");
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

/// The robot's own CA and a server certificate for `localhost` and 127.0.0.1 in `dir`, made
/// as `tablet_tls init --only-names` makes them.
fn certificates_in(dir: &Path) {
    certificates::init(&InitOptions {
        dir: dir.to_path_buf(),
        names: vec![
            Name::Dns("localhost".into()),
            Name::parse("127.0.0.1").expect("address"),
        ],
        new_ca: false,
        key_owner: None,
        now: std::time::SystemTime::now(),
    })
    .expect("certificates made");
}

async fn start_tls(dir: &Path) -> Server {
    certificates_in(dir);
    start_with(TabletBridgeParams {
        pin: "2468".into(),
        tls_cert_file: dir.join("server.crt").display().to_string(),
        tls_key_file: dir.join("server.key").display().to_string(),
        ..Default::default()
    })
    .await
}

/// A TLS client (rustls) that trusts the CAs in `ca_files` and nothing else.
fn client(ca_files: &[&Path]) -> tokio_rustls::TlsConnector {
    let mut roots = rustls::RootCertStore::empty();
    for f in ca_files {
        roots
            .add(certificates::read_ca(f.parent().expect("dir")).expect("the CA"))
            .expect("a root");
    }
    let config = rustls::ClientConfig::builder_with_provider(tablet_bridge::tls::provider())
        .with_safe_default_protocol_versions()
        .expect("versions")
        .with_root_certificates(roots)
        .with_no_client_auth();
    tokio_rustls::TlsConnector::from(Arc::new(config))
}

async fn tls_connect(
    connector: &tokio_rustls::TlsConnector,
    port: u16,
    name: &str,
) -> std::io::Result<tokio_rustls::client::TlsStream<TcpStream>> {
    let tcp = TcpStream::connect(("127.0.0.1", port)).await?;
    let name = rustls::pki_types::ServerName::try_from(name.to_string()).expect("name");
    tokio::time::timeout(DEADLINE, connector.connect(name, tcp))
        .await
        .expect("handshake in time")
}

async fn tls_request(connector: &tokio_rustls::TlsConnector, port: u16, text: &str) -> String {
    let mut s = tls_connect(connector, port, "localhost")
        .await
        .expect("TLS handshake");
    s.write_all(text.as_bytes()).await.expect("write");
    let mut out = Vec::new();
    let _ = tokio::time::timeout(DEADLINE, s.read_to_end(&mut out)).await;
    String::from_utf8_lossy(&out).into_owned()
}

/// The head of the server's answer to an upgrade from `origin`, over TLS.
async fn tls_upgrade_head(
    connector: &tokio_rustls::TlsConnector,
    port: u16,
    origin: &str,
) -> String {
    let mut s = tls_connect(connector, port, "localhost")
        .await
        .expect("TLS handshake");
    s.write_all(upgrade("/ws/therapist", port, origin).as_bytes())
        .await
        .expect("write");
    let mut head = [0u8; 512];
    let n = tokio::time::timeout(DEADLINE, s.read(&mut head))
        .await
        .expect("in time")
        .expect("read");
    String::from_utf8_lossy(&head[..n]).into_owned()
}

async fn stop(mut server: Server) {
    if let Some(stop) = server.stop.take() {
        let _ = stop.send(());
    }
    let done = tokio::time::timeout(DEADLINE, &mut server.task).await;
    assert!(matches!(done, Ok(Ok(Ok(())))), "the server stops: {done:?}");
}

#[tokio::test]
async fn over_https_the_pages_carry_csp_and_hsts_and_only_same_origin_pages_get_a_socket() {
    let dir = tempfile::tempdir().expect("dir");
    let server = start_tls(dir.path()).await;
    let port = server.port;
    let trusting = client(&[&dir.path().join("ca.crt")]);
    for page in ["/child", "/therapist"] {
        let r = tls_request(
            &trusting,
            port,
            &format!("GET {page} HTTP/1.1\r\nHost: localhost:{port}\r\nConnection: close\r\n\r\n"),
        )
        .await;
        assert!(r.starts_with("HTTP/1.1 200"), "{page}: {r}");
        assert!(
            r.contains("content-security-policy: default-src 'none'; script-src 'self'"),
            "{page}: {r}"
        );
        assert!(
            r.contains("strict-transport-security: max-age=31536000"),
            "{page}: {r}"
        );
        assert!(!r.contains("set-cookie"), "no cookies: {r}");
    }
    // Even a refusal says HSTS.
    let missing = tls_request(
        &trusting,
        port,
        "GET /nothing HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n",
    )
    .await;
    assert!(
        missing.starts_with("HTTP/1.1 404") && missing.contains("strict-transport-security"),
        "{missing}"
    );
    // Another site, and this host over plain http (a page forged on the network), are refused.
    for origin in [
        "https://evil.example".to_string(),
        format!("http://127.0.0.1:{port}"),
        format!("https://127.0.0.1:{}", port + 1),
    ] {
        let head = tls_upgrade_head(&trusting, port, &origin).await;
        assert!(head.starts_with("HTTP/1.1 403"), "{origin}: {head}");
    }
    // The page's own origin gets its WebSocket over TLS (WSS), and the child's answer crosses.
    let tls = tls_connect(&trusting, port, "localhost")
        .await
        .expect("TLS handshake");
    let mut child = Ws::handshake(Box::new(tls), port, "/ws/child", "https").await;
    assert_eq!(
        child.recv().await,
        json!({"type": "no_task", "reason": "waiting"})
    );
    stop(server).await;
}

#[tokio::test]
async fn a_client_that_does_not_trust_the_robots_ca_is_refused() {
    let dir = tempfile::tempdir().expect("dir");
    let other = tempfile::tempdir().expect("another robot's dir");
    certificates_in(other.path());
    let server = start_tls(dir.path()).await;
    let port = server.port;
    // A client trusting another robot's CA (a tablet set up for another robot).
    let stranger = client(&[&other.path().join("ca.crt")]);
    let refused = tls_connect(&stranger, port, "localhost")
        .await
        .expect_err("an unknown CA");
    assert!(refused.to_string().contains("UnknownIssuer"), "{refused}");
    // A client trusting the CA, for a name the certificate does not cover.
    let trusting = client(&[&dir.path().join("ca.crt")]);
    let refused = tls_connect(&trusting, port, "qtrobot.example")
        .await
        .expect_err("a name not covered");
    assert!(
        refused.to_string().contains("not valid for name"),
        "{refused}"
    );
    // The server is unharmed: the trusting client for its name gets the page.
    let page = tls_request(
        &trusting,
        port,
        "GET /child HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n",
    )
    .await;
    assert!(page.starts_with("HTTP/1.1 200"), "{page}");
    // So do both CAs together (a tablet for two robots).
    let both = client(&[&other.path().join("ca.crt"), &dir.path().join("ca.crt")]);
    assert!(tls_connect(&both, port, "127.0.0.1").await.is_ok());
    stop(server).await;
}

/// A ClientHello (RFC 5246 §7.4.1.2) as a TLS 1.0, 1.1 or 1.2 client sends it: `version` in
/// the hello, no supported_versions extension (so no TLS 1.3), ECDHE with AES-GCM and
/// AES-CBC suites, P-256 and X25519, ECDSA and RSA signatures.
fn client_hello(version: u16) -> Vec<u8> {
    let mut ext = Vec::new();
    let mut extension = |kind: u16, body: &[u8]| {
        ext.extend_from_slice(&kind.to_be_bytes());
        ext.extend_from_slice(&(body.len() as u16).to_be_bytes());
        ext.extend_from_slice(body);
    };
    let host = b"localhost";
    let mut sni = Vec::new();
    sni.extend_from_slice(&((host.len() + 3) as u16).to_be_bytes());
    sni.push(0);
    sni.extend_from_slice(&(host.len() as u16).to_be_bytes());
    sni.extend_from_slice(host);
    extension(0x0000, &sni);
    extension(0x000a, &[0, 4, 0x00, 0x1d, 0x00, 0x17]);
    extension(0x000b, &[1, 0]);
    extension(0x000d, &[0, 6, 0x04, 0x03, 0x08, 0x04, 0x04, 0x01]);
    let mut hello = Vec::new();
    hello.extend_from_slice(&version.to_be_bytes());
    hello.extend_from_slice(&[7u8; 32]);
    hello.push(0);
    let suites: [u16; 5] = [0xc02b, 0xc02f, 0xc009, 0xc013, 0x002f];
    hello.extend_from_slice(&((suites.len() * 2) as u16).to_be_bytes());
    for s in suites {
        hello.extend_from_slice(&s.to_be_bytes());
    }
    hello.extend_from_slice(&[1, 0]);
    hello.extend_from_slice(&(ext.len() as u16).to_be_bytes());
    hello.extend_from_slice(&ext);
    let mut handshake = vec![1u8];
    handshake.extend_from_slice(&(hello.len() as u32).to_be_bytes()[1..]);
    handshake.extend_from_slice(&hello);
    let mut record = vec![22u8, 0x03, 0x01];
    record.extend_from_slice(&(handshake.len() as u16).to_be_bytes());
    record.extend_from_slice(&handshake);
    record
}

/// The first record the server answers `hello` with: (content type, its first bytes).
async fn first_record(port: u16, hello: &[u8]) -> (u8, Vec<u8>) {
    let mut s = TcpStream::connect(("127.0.0.1", port))
        .await
        .expect("connect");
    s.write_all(hello).await.expect("write");
    let read = async {
        let mut head = [0u8; 5];
        s.read_exact(&mut head).await.expect("a record");
        let len = usize::from(u16::from_be_bytes([head[3], head[4]]));
        let mut body = vec![0u8; len.min(64)];
        s.read_exact(&mut body).await.expect("its body");
        (head[0], body)
    };
    tokio::time::timeout(DEADLINE, read).await.expect("in time")
}

#[tokio::test]
async fn tls_1_0_and_1_1_are_refused_and_plain_http_is_sent_to_https() {
    let dir = tempfile::tempdir().expect("dir");
    let server = start_tls(dir.path()).await;
    let port = server.port;
    // The same hello as TLS 1.2 gets a ServerHello (handshake record, type 2, version 1.2):
    // the hello is good, so the refusals below are for the version alone.
    let (kind, body) = first_record(port, &client_hello(0x0303)).await;
    assert_eq!(
        (kind, body[0], &body[4..6]),
        (22, 2, &[3u8, 3][..]),
        "{body:?}"
    );
    for (version, name) in [(0x0301u16, "TLS 1.0"), (0x0302, "TLS 1.1")] {
        let (kind, body) = first_record(port, &client_hello(version)).await;
        // A fatal alert (21), protocol_version (70).
        assert_eq!((kind, &body[..2]), (21, &[2u8, 70][..]), "{name}: {body:?}");
    }
    // openssl, where it is installed (tests/run.sh installs it), as a TLS 1.1 client.
    if let Ok(out) = tokio::process::Command::new("openssl")
        .args([
            "s_client",
            "-tls1_1",
            "-cipher",
            "DEFAULT:@SECLEVEL=0",
            "-connect",
        ])
        .arg(format!("127.0.0.1:{port}"))
        .stdin(std::process::Stdio::null())
        .output()
        .await
    {
        let text = String::from_utf8_lossy(&out.stderr).to_string()
            + &String::from_utf8_lossy(&out.stdout);
        // Refused with a fatal alert before the server says anything of itself (openssl
        // 3 omits signature_algorithms below TLS 1.2, which rustls answers with
        // handshake_failure rather than protocol_version).
        assert!(!out.status.success(), "{text}");
        assert!(
            text.contains("SSL alert number") && text.contains("no peer certificate available"),
            "{text}"
        );
    }
    // A browser asking for http:// on the HTTPS port is sent to the same page over https://.
    let plain = request(
        port,
        &format!("GET /therapist HTTP/1.1\r\nHost: localhost:{port}\r\n\r\n"),
    )
    .await;
    assert!(plain.starts_with("HTTP/1.1 301"), "{plain}");
    assert!(
        plain.contains(&format!("Location: https://localhost:{port}/therapist\r\n")),
        "{plain}"
    );
    stop(server).await;
}

#[test]
fn a_certificate_or_key_the_bridge_cannot_use_is_named() {
    let dir = tempfile::tempdir().expect("dir");
    certificates_in(dir.path());
    let (cert, key, ca_key) = (
        dir.path().join("server.crt"),
        dir.path().join("server.key"),
        dir.path().join("ca.key"),
    );
    let error = |c: &Path, k: &Path| match tablet_bridge::tls::server_config(c, k) {
        Ok(_) => panic!("{} with {} loaded", c.display(), k.display()),
        Err(e) => e.to_string(),
    };
    let missing = dir.path().join("missing.crt");
    let e = error(&missing, &key);
    assert!(
        e.starts_with(&format!("tls_cert_file {}: ", missing.display())),
        "{e}"
    );
    let e = error(&cert, &ca_key);
    assert!(
        e.contains("is not the key of the certificate") && e.contains("ca.key"),
        "{e}"
    );
    let e = error(&key, &key);
    assert!(
        e.contains("tls_cert_file") && e.contains("no PEM certificate"),
        "{e}"
    );
    let e = error(&cert, &cert);
    assert!(
        e.contains("tls_key_file") && e.contains("no PEM private key"),
        "{e}"
    );
    assert!(tablet_bridge::tls::server_config(&cert, &key).is_ok());
}
