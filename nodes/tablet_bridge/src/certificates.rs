//! The robot's own certificates for the tablet pages (`tablet_tls`, installed as
//! `qt-therapy-tls`): a small CA of the robot's own, which the tablets install once, and a
//! server certificate it signs for the robot's host name and addresses. Making them again
//! keeps what is still good: the CA always (the tablets trust it), the server certificate
//! while it covers every name and has 30 days left; a new one is signed by the same CA, so a
//! changed address needs nothing new on the tablets.
//!
//! The CA may sign only names of the robot (name constraints: its host names, `.local`,
//! `localhost` and private addresses), so a copy of its key cannot impersonate any other site
//! to a tablet that trusts it. Server certificates last 800 days (iPadOS refuses any TLS
//! server certificate that lasts over 825) and start a day back (a tablet's clock may lag).

use rcgen::{
    BasicConstraints, CertificateParams, CidrSubnet, DistinguishedName, DnType,
    ExtendedKeyUsagePurpose, GeneralSubtree, IsCa, Issuer, KeyPair, KeyUsagePurpose,
    NameConstraints, SanType, SerialNumber,
};
use ring::rand::SecureRandom as _;
use rustls::client::danger::ServerCertVerifier as _;
use rustls::pki_types::{CertificateDer, ServerName, UnixTime};
use std::io::Write as _;
use std::net::IpAddr;
use std::os::unix::fs::MetadataExt as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, SystemTime};

pub const CA_CERT: &str = "ca.crt";
pub const CA_KEY: &str = "ca.key";
pub const SERVER_CERT: &str = "server.crt";
pub const SERVER_KEY: &str = "server.key";

const DAY: Duration = Duration::from_secs(86_400);
/// The CA lasts 10 years: the tablets install it once.
const CA_DAYS: u32 = 3650;
/// At most 825 days for iPadOS; a little under.
const SERVER_DAYS: u32 = 800;
/// A server certificate with less left than this is made anew.
const RENEW_BEFORE_DAYS: u32 = 30;
/// Private address ranges the CA may sign besides the names it was made for: the robot's
/// address on a clinic's or its own network may change (DHCP) without a new CA.
const PRIVATE_RANGES: [(&str, u8); 8] = [
    ("10.0.0.0", 8),
    ("172.16.0.0", 12),
    ("192.168.0.0", 16),
    ("127.0.0.0", 8),
    ("169.254.0.0", 16),
    ("::1", 128),
    ("fc00::", 7),
    ("fe80::", 10),
];

#[derive(Debug, thiserror::Error)]
pub enum CertError {
    #[error("{path}: {reason}")]
    File { path: PathBuf, reason: String },
    #[error("{0:?} is neither a host name nor an IP address")]
    BadName(String),
    #[error("making a certificate: {0}")]
    Make(String),
    #[error(
        "{dir} has {CA_CERT} but no {CA_KEY}: a server certificate for {names} can only be \
         signed with it (or make a new CA with --new-ca; every tablet must then install it again)"
    )]
    NoCaKey { dir: PathBuf, names: String },
    #[error(
        "the robot's CA ({fingerprint}) may not sign {name}: {reason}. Make a new CA with \
         --new-ca (every tablet must then install it again), or leave {name} out"
    )]
    NotAllowed {
        name: String,
        fingerprint: String,
        reason: String,
    },
}

fn file_error(path: &Path, reason: impl ToString) -> CertError {
    CertError::File {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

fn make_error(e: impl ToString) -> CertError {
    CertError::Make(e.to_string())
}

/// A name a certificate covers: a DNS host name (lower case) or an IP address.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub enum Name {
    Dns(String),
    Ip(IpAddr),
}

impl Name {
    pub fn parse(text: &str) -> Result<Name, CertError> {
        let text = text.trim();
        if let Ok(ip) = text.trim_matches(['[', ']']).parse::<IpAddr>() {
            return Ok(Name::Ip(ip));
        }
        let dns = text.trim_end_matches('.').to_ascii_lowercase();
        // rustls's own rules for a host name (what a client checks the certificate against).
        match ServerName::try_from(dns.clone()) {
            Ok(ServerName::DnsName(_)) if !dns.is_empty() => Ok(Name::Dns(dns)),
            _ => Err(CertError::BadName(text.to_string())),
        }
    }

    fn server_name(&self) -> Result<ServerName<'static>, String> {
        match self {
            Name::Dns(d) => ServerName::try_from(d.clone()).map_err(|e| format!("{d:?}: {e}")),
            Name::Ip(ip) => Ok(ServerName::IpAddress((*ip).into())),
        }
    }
}

impl std::fmt::Display for Name {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Name::Dns(d) => f.write_str(d),
            Name::Ip(ip) => write!(f, "{ip}"),
        }
    }
}

/// The names a tablet may use for this computer: its host name (and `<host>.local`, its
/// mDNS name), `localhost`, and the IPv4 addresses of its interfaces with `::1`.
pub fn default_names() -> Vec<Name> {
    let mut names = vec![
        Name::Dns("localhost".into()),
        Name::Ip(IpAddr::from([0u16, 0, 0, 0, 0, 0, 0, 1])),
    ];
    if let Ok(host) = nix::unistd::gethostname()
        && let Some(host) = host.to_str()
        && let Ok(Name::Dns(host)) = Name::parse(host)
    {
        if !host.contains('.') {
            names.push(Name::Dns(format!("{host}.local")));
        }
        names.push(Name::Dns(host));
    }
    if let Ok(addresses) = nix::ifaddrs::getifaddrs() {
        for a in addresses {
            if let Some(v4) = a.address.as_ref().and_then(|s| s.as_sockaddr_in()) {
                names.push(Name::Ip(IpAddr::V4(v4.ip())));
            }
        }
    }
    names.sort();
    names.dedup();
    names
}

/// SHA-256 of a certificate, as browsers and the tablets' settings show it (`AB:CD:…`).
pub fn fingerprint(cert: &CertificateDer<'_>) -> String {
    let digest = ring::digest::digest(&ring::digest::SHA256, cert.as_ref());
    let hex: Vec<String> = digest.as_ref().iter().map(|b| format!("{b:02X}")).collect();
    hex.join(":")
}

/// The CA's certificate of `dir`.
pub fn read_ca(dir: &Path) -> Result<CertificateDer<'static>, CertError> {
    let path = dir.join(CA_CERT);
    let mut certs = crate::tls::read_certificates(&path).map_err(|r| file_error(&path, r))?;
    Ok(certs.remove(0))
}

/// Whether `chain` (server certificate first) is one a client trusting `ca` accepts for
/// every one of `names` at `at`: the reason it is not, naming the name, otherwise.
pub fn verify_server(
    ca: &CertificateDer<'static>,
    chain: &[CertificateDer<'static>],
    names: &[Name],
    at: SystemTime,
) -> Result<(), (Name, String)> {
    let mut roots = rustls::RootCertStore::empty();
    let first = names
        .first()
        .cloned()
        .unwrap_or(Name::Dns("localhost".into()));
    roots
        .add(ca.clone())
        .map_err(|e| (first.clone(), format!("the CA certificate: {e}")))?;
    let verifier = rustls::client::WebPkiServerVerifier::builder_with_provider(
        Arc::new(roots),
        crate::tls::provider(),
    )
    .build()
    .map_err(|e| (first.clone(), e.to_string()))?;
    let (leaf, rest) = chain
        .split_first()
        .ok_or_else(|| (first.clone(), "no certificate".to_string()))?;
    let since = at
        .duration_since(SystemTime::UNIX_EPOCH)
        .unwrap_or_default();
    for name in names {
        let server_name = name.server_name().map_err(|e| (name.clone(), e))?;
        verifier
            .verify_server_cert(
                leaf,
                rest,
                &server_name,
                &[],
                UnixTime::since_unix_epoch(since),
            )
            .map_err(|e| (name.clone(), e.to_string()))?;
    }
    Ok(())
}

/// What [`init`] did.
#[derive(Debug)]
pub struct Made {
    pub ca_made: bool,
    /// None: the server certificate was kept; Some(why) it was made.
    pub server_made: Option<String>,
    pub fingerprint: String,
    pub names: Vec<Name>,
}

/// How [`init`] runs.
#[derive(Debug, Clone)]
pub struct InitOptions {
    pub dir: PathBuf,
    pub names: Vec<Name>,
    /// Replace the CA even if there is one (the tablets must install the new one).
    pub new_ca: bool,
    /// Owner (uid, gid) of a new server key; None: the old key's owner, else whoever runs this.
    pub key_owner: Option<(u32, u32)>,
    pub now: SystemTime,
}

/// Makes what is missing or no longer good in `dir`: the CA, the server certificate and key.
pub fn init(options: &InitOptions) -> Result<Made, CertError> {
    let dir = &options.dir;
    std::fs::create_dir_all(dir).map_err(|e| file_error(dir, e))?;
    let names = &options.names;
    if names.is_empty() {
        return Err(CertError::Make("no name for the server certificate".into()));
    }
    let (ca_cert_path, ca_key_path) = (dir.join(CA_CERT), dir.join(CA_KEY));
    let mut ca_made = false;
    let ca_key = if options.new_ca || !ca_key_path.exists() && !ca_cert_path.exists() {
        let key = KeyPair::generate().map_err(make_error)?;
        write_file(&ca_key_path, key.serialize_pem().as_bytes(), 0o600, None)?;
        let cert = ca_params(&key, names, options.now)
            .self_signed(&key)
            .map_err(make_error)?;
        write_file(&ca_cert_path, cert.pem().as_bytes(), 0o644, None)?;
        ca_made = true;
        Some(key)
    } else if ca_key_path.exists() {
        let pem = std::fs::read_to_string(&ca_key_path).map_err(|e| file_error(&ca_key_path, e))?;
        let key = KeyPair::from_pem(&pem).map_err(|e| file_error(&ca_key_path, e))?;
        if !ca_cert_path.exists() {
            // Stopped between the key and the certificate: the same CA again from its key.
            let cert = ca_params(&key, names, options.now)
                .self_signed(&key)
                .map_err(make_error)?;
            write_file(&ca_cert_path, cert.pem().as_bytes(), 0o644, None)?;
            ca_made = true;
        }
        Some(key)
    } else {
        None
    };
    let ca = read_ca(dir)?;
    let fingerprint = fingerprint(&ca);

    let (cert_path, key_path) = (dir.join(SERVER_CERT), dir.join(SERVER_KEY));
    let renew_at = options.now + DAY * RENEW_BEFORE_DAYS;
    let why_new = if ca_made {
        Some("a new CA".to_string())
    } else if !cert_path.exists() || !key_path.exists() {
        Some("there was none".to_string())
    } else {
        let chain = crate::tls::read_certificates(&cert_path);
        let loads = crate::tls::server_config(&cert_path, &key_path);
        match (chain, loads) {
            (Err(e), _) => Some(format!("{}: {e}", cert_path.display())),
            (_, Err(e)) => Some(e.to_string()),
            (Ok(chain), Ok(_)) => {
                verify_server(&ca, &chain, names, renew_at)
                    .err()
                    .map(|(name, reason)| {
                        format!("not good for {name} in {RENEW_BEFORE_DAYS} days ({reason})")
                    })
            }
        }
    };
    if let Some(why) = &why_new {
        let Some(ca_key) = &ca_key else {
            return Err(CertError::NoCaKey {
                dir: dir.clone(),
                names: join(names),
            });
        };
        let issuer = Issuer::new(ca_params(ca_key, names, options.now), ca_key);
        let key = KeyPair::generate().map_err(make_error)?;
        let cert = server_params(names, options.now)?
            .signed_by(&key, &issuer)
            .map_err(make_error)?;
        let chain = [cert.der().clone()];
        // Checked before anything is written: a name the CA may not sign stops here. A
        // client refuses the whole certificate for any one such name, so each is tried alone
        // to name the culprit.
        if let Err((name, reason)) = verify_server(&ca, &chain, names, options.now) {
            let mut refused = Vec::new();
            for n in names {
                let alone = server_params(std::slice::from_ref(n), options.now)?
                    .signed_by(&key, &issuer)
                    .map_err(make_error)?;
                if verify_server(
                    &ca,
                    &[alone.der().clone()],
                    std::slice::from_ref(n),
                    options.now,
                )
                .is_err()
                {
                    refused.push(n.clone());
                }
            }
            return Err(CertError::NotAllowed {
                name: if refused.is_empty() {
                    name.to_string()
                } else {
                    join(&refused)
                },
                fingerprint,
                reason,
            });
        }
        let owner = options.key_owner.or_else(|| {
            std::fs::metadata(&key_path)
                .ok()
                .map(|m| (m.uid(), m.gid()))
        });
        write_file(&key_path, key.serialize_pem().as_bytes(), 0o600, owner)?;
        write_file(&cert_path, cert.pem().as_bytes(), 0o644, None)?;
        tracing::debug!(why, "server certificate made");
    } else if let Some((uid, gid)) = options.key_owner {
        // A kept key is given to the owner asked for too (the service user may be new).
        std::os::unix::fs::chown(&key_path, Some(uid), Some(gid))
            .map_err(|e| file_error(&key_path, format!("giving it to uid {uid}: {e}")))?;
    }
    Ok(Made {
        ca_made,
        server_made: why_new,
        fingerprint,
        names: names.clone(),
    })
}

fn join(names: &[Name]) -> String {
    names
        .iter()
        .map(Name::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

fn days_from(now: SystemTime, days: i64) -> time::OffsetDateTime {
    let secs = now
        .duration_since(SystemTime::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or_default();
    time::OffsetDateTime::from_unix_timestamp(secs + days * 86_400)
        .unwrap_or(time::OffsetDateTime::UNIX_EPOCH)
}

/// The CA's parameters. Its name is made from its key alone (`QTrobot therapy CA 1a2b3c4d`),
/// so the issuer of a later server certificate is the same name without reading the CA file.
fn ca_params(key: &KeyPair, names: &[Name], now: SystemTime) -> CertificateParams {
    let id = ring::digest::digest(&ring::digest::SHA256, key.public_key_raw());
    let id: String = id.as_ref()[..4]
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    let mut p = CertificateParams::default();
    let mut dn = DistinguishedName::new();
    dn.push(DnType::OrganizationName, "qt-therapy");
    dn.push(DnType::CommonName, format!("QTrobot therapy CA {id}"));
    p.distinguished_name = dn;
    p.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    p.key_usages = vec![
        KeyUsagePurpose::KeyCertSign,
        KeyUsagePurpose::CrlSign,
        KeyUsagePurpose::DigitalSignature,
    ];
    p.not_before = days_from(now, -1);
    p.not_after = days_from(now, i64::from(CA_DAYS));
    let mut permitted: Vec<GeneralSubtree> = vec![
        GeneralSubtree::DnsName("localhost".into()),
        GeneralSubtree::DnsName("local".into()),
    ];
    for name in names {
        match name {
            Name::Dns(d) if d != "localhost" && !d.ends_with(".local") => {
                permitted.push(GeneralSubtree::DnsName(d.clone()))
            }
            Name::Ip(ip) if !is_private(ip) => permitted.push(GeneralSubtree::IpAddress(
                CidrSubnet::from_addr_prefix(*ip, if ip.is_ipv4() { 32 } else { 128 }),
            )),
            _ => {}
        }
    }
    for (net, prefix) in PRIVATE_RANGES {
        if let Ok(ip) = net.parse::<IpAddr>() {
            permitted.push(GeneralSubtree::IpAddress(CidrSubnet::from_addr_prefix(
                ip, prefix,
            )));
        }
    }
    p.name_constraints = Some(NameConstraints {
        permitted_subtrees: permitted,
        excluded_subtrees: Vec::new(),
    });
    p
}

fn is_private(ip: &IpAddr) -> bool {
    PRIVATE_RANGES.iter().any(|(net, prefix)| {
        let Ok(net) = net.parse::<IpAddr>() else {
            return false;
        };
        match (ip, net) {
            (IpAddr::V4(a), IpAddr::V4(n)) => {
                let mask = u32::MAX.checked_shl(32 - u32::from(*prefix)).unwrap_or(0);
                u32::from(*a) & mask == u32::from(n) & mask
            }
            (IpAddr::V6(a), IpAddr::V6(n)) => {
                let mask = u128::MAX.checked_shl(128 - u32::from(*prefix)).unwrap_or(0);
                u128::from(*a) & mask == u128::from(n) & mask
            }
            _ => false,
        }
    })
}

fn server_params(names: &[Name], now: SystemTime) -> Result<CertificateParams, CertError> {
    let mut p = CertificateParams::default();
    let mut dn = DistinguishedName::new();
    dn.push(DnType::OrganizationName, "qt-therapy");
    dn.push(DnType::OrganizationalUnitName, "tablet bridge");
    p.distinguished_name = dn;
    p.subject_alt_names = names
        .iter()
        .map(|n| match n {
            Name::Dns(d) => d
                .clone()
                .try_into()
                .map(SanType::DnsName)
                .map_err(|_| CertError::BadName(d.clone())),
            Name::Ip(ip) => Ok(SanType::IpAddress(*ip)),
        })
        .collect::<Result<_, _>>()?;
    p.is_ca = IsCa::ExplicitNoCa;
    p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
    p.extended_key_usages = vec![ExtendedKeyUsagePurpose::ServerAuth];
    p.use_authority_key_identifier_extension = true;
    p.not_before = days_from(now, -1);
    p.not_after = days_from(now, i64::from(SERVER_DAYS));
    let mut serial = [0u8; 16];
    ring::rand::SystemRandom::new()
        .fill(&mut serial)
        .map_err(|_| make_error("no random numbers for a serial number"))?;
    serial[0] &= 0x7f;
    p.serial_number = Some(SerialNumber::from_slice(&serial));
    Ok(p)
}

/// Writes `bytes` to `path` whole and durably (`atomic_file`: a new file synced and renamed
/// over the old one), created with `mode` (never readable by others on the way), owned by
/// `owner` when given.
pub fn write_file(
    path: &Path,
    bytes: &[u8],
    mode: u32,
    owner: Option<(u32, u32)>,
) -> Result<(), CertError> {
    let mut new = atomic_file::NewFile::with_mode(path, mode).map_err(|e| file_error(path, e))?;
    let tmp = new.path().to_path_buf();
    // The mode as asked, whatever the umask (the service user must read the certificates).
    new.file()
        .set_permissions(std::os::unix::fs::PermissionsExt::from_mode(mode))
        .map_err(|e| file_error(&tmp, e))?;
    new.file()
        .write_all(bytes)
        .map_err(|e| file_error(&tmp, e))?;
    if let Some((uid, gid)) = owner {
        std::os::unix::fs::fchown(new.file(), Some(uid), Some(gid))
            .map_err(|e| file_error(&tmp, format!("giving it to uid {uid}: {e}")))?;
    }
    new.commit().map_err(|e| file_error(path, e))
}
