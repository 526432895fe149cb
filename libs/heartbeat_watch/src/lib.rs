//! Which watched nodes are alive, from their heartbeats: the sans-IO bookkeeping the game
//! manager (watching the nodes a session needs) and the tablet bridge (watching the game
//! manager) share. RustDDS reports no DDS liveliness, so the suite has its own, as Nav2's bond
//! does. A node silent for the timeout is lost until its next heartbeat; a new pid within the
//! timeout is a restart that was never lost. Times are the caller's monotonic nanoseconds; what
//! a loss means (silence the robot, pause the child page) stays with the caller.
//!
//! Heartbeats are matched by node name, so two processes beating under one name (a node started
//! twice) would look like one node restarting again and again; a pid that comes back within
//! the timeout after it was replaced is told as such, once per pair, and [`HeartbeatWatch::twins`]
//! names such pairs for as long as both still beat, so a caller can show it until one stops.
//!
//! Watching starts with the first heartbeat from any watched node: a core that hears none (a
//! replay, a unit test) watches nothing, and from then on a node never heard is lost one
//! timeout later.

use std::collections::BTreeMap;
use std::time::Duration;

/// The watch over a fixed set of nodes.
#[derive(Debug, Clone)]
pub struct HeartbeatWatch {
    names: Vec<String>,
    timeout_ns: i64,
    /// By name; empty until the first heartbeat of a watched node.
    nodes: BTreeMap<String, Watched>,
}

#[derive(Debug, Clone)]
struct Watched {
    /// Arrival of its last heartbeat (the start of the watch for a node not heard yet).
    last_ns: i64,
    /// Its process, once heard.
    pid: Option<u32>,
    /// Since when it is lost.
    lost_since: Option<i64>,
    /// The pid its last new pid replaced, and when.
    replaced: Option<(u32, i64)>,
    /// Two pids found beating together, told once.
    twice: Option<Pair>,
}

/// Two processes beating under one name, and when each last did.
#[derive(Debug, Clone)]
struct Pair {
    /// Smaller first.
    pids: (u32, u32),
    last_ns: (i64, i64),
}

impl Pair {
    fn heard(&mut self, pid: u32, now_ns: i64) {
        if pid == self.pids.0 {
            self.last_ns.0 = now_ns;
        } else if pid == self.pids.1 {
            self.last_ns.1 = now_ns;
        }
    }
}

/// A name that two processes beat under, both within the timeout: found by
/// [`HeartbeatWatch::twins`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Twins {
    pub name: String,
    /// Smaller first.
    pub pids: (u32, u32),
}

/// "policy (pids 10 and 11)", as warnings name them.
impl std::fmt::Display for Twins {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (a, b) = self.pids;
        write!(f, "{} (pids {a} and {b})", self.name)
    }
}

/// What one heartbeat told.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Heard {
    /// From a node not watched.
    Unwatched,
    /// The first heartbeat of a watched node: the watch of every watched node starts now.
    WatchStarted,
    /// A node alive as it was.
    Alive,
    /// A new pid within the timeout: never lost, but its process (and state) is new.
    Restarted { old_pid: u32 },
    /// A pid replaced less than the timeout ago beats again: two processes beat under this
    /// name (told once per pair; their alternation afterwards is [`Heard::Alive`]).
    Twice { other_pid: u32 },
    /// A lost node is back.
    Back {
        /// Since its previous heartbeat (or the start of the watch).
        silent_ns: i64,
        /// Since it was declared lost.
        lost_for_ns: i64,
    },
}

/// A node found lost by [`HeartbeatWatch::check`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Lost {
    pub name: String,
    /// Since its last heartbeat (or the start of the watch).
    pub silent_ns: i64,
    /// Its last process; None if never heard.
    pub last_pid: Option<u32>,
}

impl HeartbeatWatch {
    /// Watches `names`, each lost after `timeout` without a heartbeat.
    pub fn new(names: impl IntoIterator<Item = impl Into<String>>, timeout: Duration) -> Self {
        HeartbeatWatch {
            names: names.into_iter().map(Into::into).collect(),
            timeout_ns: i64::try_from(timeout.as_nanos()).unwrap_or(i64::MAX),
            nodes: BTreeMap::new(),
        }
    }

    /// The same with the timeout in seconds, as parameter files give it (checked there; a
    /// value that is no duration falls back to the suite's default, 4 s).
    pub fn with_timeout_s(
        names: impl IntoIterator<Item = impl Into<String>>,
        timeout_s: f64,
    ) -> Self {
        let timeout = Duration::try_from_secs_f64(timeout_s).unwrap_or(Duration::from_secs(4));
        HeartbeatWatch::new(names, timeout)
    }

    /// The nodes watched, in the order given.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// True once a watched node has been heard.
    pub fn started(&self) -> bool {
        !self.nodes.is_empty()
    }

    /// A heartbeat from `node_name` (process `pid`) arrived at `now_ns`.
    pub fn heartbeat(&mut self, node_name: &str, pid: u32, now_ns: i64) -> Heard {
        if !self.names.iter().any(|n| n == node_name) {
            return Heard::Unwatched;
        }
        let started_now = !self.started();
        if started_now {
            for name in &self.names {
                let w = Watched {
                    last_ns: now_ns,
                    pid: None,
                    lost_since: None,
                    replaced: None,
                    twice: None,
                };
                self.nodes.insert(name.clone(), w);
            }
        }
        let Some(w) = self.nodes.get_mut(node_name) else {
            return Heard::Unwatched;
        };
        let silent_ns = now_ns.saturating_sub(w.last_ns);
        let old_pid = w.pid.replace(pid);
        let previous_ns = std::mem::replace(&mut w.last_ns, now_ns);
        if let Some(pair) = w.twice.as_mut() {
            pair.heard(pid, now_ns);
        }
        if let Some(since) = w.lost_since.take() {
            let lost_for_ns = now_ns.saturating_sub(since);
            return Heard::Back {
                silent_ns,
                lost_for_ns,
            };
        }
        match old_pid {
            _ if started_now => Heard::WatchStarted,
            Some(old_pid) if old_pid != pid => {
                let back_again = w
                    .replaced
                    .is_some_and(|(p, at)| p == pid && now_ns.saturating_sub(at) < self.timeout_ns);
                w.replaced = Some((old_pid, now_ns));
                let pids = (old_pid.min(pid), old_pid.max(pid));
                if w.twice.as_ref().is_some_and(|p| p.pids == pids) {
                    Heard::Alive
                } else if back_again {
                    let mut pair = Pair {
                        pids,
                        last_ns: (now_ns, now_ns),
                    };
                    pair.heard(old_pid, previous_ns);
                    w.twice = Some(pair);
                    Heard::Twice { other_pid: old_pid }
                } else {
                    Heard::Restarted { old_pid }
                }
            }
            _ => Heard::Alive,
        }
    }

    /// Declares lost, at `now_ns`, every node silent for the timeout; returns those newly lost.
    pub fn check(&mut self, now_ns: i64) -> Vec<Lost> {
        let timeout_ns = self.timeout_ns;
        self.nodes
            .iter_mut()
            .filter(|(_, w)| w.lost_since.is_none())
            .filter(|(_, w)| now_ns.saturating_sub(w.last_ns) >= timeout_ns)
            .map(|(name, w)| {
                w.lost_since = Some(now_ns);
                Lost {
                    name: name.clone(),
                    silent_ns: now_ns.saturating_sub(w.last_ns),
                    last_pid: w.pid,
                }
            })
            .collect()
    }

    /// When [`HeartbeatWatch::check`] must next run: the earliest timeout of a node not lost.
    pub fn next_deadline_ns(&self) -> Option<i64> {
        self.nodes
            .values()
            .filter(|w| w.lost_since.is_none())
            .map(|w| w.last_ns.saturating_add(self.timeout_ns))
            .min()
    }

    /// The nodes lost now, by name.
    pub fn lost(&self) -> Vec<&str> {
        self.nodes
            .iter()
            .filter(|(_, w)| w.lost_since.is_some())
            .map(|(n, _)| n.as_str())
            .collect()
    }

    /// True while `name` is lost.
    pub fn is_lost(&self, name: &str) -> bool {
        self.nodes.get(name).is_some_and(|w| w.lost_since.is_some())
    }

    /// The names two processes still beat under at `now_ns` (each heard within the timeout),
    /// by name. A pair ends when one of them has been silent for the timeout.
    pub fn twins(&self, now_ns: i64) -> Vec<Twins> {
        let beating = |last: i64| now_ns.saturating_sub(last) < self.timeout_ns;
        self.nodes
            .iter()
            .filter_map(|(name, w)| {
                let p = w.twice.as_ref()?;
                (beating(p.last_ns.0) && beating(p.last_ns.1)).then(|| Twins {
                    name: name.clone(),
                    pids: p.pids,
                })
            })
            .collect()
    }

    /// How long `name` has been silent at `now_ns`: since its last heartbeat, or since the
    /// watch started if never heard. None if it is not watched or nothing is watched yet.
    pub fn silent_ns(&self, name: &str, now_ns: i64) -> Option<i64> {
        self.nodes
            .get(name)
            .map(|w| now_ns.saturating_sub(w.last_ns))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: i64 = 1_000_000_000;

    fn watch() -> HeartbeatWatch {
        HeartbeatWatch::new(["policy", "classifier"], Duration::from_secs(4))
    }

    #[test]
    fn nothing_is_watched_until_a_watched_node_is_heard() {
        let mut w = watch();
        assert_eq!(w.heartbeat("recorder", 5, 0), Heard::Unwatched);
        assert!(!w.started());
        assert_eq!(w.next_deadline_ns(), None);
        assert!(w.check(100 * S).is_empty());
        assert_eq!(w.heartbeat("policy", 10, S), Heard::WatchStarted);
        assert!(w.started());
        assert_eq!(w.next_deadline_ns(), Some(5 * S));
    }

    #[test]
    fn a_silent_node_is_lost_exactly_at_the_timeout_and_back_with_its_next_heartbeat() {
        let mut w = watch();
        w.heartbeat("policy", 10, 0);
        w.heartbeat("classifier", 20, 0);
        assert_eq!(w.heartbeat("policy", 10, 2 * S), Heard::Alive);
        assert!(w.check(4 * S - 1).is_empty());
        let lost = w.check(4 * S);
        assert_eq!(
            lost,
            vec![Lost {
                name: "classifier".into(),
                silent_ns: 4 * S,
                last_pid: Some(20),
            }]
        );
        assert!(w.check(5 * S).is_empty(), "a loss is told once");
        assert_eq!(w.lost(), vec!["classifier"]);
        assert!(w.is_lost("classifier") && !w.is_lost("policy"));
        // Only the policy's deadline remains.
        assert_eq!(w.next_deadline_ns(), Some(6 * S));
        assert_eq!(
            w.heartbeat("classifier", 21, 9 * S),
            Heard::Back {
                silent_ns: 9 * S,
                lost_for_ns: 5 * S,
            }
        );
        assert!(w.lost().is_empty());
    }

    #[test]
    fn a_node_never_heard_is_lost_one_timeout_after_the_watch_started() {
        let mut w = watch();
        w.heartbeat("classifier", 20, 3 * S);
        w.heartbeat("classifier", 20, 6 * S);
        let lost = w.check(7 * S);
        assert_eq!(lost.len(), 1);
        assert_eq!(lost[0].name, "policy");
        assert_eq!(lost[0].last_pid, None);
        assert_eq!(lost[0].silent_ns, 4 * S);
    }

    #[test]
    fn a_new_pid_within_the_timeout_is_a_restart_not_a_loss() {
        let mut w = watch();
        w.heartbeat("policy", 10, 0);
        assert_eq!(
            w.heartbeat("policy", 11, 3 * S),
            Heard::Restarted { old_pid: 10 }
        );
        assert_eq!(w.heartbeat("policy", 11, 4 * S), Heard::Alive);
        assert!(w.lost().is_empty());
    }

    #[test]
    fn two_processes_beating_under_one_name_are_told_once() {
        let mut w = watch();
        w.heartbeat("policy", 10, 0);
        assert_eq!(
            w.heartbeat("policy", 11, S / 10),
            Heard::Restarted { old_pid: 10 }
        );
        // Pid 10 again, 0.1 s after it was replaced: both run.
        assert_eq!(
            w.heartbeat("policy", 10, 2 * S / 10),
            Heard::Twice { other_pid: 11 }
        );
        for i in 3..40 {
            let pid = if i % 2 == 0 { 10 } else { 11 };
            assert_eq!(w.heartbeat("policy", pid, i * S / 10), Heard::Alive);
        }
        let both = vec![Twins {
            name: "policy".into(),
            pids: (10, 11),
        }];
        assert_eq!(w.twins(39 * S / 10), both);
        // A third copy is news.
        assert_eq!(
            w.heartbeat("policy", 12, 4 * S),
            Heard::Restarted { old_pid: 11 }
        );
    }

    #[test]
    fn twins_are_named_until_one_of_them_is_silent_for_the_timeout() {
        let mut w = watch();
        assert!(w.twins(0).is_empty());
        w.heartbeat("policy", 10, 0);
        w.heartbeat("policy", 11, S / 10);
        assert!(w.twins(S / 10).is_empty(), "a restart is no pair");
        w.heartbeat("policy", 10, 2 * S / 10);
        let both = vec![Twins {
            name: "policy".into(),
            pids: (10, 11),
        }];
        assert_eq!(w.twins(2 * S / 10), both);
        // Pid 11 stops after its beat at 0.3 s; 10 goes on.
        w.heartbeat("policy", 11, 3 * S / 10);
        for i in 4..60 {
            w.heartbeat("policy", 10, i * S / 10);
            let expected = if i * S / 10 < 3 * S / 10 + 4 * S {
                both.clone()
            } else {
                vec![]
            };
            assert_eq!(w.twins(i * S / 10), expected, "at {i} tenths");
        }
        assert!(w.lost().is_empty(), "the one left beats");
    }

    #[test]
    fn a_pid_seen_again_only_after_the_timeout_is_a_restart() {
        // 10 replaced by 11, which dies; long after, a new process happens to get pid 10.
        let mut w = watch();
        w.heartbeat("policy", 10, 0);
        w.heartbeat("policy", 11, S);
        w.heartbeat("policy", 11, 2 * S);
        assert_eq!(
            w.heartbeat("policy", 10, 5 * S + 1),
            Heard::Restarted { old_pid: 11 }
        );
    }

    #[test]
    fn silence_is_measured_from_the_last_heartbeat_or_the_watch_start() {
        let mut w = watch();
        assert_eq!(w.silent_ns("policy", S), None, "nothing watched yet");
        w.heartbeat("classifier", 20, 2 * S);
        assert_eq!(
            w.silent_ns("policy", 3 * S),
            Some(S),
            "never heard: since the start"
        );
        w.heartbeat("policy", 10, 3 * S);
        assert_eq!(w.silent_ns("policy", 3 * S + S / 2), Some(S / 2));
        assert_eq!(w.silent_ns("recorder", 3 * S), None, "not watched");
    }
}
