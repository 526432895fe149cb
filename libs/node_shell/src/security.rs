//! DDS Security settings read the SROS2 way: ROS_SECURITY_ENABLE, ROS_SECURITY_STRATEGY,
//! ROS_SECURITY_KEYSTORE and the enclave (ROS_SECURITY_ENCLAVE_OVERRIDE, else `--enclave`,
//! else `/`), resolved to the enclave directory of an SROS2 keystore. Security itself needs
//! the crate feature `security`; without it a request for security is a startup error, so a
//! node is never silently insecure.

use std::path::{Path, PathBuf};

/// The files RustDDS reads from an enclave directory (SROS2 / rmw_dds_common names).
pub const ENCLAVE_FILES: [&str; 6] = [
    "identity_ca.cert.pem",
    "cert.pem",
    "key.pem",
    "permissions_ca.cert.pem",
    "governance.p7s",
    "permissions.p7s",
];

/// What to do when security is enabled but the enclave's files are missing (SROS2 strategies).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SecurityStrategy {
    /// Refuse to start.
    Enforce,
    /// Start without security, with a warning.
    Permissive,
}

/// Why the security settings cannot be used.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum SecurityError {
    #[error("ROS_SECURITY_ENABLE={0:?}: expected \"true\" or \"false\"")]
    BadEnable(String),
    #[error("ROS_SECURITY_STRATEGY={0:?}: expected \"Enforce\" or \"Permissive\"")]
    BadStrategy(String),
    #[error("enclave {0:?} is not an absolute enclave path like /qt_therapy/tablet_bridge")]
    BadEnclave(String),
    #[error(
        "ROS_SECURITY_ENABLE=true with ROS_SECURITY_STRATEGY=Enforce but ROS_SECURITY_KEYSTORE \
         is not set"
    )]
    NoKeystore,
    #[error("ROS_SECURITY_STRATEGY=Enforce and enclave {enclave:?} lacks {missing:?} in {dir}")]
    MissingFiles {
        enclave: String,
        dir: String,
        missing: Vec<&'static str>,
    },
    #[error(
        "ROS_SECURITY_ENABLE=true but this binary was built without DDS security; rebuild with \
         `--features node_shell/security` (needs OpenSSL) or unset ROS_SECURITY_ENABLE"
    )]
    NotBuilt,
}

/// The outcome of reading the security settings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SecurityMode {
    /// ROS_SECURITY_ENABLE is not true.
    Off,
    /// Permissive strategy without usable enclave files: runs insecure (logged as a warning).
    PermissiveFallback { reason: String },
    /// Join the secured domain with this enclave.
    Enclave { enclave: String, dir: PathBuf },
}

impl SecurityMode {
    /// Reads the process environment; `enclave_arg` is the node's `--enclave`.
    pub fn from_env(enclave_arg: Option<&str>) -> Result<SecurityMode, SecurityError> {
        Self::from_lookup(|key| std::env::var(key).ok(), enclave_arg)
    }

    /// As [`SecurityMode::from_env`], with the environment given as a lookup function.
    pub fn from_lookup(
        env: impl Fn(&str) -> Option<String>,
        enclave_arg: Option<&str>,
    ) -> Result<SecurityMode, SecurityError> {
        match env("ROS_SECURITY_ENABLE").as_deref().map(str::trim) {
            None | Some("") | Some("false") => return Ok(SecurityMode::Off),
            Some("true") => {}
            Some(other) => return Err(SecurityError::BadEnable(other.to_string())),
        }
        let strategy = match env("ROS_SECURITY_STRATEGY").as_deref().map(str::trim) {
            None | Some("") | Some("Permissive") => SecurityStrategy::Permissive,
            Some("Enforce") => SecurityStrategy::Enforce,
            Some(other) => return Err(SecurityError::BadStrategy(other.to_string())),
        };
        // As rcl: the override variable wins over the command line.
        let enclave = env("ROS_SECURITY_ENCLAVE_OVERRIDE")
            .filter(|e| !e.trim().is_empty())
            .or_else(|| enclave_arg.map(str::to_string))
            .unwrap_or_else(|| "/".to_string());
        let enclave = enclave.trim().to_string();
        if !enclave.starts_with('/') || enclave.split('/').any(|part| part == "..") {
            return Err(SecurityError::BadEnclave(enclave));
        }
        let keystore = match env("ROS_SECURITY_KEYSTORE").filter(|k| !k.trim().is_empty()) {
            Some(k) => PathBuf::from(k),
            None => {
                return match strategy {
                    SecurityStrategy::Enforce => Err(SecurityError::NoKeystore),
                    SecurityStrategy::Permissive => Ok(SecurityMode::PermissiveFallback {
                        reason: "ROS_SECURITY_KEYSTORE is not set".into(),
                    }),
                };
            }
        };
        let dir = enclave_dir(&keystore, &enclave);
        let missing: Vec<&'static str> = ENCLAVE_FILES
            .into_iter()
            .filter(|f| !dir.join(f).is_file())
            .collect();
        if missing.is_empty() {
            return Ok(SecurityMode::Enclave { enclave, dir });
        }
        match strategy {
            SecurityStrategy::Enforce => Err(SecurityError::MissingFiles {
                enclave,
                dir: dir.display().to_string(),
                missing,
            }),
            SecurityStrategy::Permissive => Ok(SecurityMode::PermissiveFallback {
                reason: format!("enclave {enclave:?} lacks {missing:?} in {}", dir.display()),
            }),
        }
    }
}

/// `<keystore>/enclaves/<enclave path>`, the SROS2 layout.
pub fn enclave_dir(keystore: &Path, enclave: &str) -> PathBuf {
    let mut dir = keystore.join("enclaves");
    for part in enclave.split('/').filter(|p| !p.is_empty()) {
        dir.push(part);
    }
    dir
}

/// Turns on RustDDS's builtin authentication, access control and cryptography with the
/// enclave's files. SROS2 keys carry no password.
#[cfg(feature = "security")]
pub(crate) fn with_security(
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
pub(crate) fn with_security(
    _builder: rustdds::DomainParticipantBuilder,
    _enclave_dir: &std::path::Path,
) -> anyhow::Result<rustdds::DomainParticipantBuilder> {
    Err(SecurityError::NotBuilt.into())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn mode(vars: &[(&str, &str)], arg: Option<&str>) -> Result<SecurityMode, SecurityError> {
        let vars: HashMap<String, String> = vars
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        SecurityMode::from_lookup(|k| vars.get(k).cloned(), arg)
    }

    fn keystore_with(enclave: &str) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        let enclave_dir = enclave_dir(dir.path(), enclave);
        std::fs::create_dir_all(&enclave_dir).unwrap();
        for f in ENCLAVE_FILES {
            std::fs::write(enclave_dir.join(f), "x").unwrap();
        }
        dir
    }

    #[test]
    fn off_unless_enabled() {
        assert_eq!(mode(&[], None), Ok(SecurityMode::Off));
        assert_eq!(
            mode(&[("ROS_SECURITY_ENABLE", "false")], None),
            Ok(SecurityMode::Off)
        );
        assert_eq!(
            mode(&[("ROS_SECURITY_ENABLE", "yes")], None),
            Err(SecurityError::BadEnable("yes".into()))
        );
    }

    #[test]
    fn finds_the_enclave_and_the_override_wins() {
        let ks = keystore_with("/qt_therapy/tablet_bridge");
        let root = ks.path().to_str().unwrap();
        let expected = SecurityMode::Enclave {
            enclave: "/qt_therapy/tablet_bridge".into(),
            dir: ks.path().join("enclaves/qt_therapy/tablet_bridge"),
        };
        let on = [
            ("ROS_SECURITY_ENABLE", "true"),
            ("ROS_SECURITY_STRATEGY", "Enforce"),
            ("ROS_SECURITY_KEYSTORE", root),
        ];
        assert_eq!(
            mode(&on, Some("/qt_therapy/tablet_bridge")),
            Ok(expected.clone())
        );
        let mut with_override = on.to_vec();
        with_override.push(("ROS_SECURITY_ENCLAVE_OVERRIDE", "/qt_therapy/tablet_bridge"));
        assert_eq!(
            mode(&with_override, Some("/qt_therapy/game_manager")),
            Ok(expected)
        );
    }

    #[test]
    fn enforce_refuses_and_permissive_falls_back() {
        let ks = keystore_with("/qt_therapy/tablet_bridge");
        let root = ks.path().to_str().unwrap();
        let enforce = [
            ("ROS_SECURITY_ENABLE", "true"),
            ("ROS_SECURITY_STRATEGY", "Enforce"),
            ("ROS_SECURITY_KEYSTORE", root),
        ];
        assert!(matches!(
            mode(&enforce, Some("/qt_therapy/game_manager")),
            Err(SecurityError::MissingFiles { missing, .. }) if missing.len() == 6
        ));
        assert_eq!(
            mode(&enforce[..2], Some("/qt_therapy/game_manager")),
            Err(SecurityError::NoKeystore)
        );
        assert!(matches!(
            mode(&enforce, Some("qt_therapy/game_manager")),
            Err(SecurityError::BadEnclave(_))
        ));
        let permissive = [
            ("ROS_SECURITY_ENABLE", "true"),
            ("ROS_SECURITY_KEYSTORE", root),
        ];
        assert!(matches!(
            mode(&permissive, Some("/qt_therapy/game_manager")),
            Ok(SecurityMode::PermissiveFallback { .. })
        ));
    }
}
