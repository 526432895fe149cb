//! Decisions planned on a belief about the child: backward induction over the rest of the
//! session on the belief's predictive model (64 states, the actions the mask allows, ten
//! sequences), so the plan is the best the belief expects. With a baseline policy (the
//! cluster's table, greedy), an action the baseline would not take pays a caution of κ times
//! the belief's standard deviation of its expected reward: the plan leaves the baseline only
//! where the belief expects a gain larger than its own uncertainty, and follows it where the
//! belief knows little (safe policy improvement over the baseline, as SPIBB bootstraps it).

use crate::{Belief, Observation};
use q_learning::learning::{Learning, QTable, allowed_at, greedy_set, nth_member};
use q_learning::mdp::transition;
use q_learning::simulation::SessionDraws;
use rand_chacha::ChaCha8Rng;
use sequence_game::user_model_table::SUCCESS_INPUTS;
use sequence_game::{
    Action, ModelInput, Outcome, SEQUENCES_PER_SESSION, STATE_COUNT, State, UserModelTable,
};

/// The baseline policy: a Q-table's greedy actions within the mask (greedy ties all count as
/// the baseline's).
#[derive(Debug, Clone, PartialEq)]
pub struct Baseline {
    rows: [[f64; sequence_game::ACTION_COUNT]; STATE_COUNT],
}

impl Baseline {
    pub fn of_table(table: &QTable) -> Self {
        Baseline { rows: table.q }
    }

    fn greedy(&self, state: State, step: u8) -> (u8, u32) {
        greedy_set(&self.rows[state.index()], allowed_at(state, step))
    }

    /// Whether `action` is one of the baseline's greedy actions at `state` (from the second
    /// sequence on: in the start state, among a1..a3).
    pub fn takes(&self, state: State, action: Action) -> bool {
        let step = if state.is_start() { 1 } else { 2 };
        self.greedy(state, step).0 & (1 << action.index()) != 0
    }

    /// The baseline's own choice at `state` for the sequence `step`: its greedy action, a tie
    /// broken by the uniform `u` as the simulator breaks it (the k-th of n equal slices of
    /// [0, 1)), so that on the same draws it plays exactly the cluster policy's sessions.
    pub fn action(&self, state: State, step: u8, u: f64) -> Action {
        let (set, n) = self.greedy(state, step);
        let k = if n > 1 { SessionDraws::tie_of(u, n) } else { 0 };
        Action::ALL[nth_member(set, k)]
    }
}

/// What the plan knows of one input: the expected reward after each outcome, P(success), and
/// the belief's standard deviation of the expected reward.
#[derive(Debug, Clone, Copy, Default)]
struct InputValue {
    success: f64,
    reward: [f64; 2],
    reward_sd: f64,
}

fn input_values(model: &UserModelTable, learning: &Learning) -> [InputValue; SUCCESS_INPUTS] {
    let mut out = [InputValue::default(); SUCCESS_INPUTS];
    for input in ModelInput::all() {
        let s = model.success(input);
        let p = s.mean.clamp(0.0, 1.0);
        let ef = model.engagement(input, Outcome::Failure);
        let es = model.engagement(input, Outcome::Success);
        let reward = Outcome::ALL.map(|o| {
            let e = model.engagement(input, o).mean.clamp(-1.0, 1.0);
            learning.reward(o.activity_result(input.level), e)
        });
        // d E[r] / dP = r(success) − r(failure); d E[r] / dE_o = P(o) dr/dE (dr/dE: the
        // reward's weight on engagement, read off the reward function).
        let per_engagement = learning.reward(0.0, 1.0) - learning.reward(0.0, 0.0);
        let var = (s.std * (reward[1] - reward[0])).powi(2)
            + (per_engagement * p * es.std).powi(2)
            + (per_engagement * (1.0 - p) * ef.std).powi(2);
        out[input.index()] = InputValue {
            success: p,
            reward,
            reward_sd: var.sqrt(),
        };
    }
    out
}

/// A plan for the rest of a session: per sequence and state the action, and the value the
/// belief expects from there (with the caution paid).
#[derive(Debug, Clone, PartialEq)]
pub struct BeliefPlan {
    actions: [[u8; STATE_COUNT]; SEQUENCES_PER_SESSION],
    values: [[f64; STATE_COUNT]; SEQUENCES_PER_SESSION],
}

impl BeliefPlan {
    /// The planned action for the sequence `step` (1-based) from `state`.
    pub fn action(&self, state: State, step: u8) -> Action {
        let k = usize::from(step.clamp(1, SEQUENCES_PER_SESSION as u8)) - 1;
        Action::ALL[usize::from(self.actions[k][state.index()])]
    }

    /// The value the belief expects from `state` at `step` on.
    pub fn value(&self, state: State, step: u8) -> f64 {
        let k = usize::from(step.clamp(1, SEQUENCES_PER_SESSION as u8)) - 1;
        self.values[k][state.index()]
    }
}

/// Backward induction on `model` from sequence `from_step` to the session's end (the earlier
/// sequences are left as the baseline's, or a1): among the allowed actions the one with the
/// best expected return, less `caution` times its reward's standard deviation for an action
/// the `baseline` would not take; among equals the baseline's, then the lowest-numbered.
pub fn plan(
    model: &UserModelTable,
    learning: &Learning,
    baseline: Option<&Baseline>,
    caution: f64,
    from_step: u8,
) -> BeliefPlan {
    plan_within(model, learning, baseline, caution, from_step, |_, _, _| {
        true
    })
}

/// As [`plan`], but an action the `baseline` would not take is open to the plan at (state,
/// step) only where `may_leave(state, step, its input)` says so (SPIBB's bootstrapped set: see
/// [`Evidence`]).
pub fn plan_within(
    model: &UserModelTable,
    learning: &Learning,
    baseline: Option<&Baseline>,
    caution: f64,
    from_step: u8,
    may_leave: impl Fn(State, u8, ModelInput) -> bool,
) -> BeliefPlan {
    let inputs = input_values(model, learning);
    let mut actions = [[0u8; STATE_COUNT]; SEQUENCES_PER_SESSION];
    let mut values = [[0.0; STATE_COUNT]; SEQUENCES_PER_SESSION];
    let mut next = [0.0; STATE_COUNT];
    let first = usize::from(from_step.max(1)) - 1;
    for k in (first..SEQUENCES_PER_SESSION).rev() {
        let step = k as u8 + 1;
        let mut now = [0.0; STATE_COUNT];
        for state in State::all() {
            let allowed = allowed_at(state, step);
            let mut best: Option<(f64, bool, usize)> = None;
            for (a, action) in Action::ALL.iter().enumerate().take(allowed) {
                let Some((input, _)) = transition(state, *action, Outcome::Success) else {
                    continue;
                };
                let follows = baseline.is_none_or(|b| b.takes(state, *action));
                if !follows && !may_leave(state, step, input) {
                    continue;
                }
                let v = &inputs[input.index()];
                let mut q = 0.0;
                for outcome in Outcome::ALL {
                    let Some((_, after)) = transition(state, *action, outcome) else {
                        continue;
                    };
                    let po = match outcome {
                        Outcome::Success => v.success,
                        Outcome::Failure => 1.0 - v.success,
                    };
                    q += po * (v.reward[outcome.index()] + learning.gamma * next[after.index()]);
                }
                if !follows {
                    q -= caution * v.reward_sd;
                }
                let better = match best {
                    None => true,
                    Some((bq, bf, _)) => q > bq || (q == bq && follows && !bf),
                };
                if better {
                    best = Some((q, follows, a));
                }
            }
            if let Some((q, _, a)) = best {
                now[state.index()] = q;
                actions[k][state.index()] = a as u8;
            }
        }
        values[k] = now;
        next = now;
    }
    BeliefPlan { actions, values }
}

/// A deterministic policy over the rest of a session laid out for evaluation: per sequence
/// from `from_step` and state, the input its action sets up and the states after a wrong and
/// a right answer (`None` where the action is masked).
#[derive(Debug, Clone)]
pub struct CompiledPolicy {
    from_step: u8,
    steps: Vec<[Option<(u8, u8, u8)>; STATE_COUNT]>,
}

impl CompiledPolicy {
    pub fn new(from_step: u8, policy: impl Fn(State, u8) -> Action) -> Self {
        let first = usize::from(from_step.max(1)) - 1;
        let steps = (first..SEQUENCES_PER_SESSION)
            .map(|k| {
                let step = k as u8 + 1;
                let mut row = [None; STATE_COUNT];
                for state in State::all() {
                    let action = policy(state, step);
                    if action.index() >= allowed_at(state, step) {
                        continue;
                    }
                    let (Some((input, fail)), Some((_, success))) = (
                        transition(state, action, Outcome::Failure),
                        transition(state, action, Outcome::Success),
                    ) else {
                        continue;
                    };
                    row[state.index()] = Some((
                        input.index() as u8,
                        fail.index() as u8,
                        success.index() as u8,
                    ));
                }
                row
            })
            .collect();
        CompiledPolicy {
            from_step: from_step.max(1),
            steps,
        }
    }

    /// Its value on `model` from `state` at its first sequence to the session's end.
    pub fn value(&self, model: &UserModelTable, learning: &Learning, state: State) -> f64 {
        let inputs = input_values(model, learning);
        let mut next = [0.0; STATE_COUNT];
        for row in self.steps.iter().rev() {
            let mut now = [0.0; STATE_COUNT];
            for (s, cell) in row.iter().enumerate() {
                if let Some((input, fail, success)) = *cell {
                    let v = &inputs[usize::from(input)];
                    now[s] = v.success
                        * (v.reward[1] + learning.gamma * next[usize::from(success)])
                        + (1.0 - v.success)
                            * (v.reward[0] + learning.gamma * next[usize::from(fail)]);
                }
            }
            next = now;
        }
        next[state.index()]
    }

    pub fn from_step(&self) -> u8 {
        self.from_step
    }
}

/// How the guard judges a deviation from the baseline: on the plan's advantage A over the
/// baseline from this state to the session's end, under each model drawn from the belief.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GuardTest {
    /// mean(A) > κ sd(A): the gain must stand out from the belief's doubt about it.
    Sigma { caution: f64 },
    /// As `Sigma`, with κ falling as the child's sequences n accumulate: κ h / (h + n) (h:
    /// `half`, the sequences after which κ is halved).
    Fading { caution: f64, half: f64 },
    /// A chance constraint on the session's return: mean(A) > 0, and in all but a share
    /// `risk` of the drawn models the return the session loses against the baseline from
    /// here, γ^(step − 1) max(0, −A), is at most the session's margin left: `margin` less what
    /// the session's earlier deviations risked (each its loss at that same quantile).
    Chance { margin: f64, risk: f64 },
    /// Both: the gain must stand out from the doubt about it (`Sigma`'s κ) and the session's
    /// loss stay within its margin (`Chance`'s constraint). The first asks whether the
    /// deviation gains, the second bounds what one session may lose if it does not.
    SigmaChance {
        caution: f64,
        margin: f64,
        risk: f64,
    },
}

impl GuardTest {
    /// The test as it applies now: after `observations` sequences of the child, with `spent`
    /// of the session's margin risked already.
    pub fn threshold(&self, observations: usize, spent: f64) -> Threshold {
        match *self {
            GuardTest::Sigma { caution } => Threshold::Sigma(caution),
            GuardTest::Fading { caution, half } => {
                Threshold::Sigma(caution * half / (half + observations as f64))
            }
            GuardTest::Chance { margin, risk } => Threshold::Chance {
                margin: (margin - spent).max(0.0),
                risk,
            },
            GuardTest::SigmaChance {
                caution,
                margin,
                risk,
            } => Threshold::SigmaChance {
                caution,
                margin: (margin - spent).max(0.0),
                risk,
            },
        }
    }

    /// Whether its deviations spend the session's margin.
    pub fn spends_margin(&self) -> bool {
        matches!(
            self,
            GuardTest::Chance { .. } | GuardTest::SigmaChance { .. }
        )
    }
}

/// A guard test with its numbers for this decision.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Threshold {
    /// mean(A) > κ sd(A).
    Sigma(f64),
    /// mean(A) > 0 and the loss at the (1 − risk) quantile at most `margin`.
    Chance { margin: f64, risk: f64 },
    /// mean(A) > κ sd(A) and the loss at the (1 − risk) quantile at most `margin`.
    SigmaChance {
        caution: f64,
        margin: f64,
        risk: f64,
    },
}

/// What the guard found before leaving the baseline: the plan's advantage over the baseline
/// from this state to the session's end, its mean and standard deviation over the models
/// drawn from the belief.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Guard {
    pub advantage: f64,
    pub advantage_sd: f64,
    /// The mean over the models of the loss against the baseline, max(0, −advantage).
    pub expected_loss: f64,
    /// The session's return the deviation risks: γ^(step − 1) max(0, −A) at the chance
    /// test's quantile (at the largest loss drawn for the σ tests).
    pub risked_loss: f64,
    /// The test as applied.
    pub threshold: Threshold,
    /// The plan's action was played (else the baseline's).
    pub deviated: bool,
}

/// The plan's action at `state` and `step` where the baseline takes it too; elsewhere the
/// plan's action only if the plan's advantage over the baseline from here to the session's
/// end, over the `models` drawn from the belief, passes `threshold`; else the baseline's
/// (its tie broken by `u`).
#[allow(clippy::too_many_arguments)]
pub fn guarded_action(
    plan: &BeliefPlan,
    baseline: &Baseline,
    models: &[UserModelTable],
    learning: &Learning,
    state: State,
    step: u8,
    threshold: Threshold,
    u: f64,
) -> (Action, Option<Guard>) {
    let planned = plan.action(state, step);
    if baseline.takes(state, planned) {
        return (planned, None);
    }
    let planned_policy = CompiledPolicy::new(step, |s, k| plan.action(s, k));
    let baseline_policy = CompiledPolicy::new(step, |s, k| baseline.action(s, k, 0.0));
    let advantages: Vec<f64> = models
        .iter()
        .map(|m| {
            planned_policy.value(m, learning, state) - baseline_policy.value(m, learning, state)
        })
        .collect();
    let n = advantages.len().max(1) as f64;
    let mean = advantages.iter().sum::<f64>() / n;
    let sd = (advantages.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / n).sqrt();
    let expected_loss = advantages.iter().map(|a| (-a).max(0.0)).sum::<f64>() / n;
    // The session's return lost, discounted to the session's start, sorted.
    let discount = learning.gamma.powi(i32::from(step.max(1)) - 1);
    let mut losses: Vec<f64> = advantages
        .iter()
        .map(|a| discount * (-a).max(0.0))
        .collect();
    losses.sort_by(f64::total_cmp);
    let at_quantile = |q: f64| -> f64 {
        if losses.is_empty() {
            return f64::INFINITY;
        }
        let k = ((q * losses.len() as f64).ceil() as usize).clamp(1, losses.len()) - 1;
        losses[k]
    };
    let (deviated, risked_loss) = match threshold {
        Threshold::Sigma(caution) => (
            !advantages.is_empty() && mean > caution * sd,
            at_quantile(1.0),
        ),
        Threshold::Chance { margin, risk } => {
            let risked = at_quantile(1.0 - risk);
            (
                !advantages.is_empty() && mean > 0.0 && risked <= margin,
                risked,
            )
        }
        Threshold::SigmaChance {
            caution,
            margin,
            risk,
        } => {
            let risked = at_quantile(1.0 - risk);
            (
                !advantages.is_empty() && mean > caution * sd && risked <= margin,
                risked,
            )
        }
    };
    let action = if deviated {
        planned
    } else {
        baseline.action(state, step, u)
    };
    (
        action,
        Some(Guard {
            advantage: mean,
            advantage_sd: sd,
            expected_loss,
            risked_loss,
            threshold,
            deviated,
        }),
    )
}

/// How a decision is planned on the belief.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlanningRule {
    /// Backward induction on the posterior predictive model before each sequence.
    Mean,
    /// Backward induction on one model drawn from the belief at the start of each session
    /// (posterior sampling), kept for the session.
    Sampling,
    /// As `Mean`, an action the baseline would not take paying κ times its reward's σ.
    Cautious { caution: f64 },
    /// As `Mean`, but the plan leaves the baseline only where `guarded_action` lets it, on
    /// `samples` models drawn from the belief.
    Guarded { test: GuardTest, samples: usize },
    /// Safe policy improvement with baseline bootstrapping (SPIBB, Laroche et al. 2019, for a
    /// deterministic baseline): as `Mean`, but the plan may leave the baseline at a state only
    /// where the child has been seen at least `min_observations` times at the input the
    /// baseline's action sets up and at the input of the action taken instead.
    Spibb { min_observations: f64 },
}

/// One decision planned on the belief, with what it was based on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeliefDecision {
    pub action: Action,
    /// The plan's own action, before the guard.
    pub planned: Action,
    /// The baseline's action here (its tie broken as the played one's would be); `None`
    /// without a baseline.
    pub baseline: Option<Action>,
    /// The guard's finding where the plan left the baseline.
    pub guard: Option<Guard>,
    /// The return the belief expects from here to the session's end with the plan.
    pub expected_value: f64,
}

/// A belief about the child and the planner on it: decisions in, observations back, as the
/// live policy would use it (sans-IO; the random streams are the caller's).
#[derive(Debug, Clone)]
pub struct BeliefPolicy<B> {
    belief: B,
    baseline: Option<Baseline>,
    learning: Learning,
    rule: PlanningRule,
    session_plan: Option<BeliefPlan>,
    /// The session's margin the chance guard's deviations have risked so far.
    session_risked: f64,
}

impl<B: Belief> BeliefPolicy<B> {
    /// `baseline`: what the plan stays near (needed by `Cautious`, `Guarded` and `Spibb`;
    /// without one they plan as `Mean`).
    pub fn new(
        belief: B,
        baseline: Option<Baseline>,
        learning: Learning,
        rule: PlanningRule,
    ) -> Self {
        BeliefPolicy {
            belief,
            baseline,
            learning,
            rule,
            session_plan: None,
            session_risked: 0.0,
        }
    }

    pub fn belief(&self) -> &B {
        &self.belief
    }

    pub fn baseline(&self) -> Option<&Baseline> {
        self.baseline.as_ref()
    }

    /// A different baseline (e.g. the cluster's table after it learned); the belief stays.
    pub fn set_baseline(&mut self, baseline: Option<Baseline>) {
        self.baseline = baseline;
    }

    pub fn rule(&self) -> PlanningRule {
        self.rule
    }

    /// A new session: the chance guard's margin is whole again, and posterior sampling
    /// draws its model from `rng` and plans the session on it.
    pub fn start_session(&mut self, rng: &mut ChaCha8Rng) {
        self.session_risked = 0.0;
        self.session_plan = match self.rule {
            PlanningRule::Sampling => {
                Some(plan(&self.belief.sample(rng), &self.learning, None, 0.0, 1))
            }
            _ => None,
        };
    }

    /// The action for the sequence `step` (1-based) from `state`; `u` breaks the baseline's
    /// ties, `rng` gives the guard's draws.
    pub fn decide(
        &mut self,
        state: State,
        step: u8,
        u: f64,
        rng: &mut ChaCha8Rng,
    ) -> BeliefDecision {
        let baseline_action = self.baseline.as_ref().map(|b| b.action(state, step, u));
        if let Some(p) = &self.session_plan {
            let a = p.action(state, step);
            return BeliefDecision {
                action: a,
                planned: a,
                baseline: baseline_action,
                guard: None,
                expected_value: p.value(state, step),
            };
        }
        let (baseline, caution) = match (self.rule, &self.baseline) {
            (PlanningRule::Cautious { caution }, Some(b)) => (Some(b), caution),
            (PlanningRule::Spibb { .. }, Some(b)) => (Some(b), 0.0),
            _ => (None, 0.0),
        };
        let predictive = self.belief.predictive();
        let p = match (self.rule, baseline) {
            (PlanningRule::Spibb { min_observations }, Some(b)) => {
                let belief = &self.belief;
                let seen =
                    |input: ModelInput| belief.evidence(input).unwrap_or(0.0) >= min_observations;
                plan_within(
                    &predictive,
                    &self.learning,
                    Some(b),
                    0.0,
                    step,
                    |s, k, input| {
                        let own = b.action(s, k, 0.0);
                        seen(input)
                            && transition(s, own, Outcome::Success)
                                .is_some_and(|(own_input, _)| seen(own_input))
                    },
                )
            }
            _ => plan(&predictive, &self.learning, baseline, caution, step),
        };
        let planned = p.action(state, step);
        let mut decision = BeliefDecision {
            action: planned,
            planned,
            baseline: baseline_action,
            guard: None,
            expected_value: p.value(state, step),
        };
        if let (PlanningRule::Guarded { test, samples }, Some(b)) = (self.rule, &self.baseline) {
            if b.takes(state, planned) {
                return decision;
            }
            let models = self.belief.samples(rng, samples);
            let threshold = test.threshold(self.belief.observations(), self.session_risked);
            let (action, guard) =
                guarded_action(&p, b, &models, &self.learning, state, step, threshold, u);
            if let Some(g) = &guard
                && g.deviated
                && test.spends_margin()
            {
                self.session_risked += g.risked_loss;
            }
            decision.action = action;
            decision.guard = guard;
        }
        decision
    }

    /// Takes the sequence just played into account.
    pub fn observe(&mut self, observation: &Observation) {
        self.belief.observe(observation);
    }
}

#[cfg(test)]
mod tests;
