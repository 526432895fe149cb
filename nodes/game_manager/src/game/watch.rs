//! The game manager's watch of the nodes in `watched_nodes` (bookkept by the shared
//! [`HeartbeatWatch`]): one silent for `node_loss_timeout_s` is lost. A lost node means: the
//! robot is silenced and the session held (paused, not lost) until every watched node is
//! back; then it resumes by itself, or waits for the therapist's resume (`session.rs`: hold,
//! release). One watchdog timer, due when the earliest-heard node would time out, so a loss
//! is seen exactly at the timeout.
//! A node started twice (two processes beating under its name, each answering on its own) is
//! told on the operator's terminal and kept in GameState.status until one of them stops.

use super::GameManager;
use crate::protocol::{LogLevel, Output};
use heartbeat_watch::Heard;
use qt_therapy_msgs::Heartbeat;
use qt_therapy_msgs::topics::BEHAVIOUR_POLICY_NODE;

fn seconds(ns: i64) -> f64 {
    ns as f64 * 1e-9
}

impl GameManager {
    /// Watched nodes lost now, by name.
    pub fn lost_nodes(&self) -> Vec<&str> {
        self.watched.lost()
    }

    /// "a, b" of the lost nodes.
    pub(super) fn lost_names(&self) -> String {
        self.lost_nodes().join(", ")
    }

    pub(super) fn on_heartbeat(&mut self, hb: Heartbeat, now: i64) {
        match self.watched.heartbeat(&hb.node_name, hb.pid, now) {
            Heard::Unwatched => return,
            Heard::Alive => {}
            Heard::WatchStarted => {
                let names = self.watched.names().join(", ");
                self.log(
                    LogLevel::INFO,
                    format!("watching the heartbeats of {names}"),
                );
            }
            // Back within the timeout: it was never lost, but its state is new.
            Heard::Restarted { old_pid } => self.log(
                LogLevel::WARN,
                format!(
                    "node {} restarted (pid {old_pid} -> {}) within the loss timeout",
                    hb.node_name, hb.pid
                ),
            ),
            Heard::Twice { other_pid } => self.log(
                LogLevel::WARN,
                format!(
                    "two processes beat as node {} (pids {other_pid} and {}): it was started \
                     twice; stop one, as each answers, publishes and writes on its own",
                    hb.node_name, hb.pid
                ),
            ),
            Heard::Back { lost_for_ns, .. } => {
                self.on_node_back(&hb.node_name, hb.pid, lost_for_ns, now)
            }
        }
        self.update_twins(now);
        if hb.node_name == BEHAVIOUR_POLICY_NODE {
            self.on_policy_heard(now);
        }
        self.arm_watchdog();
    }

    /// "two processes beat as node a (pids 1 and 2), ..." for GameState.status.
    pub(super) fn twins_text(&self) -> String {
        let pairs: Vec<String> = self.twins.iter().map(ToString::to_string).collect();
        format!("two processes beat as node {}: stop one", pairs.join(", "))
    }

    /// Follows the watch's pairs of processes beating under one name: a pair that starts or
    /// ends is told on the operator's terminal, and GameState published with it.
    fn update_twins(&mut self, now: i64) {
        let twins = self.watched.twins(now);
        if twins == self.twins {
            return;
        }
        for t in twins.iter().filter(|t| !self.twins.contains(t)) {
            self.out.push(Output::Alarm(format!(
                "two processes beat as node {t}: stop one"
            )));
        }
        let ended: Vec<String> = self
            .twins
            .iter()
            .filter(|t| !twins.iter().any(|n| n.name == t.name))
            // Both silent is a loss, told as such.
            .filter(|t| !self.watched.is_lost(&t.name))
            .map(|t| format!("only one process beats as node {} again", t.name))
            .collect();
        for line in ended {
            self.out.push(Output::LiveLine(line));
        }
        self.twins = twins;
        self.publish_state(now);
    }

    /// Sets the watchdog for the watch's next deadline, unless one is set.
    fn arm_watchdog(&mut self) {
        if let Some(at_ns) = self.watched.next_deadline_ns() {
            self.out.extend(self.timers.set_watchdog(at_ns));
        }
    }

    pub(super) fn on_watchdog(&mut self, now: i64) {
        let lost: Vec<String> = self
            .watched
            .check(now)
            .into_iter()
            .map(|l| {
                let last = match l.last_pid {
                    Some(pid) => format!("last pid {pid}"),
                    None => "never heard".to_string(),
                };
                format!(
                    "{} (no heartbeat for {:.1} s, {last})",
                    l.name,
                    seconds(l.silent_ns)
                )
            })
            .collect();
        if !lost.is_empty() {
            let what = lost.join(", ");
            self.log(LogLevel::WARN, format!("node lost: {what}"));
            self.hold(&what, now);
        }
        self.update_twins(now);
        self.arm_watchdog();
    }

    /// A lost node is back; when none is lost any more the session may go on.
    fn on_node_back(&mut self, name: &str, pid: u32, lost_for: i64, now: i64) {
        let back = format!(
            "node {name} is back (pid {pid}) after {:.1} s lost",
            seconds(lost_for)
        );
        self.out.push(Output::LiveLine(back.clone()));
        self.release(back, now);
    }
}
