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
        Threshold::Sigma(1.0),
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
        Threshold::Sigma(1.0),
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
        Threshold::Sigma(0.0),
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
        Threshold::Sigma(1.0),
        0.5,
    );
    assert!(g.is_none());
}

/// Models where levels 2 and 3 fail and engagement is low: leaving level 1 loses there.
fn failing_above_level_one() -> UserModelTable {
    UserModelTable::tabulate(
        0,
        |i| Prediction {
            mean: if i.level == Level::ONE { 0.95 } else { 0.0 },
            std: 0.0,
        },
        |_, _| Prediction {
            mean: -0.5,
            std: 0.0,
        },
    )
}

#[test]
fn the_chance_guard_leaves_the_baseline_only_where_the_sessions_loss_stays_within_its_margin() {
    let l = learning();
    let baseline = Baseline::of_table(&level_one_table());
    let good = model(0.0);
    let bad = failing_above_level_one();
    let p = plan(&good, &l, None, 0.0, 1);
    let planned = p.action(State::START, 1);
    let models = [good.clone(), good.clone(), bad.clone()];
    let guard =
        |threshold| guarded_action(&p, &baseline, &models, &l, State::START, 1, threshold, 0.5);
    // The loss under the bad model, from the session's start (step 1: not discounted).
    let loss = {
        let planned = CompiledPolicy::new(1, |s, k| p.action(s, k));
        let base = CompiledPolicy::new(1, |s, k| baseline.action(s, k, 0.0));
        base.value(&bad, &l, State::START) - planned.value(&bad, &l, State::START)
    };
    assert!(loss > 1.0, "{loss}");
    // One model in three loses: at risk 0.1 that loss is what the deviation risks.
    let (a, g) = guard(Threshold::Chance {
        margin: 1.0,
        risk: 0.1,
    });
    let g = g.expect("judged");
    assert_eq!(a, Action::SetLevel(Level::ONE));
    assert!(!g.deviated && (g.risked_loss - loss).abs() < 1e-9, "{g:?}");
    // A margin as large as that loss lets it through; so does a risk of one in two.
    let (a, _) = guard(Threshold::Chance {
        margin: loss + 1e-9,
        risk: 0.1,
    });
    assert_eq!(a, planned);
    let (a, g) = guard(Threshold::Chance {
        margin: 0.0,
        risk: 0.5,
    });
    assert_eq!(a, planned);
    assert_eq!(g.expect("judged").risked_loss, 0.0);
    // Later in the session the same loss weighs γ^(step − 1) in the session's return.
    let state = State::after(Level::ONE, Feedback::None, Outcome::Success);
    let p5 = plan(&good, &l, None, 0.0, 5);
    if !baseline.takes(state, p5.action(state, 5)) {
        let (_, g) = guarded_action(
            &p5,
            &baseline,
            std::slice::from_ref(&bad),
            &l,
            state,
            5,
            Threshold::Chance {
                margin: 0.0,
                risk: 0.0,
            },
            0.5,
        );
        let planned = CompiledPolicy::new(5, |s, k| p5.action(s, k));
        let base = CompiledPolicy::new(5, |s, k| baseline.action(s, k, 0.0));
        let a = planned.value(&bad, &l, state) - base.value(&bad, &l, state);
        let g = g.expect("judged");
        assert!((g.risked_loss - l.gamma.powi(4) * (-a).max(0.0)).abs() < 1e-9);
    }
    // The tests as they apply after n sequences and with some margin spent.
    let fading = GuardTest::Fading {
        caution: 1.0,
        half: 10.0,
    };
    assert_eq!(fading.threshold(0, 0.0), Threshold::Sigma(1.0));
    assert_eq!(fading.threshold(10, 0.0), Threshold::Sigma(0.5));
    let chance = GuardTest::Chance {
        margin: 1.0,
        risk: 0.1,
    };
    assert_eq!(
        chance.threshold(50, 0.75),
        Threshold::Chance {
            margin: 0.25,
            risk: 0.1
        }
    );
    assert_eq!(
        chance.threshold(50, 2.0),
        Threshold::Chance {
            margin: 0.0,
            risk: 0.1
        }
    );
}

#[test]
fn the_sigma_and_chance_guard_leaves_the_baseline_only_where_both_tests_pass() {
    let l = learning();
    let baseline = Baseline::of_table(&level_one_table());
    let good = model(0.0);
    let bad = failing_above_level_one();
    let p = plan(&good, &l, None, 0.0, 1);
    let planned = p.action(State::START, 1);
    let level_one = Action::SetLevel(Level::ONE);
    let models = [good.clone(), good.clone(), bad.clone()];
    let guard =
        |threshold| guarded_action(&p, &baseline, &models, &l, State::START, 1, threshold, 0.5).0;
    let loss = {
        let planned = CompiledPolicy::new(1, |s, k| p.action(s, k));
        let base = CompiledPolicy::new(1, |s, k| baseline.action(s, k, 0.0));
        base.value(&bad, &l, State::START) - planned.value(&bad, &l, State::START)
    };
    // The mean gain alone passes (κ 0), and so does the loss within a margin as large.
    assert_eq!(guard(Threshold::Sigma(0.0)), planned);
    let both = |caution, margin| Threshold::SigmaChance {
        caution,
        margin,
        risk: 0.1,
    };
    assert_eq!(guard(both(0.0, loss + 1e-9)), planned);
    // Either failing keeps the baseline: the loss past the margin, or the gain under κ σ.
    assert_eq!(guard(both(0.0, loss - 1e-3)), level_one);
    assert_eq!(guard(Threshold::Sigma(1.0)), level_one);
    assert_eq!(guard(both(1.0, 100.0)), level_one);
    // It spends the session's margin as the chance guard does; the σ tests spend none.
    let test = GuardTest::SigmaChance {
        caution: 0.5,
        margin: 1.0,
        risk: 0.1,
    };
    assert!(test.spends_margin());
    assert!(!GuardTest::Sigma { caution: 0.5 }.spends_margin());
    assert_eq!(
        test.threshold(50, 0.75),
        Threshold::SigmaChance {
            caution: 0.5,
            margin: 0.25,
            risk: 0.1
        }
    );
}

/// A belief that is a known list of models: its draws go round the list, its predictive model
/// is the first, and it counts the sequences seen at each input.
struct Known {
    models: Vec<UserModelTable>,
    next: std::cell::Cell<usize>,
    seen: Vec<f64>,
}

impl Known {
    fn new(models: Vec<UserModelTable>) -> Self {
        Known {
            models,
            next: std::cell::Cell::new(0),
            seen: vec![0.0; SUCCESS_INPUTS],
        }
    }
}

impl Belief for Known {
    fn observe(&mut self, o: &Observation) {
        self.seen[o.input.index()] += 1.0;
    }
    fn predictive(&self) -> UserModelTable {
        self.models[0].clone()
    }
    fn sample(&self, _rng: &mut ChaCha8Rng) -> UserModelTable {
        let k = self.next.get();
        self.next.set(k + 1);
        self.models[k % self.models.len()].clone()
    }
    fn observations(&self) -> usize {
        self.seen.iter().sum::<f64>() as usize
    }
    fn evidence(&self, input: ModelInput) -> Option<f64> {
        Some(self.seen[input.index()])
    }
}

fn rng() -> ChaCha8Rng {
    <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1)
}

#[test]
fn the_chance_guard_spends_the_sessions_margin_and_gets_it_back_at_the_next_session() {
    let l = learning();
    let baseline = Baseline::of_table(&level_one_table());
    let good = model(0.0);
    // Every draw is the good model but one in four that fails above level 1.
    let belief = Known::new(vec![
        good.clone(),
        good.clone(),
        good.clone(),
        failing_above_level_one(),
    ]);
    let mut policy = BeliefPolicy::new(
        belief,
        Some(baseline),
        l,
        PlanningRule::Guarded {
            test: GuardTest::Chance {
                margin: 100.0,
                risk: 0.0,
            },
            samples: 4,
        },
    );
    policy.start_session(&mut rng());
    let first = policy.decide(State::START, 1, 0.5, &mut rng());
    let g = first.guard.expect("the plan leaves level 1");
    assert!(g.deviated && g.risked_loss > 0.0, "{g:?}");
    assert_eq!(
        g.threshold,
        Threshold::Chance {
            margin: 100.0,
            risk: 0.0
        }
    );
    // The next deviation has what is left of the margin.
    let again = policy.decide(State::START, 1, 0.5, &mut rng());
    let h = again.guard.expect("judged");
    assert_eq!(
        h.threshold,
        Threshold::Chance {
            margin: 100.0 - g.risked_loss,
            risk: 0.0
        }
    );
    policy.start_session(&mut rng());
    let fresh = policy.decide(State::START, 1, 0.5, &mut rng());
    assert_eq!(
        fresh.guard.expect("judged").threshold,
        Threshold::Chance {
            margin: 100.0,
            risk: 0.0
        }
    );
    assert_eq!(fresh.baseline, Some(Action::SetLevel(Level::ONE)));
}

#[test]
fn spibb_leaves_the_baseline_only_between_inputs_the_child_was_seen_at() {
    let l = learning();
    let baseline = Baseline::of_table(&level_one_table());
    let good = model(0.0);
    let mut policy = BeliefPolicy::new(
        Known::new(vec![good.clone()]),
        Some(baseline.clone()),
        l,
        PlanningRule::Spibb {
            min_observations: 2.0,
        },
    );
    // Nothing seen: the baseline's level 1 everywhere.
    let d = policy.decide(State::START, 1, 0.5, &mut rng());
    assert_eq!(d.action, Action::SetLevel(Level::ONE));
    // The unconstrained plan's choice at the start, and the two inputs SPIBB needs seen.
    let free = plan(&good, &l, None, 0.0, 1).action(State::START, 1);
    assert_ne!(free, Action::SetLevel(Level::ONE));
    let input_of = |a| {
        transition(State::START, a, Outcome::Success)
            .expect("allowed")
            .0
    };
    let seen = |input| Observation::new(input, Outcome::Success, 0.0).expect("observation");
    for _ in 0..2 {
        policy.observe(&seen(input_of(free)));
    }
    // Only the deviation's input seen: still the baseline's.
    let d = policy.decide(State::START, 1, 0.5, &mut rng());
    assert_eq!(d.action, Action::SetLevel(Level::ONE));
    for _ in 0..2 {
        policy.observe(&seen(input_of(Action::SetLevel(Level::ONE))));
    }
    let d = policy.decide(State::START, 1, 0.5, &mut rng());
    assert_eq!(d.action, free);
    assert!(d.guard.is_none());
}
