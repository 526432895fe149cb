//! Per-child beliefs for the decision node (`child_belief: true`), sans-IO: for each child a
//! belief about what kind of learner they are (their own Gaussian processes around their
//! first cluster's model, with a prior covariance learned from the study's children,
//! `child_belief::OwnModel`), updated from every SequenceResult of theirs and planned on
//! before each of their decisions, near the cluster's Q-table (`child_belief::planner`).
//!
//! The belief is kept as the child's observed sequences in `belief_<id>.json` beside the
//! Q-tables, written whole after each one (`versioned_json`, atomic), and rebuilt from them
//! when the child comes back, after a restart too: the same sequences give the same belief. A
//! file that cannot be used is named in the log and moved aside (`.damaged`, never deleted);
//! the child is then treated as new.

use child_belief::planner::{Baseline, BeliefDecision, BeliefPolicy, PlanningRule};
use child_belief::{Belief, LearnedCovariance, LevelBelief, Observation, OwnModel, OwnModelParams};
use q_learning::learning::{Learning, QTable};
use q_learning::q_table_file::QTableOwner;
use qt_therapy_msgs::SequenceResult;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sequence_game::{Feedback, Level, ModelInput, Outcome, State, UserModelTable, stable_id_hash};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use versioned_json::{FileError, Kind};

/// A child's belief file.
pub const BELIEF_FILE: Kind = Kind {
    format: "qt_therapy child_belief",
    version: 1,
    name: "child belief",
};

/// What a belief file holds: the child's observed sequences, in the order they were learned.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BeliefFile {
    pub format: String,
    pub version: u32,
    pub user_id: String,
    /// The cluster whose model is the belief's prior mean (the child's cluster at their first
    /// decision; it stays when a later session names another).
    pub prior_cluster: usize,
    pub observations: Vec<ObservedSequence>,
}

/// One sequence of the child's, as the belief learned it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservedSequence {
    pub session_id: String,
    pub sequence_index: u8,
    /// The input (L, F, PS) it was played at.
    pub level: u8,
    pub feedback: u8,
    pub previous_score: i8,
    /// +1 right, −1 wrong or timed out.
    pub outcome: i8,
    /// Mean engagement over its period; absent where no face was seen.
    pub engagement: Option<f64>,
}

impl ObservedSequence {
    fn observation(&self) -> Result<Observation, String> {
        let input = model_input(self.level, self.feedback, self.previous_score)?;
        let outcome = Outcome::new(self.outcome.into()).map_err(|e| e.to_string())?;
        match self.engagement {
            Some(e) => Observation::new(input, outcome, e).map_err(|e| e.to_string()),
            None => Ok(Observation::without_engagement(input, outcome)),
        }
    }
}

/// The input (L, F, PS) of a sequence, or what is wrong with it.
fn model_input(level: u8, feedback: u8, previous_score: i8) -> Result<ModelInput, String> {
    let e = |e: sequence_game::GameError| e.to_string();
    ModelInput::new(
        Level::new(level.into()).map_err(e)?,
        Feedback::new(feedback.into()).map_err(e)?,
        previous_score,
    )
    .map_err(e)
}

/// Why a child's belief could not serve or learn; the Q-tables are not concerned.
#[derive(Debug, thiserror::Error)]
pub enum BeliefServeError {
    #[error("result: {0}")]
    Result(String),
    #[error("prior cluster {cluster} of {user}'s belief: the user models hold {count}")]
    PriorCluster {
        user: String,
        cluster: usize,
        count: usize,
    },
    #[error("{user}'s belief: {reason}")]
    Belief { user: String, reason: String },
    #[error(
        "learned in memory, but its file could not be written (tried again after the next sequence): {0}"
    )]
    Save(FileError),
}

/// How the node's beliefs are made and planned on.
#[derive(Debug, Clone)]
pub struct BeliefSettings {
    /// The prior covariance learned offline (`child_belief::prior_file`).
    pub covariance: LearnedCovariance,
    pub own_model: OwnModelParams,
    pub rule: PlanningRule,
    pub learning: Learning,
    /// Every draw (the guard's models, the baseline's ties) is keyed by it.
    pub seed: u64,
}

/// One decision planned on a child's belief, with what the belief said.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedDecision {
    pub decision: BeliefDecision,
    pub levels: [LevelBelief; 3],
    pub observations: usize,
    /// e.g. "belief of u1 (12 sequences, prior cluster 0, q_tables/belief_u1.json)".
    pub described: String,
}

struct ChildBelief {
    path: PathBuf,
    file: BeliefFile,
    policy: BeliefPolicy<OwnModel>,
    session: Option<String>,
    /// The last save failed: the file is behind memory until a save succeeds.
    unsaved: bool,
}

/// Every child's belief opened so far.
pub struct ChildBeliefs {
    dir: PathBuf,
    settings: BeliefSettings,
    /// Per cluster, its user model: the prior mean of a child first seen in it.
    priors: Vec<UserModelTable>,
    children: BTreeMap<String, ChildBelief>,
}

impl std::fmt::Debug for ChildBeliefs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ChildBeliefs")
            .field("dir", &self.dir)
            .field("rule", &self.settings.rule)
            .field("children", &self.children.keys().collect::<Vec<_>>())
            .finish()
    }
}

/// The belief file of `user_id` in `dir`, if the id can name a file (the per-user Q-tables'
/// rule, `QTableOwner`).
pub fn belief_file(dir: &Path, user_id: &str) -> Option<PathBuf> {
    QTableOwner::User(user_id.to_string())
        .file_name()
        .ok()
        .map(|_| dir.join(format!("belief_{user_id}.json")))
}

impl ChildBeliefs {
    pub fn new(dir: &Path, settings: BeliefSettings, priors: Vec<UserModelTable>) -> Self {
        ChildBeliefs {
            dir: dir.to_path_buf(),
            settings,
            priors,
            children: BTreeMap::new(),
        }
    }

    /// Whether `user_id` gets a belief: an id that can name a file.
    pub fn serves(&self, user_id: &str) -> bool {
        belief_file(&self.dir, user_id).is_some()
    }

    /// The child's belief, opened from their file or made new from cluster `k`'s model.
    fn child(&mut self, user_id: &str, k: usize) -> Result<&mut ChildBelief, BeliefServeError> {
        if !self.children.contains_key(user_id) {
            let path = belief_file(&self.dir, user_id).ok_or_else(|| BeliefServeError::Belief {
                user: user_id.into(),
                reason: "the id cannot name a file".into(),
            })?;
            let opened = match self.open(&path, user_id) {
                Ok(Some(child)) => child,
                Ok(None) => self.make(path, user_id, k)?,
                Err(reason) => {
                    let aside = move_aside(&path);
                    tracing::error!(user = user_id, file = %path.display(),
                        "belief file refused: {reason}. The child is treated as new; the file \
                         is kept as {}", aside.as_deref().map_or_else(
                            |e| format!("is (moving it failed: {e})"),
                            |p| p.display().to_string()));
                    self.make(path, user_id, k)?
                }
            };
            tracing::info!(user = user_id, file = %opened.path.display(),
                observations = opened.file.observations.len(),
                prior_cluster = opened.file.prior_cluster, "child belief ready");
            self.children.insert(user_id.to_string(), opened);
        }
        self.children
            .get_mut(user_id)
            .ok_or_else(|| BeliefServeError::Belief {
                user: user_id.into(),
                reason: "not opened".into(),
            })
    }

    /// `Ok(None)`: no file. `Err`: a file that cannot be used, and why.
    fn open(&self, path: &Path, user_id: &str) -> Result<Option<ChildBelief>, String> {
        if !path.exists() {
            return Ok(None);
        }
        let file: BeliefFile = BELIEF_FILE.load(path).map_err(|e| e.to_string())?;
        if file.user_id != user_id {
            return Err(format!(
                "it is {:?}'s belief, not {user_id:?}'s",
                file.user_id
            ));
        }
        let mut child = self
            .make(path.to_path_buf(), user_id, file.prior_cluster)
            .map_err(|e| e.to_string())?;
        for (i, o) in file.observations.iter().enumerate() {
            let observation = o
                .observation()
                .map_err(|e| format!("observations[{i}]: {e}"))?;
            child.policy.observe(&observation);
        }
        child.file = file;
        Ok(Some(child))
    }

    fn make(
        &self,
        path: PathBuf,
        user_id: &str,
        prior_cluster: usize,
    ) -> Result<ChildBelief, BeliefServeError> {
        let prior = self
            .priors
            .get(prior_cluster)
            .ok_or(BeliefServeError::PriorCluster {
                user: user_id.into(),
                cluster: prior_cluster,
                count: self.priors.len(),
            })?;
        let s = &self.settings;
        let model = OwnModel::with_covariance(prior, &s.covariance, s.own_model).map_err(|e| {
            BeliefServeError::Belief {
                user: user_id.into(),
                reason: e.to_string(),
            }
        })?;
        Ok(ChildBelief {
            path,
            file: BeliefFile {
                format: BELIEF_FILE.format.into(),
                version: BELIEF_FILE.version,
                user_id: user_id.into(),
                prior_cluster,
                observations: Vec::new(),
            },
            policy: BeliefPolicy::new(model, None, s.learning, s.rule),
            session: None,
            unsaved: false,
        })
    }

    /// The decision for `user_id` at `state` and `step` of `session_id`, planned on their
    /// belief near `table` (the Q-table that would decide for them); `k`: their cluster now,
    /// the prior of a child first seen.
    #[allow(clippy::too_many_arguments)]
    pub fn decide(
        &mut self,
        user_id: &str,
        session_id: &str,
        k: usize,
        table: &QTable,
        state: State,
        step: u8,
    ) -> Result<PlannedDecision, BeliefServeError> {
        let seed = self.settings.seed;
        let child = self.child(user_id, k)?;
        let session_key = stable_id_hash(user_id) ^ stable_id_hash(session_id).rotate_left(17);
        if child.session.as_deref() != Some(session_id) {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ session_key);
            child.policy.start_session(&mut rng);
            child.session = Some(session_id.to_string());
        }
        child.policy.set_baseline(Some(Baseline::of_table(table)));
        // Each decision's draws keyed by (seed, child, session, step): the same seed and bag
        // give the same decisions, whatever came before in the node's life.
        let mut rng =
            ChaCha8Rng::seed_from_u64(seed ^ session_key ^ u64::from(step).rotate_left(40));
        let u = rng.random::<f64>();
        let decision = child.policy.decide(state, step, u, &mut rng);
        let belief = child.policy.belief();
        let observations = belief.observations();
        Ok(PlannedDecision {
            decision,
            levels: child_belief::level_summary(&belief.predictive()),
            observations,
            described: format!(
                "belief of {user_id} ({observations} sequences, prior cluster {}, {})",
                child.file.prior_cluster,
                child.path.display()
            ),
        })
    }

    /// Learns one of the child's results into their belief and writes their file; false when
    /// that sequence was learned already (sent again after a restart). `k`: their cluster now
    /// (the prior of a child first seen).
    pub fn learn(&mut self, r: &SequenceResult, k: usize) -> Result<bool, BeliefServeError> {
        let state = r
            .state
            .to_state()
            .map_err(|e| BeliefServeError::Result(format!("state: {}", e.reason)))?;
        let input = model_input(r.level, r.feedback, state.previous_score)
            .map_err(BeliefServeError::Result)?;
        let observed = ObservedSequence {
            session_id: r.session_id.clone(),
            sequence_index: r.sequence_index,
            level: input.level.get(),
            feedback: input.feedback as u8,
            previous_score: input.previous_score,
            outcome: r.outcome,
            engagement: r.seen_engagement(),
        };
        let observation = observed.observation().map_err(BeliefServeError::Result)?;
        let child = self.child(&r.user_id, k)?;
        if child
            .file
            .observations
            .iter()
            .any(|o| o.session_id == r.session_id && o.sequence_index == r.sequence_index)
        {
            return Ok(false);
        }
        child.policy.observe(&observation);
        child.file.observations.push(observed);
        match BELIEF_FILE.save(&child.path, &child.file) {
            Ok(()) => {
                child.unsaved = false;
                Ok(true)
            }
            Err(e) => {
                child.unsaved = true;
                Err(BeliefServeError::Save(e))
            }
        }
    }

    /// Children whose file is behind their belief in memory (a failed write).
    pub fn unsaved(&self) -> impl Iterator<Item = &str> {
        self.children
            .iter()
            .filter(|(_, c)| c.unsaved)
            .map(|(id, _)| id.as_str())
    }
}

/// Moves an unusable belief file to `<file>.damaged` (or `.damaged.2`, ...): kept for
/// whoever wants to look, out of the way of the new belief.
fn move_aside(path: &Path) -> std::io::Result<PathBuf> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut aside = path.with_file_name(format!("{name}.damaged"));
    let mut n = 2;
    while aside.exists() {
        aside = path.with_file_name(format!("{name}.damaged.{n}"));
        n += 1;
    }
    atomic_file::rename(path, &aside)?;
    Ok(aside)
}

#[cfg(test)]
mod tests;
