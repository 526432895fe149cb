//! The node's parameters (`params/behaviour_policy.yaml`, ROS 2 form) and their checks. The
//! defaults are the authors' constants, so the yaml, this struct and `Learning::default()`
//! say the same thing (a test holds them together); the learning constants are checked where
//! every `Learning` is made (`q_learning::LearningConstants`).

use child_belief::planner::{GuardTest, PlanningRule};
use q_learning::learning::{Learning, LearningConstants, MAX_EPSILON, Mode, Reward};

/// The behaviour policy node's parameters (each key's meaning at length:
/// `params/behaviour_policy.yaml`).
#[derive(
    Debug,
    Clone,
    PartialEq,
    serde::Deserialize,
    serde::Serialize,
    node_shell::parameters::DescribedParameters,
)]
#[serde(deny_unknown_fields, default)]
pub struct BehaviourPolicyParams {
    /// User models (clusters) the Q-tables belong to.
    pub user_model_file: String,
    /// Directory of the Q-tables, cluster_<k>.json (and user_<id>.json), saved after every
    /// learned sequence; locked while the node runs.
    pub q_table_dir: String,
    /// true: every user also gets a table of their own, made from their cluster's at their
    /// first decision.
    pub per_user_q_tables: bool,
    /// A cluster without a file gets one pretrained in simulation: epochs (x 100 sessions)
    /// per run.
    pub pretrain_epochs: i64,
    /// Pretraining: independent runs; the best over its last epoch is kept.
    pub pretrain_runs: i64,
    /// Pretraining state: false = PS is the latest result; true = the authors' one-step lag.
    pub pretrain_state_lags_result: bool,
    /// Real sessions: greedy actions (ties broken at random), still learning; false: softmax.
    pub exploitation_only: bool,
    /// With `exploitation_only`: the share ε of decisions drawn uniformly from the allowed
    /// actions instead of greedily (0: greedy, the default; at most `MAX_EPSILON`).
    pub exploration_epsilon: f64,
    /// Seed of every random draw (softmax, ties, pretraining).
    pub seed: i64,
    /// Cluster used when the therapist did not choose one (-1 in the command).
    pub default_cluster: i64,
    /// Reward F_r: "RE", "RE+bE" or "lE".
    pub reward: String,
    /// Learning rate alpha.
    pub alpha: f64,
    /// Discount gamma.
    pub gamma: f64,
    /// Softmax temperature of an unvisited state.
    pub initial_temperature: f64,
    /// The temperature never falls below this.
    pub min_temperature: f64,
    /// The temperature falls by this per counted visit of the state.
    pub temperature_decay: f64,
    /// Weight beta of engagement in RE + beta E.
    pub beta: f64,
    /// Weight lambda of engagement in lambda E.
    pub lambda: f64,
    /// How long a decision request waits for the result it follows (`after_sequence`) before
    /// it is refused, in seconds.
    pub result_wait_s: f64,
    /// true: each child's decisions are planned on a belief about them (their own model around
    /// their cluster's, learned from their answers and engagement), near the table that would
    /// decide for them; kept as belief_<id>.json in q_table_dir.
    pub child_belief: bool,
    /// The prior covariance of a child's own model (`policy_lab child-belief-prior`).
    pub child_belief_prior_file: String,
    /// The guard: the plan leaves the table only where its advantage over the table, over
    /// models drawn from the belief, is positive on average and, in all but a share
    /// `child_belief_risk` of them, loses at most what is left of this much of the session's
    /// return against the table.
    pub child_belief_margin: f64,
    /// The share of drawn models allowed past the margin.
    pub child_belief_risk: f64,
    /// Models drawn from the belief to judge a deviation from the table.
    pub child_belief_guard_samples: i64,
}

impl Default for BehaviourPolicyParams {
    fn default() -> Self {
        let l = LearningConstants::default();
        BehaviourPolicyParams {
            user_model_file: "nodes/user_model/models/migrave_study_c2.json".into(),
            q_table_dir: "out/q_tables".into(),
            per_user_q_tables: false,
            pretrain_epochs: 100,
            pretrain_runs: 5,
            pretrain_state_lags_result: false,
            exploitation_only: true,
            exploration_epsilon: 0.0,
            seed: 7,
            default_cluster: 0,
            reward: Reward::RePlusBetaE.name().into(),
            alpha: l.alpha,
            gamma: l.gamma,
            initial_temperature: l.initial_temperature,
            min_temperature: l.min_temperature,
            temperature_decay: l.temperature_decay,
            beta: l.beta,
            lambda: l.lambda,
            result_wait_s: 1.0,
            child_belief: false,
            child_belief_prior_file: "nodes/behaviour_policy/models/child_belief_prior_c2.json"
                .into(),
            child_belief_margin: 0.5,
            child_belief_risk: 0.1,
            child_belief_guard_samples: 64,
        }
    }
}

/// A parameter with a value the policy cannot use.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("parameter {key}: {reason}")]
pub struct ParamError {
    pub key: &'static str,
    pub reason: String,
}

fn check(key: &'static str, ok: bool, reason: impl FnOnce() -> String) -> Result<(), ParamError> {
    if ok {
        Ok(())
    } else {
        Err(ParamError {
            key,
            reason: reason(),
        })
    }
}

impl BehaviourPolicyParams {
    /// The learning constants, checked.
    pub fn learning(&self) -> Result<Learning, ParamError> {
        let reward = Reward::parse(&self.reward).ok_or_else(|| ParamError {
            key: "reward",
            reason: format!("{:?} is not RE, RE+bE or lE", self.reward),
        })?;
        let learning = LearningConstants {
            alpha: self.alpha,
            gamma: self.gamma,
            initial_temperature: self.initial_temperature,
            min_temperature: self.min_temperature,
            temperature_decay: self.temperature_decay,
            beta: self.beta,
            lambda: self.lambda,
        }
        .learning(reward)
        .map_err(|e| ParamError {
            key: e.key,
            reason: e.reason,
        })?;
        // Checked with the constants, at start-up: how actions are picked is as much part of
        // what the node was asked to do.
        self.exploration()?;
        Ok(learning)
    }

    /// How actions are picked, checked: softmax (`exploitation_only: false`), greedy, or
    /// greedy with logged exploration (`exploration_epsilon` above 0).
    pub fn exploration(&self) -> Result<Mode, ParamError> {
        let e = self.exploration_epsilon;
        check(
            "exploration_epsilon",
            e.is_finite() && (0.0..=MAX_EPSILON).contains(&e),
            || format!("{e} is not in [0, {MAX_EPSILON}]"),
        )?;
        check(
            "exploration_epsilon",
            e == 0.0 || self.exploitation_only,
            || {
                format!(
                    "{e} needs exploitation_only: true (the softmax explores by itself; ε \
                     explores around the greedy choice)"
                )
            },
        )?;
        Ok(match (self.exploitation_only, e > 0.0) {
            (false, _) => Mode::Explore,
            (true, false) => Mode::Exploit,
            (true, true) => Mode::EpsilonGreedy(e),
        })
    }

    /// [`Self::exploration`], once [`Self::learning`] has checked it (as the node does at
    /// start-up); a value that fails the check gives the greedy mode.
    pub fn mode(&self) -> Mode {
        self.exploration().unwrap_or(Mode::Exploit)
    }

    pub fn seed(&self) -> u64 {
        // Negative seeds (YAML integers are signed) are as good as any: keep the bits.
        self.seed as u64
    }

    /// The longest wait for a request's result, in ns: under the game manager's deadline for
    /// the whole call (2 s), so a refusal reaches it in time.
    pub fn result_wait_ns(&self) -> Result<i64, ParamError> {
        check(
            "result_wait_s",
            self.result_wait_s.is_finite() && (0.0..=30.0).contains(&self.result_wait_s),
            || format!("{} is not in [0, 30] s", self.result_wait_s),
        )?;
        Ok((self.result_wait_s * 1e9).round() as i64)
    }

    /// The planning rule of `child_belief`, checked (also when it is off, so a bad value is
    /// found before it is turned on): it plans greedily on the belief, so neither the softmax
    /// nor ε may explore beside it.
    pub fn child_belief_rule(&self) -> Result<PlanningRule, ParamError> {
        let (margin, risk) = (self.child_belief_margin, self.child_belief_risk);
        check(
            "child_belief_margin",
            margin.is_finite() && (0.0..=100.0).contains(&margin),
            || format!("{margin} is not in [0, 100] (the session's return)"),
        )?;
        check(
            "child_belief_risk",
            risk.is_finite() && (0.0..1.0).contains(&risk),
            || format!("{risk} is not in [0, 1)"),
        )?;
        let samples = usize::try_from(self.child_belief_guard_samples)
            .ok()
            .filter(|n| (2..=1024).contains(n));
        let samples = samples.ok_or_else(|| ParamError {
            key: "child_belief_guard_samples",
            reason: format!("{} is not in [2, 1024]", self.child_belief_guard_samples),
        })?;
        check(
            "child_belief",
            !self.child_belief || self.mode() == Mode::Exploit,
            || {
                "needs exploitation_only: true and exploration_epsilon: 0 (the belief's plan \
                 decides; the guard bounds its departures from the table)"
                    .into()
            },
        )?;
        Ok(PlanningRule::Guarded {
            test: GuardTest::Chance { margin, risk },
            samples,
        })
    }

    pub fn pretraining(&self) -> Result<(usize, usize), ParamError> {
        let epochs = usize::try_from(self.pretrain_epochs)
            .ok()
            .filter(|e| *e > 0);
        let runs = usize::try_from(self.pretrain_runs).ok().filter(|r| *r > 0);
        match (epochs, runs) {
            (Some(e), Some(r)) => Ok((e, r)),
            (None, _) => Err(ParamError {
                key: "pretrain_epochs",
                reason: format!("{} must be at least 1", self.pretrain_epochs),
            }),
            (_, None) => Err(ParamError {
                key: "pretrain_runs",
                reason: format!("{} must be at least 1", self.pretrain_runs),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_yaml_file_says_what_default_says() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../params/behaviour_policy.yaml");
        let from_file: BehaviourPolicyParams =
            node_shell::params::load_parameters(&path, "behaviour_policy").expect("yaml");
        assert_eq!(from_file, BehaviourPolicyParams::default());
        let mut l = from_file.learning().expect("valid");
        assert_eq!(l.reward, Reward::RePlusBetaE);
        l.reward = Reward::Re;
        assert_eq!(l, Learning::default());
    }

    #[test]
    fn bad_values_are_named() {
        let p = BehaviourPolicyParams {
            reward: "RE+E".into(),
            ..Default::default()
        };
        assert_eq!(p.learning().expect_err("reward").key, "reward");
        for (p, key) in [
            (
                BehaviourPolicyParams {
                    alpha: f64::NAN,
                    ..Default::default()
                },
                "alpha",
            ),
            (
                BehaviourPolicyParams {
                    gamma: 1.5,
                    ..Default::default()
                },
                "gamma",
            ),
            (
                BehaviourPolicyParams {
                    min_temperature: 0.0,
                    ..Default::default()
                },
                "min_temperature",
            ),
        ] {
            assert_eq!(p.learning().expect_err(key).key, key);
        }
        let p = BehaviourPolicyParams {
            pretrain_runs: 0,
            ..Default::default()
        };
        assert_eq!(p.pretraining().expect_err("runs").key, "pretrain_runs");
    }

    #[test]
    fn exploration_is_off_by_default_bounded_and_only_around_the_greedy_choice() {
        let p = BehaviourPolicyParams::default();
        assert_eq!(p.exploration(), Ok(Mode::Exploit));
        assert_eq!(p.mode(), Mode::Exploit);
        let with = |exploitation_only, exploration_epsilon| BehaviourPolicyParams {
            exploitation_only,
            exploration_epsilon,
            ..Default::default()
        };
        assert_eq!(with(true, 0.1).exploration(), Ok(Mode::EpsilonGreedy(0.1)));
        assert_eq!(with(true, 0.1).mode(), Mode::EpsilonGreedy(0.1));
        assert_eq!(with(false, 0.0).exploration(), Ok(Mode::Explore));
        for (p, words) in [
            (with(true, MAX_EPSILON + 0.01), "is not in [0, 0.3]"),
            (with(true, -0.1), "is not in [0, 0.3]"),
            (with(true, f64::NAN), "is not in [0, 0.3]"),
            (with(false, 0.1), "needs exploitation_only: true"),
        ] {
            let e = p.learning().expect_err("refused at start-up");
            assert_eq!(e.key, "exploration_epsilon");
            assert!(e.to_string().contains(words), "{e}");
            assert_eq!(p.mode(), Mode::Exploit, "never explores on a refused value");
        }
    }

    #[test]
    fn the_child_belief_is_off_by_default_and_refuses_exploration_beside_it() {
        let p = BehaviourPolicyParams::default();
        assert!(!p.child_belief);
        assert!(p.child_belief_rule().is_ok());
        let on = |exploitation_only, exploration_epsilon| BehaviourPolicyParams {
            child_belief: true,
            exploitation_only,
            exploration_epsilon,
            ..Default::default()
        };
        assert!(on(true, 0.0).child_belief_rule().is_ok());
        for p in [on(false, 0.0), on(true, 0.1)] {
            let e = p.child_belief_rule().expect_err("refused");
            assert_eq!(e.key, "child_belief");
            assert!(
                e.to_string().contains("needs exploitation_only: true"),
                "{e}"
            );
        }
        for (p, key) in [
            (
                BehaviourPolicyParams {
                    child_belief_margin: f64::NAN,
                    ..Default::default()
                },
                "child_belief_margin",
            ),
            (
                BehaviourPolicyParams {
                    child_belief_risk: 1.0,
                    ..Default::default()
                },
                "child_belief_risk",
            ),
            (
                BehaviourPolicyParams {
                    child_belief_guard_samples: 1,
                    ..Default::default()
                },
                "child_belief_guard_samples",
            ),
        ] {
            assert_eq!(p.child_belief_rule().expect_err(key).key, key);
        }
    }
}
