//! `policy_lab supervision`: supervised autonomy measured on the study's children
//! (`policy_lab::child_study::supervision`): for each proposal rule, how many decisions a session
//! sends to the therapist and how much score a therapist who knows the child protects by
//! answering them, leave one child out. Prints one row per rule; writes supervision.json (each
//! rule's summary) and supervision.csv (per child and rule: proposals, replaced and score per
//! session, and the score protected).

use super::child_study::ChildStudyArgs;
use anyhow::Context;
use policy_lab::child_study::supervision::{
    ChildSupervision, Sigma, Supervised, Trigger, TriggerSummary, cases, matched_random, paired,
    run_study, summarise,
};
use policy_lab::stats::PairedComparison;
use q_learning::mdp::Objective;
use q_learning::{Learning, Reward};
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    #[command(flatten)]
    study: ChildStudyArgs,
    /// What the simulated therapist plays at a proposal: the child's `score`-optimal action
    /// (the score a proposal protects), or their `return`-optimal one (the policy's own
    /// objective, engagement included).
    #[arg(long, default_value = "score", value_parser = parse_objective)]
    therapist: Objective,
    /// Where supervision.json and supervision.csv go.
    #[arg(long, default_value = "out/supervision")]
    output: PathBuf,
}

fn parse_objective(s: &str) -> Result<Objective, String> {
    match s {
        "score" => Ok(Objective::Score),
        "return" => Ok(Objective::Return),
        _ => Err(format!("{s:?} is not `score` or `return`")),
    }
}

/// The rules measured: none; the game manager's two rules alone and together at their
/// defaults; σ of the fitted-noise models at several limits, alone and with the temperature
/// rule; proposals at random at several rates; every decision.
fn triggers() -> Vec<Trigger> {
    let mut t = vec![
        Trigger::Never,
        Trigger::temperature(100.0),
        Trigger::sigma(0.3, Sigma::Paper),
        Trigger::Rule {
            above_temperature: 100.0,
            above_success_std: 0.3,
            sigma: Sigma::Paper,
        },
    ];
    for limit in [0.10, 0.12, 0.15, 0.18] {
        t.push(Trigger::sigma(limit, Sigma::FittedNoise));
    }
    t.push(Trigger::Rule {
        above_temperature: 100.0,
        above_success_std: 0.15,
        sigma: Sigma::FittedNoise,
    });
    for p in [0.1, 0.2, 0.3, 0.5] {
        t.push(Trigger::Random(p));
    }
    t.push(Trigger::Always);
    t
}

fn interval(c: &PairedComparison) -> String {
    c.all.t_interval.map_or_else(
        || "-".into(),
        |i| format!("[{:+.2}, {:+.2}]", i.low, i.high),
    )
}

/// One row per rule; `versus_random[t]`: the rule's score minus proposals at random at its
/// rate, paired by child.
fn table(summary: &[TriggerSummary], versus_random: &[Option<PairedComparison>]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<38} {:>8} {:>8} {:>6} {:>7} {:>22} {:>12} {:>7} {:>8} {:>22}",
        "rule",
        "proposed",
        "replaced",
        "score",
        "return",
        "protected [95 % t]",
        "W/T/L",
        "median",
        "per prop",
        "vs random, same rate"
    );
    for (s, r) in summary.iter().zip(versus_random) {
        let a = &s.protected.all;
        let _ = writeln!(
            out,
            "{:<38} {:>8.2} {:>8.2} {:>6.2} {:>7.2} {:>+6.2} {:>15} {:>12} {:>+7.2} {:>8} {:>22}",
            s.name,
            s.proposals,
            s.replaced,
            s.score,
            s.discounted_return,
            a.mean,
            interval(&s.protected),
            format!("{} / {} / {}", a.wins, a.ties, a.losses),
            a.median,
            s.protected_per_proposal
                .map_or_else(|| "-".into(), |p| format!("{p:+.2}")),
            r.as_ref().map_or_else(
                || "-".into(),
                |c| format!("{:+.2} {}", c.all.mean, interval(c))
            )
        );
    }
    out
}

fn csv(results: &[ChildSupervision], triggers: &[Trigger]) -> String {
    let mut out = String::from(
        "child,cluster,rule,proposals_per_session,replaced_per_session,score_per_session,protected_per_session\n",
    );
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    for c in results {
        let never = mean(&c.runs[0].iter().map(|x| x.score).collect::<Vec<_>>());
        for (t, trigger) in triggers.iter().enumerate() {
            let of = |f: fn(&Supervised) -> f64| mean(&c.runs[t].iter().map(f).collect::<Vec<_>>());
            let _ = writeln!(
                out,
                "{},{},\"{}\",{:.4},{:.4},{:.4},{:.4}",
                c.user,
                c.cluster,
                trigger.name(),
                of(|x| x.proposals),
                of(|x| x.replaced),
                of(|x| x.score),
                of(|x| x.score) - never
            );
        }
    }
    out
}

pub fn run(args: Args) -> anyhow::Result<()> {
    // The policy the node runs: RE + βE with the authors' constants.
    let (records, spec) = args.study.read(Learning {
        reward: Reward::RePlusBetaE,
        ..Learning::default()
    })?;
    let a = &args.study;
    let started = std::time::Instant::now();
    let cases = cases(&records, &spec.fit).context("fitting the leave-one-out models")?;
    let rules = triggers();
    let bar = super::progress_bar(2 * cases.len() as u64);
    let first = run_study(&cases, &spec, &rules, args.therapist, &|| bar.inc(1));
    // Then, for each rule, proposals at random at its rate: on the same children and draws.
    let matched = matched_random(&summarise(&first, &rules, 0, 0, a.seed));
    let mut triggers = rules.clone();
    triggers.extend(matched.iter().flatten());
    let results = run_study(&cases, &spec, &triggers, args.therapist, &|| bar.inc(1));
    bar.finish_and_clear();
    let summary = summarise(&results, &triggers, 0, a.bootstrap, a.seed);
    let mut next = rules.len();
    let versus_random: Vec<Option<PairedComparison>> = matched
        .iter()
        .enumerate()
        .map(|(t, m)| {
            m.map(|_| {
                next += 1;
                paired(&results, t, next - 1, |x| x.score, a.bootstrap, a.seed)
            })
        })
        .collect();
    println!(
        "{} children, each left out of the models that place them; the cluster's policy \
         pretrained as the node does ({} runs x {} epochs), greedy; {} sessions x {} seeds per \
         child and rule, the same draws for every rule; the therapist plays the child's \
         {}-optimal action at each proposal; {:.1} s",
        results.len(),
        a.pretrain_runs,
        a.pretrain_epochs,
        a.sessions,
        a.seeds,
        match args.therapist {
            Objective::Score => "score",
            Objective::Return => "return",
        },
        started.elapsed().as_secs_f64()
    );
    print!("{}", table(&summary[..rules.len()], &versus_random));
    println!(
        "per session, means over children: proposed / replaced decisions, score, discounted \
         return; protected: score minus the policy's alone, paired by child (95 % t interval \
         over children; wins / ties / losses by each child's interval over seeds; median); \
         per prop: mean protected / mean proposed; vs random: the rule's score minus that of \
         proposals at random at the rule's mean rate, paired by child [95 % t]"
    );
    for s in &summary[..rules.len()] {
        if let Some((child, without)) = &s.protected.most_influential
            && s.proposals > 0.0
        {
            println!(
                "  {}: without {} ({:+.2}) protected {:+.2}",
                s.name, child.unit, child.difference, without.mean
            );
        }
    }
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let json = args.output.join("supervision.json");
    atomic_file::write(&json, serde_json::to_string_pretty(&summary)?.as_bytes())
        .with_context(|| format!("writing {}", json.display()))?;
    let csv_path = args.output.join("supervision.csv");
    atomic_file::write(&csv_path, csv(&results, &triggers).as_bytes())
        .with_context(|| format!("writing {}", csv_path.display()))?;
    println!("wrote {} and {}", json.display(), csv_path.display());
    Ok(())
}
