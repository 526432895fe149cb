//! Per-child beliefs in the node's core: updates on known answers, the file across a restart,
//! a result sent twice, a damaged file, the action mask and the guard, and determinism.

use super::*;
use child_belief::planner::GuardTest;
use qt_therapy_msgs::BehaviourState;
use sequence_game::{Action, Prediction};

/// The study's two cluster models, as the node plays them.
fn priors() -> Vec<UserModelTable> {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../user_model/models/migrave_study_c2.json");
    user_models::UserModelSet::load(&path)
        .expect("the repository's user models")
        .tables()
}

/// A covariance learned from two made-up children around cluster 0's model.
fn covariance(priors: &[UserModelTable]) -> LearnedCovariance {
    let shifted = |dp: f64, de: f64| {
        let p = &priors[0];
        UserModelTable::tabulate(
            0,
            |i| Prediction {
                mean: (p.success(i).mean + dp).clamp(0.0, 1.0),
                std: 0.0,
            },
            |i, o| Prediction {
                mean: (p.engagement(i, o).mean + de).clamp(-1.0, 1.0),
                std: 0.0,
            },
        )
    };
    let (a, b) = (shifted(0.3, 0.2), shifted(-0.3, -0.4));
    LearnedCovariance::from_children(&[(&a, &priors[0]), (&b, &priors[0])], 0.5, 0.01)
        .expect("learned")
}

fn settings(priors: &[UserModelTable], rule: PlanningRule) -> BeliefSettings {
    BeliefSettings {
        covariance: covariance(priors),
        own_model: OwnModelParams::default(),
        rule,
        learning: Learning::default(),
        seed: 7,
    }
}

/// The node's rule, as `params/behaviour_policy.yaml` sets it.
fn chosen() -> PlanningRule {
    crate::BehaviourPolicyParams::default()
        .child_belief_rule()
        .expect("the default rule")
}

/// The σ guard at `caution`: its contract is simple to check.
fn sigma(caution: f64) -> PlanningRule {
    PlanningRule::Guarded {
        test: GuardTest::Sigma { caution },
        samples: 32,
    }
}

fn beliefs(dir: &Path, rule: PlanningRule) -> ChildBeliefs {
    let p = priors();
    ChildBeliefs::new(dir, settings(&p, rule), p)
}

/// A table preferring level 1 everywhere, feedback never.
fn table() -> QTable {
    let mut t = QTable::default();
    for row in t.q.iter_mut() {
        *row = [1.0, 0.5, 0.25, 0.0, 0.0];
    }
    t
}

/// Sequence `index` of `session` for u1: level `level` from the state before, right or wrong.
fn result(session: &str, index: u8, before: State, level: u8, right: bool) -> SequenceResult {
    SequenceResult {
        session_id: session.into(),
        user_id: "u1".into(),
        sequence_index: index,
        state: BehaviourState::from_state(before),
        action: level - 1,
        level,
        feedback: 0,
        outcome: if right { 1 } else { -1 },
        activity_result: if right { f64::from(level) as f32 } else { -1.0 },
        engagement: 0.5,
        engagement_per_second: vec![0.5],
        sequences_planned: 10,
        ..Default::default()
    }
}

/// `n` sequences at level 3 from the state each leaves, right or wrong as `right(i)`.
fn play(b: &mut ChildBeliefs, session: &str, n: u8, right: impl Fn(u8) -> bool) -> State {
    play_at(b, session, 3, n, right)
}

fn play_at(
    b: &mut ChildBeliefs,
    session: &str,
    level: u8,
    n: u8,
    right: impl Fn(u8) -> bool,
) -> State {
    let mut state = State::START;
    for i in 1..=n {
        let r = result(session, i, state, level, right(i));
        assert!(b.learn(&r, 0).expect("learns"), "sequence {i} is new");
        state = State::new(level.into(), 0, r.score().into()).expect("state");
    }
    state
}

#[test]
fn right_answers_at_level_3_raise_the_belief_there_and_wrong_ones_lower_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut b = beliefs(dir.path(), chosen());
    let before = b
        .decide("u1", "s1", 0, &table(), State::START, 1)
        .expect("decides");
    assert_eq!(before.observations, 0);
    play(&mut b, "s1", 6, |_| true);
    let after = b
        .decide("u1", "s1", 0, &table(), State::new(3, 0, 3).expect("s"), 7)
        .expect("decides");
    assert_eq!(after.observations, 6);
    assert!(
        after.levels[2].success > before.levels[2].success + 0.1,
        "{:?} -> {:?}",
        before.levels[2],
        after.levels[2]
    );
    assert!(after.levels[2].success_sd < before.levels[2].success_sd);

    // Level 1, where the cluster expects 94 % right: six wrong answers there.
    let mut wrong = beliefs(tempfile::tempdir().expect("tempdir").path(), chosen());
    play_at(&mut wrong, "s1", 1, 6, |_| false);
    let failed = wrong
        .decide("u1", "s1", 0, &table(), State::new(1, 0, -1).expect("s"), 7)
        .expect("decides");
    assert!(
        failed.levels[0].success < before.levels[0].success - 0.1,
        "{:?} -> {:?}",
        before.levels[0],
        failed.levels[0]
    );
    assert!(failed.levels[0].success_sd < before.levels[0].success_sd);
}

#[test]
fn the_belief_file_brings_the_same_belief_back_after_a_restart() {
    let dir = tempfile::tempdir().expect("tempdir");
    let state = {
        let mut b = beliefs(dir.path(), chosen());
        play(&mut b, "s1", 5, |i| i % 2 == 1)
    };
    let path = dir.path().join("belief_u1.json");
    let file: BeliefFile = BELIEF_FILE.load(&path).expect("written");
    assert_eq!(file.observations.len(), 5);
    assert_eq!(file.prior_cluster, 0);

    // Two nodes started on the file: the same belief, the same decision.
    let mut a = beliefs(dir.path(), chosen());
    let mut c = beliefs(dir.path(), chosen());
    let da = a.decide("u1", "s2", 0, &table(), state, 2).expect("a");
    let dc = c.decide("u1", "s2", 0, &table(), state, 2).expect("c");
    assert_eq!(da, dc);
    assert_eq!(da.observations, 5);
    // And the one that never stopped.
    let mut live = beliefs(tempfile::tempdir().expect("tempdir").path(), chosen());
    play(&mut live, "s1", 5, |i| i % 2 == 1);
    let dl = live
        .decide("u1", "s2", 0, &table(), state, 2)
        .expect("live");
    assert_eq!(dl.levels, da.levels);
    assert_eq!(dl.decision, da.decision);
}

#[test]
fn a_result_sent_again_is_learned_once_and_a_later_cluster_keeps_the_first_prior() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut b = beliefs(dir.path(), chosen());
    let r = result("s1", 1, State::START, 2, true);
    assert!(b.learn(&r, 0).expect("learns"));
    let bytes = std::fs::read(dir.path().join("belief_u1.json")).expect("file");
    assert!(!b.learn(&r, 1).expect("a repeat"), "learned twice");
    assert_eq!(
        std::fs::read(dir.path().join("belief_u1.json")).expect("file"),
        bytes
    );
    let d = b
        .decide("u1", "s2", 1, &table(), State::START, 1)
        .expect("decides");
    assert!(d.described.contains("prior cluster 0"), "{}", d.described);
}

#[test]
fn a_damaged_belief_file_is_named_kept_aside_and_the_child_starts_anew() {
    let dir = tempfile::tempdir().expect("tempdir");
    {
        let mut b = beliefs(dir.path(), chosen());
        play(&mut b, "s1", 3, |_| true);
    }
    let path = dir.path().join("belief_u1.json");
    let whole = std::fs::read(&path).expect("file");
    std::fs::write(&path, &whole[..whole.len() / 2]).expect("cut");
    let mut b = beliefs(dir.path(), chosen());
    let d = b
        .decide("u1", "s2", 0, &table(), State::START, 1)
        .expect("decides as for a new child");
    assert_eq!(d.observations, 0);
    let aside = dir.path().join("belief_u1.json.damaged");
    assert_eq!(
        std::fs::read(&aside).expect("kept"),
        &whole[..whole.len() / 2]
    );
    assert!(
        !path.exists(),
        "nothing written before a sequence is learned"
    );
    assert!(
        b.learn(&result("s2", 1, State::START, 1, true), 0)
            .expect("learns")
    );
    let file: BeliefFile = BELIEF_FILE.load(&path).expect("a new file");
    assert_eq!(file.observations.len(), 1);

    // Another child's file, or a sequence that is no sequence, is refused the same way.
    let mut other = file.clone();
    other.user_id = "u2".into();
    BELIEF_FILE.save(&path, &other).expect("writes");
    let mut b = beliefs(dir.path(), chosen());
    assert_eq!(
        b.decide("u1", "s3", 0, &table(), State::START, 1)
            .expect("new")
            .observations,
        0
    );
    assert!(dir.path().join("belief_u1.json.damaged.2").exists());
}

#[test]
fn a_result_that_is_no_sequence_is_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut b = beliefs(dir.path(), chosen());
    let mut r = result("s1", 1, State::START, 2, true);
    r.level = 4;
    let e = b.learn(&r, 0).expect_err("level 4").to_string();
    assert!(e.starts_with("result: "), "{e}");
    let mut r = result("s1", 1, State::START, 2, true);
    r.outcome = 0;
    assert!(b.learn(&r, 0).is_err());
    assert!(!dir.path().join("belief_u1.json").exists());
}

#[test]
fn decisions_keep_to_the_mask_and_the_guards_let_only_clear_gains_leave_the_table() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut bold = beliefs(dir.path(), sigma(0.0));
    let mut careful = beliefs(tempfile::tempdir().expect("tempdir").path(), sigma(10.0));
    let mut chance = beliefs(tempfile::tempdir().expect("tempdir").path(), chosen());
    for b in [&mut bold, &mut careful, &mut chance] {
        play(b, "s1", 8, |i| i != 4);
    }
    let (mut left, mut careful_left) = (0, 0);
    for (i, state) in State::all().enumerate() {
        for step in 1..=10u8 {
            if state.is_start() != (step == 1) {
                continue;
            }
            let session = format!("t{i}");
            let d = bold
                .decide("u1", &session, 0, &table(), state, step)
                .expect("decides");
            assert!(
                d.decision.action.index() < q_learning::learning::allowed_at(state, step),
                "{:?} at {state} step {step}",
                d.decision.action
            );
            assert!(d.decision.action.apply(state).is_some());
            if step == 1 {
                assert!(matches!(d.decision.action, Action::SetLevel(_)));
            }
            left += usize::from(Some(d.decision.action) != d.decision.baseline);
            let c = careful
                .decide("u1", &session, 0, &table(), state, step)
                .expect("decides");
            // The guard's contract: the table's action, or a gain 10 sd clear of doubt.
            let kept = Some(c.decision.action) == c.decision.baseline;
            let cleared = c
                .decision
                .guard
                .is_some_and(|g| g.deviated && g.advantage > 10.0 * g.advantage_sd);
            assert!(kept || cleared, "{state} step {step}: {:?}", c.decision);
            careful_left += usize::from(!kept);
            // The node's chance guard: a gain on average, and a loss past the session's margin
            // (0.5) in at most a tenth of the drawn models.
            let d = chance
                .decide("u1", &session, 0, &table(), state, step)
                .expect("decides");
            let kept = Some(d.decision.action) == d.decision.baseline;
            let within = d
                .decision
                .guard
                .is_some_and(|g| g.deviated && g.advantage > 0.0 && g.risked_loss <= 0.5);
            assert!(kept || within, "{state} step {step}: {:?}", d.decision);
        }
    }
    assert!(left > 0, "with no caution the plan never left the table");
    assert!(careful_left < left, "{careful_left} of {left}");
}

#[test]
fn the_same_seed_and_sequences_give_the_same_decisions() {
    let run = || {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut b = beliefs(dir.path(), chosen());
        let mut out = Vec::new();
        let mut state = State::START;
        for i in 1..=10u8 {
            let d = b
                .decide("u1", "s1", 0, &table(), state, i)
                .expect("decides");
            let (level, _) = d.decision.action.apply(state).expect("allowed");
            let r = SequenceResult {
                action: d.decision.action.index() as u8,
                ..result("s1", i, state, level.get(), i % 3 != 0)
            };
            let r = SequenceResult {
                feedback: d.decision.action.apply(state).expect("allowed").1 as u8,
                ..r
            };
            b.learn(&r, 0).expect("learns");
            state = State::new(r.level.into(), r.feedback.into(), r.score().into()).expect("s");
            out.push((d.decision, d.levels, d.observations));
        }
        out
    };
    assert_eq!(run(), run());
}
