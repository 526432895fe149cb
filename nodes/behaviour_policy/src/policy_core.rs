//! The behaviour-policy node's core, sans-IO: answers `DecideAction` with an explained
//! `Decision` (all Q-values, probabilities, temperature, explored or not), refuses feedback on
//! the first sequence, learns online from every `SequenceResult`, and saves the cluster's
//! Q-table atomically after each update.

use crate::learning::{Learning, Mode, QTable, Reward};
use crate::q_table_file::{QTableError, QTableFile};
use qt_therapy_msgs::{
    BehaviourState, DecideActionRequest, Decision, SequenceResult, std_msgs::Header,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sequence_game::{Action, State, UserModelTable};
use std::path::{Path, PathBuf};

/// Parameters of the node (`params/behaviour_policy.yaml`).
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PolicyParams {
    pub user_model_file: String,
    pub q_table_dir: String,
    pub exploitation_only: bool,
    pub seed: i64,
    pub default_cluster: i64,
    pub reward: String,
    pub alpha: f64,
    pub gamma: f64,
    pub initial_temperature: f64,
    pub min_temperature: f64,
    pub temperature_decay: f64,
    pub beta: f64,
    pub lambda: f64,
    pub pretrain_epochs: i64,
}

impl Default for PolicyParams {
    fn default() -> Self {
        PolicyParams {
            user_model_file: "nodes/user_model/models/migrave_study_c2.json".into(),
            q_table_dir: "out/q_tables".into(),
            exploitation_only: true,
            seed: 7,
            default_cluster: 0,
            reward: "RE+bE".into(),
            alpha: 0.05,
            gamma: 0.95,
            initial_temperature: 300.0,
            min_temperature: 0.5,
            temperature_decay: 5.0,
            beta: 3.0,
            lambda: 3.0,
            pretrain_epochs: 100,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum PolicyError {
    #[error("parameter {key}: {reason}")]
    Parameter { key: &'static str, reason: String },
    #[error("unknown user model cluster {cluster}: the policy holds {count}")]
    UnknownCluster { cluster: i64, count: usize },
    #[error("state {0}")]
    State(String),
    #[error("engagement {0} is not a number in [-1, 1]")]
    Engagement(f32),
    #[error(transparent)]
    QTable(#[from] QTableError),
}

impl PolicyParams {
    pub fn learning(&self) -> Result<Learning, PolicyError> {
        let reward = Reward::parse(&self.reward).ok_or_else(|| PolicyError::Parameter {
            key: "reward",
            reason: format!("{:?} is not RE, RE+bE or lE", self.reward),
        })?;
        let positive = |key, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(PolicyError::Parameter {
                    key,
                    reason: format!("{v} must be positive"),
                })
            }
        };
        positive("alpha", self.alpha)?;
        positive("initial_temperature", self.initial_temperature)?;
        positive("min_temperature", self.min_temperature)?;
        if !(0.0..=1.0).contains(&self.gamma) {
            return Err(PolicyError::Parameter {
                key: "gamma",
                reason: format!("{} is outside [0, 1]", self.gamma),
            });
        }
        Ok(Learning {
            alpha: self.alpha,
            gamma: self.gamma,
            initial_temperature: self.initial_temperature,
            min_temperature: self.min_temperature,
            temperature_decay: self.temperature_decay,
            beta: self.beta,
            lambda: self.lambda,
            reward,
            // The live game reports the result it just saw.
            state_lags_result: false,
        })
    }
}

/// One cluster's live policy.
struct ClusterPolicy {
    file: QTableFile,
    path: PathBuf,
}

/// The node's core.
pub struct PolicyCore {
    clusters: Vec<ClusterPolicy>,
    learning: Learning,
    mode: Mode,
    default_cluster: i64,
    rng: ChaCha8Rng,
}

impl PolicyCore {
    /// Loads each cluster's Q-table from `q_table_dir/cluster_<k>.json`, or pretrains one in
    /// simulation against that cluster's user model (and saves it) when there is none.
    pub fn new(
        params: &PolicyParams,
        models: &[UserModelTable],
        base: &Path,
    ) -> Result<PolicyCore, PolicyError> {
        let learning = params.learning()?;
        let dir = base.join(&params.q_table_dir);
        let mut clusters = Vec::new();
        for (k, model) in models.iter().enumerate() {
            let path = dir.join(format!("cluster_{k}.json"));
            let file = if path.exists() {
                QTableFile::load(&path)?
            } else {
                let epochs = usize::try_from(params.pretrain_epochs).unwrap_or(0);
                let run = crate::experiments::train_run(
                    model,
                    &learning,
                    Mode::Explore,
                    QTable::default(),
                    epochs,
                    100,
                    crate::experiments::run_seed(params.seed as u64, k, 0),
                );
                let f = QTableFile::new(
                    &format!("cluster {k}"),
                    &format!(
                        "pretrained in simulation: {epochs} epochs x 100 sessions, reward {}, against {}",
                        learning.reward.name(),
                        params.user_model_file
                    ),
                    run.q_table,
                );
                f.save(&path)?;
                f
            };
            clusters.push(ClusterPolicy { file, path });
        }
        Ok(PolicyCore {
            clusters,
            learning,
            mode: if params.exploitation_only {
                Mode::Exploit
            } else {
                Mode::Explore
            },
            default_cluster: params.default_cluster,
            rng: ChaCha8Rng::seed_from_u64(params.seed as u64),
        })
    }

    fn cluster_index(&self, cluster: i32) -> Result<usize, PolicyError> {
        let c = if cluster < 0 {
            self.default_cluster
        } else {
            i64::from(cluster)
        };
        usize::try_from(c)
            .ok()
            .filter(|c| *c < self.clusters.len())
            .ok_or(PolicyError::UnknownCluster {
                cluster: c,
                count: self.clusters.len(),
            })
    }

    /// The next action for a (validated) request.
    pub fn decide(
        &mut self,
        request: &DecideActionRequest,
        header: Header,
    ) -> Result<Decision, PolicyError> {
        let k = self.cluster_index(request.user_model_cluster)?;
        let state = request
            .state
            .to_state()
            .map_err(|e| PolicyError::State(e.reason))?;
        // The first sequence has no context for feedback: only the start state's actions.
        let state = if request.step == 1 {
            State::START
        } else {
            state
        };
        let policy = &self.clusters[k];
        let choice = policy
            .file
            .table
            .choose(state, self.mode, &self.learning, &mut self.rng);
        let (level, feedback) = choice
            .action
            .apply(state)
            .ok_or_else(|| PolicyError::State(format!("{state} allows no {}", choice.action)))?;
        Ok(Decision {
            header,
            session_id: request.session_id.clone(),
            step: request.step,
            state: BehaviourState::from_state(state),
            action: choice.action.index() as u8,
            level: level.get(),
            feedback: feedback as u8,
            q_values: choice.q_values.to_vec(),
            probabilities: choice.probabilities.to_vec(),
            temperature: choice.temperature,
            explored: choice.explored,
            exploitation_only: self.mode == Mode::Exploit,
            model_used: format!(
                "cluster {k} ({}, {} updates)",
                policy.path.display(),
                policy.file.updates
            ),
        })
    }

    /// Learns from one played sequence and saves the Q-table.
    pub fn learn(&mut self, result: &SequenceResult) -> Result<(), PolicyError> {
        let k = self.cluster_index(result.user_model_cluster)?;
        if !(result.engagement.is_finite() && (-1.0..=1.0).contains(&result.engagement)) {
            return Err(PolicyError::Engagement(result.engagement));
        }
        let state = result
            .state
            .to_state()
            .map_err(|e| PolicyError::State(e.reason))?;
        let action =
            Action::new(result.action.into()).map_err(|e| PolicyError::State(e.to_string()))?;
        let next = State::new(
            result.level.into(),
            result.feedback.into(),
            i64::from(result.level) * i64::from(result.outcome),
        )
        .map_err(|e| PolicyError::State(e.to_string()))?;
        // No face was seen: E is unknown, so it counts as neutral (0) and only RE speaks.
        let engagement = if result.engagement_per_second.is_empty() {
            0.0
        } else {
            f64::from(result.engagement)
        };
        let reward = self
            .learning
            .reward(f64::from(result.activity_result), engagement);
        let policy = &mut self.clusters[k];
        policy.file.table.update(
            state,
            action,
            reward,
            next,
            result.sequence_index >= 10,
            &self.learning,
        );
        policy.file.updates += 1;
        policy.file.save(&policy.path)?;
        Ok(())
    }
}
