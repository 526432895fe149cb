//! The time a node reads: the system's clocks when it runs over DDS, or a virtual clock when the
//! suite runs in one process (tokio's paused time), so the same node code runs live and in
//! simulation. A node asks its bus for its clock (`Bus::clock`) and never reads the system
//! clock itself; every timer it sets is a tokio timer (`Clock::sleep_until`,
//! `tokio::time::interval`), so the runtime's one timer driver fires the timers of every node
//! of a process, and a paused runtime jumps to the next one as soon as every node is idle.
//!
//! Two readings, for two uses (docs/contract.md, "Time"). `now_nanos` is the wall clock: it
//! stamps what leaves the process (message headers, ids made of the time), and it steps when
//! NTP first syncs or someone sets the clock. `steady_nanos` never steps: the wall clock as it
//! read when the process first asked, advanced by the monotonic clock since, so it reads like
//! the wall clock until that is stepped. Durations, timeouts, watchdogs and timers are on it,
//! and so is every ordering inside the process; its readings never leave the process but as
//! times in its own files. On a virtual clock the two are one.

use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use std::time::Duration;
use tokio::time::Instant;

/// A node's clock: message time in nanoseconds since the epoch, and timers on it.
#[derive(Debug, Clone, Copy)]
pub struct Clock(Kind);

#[derive(Debug, Clone, Copy)]
enum Kind {
    /// The system's clocks (the robot): the wall clock, and the steady clock started on it.
    Wall,
    /// `epoch_ns` at `origin`, then running with tokio's clock: virtual in a runtime whose
    /// time is paused, so a whole session takes as long as its work, not its minutes.
    Virtual { epoch_ns: i64, origin: Instant },
}

/// Wall-clock time in nanoseconds since the epoch.
pub fn wall_nanos() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as i64)
        .unwrap_or(0)
}

/// The steady clock's start, once per process: the monotonic clock and the wall clock read
/// together.
fn steady_origin() -> (std::time::Instant, i64) {
    static ORIGIN: std::sync::OnceLock<(std::time::Instant, i64)> = std::sync::OnceLock::new();
    *ORIGIN.get_or_init(|| (std::time::Instant::now(), wall_nanos()))
}

/// The process's steady clock in nanoseconds: the wall clock as it read at the start, advanced
/// by the monotonic clock since. It never steps.
pub fn steady_nanos() -> i64 {
    let (at, wall) = steady_origin();
    wall.saturating_add(i64::try_from(at.elapsed().as_nanos()).unwrap_or(i64::MAX))
}

impl Clock {
    /// The system's clock.
    pub fn wall() -> Clock {
        Clock(Kind::Wall)
    }

    /// A clock that reads `epoch_ns` now and then runs with tokio's clock (call it inside the
    /// runtime whose time it follows).
    pub fn starting_at(epoch_ns: i64) -> Clock {
        Clock(Kind::Virtual {
            epoch_ns,
            origin: Instant::now(),
        })
    }

    /// Whether this is a virtual clock (an in-process run).
    pub fn is_virtual(&self) -> bool {
        matches!(self.0, Kind::Virtual { .. })
    }

    /// The wall clock: nanoseconds since the epoch, now. For stamps; it may step.
    pub fn now_nanos(&self) -> i64 {
        match self.0 {
            Kind::Wall => wall_nanos(),
            Kind::Virtual { epoch_ns, origin } => {
                epoch_ns.saturating_add(origin.elapsed().as_nanos() as i64)
            }
        }
    }

    /// The steady clock: nanoseconds that read like the wall clock's but never step (see the
    /// module's documentation). For durations, timers and ordering within the process.
    pub fn steady_nanos(&self) -> i64 {
        match self.0 {
            Kind::Wall => steady_nanos(),
            Kind::Virtual { .. } => self.now_nanos(),
        }
    }

    /// Now, as a ROS time (the wall clock).
    pub fn now(&self) -> Time {
        Time::from_nanos(self.now_nanos())
    }

    /// A header stamped now (the wall clock).
    pub fn header_now(&self) -> Header {
        Header::at(self.now())
    }

    /// The tokio instant at which the steady clock will read `at_ns` (now, if that is past).
    /// A step of the wall clock moves no timer.
    pub fn instant_at(&self, at_ns: i64) -> Instant {
        match self.0 {
            Kind::Wall => {
                let (at, wall) = steady_origin();
                Instant::from_std(at) + nanos_until(wall, at_ns)
            }
            Kind::Virtual { epoch_ns, origin } => origin + nanos_until(epoch_ns, at_ns),
        }
    }

    /// A timer that fires when the steady clock reads `at_ns`.
    pub fn sleep_until(&self, at_ns: i64) -> tokio::time::Sleep {
        tokio::time::sleep_until(self.instant_at(at_ns))
    }
}

/// From `from_ns` to `to_ns`, zero when it is past.
fn nanos_until(from_ns: i64, to_ns: i64) -> Duration {
    Duration::from_nanos(u64::try_from(to_ns.saturating_sub(from_ns)).unwrap_or(0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(start_paused = true)]
    async fn a_virtual_clock_runs_with_paused_time_and_its_timers_fire_on_it() {
        let clock = Clock::starting_at(1_000_000_000);
        assert_eq!(clock.now_nanos(), 1_000_000_000);
        let started = std::time::Instant::now();
        // An hour of timers in no time: the runtime jumps to each.
        clock.sleep_until(1_000_000_000 + 3_600_000_000_000).await;
        assert_eq!(clock.now_nanos(), 1_000_000_000 + 3_600_000_000_000);
        assert!(started.elapsed() < Duration::from_secs(5));
        // A time past is due at once.
        clock.sleep_until(0).await;
        assert_eq!(clock.now().sec, 3_601);
    }

    #[tokio::test]
    async fn the_wall_clock_reads_the_system_time() {
        let clock = Clock::wall();
        let before = wall_nanos();
        let now = clock.now_nanos();
        assert!(now >= before && now - before < 1_000_000_000);
        assert!(!clock.is_virtual());
        let due = clock.steady_nanos() + 20_000_000;
        clock.sleep_until(due).await;
        assert!(clock.steady_nanos() >= due);
        // Unstepped, the steady clock reads as the wall clock did (NTP's slewing aside).
        assert!((clock.steady_nanos() - wall_nanos()).abs() < 100_000_000);
    }
}
