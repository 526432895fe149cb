//! Parameters changed while the node runs (`ros2 param set`, through the node shell): the
//! language and supervised autonomy's settings between sessions; refused, with the reason,
//! during a session, for a value the game cannot use, and for every other key.

use super::harness::*;
use crate::game::parameters::WRITABLE;
use crate::params::GameManagerParams;
use crate::protocol::Output;
use node_shell::parameters::DescribedParameters;
use qt_therapy_msgs::ActionProposal;

fn says(h: &Harness) -> Vec<String> {
    h.outputs()
        .filter_map(|o| match o {
            Output::Say(s) => Some(s.clone()),
            _ => None,
        })
        .collect()
}

fn with(change: impl FnOnce(&mut GameManagerParams)) -> GameManagerParams {
    let mut p = GameManagerParams::default();
    change(&mut p);
    p
}

fn keys(k: &[&str]) -> Vec<String> {
    k.iter().map(|s| s.to_string()).collect()
}

#[test]
fn the_writable_keys_are_the_ones_the_parameter_file_marks() {
    let marked: Vec<&str> = GameManagerParams::declared()
        .iter()
        .filter(|d| d.writable)
        .map(|d| d.name)
        .collect();
    assert_eq!(marked, WRITABLE);
}

#[test]
fn the_language_changes_between_sessions_not_during_one() {
    let mut h = Harness::new(
        GameManagerParams::default(),
        rule_policy(),
        scripted_child(vec![]),
    );
    h.start("s1");
    h.run_until(T0 + 2 * S);
    let german = with(|p| p.lines.language = "de".into());
    let e =
        h.gm.change_parameters(german.clone(), &keys(&["language"]))
            .expect_err("a session is under way");
    assert_eq!(
        e,
        "language: changes between sessions, and session s1 is under way"
    );
    h.run(3600.0);
    assert_eq!(h.summaries().len(), 1);
    let english = says(&h).len();
    assert!(says(&h)[0].starts_with("Hello!"), "{:?}", says(&h)[0]);

    h.gm.change_parameters(german, &keys(&["language"]))
        .expect("between sessions");
    assert_eq!(h.gm.params().lines.language, "de");
    h.start("s2");
    h.run(3600.0);
    assert_eq!(h.summaries().len(), 2);
    let second = &says(&h)[english..];
    assert!(second[0].starts_with("Hallo!"), "{:?}", second[0]);
}

#[test]
fn a_value_the_game_cannot_use_and_other_keys_are_refused() {
    let mut h = Harness::new(
        GameManagerParams::default(),
        rule_policy(),
        scripted_child(vec![]),
    );
    let e =
        h.gm.change_parameters(
            with(|p| p.lines.language = "fr".into()),
            &keys(&["language"]),
        )
        .expect_err("no French lines");
    assert!(e.contains("language") && e.contains("\"fr\""), "{e}");
    let e =
        h.gm.change_parameters(
            with(|p| p.supervision.proposal_countdown_s = -1.0),
            &keys(&["proposal_countdown_s"]),
        )
        .expect_err("negative countdown");
    assert!(e.contains("proposal_countdown_s"), "{e}");
    let e =
        h.gm.change_parameters(with(|p| p.session.seed = 1), &keys(&["seed"]))
            .expect_err("read-only");
    assert!(
        e.starts_with("seed: only language, supervised_autonomy"),
        "{e}"
    );
    assert_eq!(h.gm.params(), &GameManagerParams::default());
}

#[test]
fn supervised_autonomy_turned_on_between_sessions_proposes_in_the_next() {
    // Every state hot (temperature 250): a supervised session proposes every decision.
    let hot = Box::new(|req: &qt_therapy_msgs::DecideActionRequest| {
        let mut response = rule_decision(req);
        response.decision.temperature = 250.0;
        PolicyReply::Answer {
            after_s: 0.05,
            response,
        }
    });
    let mut h = Harness::new(GameManagerParams::default(), hot, scripted_child(vec![]));
    h.start("s1");
    h.run(3600.0);
    let proposed = |h: &Harness| {
        h.outputs()
            .filter(|o| matches!(o, Output::Proposal(p) if p.status == ActionProposal::PROPOSED))
            .count()
    };
    assert_eq!(proposed(&h), 0);
    h.gm.change_parameters(
        with(|p| p.supervision.supervised_autonomy = true),
        &keys(&["supervised_autonomy"]),
    )
    .expect("between sessions");
    h.start("s2");
    h.run(3600.0);
    assert_eq!(h.summaries().len(), 2);
    assert!(proposed(&h) > 0, "the second session proposed nothing");
    assert_eq!(h.summaries()[1].proposals as usize, proposed(&h));
}
