//! The planner on a belief against the exact backward induction (`mdp`), the mask, the
//! baseline and the guard.

use super::*;
use q_learning::mdp::{
    Objective, StepPolicy, TargetPolicy, TargetTemperature, exact_value, optimal_policy,
};
use sequence_game::{Feedback, Level, Prediction};

fn learning() -> Learning {
    Learning {
        reward: q_learning::Reward::RePlusBetaE,
        ..Learning::default()
    }
}

/// A model where level 2 goes well and engagement rises with feedback, with `sd` on every
/// value.
fn model(sd: f64) -> UserModelTable {
    UserModelTable::tabulate(
        0,
        |i| Prediction {
            mean: match i.level.get() {
                1 => 0.95,
                2 => 0.8,
                _ => 0.3,
            },
            std: sd,
        },
        |i, o| Prediction {
            mean: 0.2 * i.feedback.index() as f64 - if o == Outcome::Failure { 0.3 } else { 0.0 },
            std: sd,
        },
    )
}

/// A deterministic step policy of a plan, for `mdp`.
struct Planned<'a>(&'a BeliefPlan);

impl StepPolicy for Planned<'_> {
    fn probabilities(&self, state: State, step: u8) -> [f64; sequence_game::ACTION_COUNT] {
        let mut p = [0.0; sequence_game::ACTION_COUNT];
        p[self.0.action(state, step).index()] = 1.0;
        p
    }
}

#[test]
fn without_a_baseline_the_plan_is_the_optimal_policy() {
    let m = model(0.2);
    let l = learning();
    let p = plan(&m, &l, None, 0.0, 1);
    let optimal = optimal_policy(&m, &l, Objective::Return);
    for step in 1..=SEQUENCES_PER_SESSION as u8 {
        for state in State::all() {
            let o = optimal.probabilities(state, step);
            assert_eq!(o[p.action(state, step).index()], 1.0, "{state} at {step}");
            // Within the mask: levels only at the first sequence and in the start state.
            assert!(p.action(state, step).index() < allowed_at(state, step));
        }
    }
    let exact = exact_value(&m, &Planned(&p), &l).discounted_return;
    assert!((p.value(State::START, 1) - exact).abs() < 1e-9);
    assert!((exact - optimal.value.discounted_return).abs() < 1e-9);
    // A compiled policy's value is the exact value too.
    let compiled = CompiledPolicy::new(1, |s, k| p.action(s, k));
    assert!((compiled.value(&m, &l, State::START) - exact).abs() < 1e-9);
}

/// A table whose greedy action is a1 (level 1) everywhere.
fn level_one_table() -> QTable {
    let mut t = QTable::default();
    for row in t.q.iter_mut() {
        row[0] = 1.0;
    }
    t
}

#[test]
fn caution_keeps_the_plan_on_the_baseline_where_the_belief_is_unsure() {
    let l = learning();
    let baseline = Baseline::of_table(&level_one_table());
    // Sure of the model: the plan leaves level 1 (level 2 pays more here).
    let sure = plan(&model(0.0), &l, Some(&baseline), 5.0, 1);
    assert_ne!(sure.action(State::START, 1), Action::SetLevel(Level::ONE));
    // Unsure: every deviation pays κ σ and the plan is the baseline's.
    let unsure = plan(&model(0.4), &l, Some(&baseline), 5.0, 1);
    for step in 1..=SEQUENCES_PER_SESSION as u8 {
        for state in State::all() {
            assert_eq!(unsure.action(state, step), Action::SetLevel(Level::ONE));
        }
    }
    // The baseline's own ties are broken by the draw, as the simulator breaks them.
    let mut tied = QTable::default();
    tied.q[State::START.index()] = [1.0, 1.0, 0.0, 0.0, 0.0];
    let b = Baseline::of_table(&tied);
    assert_eq!(b.action(State::START, 1, 0.2), Action::SetLevel(Level::ONE));
    assert_eq!(b.action(State::START, 1, 0.7), Action::SetLevel(Level::TWO));
    assert!(b.takes(State::START, Action::SetLevel(Level::TWO)));
    assert!(!b.takes(State::START, Action::SetLevel(Level::THREE)));
    // And on the same draws the baseline is the greedy table's policy, exactly.
    let greedy = TargetPolicy::new(tied, TargetTemperature::Greedy).expect("policy");
    let p = greedy.probabilities(State::START, 1);
    assert_eq!(p[..2], [0.5, 0.5]);
}

#[test]
fn the_guard_leaves_the_baseline_only_for_a_gain_the_drawn_models_agree_on() {
    let l = learning();
    let baseline = Baseline::of_table(&level_one_table());
    let good = model(0.0);
    let p = plan(&good, &l, None, 0.0, 1);
    let planned = p.action(State::START, 1);
    assert_ne!(planned, Action::SetLevel(Level::ONE));
    // Every drawn model agrees: the plan's action.
    let (a, g) = guarded_action(
        &p,
        &baseline,
        &[good.clone(), good.clone()],
        &l,
        State::START,
        1,
        1.0,
        0.5,
    );
    assert_eq!(a, planned);
    let g = g.expect("a deviation is judged");
    assert!(g.deviated && g.advantage > 0.0 && g.advantage_sd == 0.0 && g.expected_loss == 0.0);
    // One drawn model in three where levels 2 and 3 fail: the mean gain does not clear one σ.
    let bad = UserModelTable::tabulate(
        0,
        |i| Prediction {
            mean: if i.level == Level::ONE { 0.95 } else { 0.0 },
            std: 0.0,
        },
        |_, _| Prediction {
            mean: -0.5,
            std: 0.0,
        },
    );
    let (a, g) = guarded_action(
        &p,
        &baseline,
        &[good.clone(), good.clone(), bad.clone()],
        &l,
        State::START,
        1,
        1.0,
        0.5,
    );
    assert_eq!(a, Action::SetLevel(Level::ONE));
    let g = g.expect("judged");
    assert!(
        !g.deviated && g.advantage > 0.0 && g.expected_loss > 0.0,
        "{g:?}"
    );
    // No caution: a positive mean gain is enough.
    let (a, _) = guarded_action(
        &p,
        &baseline,
        &[good.clone(), good.clone(), bad],
        &l,
        State::START,
        1,
        0.0,
        0.5,
    );
    assert_eq!(a, planned);
    // Where the baseline takes the plan's action, there is nothing to judge.
    let all_level_two = plan(&good, &l, None, 0.0, 1);
    let state = State::after(Level::TWO, Feedback::None, Outcome::Success);
    let mut t = QTable::default();
    t.q[state.index()][all_level_two.action(state, 2).index()] = 1.0;
    let (_, g) = guarded_action(
        &all_level_two,
        &Baseline::of_table(&t),
        &[],
        &l,
        state,
        2,
        1.0,
        0.5,
    );
    assert!(g.is_none());
}
