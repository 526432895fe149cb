//! One training run of the evaluation: E epochs of 100 simulated sessions from a given Q-table,
//! recording per epoch the mean score, engagement, ratio, return, V and share of exploratory
//! steps of its sessions, with the authors' or plain epoch bookkeeping; the best of several
//! runs. The node pretrains a cluster's table with it; the lab's studies run many.

use crate::learning::{Learning, Mode, QTable};
use crate::simulation::{
    SessionMetrics, SessionSettings, SimulatedRun, SimulatedUser, run_session, run_sessions,
};
use sequence_game::{SEQUENCES_PER_SESSION, UserModelTable};

/// How sessions are grouped into epochs and which session counts visits for the temperature.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EpochScheme {
    /// Epoch e is sessions [100e, 100e + 99]; visits are counted in its first session.
    Blocks,
    /// The authors' exact bookkeeping: 100E − 1 sessions; the first epoch point is session 1
    /// alone, epoch k ≥ 1 is sessions 100(k−1)+2 ..= 100k+1 (1-based) and the last, partial
    /// group is dropped; visits are counted in sessions 100, 200, … (1-based).
    Authors,
}

/// Shape of one run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunSpec {
    pub epochs: usize,
    pub sessions_per_epoch: usize,
    pub scheme: EpochScheme,
    pub state_lags_result: bool,
}

impl RunSpec {
    pub fn sessions(&self) -> usize {
        match self.scheme {
            EpochScheme::Blocks => self.epochs * self.sessions_per_epoch,
            EpochScheme::Authors => (self.epochs * self.sessions_per_epoch).saturating_sub(1),
        }
    }

    pub(crate) fn epoch_of(&self, session: usize) -> usize {
        match self.scheme {
            EpochScheme::Blocks => session / self.sessions_per_epoch,
            EpochScheme::Authors if session == 0 => 0,
            EpochScheme::Authors => (session - 1) / self.sessions_per_epoch + 1,
        }
    }

    pub(crate) fn counts_visits(&self, session: usize) -> bool {
        match self.scheme {
            EpochScheme::Blocks => session.is_multiple_of(self.sessions_per_epoch),
            EpochScheme::Authors => (session + 1).is_multiple_of(self.sessions_per_epoch),
        }
    }
}

/// Means over one epoch's sessions of one run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EpochMetrics {
    pub score: f64,
    pub engagement: f64,
    pub ratio: f64,
    pub discounted_return: f64,
    pub start_value: f64,
    /// Share of steps that drew a non-greedy action.
    pub explored: f64,
}

impl EpochMetrics {
    pub const NAMES: [&'static str; 6] =
        ["score", "engagement", "ratio", "return", "v", "explored"];

    pub fn values(&self) -> [f64; 6] {
        [
            self.score,
            self.engagement,
            self.ratio,
            self.discounted_return,
            self.start_value,
            self.explored,
        ]
    }

    pub fn from_values(v: [f64; 6]) -> Self {
        EpochMetrics {
            score: v[0],
            engagement: v[1],
            ratio: v[2],
            discounted_return: v[3],
            start_value: v[4],
            explored: v[5],
        }
    }
}

/// One run's curve, its final Q-table, and its mean return over its last
/// `sessions_per_epoch` sessions (how the best run is chosen for transfer).
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    pub epochs: Vec<EpochMetrics>,
    pub q_table: QTable,
    pub final_return: f64,
}

/// Per-epoch sums of one run's sessions, and the return of its last epoch's worth.
struct Tally {
    sums: Vec<[f64; 6]>,
    counts: Vec<usize>,
    tail: f64,
    tail_sessions: usize,
}

impl Tally {
    fn new(spec: &RunSpec) -> Self {
        Tally {
            sums: vec![[0.0; 6]; spec.epochs],
            counts: vec![0; spec.epochs],
            tail: 0.0,
            tail_sessions: 0,
        }
    }

    fn add(&mut self, spec: &RunSpec, session: usize, m: &SessionMetrics) {
        if session + spec.sessions_per_epoch >= spec.sessions() {
            self.tail += m.discounted_return;
            self.tail_sessions += 1;
        }
        let e = spec.epoch_of(session);
        if e < spec.epochs {
            let s = &mut self.sums[e];
            s[0] += m.score;
            s[1] += m.engagement;
            s[2] += m.score / m.max_score;
            s[3] += m.discounted_return;
            s[4] += m.start_value;
            s[5] += f64::from(m.explored) / SEQUENCES_PER_SESSION as f64;
            self.counts[e] += 1;
        }
    }

    fn finish(self, q_table: QTable) -> Run {
        let epochs = self
            .sums
            .iter()
            .zip(&self.counts)
            .map(|(s, &n)| EpochMetrics::from_values(s.map(|x| x / n.max(1) as f64)))
            .collect();
        Run {
            epochs,
            q_table,
            final_return: self.tail / self.tail_sessions.max(1) as f64,
        }
    }
}

/// Trains one run from `initial`.
pub fn train_run(
    user: &SimulatedUser,
    settings: &SessionSettings,
    initial: QTable,
    spec: &RunSpec,
    seed: u64,
) -> Run {
    let mut run = SimulatedRun::seeded(initial, seed);
    let mut tally = Tally::new(spec);
    for session in 0..spec.sessions() {
        let count = spec.counts_visits(session);
        let m = run_session(&mut run, user, settings, count);
        tally.add(spec, session, &m);
    }
    tally.finish(run.into_table())
}

/// N runs from `initial`, interleaved on one thread (see `run_sessions`); the same result as
/// N `train_run` calls with these seeds.
pub fn train_runs<const N: usize>(
    user: &SimulatedUser,
    settings: &SessionSettings,
    initial: &QTable,
    spec: &RunSpec,
    seeds: [u64; N],
) -> [Run; N] {
    let mut runs = seeds.map(|seed| SimulatedRun::seeded(initial.clone(), seed));
    let mut tallies = seeds.map(|_| Tally::new(spec));
    for session in 0..spec.sessions() {
        let count = spec.counts_visits(session);
        let ms = run_sessions(&mut runs, user, settings, count);
        for (tally, m) in tallies.iter_mut().zip(&ms) {
            tally.add(spec, session, m);
        }
    }
    let mut runs = runs.into_iter();
    tallies.map(|t| {
        t.finish(
            runs.next()
                .map(SimulatedRun::into_table)
                .unwrap_or_default(),
        )
    })
}

/// The run with the highest mean return over its last epoch (the paper's transfer source).
pub fn best_run(runs: &[Run]) -> Option<usize> {
    (0..runs.len()).max_by(|&a, &b| runs[a].final_return.total_cmp(&runs[b].final_return))
}

/// How the node pretrains a cluster's table that has no file: `runs` softmax runs of `epochs`
/// epochs of 100 sessions from an empty table against the cluster's user model, the best kept.
/// The per-child study pretrains the cluster policy its children meet the same way.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pretraining {
    pub epochs: usize,
    pub runs: usize,
    /// The simulated state's convention (`SessionSettings::state_lags_result`).
    pub state_lags_result: bool,
}

impl Pretraining {
    /// The best of the runs (by its last epoch's mean return); run r is seeded with
    /// `seed(r)`. `None` when there are no runs.
    pub fn best_run(
        &self,
        model: &UserModelTable,
        learning: &Learning,
        seed: impl Fn(usize) -> u64,
    ) -> Option<Run> {
        let settings = SessionSettings {
            learning: *learning,
            mode: Mode::Explore,
            state_lags_result: self.state_lags_result,
        };
        let spec = RunSpec {
            epochs: self.epochs,
            sessions_per_epoch: 100,
            scheme: EpochScheme::Blocks,
            state_lags_result: self.state_lags_result,
        };
        let user = SimulatedUser::new(model, learning);
        let mut runs: Vec<Run> = (0..self.runs)
            .map(|r| train_run(&user, &settings, QTable::default(), &spec, seed(r)))
            .collect();
        let best = best_run(&runs)?;
        Some(runs.swap_remove(best))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn authors_scheme_bins_like_their_scripts() {
        let s = RunSpec {
            epochs: 3,
            sessions_per_epoch: 100,
            scheme: EpochScheme::Authors,
            state_lags_result: true,
        };
        assert_eq!(s.sessions(), 299);
        let bins: Vec<usize> = [0, 1, 100, 101, 200, 201, 298]
            .iter()
            .map(|&i| s.epoch_of(i))
            .collect();
        assert_eq!(bins, [0, 1, 1, 2, 2, 3, 3]);
        assert!(s.counts_visits(99) && s.counts_visits(199) && !s.counts_visits(0));
        let b = RunSpec {
            scheme: EpochScheme::Blocks,
            ..s
        };
        assert_eq!(
            (b.sessions(), b.epoch_of(199), b.epoch_of(200)),
            (300, 1, 2)
        );
        assert!(b.counts_visits(0) && b.counts_visits(200) && !b.counts_visits(99));
    }

    #[test]
    fn pretraining_keeps_the_best_of_its_seeded_runs() {
        let model = &crate::reference_tables::per_level_reference_tables()[1];
        let learning = Learning::default();
        let p = Pretraining {
            epochs: 2,
            runs: 3,
            state_lags_result: false,
        };
        let best = p
            .best_run(model, &learning, |r| 40 + r as u64)
            .expect("a run");
        let settings = SessionSettings {
            learning,
            mode: Mode::Explore,
            state_lags_result: false,
        };
        let spec = RunSpec {
            epochs: 2,
            sessions_per_epoch: 100,
            scheme: EpochScheme::Blocks,
            state_lags_result: false,
        };
        let user = SimulatedUser::new(model, &learning);
        let runs: Vec<Run> = (0..3)
            .map(|r| train_run(&user, &settings, QTable::default(), &spec, 40 + r))
            .collect();
        assert!(runs.iter().all(|r| r.final_return <= best.final_return));
        assert!(runs.contains(&best));
        assert_eq!(
            Pretraining { runs: 0, ..p }.best_run(model, &learning, |r| r as u64),
            None
        );
    }
}
