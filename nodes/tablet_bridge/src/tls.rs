//! HTTPS for the tablet pages: the server certificate and key (`tls_cert_file`,
//! `tls_key_file`) loaded into a rustls configuration (TLS 1.3 and 1.2 only, ring: no OpenSSL),
//! and a listener that does each handshake on a task of its own, so a client that connects
//! and says nothing holds up no other tablet. A browser that asks the TLS port for `http://`
//! (a bookmark from before HTTPS) is sent to the same page over `https://`.

use rustls::ServerConfig;
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Semaphore, mpsc};
use tokio_rustls::TlsAcceptor;
use tokio_rustls::server::TlsStream;

/// A client gets this long for its whole handshake (or its plain-HTTP request line).
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);
/// Handshakes under way at once; further connections wait in the kernel's backlog.
const MAX_HANDSHAKES: usize = 64;
/// The most of a plain-HTTP request read to redirect it.
const MAX_PLAIN_REQUEST: usize = 8 * 1024;

/// The certificate or key could not be used; names the file and what is wrong with it.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    #[error("tls_cert_file {path}: {reason}")]
    Certificate { path: PathBuf, reason: String },
    #[error("tls_key_file {path}: {reason}")]
    Key { path: PathBuf, reason: String },
    #[error("tls_key_file {key} is not the key of the certificate in tls_cert_file {cert}")]
    KeyMismatch { cert: PathBuf, key: PathBuf },
    #[error("the TLS configuration: {0}")]
    Config(String),
}

/// The crypto every TLS use of this crate takes: ring, named, so another crate that turns on
/// rustls's other provider cannot make the choice ambiguous. rustls 0.23.48 deprecates it for
/// its want of post-quantum key exchange (X25519MLKEM768), which only aws-lc-rs brings, and
/// that needs cmake and a C toolchain to build; the key exchange stays X25519 / P-256 ECDHE
/// (docs/security.md says what that means).
#[allow(deprecated)]
pub fn provider() -> Arc<rustls::crypto::CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

/// The certificates of a PEM file, in order (the server's first, then any intermediates).
pub fn read_certificates(path: &Path) -> Result<Vec<CertificateDer<'static>>, String> {
    let certs = CertificateDer::pem_file_iter(path)
        .map_err(|e| pem_reason(&e))?
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| pem_reason(&e))?;
    if certs.is_empty() {
        return Err("holds no PEM certificate (-----BEGIN CERTIFICATE-----)".into());
    }
    Ok(certs)
}

fn pem_reason(e: &rustls::pki_types::pem::Error) -> String {
    match e {
        rustls::pki_types::pem::Error::Io(io) => io.to_string(),
        other => format!("not PEM: {other}"),
    }
}

/// The server's TLS configuration from its certificate chain and key files.
pub fn server_config(cert: &Path, key: &Path) -> Result<Arc<ServerConfig>, TlsError> {
    let chain = read_certificates(cert).map_err(|reason| TlsError::Certificate {
        path: cert.into(),
        reason,
    })?;
    let private = PrivateKeyDer::from_pem_file(key).map_err(|e| TlsError::Key {
        path: key.into(),
        reason: match e {
            rustls::pki_types::pem::Error::NoItemsFound => {
                "holds no PEM private key (-----BEGIN PRIVATE KEY-----, EC or RSA)".into()
            }
            other => pem_reason(&other),
        },
    })?;
    let builder = ServerConfig::builder_with_provider(provider())
        .with_protocol_versions(&[&rustls::version::TLS13, &rustls::version::TLS12])
        .map_err(|e| TlsError::Config(e.to_string()))?;
    let mut config = builder
        .with_no_client_auth()
        .with_single_cert(chain, private)
        .map_err(|e| match e {
            rustls::Error::InconsistentKeys(_) => TlsError::KeyMismatch {
                cert: cert.into(),
                key: key.into(),
            },
            other => TlsError::Key {
                path: key.into(),
                reason: other.to_string(),
            },
        })?;
    // The pages are served over HTTP/1.1 only (WebSocket upgrades need it).
    config.alpn_protocols = vec![b"http/1.1".to_vec()];
    Ok(Arc::new(config))
}

/// The accepted TLS connections, for `axum::serve`; handshakes run on tasks of their own.
pub struct TlsListener {
    local: SocketAddr,
    ready: mpsc::Receiver<(TlsStream<TcpStream>, SocketAddr)>,
    acceptor: tokio::task::JoinHandle<()>,
}

impl TlsListener {
    pub fn new(listener: TcpListener, config: Arc<ServerConfig>) -> std::io::Result<TlsListener> {
        let local = listener.local_addr()?;
        let (tx, ready) = mpsc::channel(MAX_HANDSHAKES);
        let acceptor = tokio::spawn(accept_loop(listener, TlsAcceptor::from(config), tx));
        Ok(TlsListener {
            local,
            ready,
            acceptor,
        })
    }
}

impl Drop for TlsListener {
    fn drop(&mut self) {
        self.acceptor.abort();
    }
}

impl axum::serve::Listener for TlsListener {
    type Io = TlsStream<TcpStream>;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        match self.ready.recv().await {
            Some(connection) => connection,
            // The accept loop ended (it only does when aborted): no more connections.
            None => std::future::pending().await,
        }
    }

    fn local_addr(&self) -> std::io::Result<SocketAddr> {
        Ok(self.local)
    }
}

async fn accept_loop(
    listener: TcpListener,
    acceptor: TlsAcceptor,
    ready: mpsc::Sender<(TlsStream<TcpStream>, SocketAddr)>,
) {
    let permits = Arc::new(Semaphore::new(MAX_HANDSHAKES));
    let port = listener.local_addr().map(|a| a.port()).unwrap_or_default();
    loop {
        let Ok(permit) = permits.clone().acquire_owned().await else {
            return;
        };
        let (tcp, peer) = match listener.accept().await {
            Ok(c) => c,
            Err(e) => {
                // Out of file descriptors and the like: wait instead of spinning.
                tracing::warn!("accepting a tablet connection: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        let (acceptor, ready) = (acceptor.clone(), ready.clone());
        tokio::spawn(async move {
            let handshake = handshake(&acceptor, tcp, peer, port);
            if let Ok(Some(tls)) = tokio::time::timeout(HANDSHAKE_TIMEOUT, handshake).await {
                let _ = ready.send((tls, peer)).await;
            }
            drop(permit);
        });
    }
}

/// The TLS connection, or None when the client spoke plain HTTP (redirected) or the
/// handshake failed (logged with what it means for a tablet).
async fn handshake(
    acceptor: &TlsAcceptor,
    tcp: TcpStream,
    peer: SocketAddr,
    port: u16,
) -> Option<TlsStream<TcpStream>> {
    let mut first = [0u8; 1];
    // A TLS connection starts with a handshake record (content type 22).
    match tcp.peek(&mut first).await {
        Ok(1) if first[0] != 22 => {
            redirect_plain_http(tcp, peer, port).await;
            return None;
        }
        Ok(1) => {}
        _ => return None,
    }
    match acceptor.accept(tcp).await {
        Ok(tls) => Some(tls),
        Err(e) => {
            use std::io::ErrorKind as K;
            // A browser's speculative connection closed unused is no news.
            if matches!(
                e.kind(),
                K::UnexpectedEof | K::ConnectionReset | K::BrokenPipe
            ) {
                tracing::debug!(%peer, "TLS handshake ended by the client: {e}");
            } else {
                tracing::warn!(%peer, "TLS handshake refused: {}", handshake_error(&e));
            }
            None
        }
    }
}

/// What a failed handshake means, in the words an operator needs.
pub fn handshake_error(e: &std::io::Error) -> String {
    let Some(tls) = e
        .get_ref()
        .and_then(|inner| inner.downcast_ref::<rustls::Error>())
    else {
        return e.to_string();
    };
    use rustls::AlertDescription as A;
    match tls {
        rustls::Error::AlertReceived(A::UnknownCA | A::BadCertificate | A::CertificateUnknown) => {
            format!(
                "{tls}: the tablet does not trust this certificate (install the robot's CA on \
                 it: qt-therapy-tls export-ca, docs/install.md)"
            )
        }
        rustls::Error::PeerIncompatible(_) => {
            format!("{tls}: the client offers only what the bridge refuses (TLS 1.0/1.1?)")
        }
        other => other.to_string(),
    }
}

/// Answers a plain-HTTP request on the TLS port with a redirect to the same page over HTTPS.
async fn redirect_plain_http(mut tcp: TcpStream, peer: SocketAddr, port: u16) {
    let mut head = Vec::new();
    let mut buf = [0u8; 1024];
    while !head.windows(4).any(|w| w == b"\r\n\r\n") && head.len() < MAX_PLAIN_REQUEST {
        match tcp.read(&mut buf).await {
            Ok(0) | Err(_) => return,
            Ok(n) => head.extend_from_slice(&buf[..n]),
        }
    }
    let text = String::from_utf8_lossy(&head);
    let response = match redirect_target(&text, port) {
        Some(location) => {
            tracing::info!(%peer, "plain HTTP on the HTTPS port: redirected to {location}");
            format!(
                "HTTP/1.1 301 Moved Permanently\r\nLocation: {location}\r\nContent-Length: 0\r\n\
                 Connection: close\r\n\r\n"
            )
        }
        None => {
            "HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\nConnection: close\r\n\r\n".to_string()
        }
    };
    let _ = tcp.write_all(response.as_bytes()).await;
    let _ = tcp.shutdown().await;
}

/// `https://<Host><path>` for a plain request head; the host is the one the client asked for
/// (so a bookmark keeps its name) when it is a plain host name or address, and the path one
/// the bridge serves or not (the HTTPS side answers 404). None for anything else.
pub fn redirect_target(head: &str, port: u16) -> Option<String> {
    let mut lines = head.split("\r\n");
    let mut request = lines.next()?.split(' ');
    let (_method, path) = (request.next()?, request.next()?);
    let path_ok = path.starts_with('/')
        && path
            .bytes()
            .all(|b| b.is_ascii_graphic() && b != b'"' && b != b'<' && b != b'>');
    let host = lines.take_while(|l| !l.is_empty()).find_map(|l| {
        let (name, value) = l.split_once(':')?;
        name.trim()
            .eq_ignore_ascii_case("host")
            .then(|| value.trim())
    })?;
    let host_ok = !host.is_empty()
        && host
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b".-:[]".contains(&b));
    if !(path_ok && host_ok) {
        return None;
    }
    // A Host without a port is the default one, which is not this one.
    let has_port = host.rsplit_once(':').is_some_and(|(_, p)| !p.contains(']'));
    let host = if has_port {
        host.to_string()
    } else {
        format!("{host}:{port}")
    };
    Some(format!("https://{host}{path}"))
}

#[cfg(test)]
mod tests {
    use super::{handshake_error, redirect_target};

    #[test]
    fn a_refused_handshake_is_told_in_the_operators_words() {
        // As tokio-rustls hands rustls's error over.
        let io = |e: rustls::Error| std::io::Error::new(std::io::ErrorKind::InvalidData, e);
        let untrusted = io(rustls::Error::AlertReceived(
            rustls::AlertDescription::UnknownCA,
        ));
        assert!(
            handshake_error(&untrusted).contains("does not trust this certificate"),
            "{}",
            handshake_error(&untrusted)
        );
        let old = io(rustls::Error::PeerIncompatible(
            rustls::PeerIncompatible::Tls12NotOfferedOrEnabled,
        ));
        assert!(handshake_error(&old).contains("TLS 1.0/1.1"));
    }

    #[test]
    fn plain_requests_are_sent_to_the_same_page_over_https() {
        let head = "GET /therapist HTTP/1.1\r\nHost: qtrobot.local:8080\r\n\r\n";
        assert_eq!(
            redirect_target(head, 8080).as_deref(),
            Some("https://qtrobot.local:8080/therapist")
        );
        let head = "GET /child?x=1 HTTP/1.1\r\nhost: 10.0.0.5\r\n\r\n";
        assert_eq!(
            redirect_target(head, 8080).as_deref(),
            Some("https://10.0.0.5:8080/child?x=1")
        );
        let head = "GET / HTTP/1.1\r\nHost: [fd00::5]\r\n\r\n";
        assert_eq!(
            redirect_target(head, 8443).as_deref(),
            Some("https://[fd00::5]:8443/")
        );
        for bad in [
            "GET /child HTTP/1.1\r\n\r\n",
            "GET /child HTTP/1.1\r\nHost: evil.example/x\r\n\r\n",
            "GET http://evil.example/ HTTP/1.1\r\nHost: a\r\n\r\n",
            "GET /a\"b HTTP/1.1\r\nHost: a\r\n\r\n",
            "",
        ] {
            assert_eq!(redirect_target(bad, 8080), None, "{bad:?}");
        }
    }
}
