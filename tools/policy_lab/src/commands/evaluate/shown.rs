//! What `evaluate` shows of an evaluation: the estimates with the intervals that mean nothing
//! withheld (and why), how far the new policy leaves the logged actions, and the sessions left
//! out, by kind, with the bias leaving them out brings.

use policy_lab::off_policy::recorded::{LeftOutKind, LoggedSessions};
use policy_lab::off_policy::{Evaluation, Limits};
use std::fmt::Write as _;

/// One estimate as it may be shown: its interval, or why there is none.
#[derive(Debug, Clone, serde::Serialize)]
pub(super) struct Shown {
    pub estimator: &'static str,
    pub quantity: &'static str,
    pub value: f64,
    pub interval: Option<[f64; 2]>,
    pub no_interval: Option<String>,
}

/// The estimates with the intervals that mean nothing withheld: the weighted estimate's below
/// the effective sessions required, and any of zero width.
pub(super) fn shown(e: &Evaluation, limits: &Limits) -> Vec<Shown> {
    let mut out = Vec::new();
    for (quantity, q) in [
        ("discounted return", &e.discounted_return),
        ("score", &e.score),
    ] {
        for (estimator, x, kind) in [
            ("logged policy (actual)", Some(q.logged), 0),
            ("new policy, weighted IS", q.weighted_is, 1),
            ("new policy, per-decision IS", Some(q.per_decision_is), 2),
        ] {
            let Some(x) = x else {
                continue;
            };
            let no_interval = if kind == 1 && !e.weighted_interval_holds(limits) {
                Some(format!(
                    "rests on {:.1} effective sessions, below {}",
                    e.effective_sample_size, limits.min_effective_sessions
                ))
            } else if kind == 2 && !e.per_decision_interval_holds() {
                Some(
                    "no logged session follows the new policy throughout, so the estimate \
                     rests on the beginnings of sessions only"
                        .into(),
                )
            } else if x.high.partial_cmp(&x.low) != Some(std::cmp::Ordering::Greater) {
                Some("every bootstrap resample gave the same value".into())
            } else {
                None
            };
            out.push(Shown {
                estimator,
                quantity,
                value: x.value,
                interval: no_interval.is_none().then_some([x.low, x.high]),
                no_interval,
            });
        }
    }
    out
}

fn cell(s: Option<&Shown>) -> String {
    match s {
        Some(Shown {
            value,
            interval: Some([lo, hi]),
            ..
        }) => format!("{value:>8.2}  [{lo:>7.2}, {hi:>7.2}]"),
        Some(Shown { value, .. }) => format!("{value:>8.2}  (no interval)"),
        None => format!("{:>8}  (no session has weight)", "-"),
    }
}

/// The table every evaluation prints, and the reasons for any interval withheld.
pub(super) fn estimates_table(e: &Evaluation, rows: &[Shown]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<30} {:>28}   {:>28}",
        "", "discounted return [95 % CI]", "score L·O [95 % CI]"
    );
    for estimator in [
        "logged policy (actual)",
        "new policy, weighted IS",
        "new policy, per-decision IS",
    ] {
        let find = |quantity: &str| {
            rows.iter()
                .find(|r| r.estimator == estimator && r.quantity == quantity)
        };
        let _ = writeln!(
            out,
            "{estimator:<30} {:>28}   {:>28}",
            cell(find("discounted return")),
            cell(find("score"))
        );
    }
    let mut reasons: Vec<String> = rows
        .iter()
        .filter_map(|r| Some(format!("{}: {}", r.estimator, r.no_interval.as_ref()?)))
        .collect();
    reasons.dedup();
    for r in reasons {
        let _ = writeln!(out, "no interval for the {r}");
    }
    let _ = writeln!(
        out,
        "effective sample size {:.1} of {} sessions ({} with weight above 0); the new policy \
         gives the logged actions probability {:.3} on average",
        e.effective_sample_size, e.sessions, e.sessions_with_weight, e.mean_new_probability
    );
    out
}

/// How much the new policy leaves the logged actions.
pub(super) fn support_line(e: &Evaluation) -> String {
    match (e.sessions_leaving_support, e.mass_outside_support) {
        (Some(share), Some(per_decision)) => format!(
            "the new policy would leave the actions the logged policy took in {:.1} % of its \
             sessions ({:.1} % of its probability per decision)",
            100.0 * share,
            100.0 * per_decision
        ),
        _ => "the logged distributions are missing: support unknown".into(),
    }
}

/// The sessions left out, counted by kind, with the bias that leaving them out brings.
pub(super) fn left_out_lines(log: &LoggedSessions) -> String {
    let mut out = String::new();
    let seen = log.seen();
    let _ = writeln!(
        out,
        "sessions: {seen} recorded, {} evaluated, {} left out ({:.0} %){}",
        log.sessions.len(),
        log.left_out.len(),
        100.0 * log.left_out.len() as f64 / seen.max(1) as f64,
        if log.left_out.is_empty() {
            String::new()
        } else {
            format!(
                ": {}",
                LeftOutKind::ALL
                    .iter()
                    .map(|k| format!("{} {}", log.left_out_for(*k), k.describe()))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        }
    );
    for l in &log.left_out {
        let _ = writeln!(out, "  left out {}: {}", l.session_id, l.reason);
    }
    if !log.left_out.is_empty() {
        let _ = writeln!(
            out,
            "  The estimates describe only the sessions the policy played whole. Sessions the \
             therapist stopped or steered, and those the fallback stepped into, are not a \
             random share (a therapist steps in when a session goes badly; under supervised \
             autonomy every replaced proposal drops its session), so the estimates lean \
             toward the sessions that went as the policy planned."
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use policy_lab::off_policy::evaluate;
    use q_learning::mdp::{TargetPolicy, TargetTemperature};
    use q_learning::{Learning, QTableFile};
    use std::path::Path;

    #[test]
    fn no_interval_from_logs_no_session_of_which_the_new_policy_follows() {
        use q_learning::mdp::simulate_sessions;
        use q_learning::reference_tables::per_level_reference_tables;
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../bags/q_tables");
        let table = |k: usize| {
            QTableFile::load(&root.join(format!("cluster_{k}.json")))
                .expect("sample table")
                .table
        };
        let learning = Learning::default();
        // Logged by cluster 0's table exploring a little; judged: cluster 1's, greedy.
        let logging =
            TargetPolicy::new(table(0), TargetTemperature::EpsilonGreedy(0.1)).expect("policy");
        let (log, full) = simulate_sessions(&per_level_reference_tables()[0], &logging, 80, 3);
        let greedy = TargetPolicy::new(table(1), TargetTemperature::Greedy).expect("policy");
        let e = evaluate(&log, Some(&full), &greedy, &learning, 100, 3).expect("evaluates");
        assert_eq!(e.sessions_with_weight, 0);
        let limits = Limits::default();
        assert!(
            e.refusals(&limits).is_empty(),
            "every action is in the support"
        );
        let rows = shown(&e, &limits);
        let pdis: Vec<&Shown> = rows
            .iter()
            .filter(|r| r.estimator == "new policy, per-decision IS")
            .collect();
        assert_eq!(pdis.len(), 2);
        for r in pdis {
            assert!(r.interval.is_none(), "{r:?}");
            let why = r.no_interval.as_deref().unwrap_or_default();
            assert!(
                why.contains("no logged session follows the new policy"),
                "{why}"
            );
        }
        // Judged on the same logs, its own greedy choice keeps its intervals.
        let own = TargetPolicy::new(table(0), TargetTemperature::Greedy).expect("policy");
        let e = evaluate(&log, Some(&full), &own, &learning, 100, 3).expect("evaluates");
        assert!(
            shown(&e, &limits).iter().all(|r| r.interval.is_some()),
            "{e:?}"
        );
    }
}
