//! The tablet bridge's parameters (`params/tablet_bridge.yaml`) and their checks: where the
//! pages are served and with which certificate, the therapist PIN, and the limits that keep a
//! misbehaving tablet harmless.

use std::net::SocketAddr;
use std::path::PathBuf;

/// `tablet_bridge.ros__parameters`.
#[derive(
    Debug, Clone, serde::Deserialize, serde::Serialize, node_shell::parameters::DescribedParameters,
)]
#[serde(deny_unknown_fields, default)]
pub struct TabletBridgeParams {
    /// Address the HTTPS + WebSocket server listens on.
    pub http_bind: String,
    /// The server's certificate chain (PEM, its own first); empty: no TLS.
    pub tls_cert_file: String,
    /// The certificate's private key (PEM).
    pub tls_key_file: String,
    /// Serve plain HTTP on an address other computers reach (never needed on loopback).
    pub allow_plain_http: bool,
    /// The therapist page's PIN (env `QT_TABLET_PIN` overrides it). Hidden from the ROS 2
    /// graph: anyone on the domain could read it through `ros2 param get`.
    #[parameter(hidden)]
    pub pin: String,
    /// Page language: `en` or `de`.
    pub language: String,
    /// Where the game manager's runs are (session files and bags, a directory per run, at
    /// any depth): the therapist page's list of children and their progress are read here.
    pub sessions_root: String,
    /// Token bucket per connection: sustained messages per second.
    pub ws_messages_per_second: f64,
    /// Token bucket per connection: burst size.
    pub ws_burst: u32,
    /// Largest WebSocket text message accepted, in bytes.
    pub ws_max_message_bytes: usize,
    /// A connection whose messages were dropped this many times in a row for flooding is closed.
    pub ws_max_dropped_before_close: u32,
    /// Most tablet connections at once (both pages together).
    pub max_clients: usize,
    /// Wrong PINs allowed per minute over all connections; a connection that gets it wrong this
    /// many times is closed.
    pub pin_max_failures: u32,
    /// Expected-engagement points kept for the therapist's trend chart.
    pub engagement_history: usize,
    /// Seconds without a heartbeat from the game manager after which the pages show it lost.
    pub game_manager_loss_timeout_s: f64,
}

impl Default for TabletBridgeParams {
    fn default() -> Self {
        TabletBridgeParams {
            http_bind: "127.0.0.1:8080".into(),
            tls_cert_file: String::new(),
            tls_key_file: String::new(),
            allow_plain_http: false,
            pin: "1234".into(),
            language: "en".into(),
            sessions_root: "out".into(),
            ws_messages_per_second: 5.0,
            ws_burst: 20,
            ws_max_message_bytes: 4096,
            ws_max_dropped_before_close: 200,
            max_clients: 16,
            pin_max_failures: 5,
            engagement_history: 300,
            game_manager_loss_timeout_s: 4.0,
        }
    }
}

/// A parameter value the bridge cannot run with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("tablet_bridge parameter {key}: {reason}")]
pub struct InvalidParameter {
    pub key: &'static str,
    pub reason: String,
}

/// The page languages shipped.
pub const LANGUAGES: [&str; 2] = ["en", "de"];

/// Shortest PIN accepted, so a guessable default cannot slip through by accident.
pub const MIN_PIN_LEN: usize = 4;

impl TabletBridgeParams {
    /// The certificate and key files, when the pages are served over HTTPS.
    pub fn tls_files(&self) -> Option<(PathBuf, PathBuf)> {
        (!self.tls_cert_file.is_empty()).then(|| {
            (
                self.tls_cert_file.clone().into(),
                self.tls_key_file.clone().into(),
            )
        })
    }

    /// Checks every value; the node refuses to start on the first bad one.
    pub fn validate(&self) -> Result<SocketAddr, InvalidParameter> {
        let bad = |key, reason: String| Err(InvalidParameter { key, reason });
        let addr: SocketAddr = match self.http_bind.parse() {
            Ok(a) => a,
            Err(e) => {
                return bad(
                    "http_bind",
                    format!("{:?} is not ip:port ({e})", self.http_bind),
                );
            }
        };
        match (self.tls_cert_file.is_empty(), self.tls_key_file.is_empty()) {
            (true, false) => {
                return bad("tls_cert_file", "is empty but tls_key_file is set".into());
            }
            (false, true) => {
                return bad("tls_key_file", "is empty but tls_cert_file is set".into());
            }
            (true, true) if !addr.ip().is_loopback() && !self.allow_plain_http => {
                return bad(
                    "tls_cert_file",
                    format!(
                        "is empty, so the pages (the PIN, a child's results) would cross the \
                         network unencrypted on {addr}: name the certificate and key \
                         (tls_cert_file, tls_key_file; `tablet_tls init` makes them), or set \
                         allow_plain_http: true to serve plain HTTP all the same"
                    ),
                );
            }
            _ => {}
        }
        if self.pin.chars().count() < MIN_PIN_LEN || self.pin.chars().any(char::is_control) {
            return bad(
                "pin",
                format!("must be at least {MIN_PIN_LEN} characters without control characters"),
            );
        }
        if !LANGUAGES.contains(&self.language.as_str()) {
            return bad(
                "language",
                format!("{:?} is not one of {LANGUAGES:?}", self.language),
            );
        }
        if self.sessions_root.trim().is_empty() {
            return bad(
                "sessions_root",
                "is empty: name the directory the game manager's runs are in".into(),
            );
        }
        if !(self.ws_messages_per_second.is_finite() && self.ws_messages_per_second > 0.0) {
            return bad("ws_messages_per_second", "must be a positive number".into());
        }
        let positive: [(&'static str, usize); 6] = [
            ("ws_burst", self.ws_burst as usize),
            ("ws_max_message_bytes", self.ws_max_message_bytes),
            (
                "ws_max_dropped_before_close",
                self.ws_max_dropped_before_close as usize,
            ),
            ("max_clients", self.max_clients),
            ("pin_max_failures", self.pin_max_failures as usize),
            ("engagement_history", self.engagement_history),
        ];
        for (key, v) in positive {
            if v == 0 {
                return bad(key, "must be at least 1".into());
            }
        }
        let t = self.game_manager_loss_timeout_s;
        if !(t.is_finite() && (0.2..=600.0).contains(&t)) {
            return bad(
                "game_manager_loss_timeout_s",
                format!("{t} is not a number of seconds in [0.2, 600]"),
            );
        }
        if self.ws_max_message_bytes > 1 << 20 {
            return bad("ws_max_message_bytes", "must be at most 1 MiB".into());
        }
        Ok(addr)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_bad_values_name_their_key() {
        let p = TabletBridgeParams::default();
        assert_eq!(p.validate().map(|a| a.port()), Ok(8080));
        let cases: [(&str, TabletBridgeParams); 6] = [
            (
                "game_manager_loss_timeout_s",
                TabletBridgeParams {
                    game_manager_loss_timeout_s: 0.0,
                    ..p.clone()
                },
            ),
            (
                "http_bind",
                TabletBridgeParams {
                    http_bind: "localhost".into(),
                    ..p.clone()
                },
            ),
            (
                "pin",
                TabletBridgeParams {
                    pin: "12".into(),
                    ..p.clone()
                },
            ),
            (
                "language",
                TabletBridgeParams {
                    language: "fr".into(),
                    ..p.clone()
                },
            ),
            (
                "ws_messages_per_second",
                TabletBridgeParams {
                    ws_messages_per_second: f64::NAN,
                    ..p.clone()
                },
            ),
            (
                "ws_burst",
                TabletBridgeParams {
                    ws_burst: 0,
                    ..p.clone()
                },
            ),
        ];
        for (key, params) in cases {
            let e = params.validate().expect_err(key);
            assert_eq!(e.key, key);
            assert!(e.to_string().contains(key), "{e}");
        }
    }

    #[test]
    fn plain_http_only_on_loopback_or_when_allowed_in_words() {
        let on = |bind: &str| TabletBridgeParams {
            http_bind: bind.into(),
            ..TabletBridgeParams::default()
        };
        assert!(on("127.0.0.1:8080").validate().is_ok());
        assert!(on("[::1]:8080").validate().is_ok());
        for bind in ["0.0.0.0:8080", "10.0.0.5:8080", "[::]:8080"] {
            let e = on(bind).validate().expect_err(bind);
            assert_eq!(e.key, "tls_cert_file", "{e}");
            assert!(e.reason.contains("allow_plain_http"), "{e}");
            let allowed = TabletBridgeParams {
                allow_plain_http: true,
                ..on(bind)
            };
            assert!(allowed.validate().is_ok(), "{bind}");
        }
        let tls = TabletBridgeParams {
            tls_cert_file: "/etc/qt-therapy/tls/server.crt".into(),
            tls_key_file: "/etc/qt-therapy/tls/server.key".into(),
            ..on("0.0.0.0:8080")
        };
        assert!(tls.validate().is_ok());
        assert!(tls.tls_files().is_some());
        let half = TabletBridgeParams {
            tls_key_file: String::new(),
            ..tls.clone()
        };
        assert_eq!(half.validate().map_err(|e| e.key), Err("tls_key_file"));
        let half = TabletBridgeParams {
            tls_cert_file: String::new(),
            ..tls
        };
        assert_eq!(half.validate().map_err(|e| e.key), Err("tls_cert_file"));
    }

    #[test]
    fn the_shipped_yaml_matches_the_defaults() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../params/tablet_bridge.yaml");
        let p: TabletBridgeParams =
            node_shell::params::load_parameters(&path, "tablet_bridge").expect("yaml loads");
        let d = TabletBridgeParams::default();
        assert_eq!(format!("{p:?}"), format!("{d:?}"));
    }
}
