//! The game's timers: what each timer the core asked for is for, and the heartbeat watchdog's.
//! The run loop keeps the due times and feeds back `Input::TimerFired { id }`; here each id
//! is told apart as the watchdog's, a game timer still wanted, or a stale one (forgotten by
//! a pause, a stop or a new session: it fires and is ignored, so nothing is ever cancelled).

use crate::protocol::Output;
use std::collections::BTreeMap;

/// What a game timer is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Timer {
    PolicyDeadline {
        request_id: u64,
    },
    /// A second look at the policy's heartbeat, put off by a deadline that found it heard
    /// too recently to tell a dead process from a slow one.
    PolicyHeartbeatLook {
        request_id: u64,
    },
    SpeechDone,
    FeedbackDone,
    Word(usize),
    SequenceSaid,
    AnswerTimeout,
    Settled,
    /// The open proposal's countdown ran out.
    ProposalRunsOut,
}

/// A fired timer, told apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Fired {
    /// The heartbeat watchdog's.
    Watchdog,
    Game(Timer),
    /// Forgotten since it was set.
    Stale,
}

/// The timers set and not yet fired or forgotten.
#[derive(Debug)]
pub(super) struct Timers {
    wanted: BTreeMap<u64, Timer>,
    next_id: u64,
    /// The heartbeat watchdog's timer id, while one is set.
    watchdog: Option<u64>,
}

impl Timers {
    pub(super) fn new() -> Self {
        Timers {
            wanted: BTreeMap::new(),
            next_id: 1,
            watchdog: None,
        }
    }

    fn new_id(&mut self) -> u64 {
        let id = self.next_id;
        self.next_id += 1;
        id
    }

    /// Sets `timer` for `at_ns`: the output that asks the run loop for it.
    pub(super) fn set(&mut self, timer: Timer, at_ns: i64) -> Output {
        let id = self.new_id();
        self.wanted.insert(id, timer);
        Output::SetTimer { id, at_ns }
    }

    /// Sets the watchdog for `at_ns`, unless one is set.
    pub(super) fn set_watchdog(&mut self, at_ns: i64) -> Option<Output> {
        if self.watchdog.is_some() {
            return None;
        }
        let id = self.new_id();
        self.watchdog = Some(id);
        Some(Output::SetTimer { id, at_ns })
    }

    /// Timer `id` fired: whose it was (each fires once).
    pub(super) fn fired(&mut self, id: u64) -> Fired {
        if self.watchdog == Some(id) {
            self.watchdog = None;
            return Fired::Watchdog;
        }
        self.wanted.remove(&id).map_or(Fired::Stale, Fired::Game)
    }

    /// Forgets the game timers `keep` refuses (they still fire, and are then ignored).
    pub(super) fn forget_unless(&mut self, keep: impl Fn(&Timer) -> bool) {
        self.wanted.retain(|_, t| keep(t));
    }

    /// Forgets every game timer (the watchdog's stays).
    pub(super) fn forget_all(&mut self) {
        self.wanted.clear();
    }
}
