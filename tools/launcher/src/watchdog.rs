//! systemd's watchdog, fed by the launcher only while its nodes are alive. Under a unit with
//! `WatchdogSec=` systemd sets `WATCHDOG_USEC` (and `WATCHDOG_PID`, `NOTIFY_SOCKET`); the
//! launcher then sends `WATCHDOG=1` to `$NOTIFY_SOCKET` (sd_notify's protocol: one datagram)
//! at each look that finds every node it runs alive: not stopped (SIGSTOP, a debugger: state
//! `T` or `t` in `/proc/<pid>/stat`) and not a zombie. A node frozen, or the launcher itself
//! stuck, for the whole `WatchdogSec` stops the feeding, and systemd stops and restarts the
//! service (qt-therapy.service, docs/install.md).

use std::ffi::OsString;
use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::time::Duration;

/// How often the launcher looks at its nodes (and feeds the watchdog if they are alive), at
/// most: a quarter of the watchdog's timeout when that is shorter.
const LOOK_EVERY: Duration = Duration::from_secs(1);

/// Why the watchdog asked for could not be fed.
#[derive(Debug, thiserror::Error)]
pub enum WatchdogError {
    #[error("WATCHDOG_USEC={0:?} is not a number of microseconds above 0")]
    Usec(String),
    #[error(
        "WATCHDOG_USEC is set but NOTIFY_SOCKET is not: nowhere to send the watchdog's keep-alive"
    )]
    NoSocket,
    #[error("NOTIFY_SOCKET={0:?} is not a socket path (/...) or an abstract name (@...)")]
    Socket(OsString),
    #[error("opening a datagram socket for NOTIFY_SOCKET: {0}")]
    Io(#[from] std::io::Error),
}

/// The watchdog systemd asked for.
#[derive(Debug)]
pub struct Watchdog {
    socket: UnixDatagram,
    address: SocketAddr,
    /// systemd's timeout (`WATCHDOG_USEC`).
    pub timeout: Duration,
}

/// The variables systemd sets for the watchdog, which the nodes must not inherit (as
/// sd_watchdog_enabled's `unset_environment`): they are not the service's main process.
pub const ENVIRONMENT: [&str; 3] = ["WATCHDOG_USEC", "WATCHDOG_PID", "NOTIFY_SOCKET"];

impl Watchdog {
    /// The watchdog the environment asks this process to feed, if any.
    pub fn from_env() -> Result<Option<Watchdog>, WatchdogError> {
        Watchdog::from_values(
            std::env::var("WATCHDOG_USEC").ok(),
            std::env::var("WATCHDOG_PID").ok(),
            std::env::var_os("NOTIFY_SOCKET"),
            std::process::id(),
        )
    }

    /// As sd_watchdog_enabled: asked for when `WATCHDOG_USEC` is set and `WATCHDOG_PID`, if
    /// set, is `own_pid` (else it is meant for another process).
    fn from_values(
        usec: Option<String>,
        pid: Option<String>,
        socket: Option<OsString>,
        own_pid: u32,
    ) -> Result<Option<Watchdog>, WatchdogError> {
        let Some(usec) = usec.filter(|u| !u.is_empty()) else {
            return Ok(None);
        };
        if pid
            .as_deref()
            .is_some_and(|p| p.trim().parse::<u32>().ok() != Some(own_pid))
        {
            return Ok(None);
        }
        let timeout = match usec.trim().parse::<u64>() {
            Ok(u) if u > 0 => Duration::from_micros(u),
            _ => return Err(WatchdogError::Usec(usec)),
        };
        let socket_name = socket
            .filter(|s| !s.is_empty())
            .ok_or(WatchdogError::NoSocket)?;
        let address = notify_address(&socket_name)?;
        Ok(Some(Watchdog {
            socket: UnixDatagram::unbound()?,
            address,
            timeout,
        }))
    }

    /// How often to look at the nodes.
    pub fn look_every(&self) -> Duration {
        LOOK_EVERY.min(self.timeout / 4)
    }

    /// Tells systemd the service is alive.
    pub fn feed(&self) -> std::io::Result<()> {
        self.socket
            .send_to_addr(b"WATCHDOG=1", &self.address)
            .map(|_| ())
    }
}

/// `NOTIFY_SOCKET`'s address: a path, or `@name` for a Linux abstract socket.
fn notify_address(name: &std::ffi::OsStr) -> Result<SocketAddr, WatchdogError> {
    use std::os::linux::net::SocketAddrExt;
    use std::os::unix::ffi::OsStrExt;
    let bytes = name.as_bytes();
    match bytes.first() {
        Some(b'/') => Ok(SocketAddr::from_pathname(name)?),
        Some(b'@') => Ok(SocketAddr::from_abstract_name(&bytes[1..])?),
        _ => Err(WatchdogError::Socket(name.to_os_string())),
    }
}

/// Why a node does not count as alive, from the state letter of its `/proc/<pid>/stat`; None
/// when it is alive (running, sleeping, waiting on a disk) or gone (its exit is the
/// supervisor's business: it reports it and respawns).
pub fn not_alive(pid: u32) -> Option<&'static str> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    not_alive_in(&stat)
}

/// [`not_alive`] from the text of a `stat` file: `pid (comm) S ...`, where comm may hold
/// spaces and parentheses, so the state follows the last `)`.
fn not_alive_in(stat: &str) -> Option<&'static str> {
    let state = stat.rsplit_once(')')?.1.split_whitespace().next()?;
    match state {
        "T" => Some("stopped"),
        "t" => Some("stopped by a debugger"),
        "Z" | "X" => Some("dead, not yet reaped"),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn from(
        usec: Option<&str>,
        pid: Option<&str>,
        socket: Option<&str>,
    ) -> Result<Option<Watchdog>, WatchdogError> {
        Watchdog::from_values(
            usec.map(String::from),
            pid.map(String::from),
            socket.map(OsString::from),
            4242,
        )
    }

    #[test]
    fn the_watchdog_is_asked_for_as_sd_watchdog_enabled_reads_it() {
        assert!(from(None, None, Some("/run/systemd/notify")).is_ok_and(|w| w.is_none()));
        let w = from(Some("30000000"), Some("4242"), Some("/run/systemd/notify"))
            .expect("valid")
            .expect("asked for");
        assert_eq!(w.timeout, Duration::from_secs(30));
        assert_eq!(w.look_every(), Duration::from_secs(1));
        // Meant for another process (the launcher started by a script that did not exec it).
        assert!(from(Some("30000000"), Some("17"), Some("/x")).is_ok_and(|w| w.is_none()));
        // No WATCHDOG_PID: for whoever reads it.
        assert!(
            from(Some("400000"), None, Some("@abstract"))
                .is_ok_and(|w| w.is_some_and(|w| w.look_every() == Duration::from_millis(100)))
        );
    }

    #[test]
    fn a_watchdog_that_cannot_be_fed_is_named() {
        let message = |r: Result<Option<Watchdog>, WatchdogError>| match r {
            Err(e) => e.to_string(),
            Ok(w) => panic!("accepted: {w:?}"),
        };
        assert_eq!(
            message(from(Some("soon"), None, Some("/x"))),
            "WATCHDOG_USEC=\"soon\" is not a number of microseconds above 0"
        );
        assert_eq!(
            message(from(Some("0"), None, Some("/x"))),
            "WATCHDOG_USEC=\"0\" is not a number of microseconds above 0"
        );
        assert!(message(from(Some("1000"), None, None)).starts_with("WATCHDOG_USEC is set but"));
        assert_eq!(
            message(from(Some("1000"), None, Some("relative/path"))),
            "NOTIFY_SOCKET=\"relative/path\" is not a socket path (/...) or an abstract name (@...)"
        );
    }

    #[test]
    fn a_stopped_or_dead_node_is_not_alive_and_a_sleeping_one_is() {
        // Lines as Linux writes them; the name may hold spaces and parentheses.
        assert_eq!(not_alive_in("12 (game_manager) S 1 12 12 0 -1"), None);
        assert_eq!(not_alive_in("12 (tokio (rt) 1) R 1 12 12"), None);
        assert_eq!(not_alive_in("12 (bag) D 1 12 12"), None);
        assert_eq!(not_alive_in("12 (user_model) T 1 12 12"), Some("stopped"));
        assert_eq!(
            not_alive_in("12 (a) b) t 1 12 12"),
            Some("stopped by a debugger")
        );
        assert_eq!(
            not_alive_in("12 (bag) Z 1 12 12"),
            Some("dead, not yet reaped")
        );
        assert_eq!(not_alive_in("garbage"), None);
    }

    #[test]
    fn this_process_is_alive_and_a_stopped_child_is_not() {
        assert_eq!(not_alive(std::process::id()), None);
        let mut child = std::process::Command::new("sleep")
            .arg("30")
            .spawn()
            .expect("sleep runs");
        let pid = child.id();
        let signal = |s| {
            nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(i32::try_from(pid).expect("a pid")),
                s,
            )
            .expect("signals the child")
        };
        signal(nix::sys::signal::Signal::SIGSTOP);
        let seen = (0..100).find_map(|_| {
            std::thread::sleep(Duration::from_millis(20));
            not_alive(pid)
        });
        assert_eq!(seen, Some("stopped"));
        signal(nix::sys::signal::Signal::SIGCONT);
        let back = (0..100).any(|_| {
            std::thread::sleep(Duration::from_millis(20));
            not_alive(pid).is_none()
        });
        assert!(back);
        let _ = child.kill();
        let _ = child.wait();
    }

    #[test]
    fn feeding_sends_watchdog_1_to_the_socket() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("notify");
        let systemd = UnixDatagram::bind(&path).expect("binds");
        let w = from(Some("2000000"), None, path.to_str())
            .expect("valid")
            .expect("asked for");
        w.feed().expect("sends");
        let mut buf = [0u8; 64];
        let n = systemd.recv(&mut buf).expect("receives");
        assert_eq!(&buf[..n], b"WATCHDOG=1");
    }
}
