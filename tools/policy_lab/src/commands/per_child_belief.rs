//! `policy_lab per-child-belief`: per-child adaptation by a belief about the child
//! (`policy_lab::child_study::per_child_belief`), on `per-child`'s leave-one-child-out study and its
//! draws: each belief arm beside the cluster policy, the per-user table and the child's
//! optimum, paired by child; the share of the cluster-to-optimum return gap each captures,
//! the worst child-session against the cluster policy, and what identifying the child among
//! the known models alone could reach.

use super::child_study::ChildStudyArgs;
use super::{LearningArgs, parse_reward};
use anyhow::Context;
use child_belief::{LibraryParams, OwnModelParams};
use policy_lab::child_study::per_child::StudySpec;
use policy_lab::child_study::per_child::{Arm, ChildResult, SessionRun, cases, run_study};
use policy_lab::child_study::per_child_belief::{
    BeliefArm, BeliefSpec, Identification, Planning, Representation, Start, identification,
    library_cases, run_belief_arm,
};
use policy_lab::stats::{Interval, PairedComparison, mean, quantile, t_interval};
use q_learning::Reward;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::fmt::Write as _;
use std::path::PathBuf;
use user_models::InteractionRecord;

#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    #[command(flatten)]
    study: ChildStudyArgs,
    #[arg(long, default_value = "RE+bE", value_parser = parse_reward)]
    reward: Reward,
    #[command(flatten)]
    learning: LearningArgs,
    /// The belief arms: REPRESENTATION-PLANNING-START, the representation library, own or
    /// learned (own model, learned covariance), the planning mean, sampling, cautious,
    /// guarded, fading, chance, bounded or spibb, the start cluster or population, e.g.
    /// library-mean-cluster. By default the chosen rule from both starts.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "learned-chance-cluster,learned-chance-population"
    )]
    arms: Vec<String>,
    /// Library: σ of an observed engagement around a known model's prediction.
    #[arg(long, default_value_t = LibraryParams::default().engagement_sd)]
    engagement_sd: f64,
    /// Library: each known model's P(success) is clamped into [floor, 1 − floor].
    #[arg(long, default_value_t = LibraryParams::default().success_floor)]
    success_floor: f64,
    /// Library: the log-likelihood so far is multiplied by this before each observation.
    #[arg(long, default_value_t = LibraryParams::default().forgetting)]
    library_forgetting: f64,
    /// Library from a cluster: prior weight of each known model of another cluster.
    #[arg(long, default_value_t = BeliefSpec::default().other_cluster_weight)]
    other_cluster_weight: f64,
    /// Library from a cluster: prior weight of the cluster's model (1 per child).
    #[arg(long, default_value_t = BeliefSpec::default().cluster_model_weight)]
    cluster_model_weight: f64,
    /// Own model: prior σ of P(success) around the prior model.
    #[arg(long, default_value_t = OwnModelParams::default().success_sd)]
    own_success_sd: f64,
    /// Own model: prior σ of engagement around the prior model.
    #[arg(long, default_value_t = OwnModelParams::default().engagement_sd)]
    own_engagement_sd: f64,
    /// Own model: noise variance of one answer.
    #[arg(long, default_value_t = OwnModelParams::default().answer_noise)]
    answer_noise: f64,
    /// Own model: noise σ of one engagement.
    #[arg(long, default_value_t = OwnModelParams::default().engagement_noise)]
    engagement_noise: f64,
    /// Own model: prior correlation between adjacent levels.
    #[arg(long, default_value_t = OwnModelParams::default().level_correlation)]
    level_correlation: f64,
    /// Own model: prior correlation between different feedbacks.
    #[arg(long, default_value_t = OwnModelParams::default().feedback_correlation)]
    feedback_correlation: f64,
    /// Own model: length scale over the previous score.
    #[arg(long, default_value_t = OwnModelParams::default().previous_score_length)]
    previous_score_length: f64,
    /// Own model: prior correlation of engagement after a right and a wrong answer.
    #[arg(long, default_value_t = OwnModelParams::default().outcome_correlation)]
    outcome_correlation: f64,
    /// Own model: each earlier observation's weight is multiplied by this per observation.
    #[arg(long, default_value_t = OwnModelParams::default().forgetting)]
    own_forgetting: f64,
    /// Cautious planning: κ, the standard deviations of its expected reward an action the
    /// baseline would not take must clear.
    #[arg(long, default_value_t = BeliefSpec::default().caution)]
    caution: f64,
    /// Learned covariance: shrinkage of the correlations towards 0.
    #[arg(long, default_value_t = BeliefSpec::default().shrinkage)]
    shrinkage: f64,
    /// Learned covariance: the least variance of any input.
    #[arg(long, default_value_t = BeliefSpec::default().variance_floor)]
    variance_floor: f64,
    /// Learned covariance: scaled by this.
    #[arg(long, default_value_t = BeliefSpec::default().covariance_scale)]
    covariance_scale: f64,
    /// Sessions the baseline plays alone at the start while the belief watches.
    #[arg(long, default_value_t = BeliefSpec::default().baseline_sessions)]
    baseline_sessions: usize,
    /// Guarded planning: models drawn from the belief to judge a deviation.
    #[arg(long, default_value_t = BeliefSpec::default().guard_samples)]
    guard_samples: usize,
    /// Fading guard: the child's sequences after which κ is halved.
    #[arg(long, default_value_t = BeliefSpec::default().fading_half)]
    fading_half: f64,
    /// Chance guard: the session's return a session's deviations may risk against the
    /// baseline.
    #[arg(long, default_value_t = BeliefSpec::default().chance_margin)]
    chance_margin: f64,
    /// Chance guard: the share of drawn models allowed to lose more.
    #[arg(long, default_value_t = BeliefSpec::default().chance_risk)]
    chance_risk: f64,
    /// SPIBB: the child's sequences at an input before the plan may use it.
    #[arg(long, default_value_t = BeliefSpec::default().spibb_min_observations)]
    spibb_min_observations: f64,
    /// Only the first N children play (each still in the others' libraries).
    #[arg(long, default_value_t = usize::MAX, hide_default_value = true)]
    children: usize,
    /// Where the CSV files go.
    #[arg(long, default_value = "out/per_child_belief")]
    output: PathBuf,
}

fn parse_arm(s: &str) -> anyhow::Result<BeliefArm> {
    let parts: Vec<&str> = s.split('-').collect();
    let [r, p, st] = parts.as_slice() else {
        anyhow::bail!(
            "arm {s:?}: expected REPRESENTATION-PLANNING-START, e.g. library-mean-cluster"
        );
    };
    Ok(BeliefArm {
        representation: match *r {
            "library" => Representation::Library,
            "own" => Representation::OwnModel,
            "learned" => Representation::OwnModelLearned,
            _ => anyhow::bail!("arm {s:?}: representation is library, own or learned"),
        },
        planning: match *p {
            "mean" => Planning::Mean,
            "sampling" => Planning::Sampling,
            "cautious" => Planning::Cautious,
            "guarded" => Planning::Guarded,
            "fading" => Planning::Fading,
            "chance" => Planning::Chance,
            "bounded" => Planning::SigmaChance,
            "spibb" => Planning::Spibb,
            _ => anyhow::bail!(
                "arm {s:?}: planning is mean, sampling, cautious, guarded, fading, chance, bounded \
                 (σ and chance) or spibb"
            ),
        },
        start: match *st {
            "cluster" => Start::Cluster,
            "population" => Start::Population,
            _ => anyhow::bail!("arm {s:?}: start is cluster or population"),
        },
    })
}

/// One arm's sessions for every child: `[child][seed][session]`.
type ArmRuns = Vec<Vec<SessionRun>>;

/// One child's mean return over seeds and the sessions `window`.
fn child_return(runs: &[SessionRun], window: std::ops::Range<usize>) -> f64 {
    mean(
        &runs
            .iter()
            .map(|r| {
                mean(
                    &r[window.clone()]
                        .iter()
                        .map(|m| m.discounted_return)
                        .collect::<Vec<_>>(),
                )
            })
            .collect::<Vec<_>>(),
    )
}

/// The share of the cluster-to-optimum gap captured over children: Σ (arm − cluster) /
/// Σ (optimum − cluster), with its 95 % percentile-bootstrap interval over children.
fn gap_share(
    arm: &[f64],
    cluster: &[f64],
    optimum: &[f64],
    resamples: usize,
    seed: u64,
) -> (f64, Option<Interval>) {
    let ratio = |idx: &mut dyn Iterator<Item = usize>| {
        let (mut num, mut den) = (0.0, 0.0);
        for i in idx {
            num += arm[i] - cluster[i];
            den += optimum[i] - cluster[i];
        }
        num / den
    };
    let n = arm.len();
    let share = ratio(&mut (0..n));
    if n < 2 || resamples == 0 {
        return (share, None);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut draws: Vec<f64> = (0..resamples)
        .map(|_| {
            let picks: Vec<usize> = (0..n).map(|_| rng.random_range(0..n)).collect();
            ratio(&mut picks.into_iter())
        })
        .collect();
    draws.sort_by(f64::total_cmp);
    (
        share,
        Some(Interval {
            low: quantile(&draws, 0.025),
            high: quantile(&draws, 0.975),
        }),
    )
}

fn interval(i: Option<Interval>) -> String {
    i.map_or_else(
        || "-".into(),
        |i| format!("[{:+.2}, {:+.2}]", i.low, i.high),
    )
}

fn percent(i: Option<Interval>) -> String {
    i.map_or_else(
        || "-".into(),
        |i| format!("[{:.0} %, {:.0} %]", 100.0 * i.low, 100.0 * i.high),
    )
}

/// The child-sessions against the cluster policy: per child and session the mean over seeds
/// of arm − cluster in return.
struct Harm {
    /// The worst: its mean, standard error over seeds, child and session (1-based).
    worst: (f64, f64, String, usize),
    /// How many child-sessions are more than 1 below.
    below_one: usize,
    child_sessions: usize,
}

fn harm(arm: &ArmRuns, cluster: &ArmRuns, users: &[String]) -> Harm {
    let mut h = Harm {
        worst: (f64::INFINITY, 0.0, String::new(), 0),
        below_one: 0,
        child_sessions: 0,
    };
    for ((a, c), user) in arm.iter().zip(cluster).zip(users) {
        let sessions = a.first().map_or(0, Vec::len);
        for k in 0..sessions {
            let d: Vec<f64> = a
                .iter()
                .zip(c)
                .map(|(x, y)| x[k].discounted_return - y[k].discounted_return)
                .collect();
            let m = mean(&d);
            h.child_sessions += 1;
            h.below_one += usize::from(m < -1.0);
            if m < h.worst.0 {
                let se = policy_lab::stats::sample_std(&d) / (d.len() as f64).sqrt();
                h.worst = (m, se, user.clone(), k + 1);
            }
        }
    }
    h
}

/// The paired comparison of two arms' returns over `window`, by child.
fn paired_return(
    a: &ArmRuns,
    b: &ArmRuns,
    users: &[String],
    window: std::ops::Range<usize>,
    resamples: usize,
    seed: u64,
) -> PairedComparison {
    let units: Vec<(String, Vec<f64>)> = a
        .iter()
        .zip(b)
        .zip(users)
        .map(|((x, y), u)| {
            let d = x
                .iter()
                .zip(y)
                .map(|(rx, ry)| {
                    let w = window.clone();
                    mean(
                        &rx[w.clone()]
                            .iter()
                            .map(|m| m.discounted_return)
                            .collect::<Vec<_>>(),
                    ) - mean(
                        &ry[w]
                            .iter()
                            .map(|m| m.discounted_return)
                            .collect::<Vec<_>>(),
                    )
                })
                .collect();
            (u.clone(), d)
        })
        .collect();
    PairedComparison::of(&units, resamples, seed)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let learning = args.learning.learning(args.reward)?;
    let (records, spec) = args.study.read(learning)?;
    let arms: Vec<BeliefArm> = args
        .arms
        .iter()
        .map(|a| parse_arm(a))
        .collect::<anyhow::Result<_>>()?;
    let belief_spec = BeliefSpec {
        library: LibraryParams {
            engagement_sd: args.engagement_sd,
            success_floor: args.success_floor,
            forgetting: args.library_forgetting,
        },
        other_cluster_weight: args.other_cluster_weight,
        cluster_model_weight: args.cluster_model_weight,
        own_model: OwnModelParams {
            success_sd: args.own_success_sd,
            engagement_sd: args.own_engagement_sd,
            answer_noise: args.answer_noise,
            engagement_noise: args.engagement_noise,
            level_correlation: args.level_correlation,
            feedback_correlation: args.feedback_correlation,
            previous_score_length: args.previous_score_length,
            outcome_correlation: args.outcome_correlation,
            forgetting: args.own_forgetting,
        },
        shrinkage: args.shrinkage,
        variance_floor: args.variance_floor,
        covariance_scale: args.covariance_scale,
        caution: args.caution,
        baseline_sessions: args.baseline_sessions,
        guard_samples: args.guard_samples,
        fading_half: args.fading_half,
        chance_margin: args.chance_margin,
        chance_risk: args.chance_risk,
        spibb_min_observations: args.spibb_min_observations,
    };
    belief_spec.library.validate()?;
    belief_spec.own_model.validate()?;
    let started = std::time::Instant::now();
    let runs = run_arms(&records, &spec, &belief_spec, &arms, args.children)?;
    let r = report(&runs, &spec, args.study.bootstrap);
    print!("{}", r.text);
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let mut written = Vec::new();
    for (name, text) in &r.files {
        let path = args.output.join(name);
        atomic_file::write(&path, text.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        written.push(path.display().to_string());
    }
    // On stderr, so that the same run prints the same standard output.
    eprintln!(
        "wrote {} ({:.1} s)",
        written.join(", "),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Every arm's sessions, the per-child study's and the belief arms', and what identification
/// alone reaches.
struct StudyRuns {
    users: Vec<String>,
    cluster: ArmRuns,
    optimum: ArmRuns,
    /// The per-user table, then each belief arm.
    named: Vec<(String, ArmRuns)>,
    identification: Vec<Identification>,
}

/// `children`: the first so many children play (every child is still in the others'
/// libraries).
fn run_arms(
    records: &[InteractionRecord],
    spec: &StudySpec,
    belief_spec: &BeliefSpec,
    arms: &[BeliefArm],
    children: usize,
) -> anyhow::Result<StudyRuns> {
    let all = cases(records, &spec.fit).context("fitting the leave-one-child-out models")?;
    let library = library_cases(records, &all, &spec.fit)
        .context("fitting the known models without each child")?;
    let cases = &all[..children.min(all.len())];
    let baseline: Vec<ChildResult> = run_study(cases, spec, &|| {});
    let of_arm = |arm: Arm| -> ArmRuns {
        baseline
            .iter()
            .map(|c| c.runs[arm as usize].clone())
            .collect()
    };
    let mut named: Vec<(String, ArmRuns)> = vec![("per-user table".into(), of_arm(Arm::PerUser))];
    let bar = super::progress_bar((arms.len() * cases.len()) as u64);
    for arm in arms {
        let runs: ArmRuns = (0..cases.len())
            .map(|i| {
                let r = run_belief_arm(&library, i, arm, belief_spec, spec)
                    .with_context(|| format!("{} for {}", arm.name(), library[i].case.user));
                bar.inc(1);
                r
            })
            .collect::<anyhow::Result<_>>()?;
        named.push((arm.name(), runs));
    }
    bar.finish_and_clear();
    Ok(StudyRuns {
        users: cases.iter().map(|c| c.user.clone()).collect(),
        cluster: of_arm(Arm::Cluster),
        optimum: of_arm(Arm::Optimal),
        named,
        identification: (0..cases.len())
            .map(|i| identification(&library, i, spec, belief_spec))
            .collect(),
    })
}

/// What the command prints and the files it writes (name, content).
struct Report {
    text: String,
    files: Vec<(&'static str, String)>,
}

fn csv_name(name: &str) -> String {
    name.replace(", ", "_").replace(' ', "_")
}

fn report(r: &StudyRuns, spec: &StudySpec, bootstrap: usize) -> Report {
    let (users, cluster, optimum, named) = (&r.users, &r.cluster, &r.optimum, &r.named);
    let seed = spec.seed;
    let sessions = spec.sessions;
    let windows: Vec<std::ops::Range<usize>> = [0..5, 5..10, 10..20, 0..20]
        .into_iter()
        .filter(|w| w.end <= sessions)
        .collect();
    let mut text = String::new();
    let _ = writeln!(
        text,
        "{} children, {} seeds, {} sessions; reward {}; return per session, mean over children",
        users.len(),
        spec.seeds,
        sessions,
        spec.learning.reward
    );
    let per_child = |runs: &ArmRuns, w: &std::ops::Range<usize>| -> Vec<f64> {
        runs.iter().map(|r| child_return(r, w.clone())).collect()
    };
    for w in &windows {
        let c = per_child(cluster, w);
        let o = per_child(optimum, w);
        let _ = writeln!(
            text,
            "\nsessions {}-{}: cluster policy {:.2}, child's optimum {:.2}",
            w.start + 1,
            w.end,
            mean(&c),
            mean(&o)
        );
        let _ = writeln!(
            text,
            "{:<56} {:>7} {:>9} {:>18} {:>10} {:>18} {:>9} {:>24}",
            "arm",
            "return",
            "gap share",
            "95 % bootstrap",
            "− cluster",
            "95 % t",
            "W/T/L",
            "share − per-user's [b.]"
        );
        let per_user_share = per_child(&named[0].1, w);
        for (name, runs) in named {
            let a = per_child(runs, w);
            let (share, ci) = gap_share(&a, &c, &o, bootstrap, seed);
            // Σ (arm − per-user) / Σ (optimum − cluster): the shares' difference, paired by
            // child.
            let shifted: Vec<f64> = a
                .iter()
                .zip(&per_user_share)
                .zip(&c)
                .map(|((x, p), c)| x - p + c)
                .collect();
            let (diff, diff_ci) = gap_share(&shifted, &c, &o, bootstrap, seed);
            let p = paired_return(runs, cluster, users, w.clone(), 0, seed);
            let _ = writeln!(
                text,
                "{:<56} {:>7.2} {:>8.1} % {:>18} {:>+10.2} {:>18} {:>3}/{}/{} {:>+6.1} % {:>17}",
                name,
                mean(&a),
                100.0 * share,
                percent(ci),
                p.all.mean,
                interval(p.all.t_interval),
                p.all.wins,
                p.all.ties,
                p.all.losses,
                100.0 * diff,
                percent(diff_ci)
            );
        }
    }
    let _ = writeln!(
        text,
        "\nWorst child-session against the cluster policy (mean over seeds of the return \
         difference):"
    );
    for (name, runs) in named {
        let h = harm(runs, cluster, users);
        let (d, se, user, k) = &h.worst;
        let _ = writeln!(
            text,
            "{name:<56} {d:+.2} ± {se:.2} s.e. ({user}, session {k}); {} of {} child-sessions \
             below −1",
            h.below_one, h.child_sessions
        );
    }
    let _ = writeln!(
        text,
        "\nPer session, return: mean over children (with its 95 % t interval over children in \
         per_child_belief_sessions.csv)"
    );
    let mut sessions_csv = String::from("arm,session,mean,t_low,t_high,cluster,optimum\n");
    for (name, runs) in named {
        let _ = write!(text, "{name:<56}");
        for k in 0..sessions {
            let at = |r: &ArmRuns| {
                r.iter()
                    .map(|r| child_return(r, k..k + 1))
                    .collect::<Vec<_>>()
            };
            let v = at(runs);
            let _ = write!(text, " {:.1}", mean(&v));
            let (lo, hi) = t_interval(&v).map_or((f64::NAN, f64::NAN), |i| (i.low, i.high));
            let _ = writeln!(
                sessions_csv,
                "{},{},{},{lo},{hi},{},{}",
                csv_name(name),
                k + 1,
                mean(&v),
                mean(&at(cluster)),
                mean(&at(optimum))
            );
        }
        text.push('\n');
    }
    // Identification alone.
    let ids = &r.identification;
    let c: Vec<f64> = ids
        .iter()
        .map(|x| x.cluster_policy.discounted_return)
        .collect();
    let o: Vec<f64> = ids.iter().map(|x| x.optimal.discounted_return).collect();
    let b: Vec<f64> = ids.iter().map(|x| x.best_known.discounted_return).collect();
    let m: Vec<f64> = ids
        .iter()
        .map(|x| x.cluster_model_optimal.discounted_return)
        .collect();
    let (share, ci) = gap_share(&b, &c, &o, bootstrap, seed);
    let (share_m, ci_m) = gap_share(&m, &c, &o, bootstrap, seed);
    let _ = writeln!(
        text,
        "\nExact expected return per session on the child's model (mean over children): cluster \
         policy {:.2}, optimum {:.2}; the best known model's optimal policy {:.2} (gap share \
         {:.1} % {}); the cluster model's optimal policy {:.2} ({:.1} % {})",
        mean(&c),
        mean(&o),
        mean(&b),
        100.0 * share,
        percent(ci),
        mean(&m),
        100.0 * share_m,
        percent(ci_m)
    );
    let _ = writeln!(
        text,
        "{:<10} {:>8} {:>8} {:>8} {:>8}  best known",
        "child", "cluster", "cl.model", "best", "optimum"
    );
    for (x, u) in ids.iter().zip(users) {
        let _ = writeln!(
            text,
            "{:<10} {:>8.2} {:>8.2} {:>8.2} {:>8.2}  {}",
            u,
            x.cluster_policy.discounted_return,
            x.cluster_model_optimal.discounted_return,
            x.best_known.discounted_return,
            x.optimal.discounted_return,
            x.best_known_model
        );
    }
    let mut csv = String::from("user,arm,seed,session,score,engagement,return\n");
    let mut all: Vec<(String, &ArmRuns)> =
        vec![("cluster".into(), cluster), ("optimal".into(), optimum)];
    all.extend(named.iter().map(|(n, r)| (n.clone(), r)));
    for (name, runs) in all {
        for (u, child) in users.iter().zip(runs) {
            for (s, run) in child.iter().enumerate() {
                for (k, m) in run.iter().enumerate() {
                    let _ = writeln!(
                        csv,
                        "{u},{},{s},{},{},{},{}",
                        csv_name(&name),
                        k + 1,
                        m.score,
                        m.engagement,
                        m.discounted_return
                    );
                }
            }
        }
    }
    Report {
        text,
        files: vec![
            ("per_child_belief.csv", csv),
            ("per_child_belief_sessions.csv", sessions_csv),
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use q_learning::Learning;
    use user_models::simulate::{StudySpec as SyntheticStudy, simulate_study};

    #[test]
    fn the_belief_study_prints_and_writes_the_same_twice() {
        // Two whole runs on the synthetic study (user_models' simulated one), from the fits
        // on: the same tables and CSV files, byte for byte.
        let records = simulate_study(&SyntheticStudy::default());
        let spec = StudySpec {
            fit: user_models::FitOptions {
                optimise: false,
                ..Default::default()
            },
            learning: Learning {
                reward: Reward::RePlusBetaE,
                ..Learning::default()
            },
            pretrain_epochs: 10,
            pretrain_runs: 2,
            sessions: 6,
            seeds: 3,
            seed: 3,
        };
        let arms: Vec<BeliefArm> = ["library-mean-cluster", "learned-guarded-cluster"]
            .iter()
            .map(|a| parse_arm(a).expect("an arm"))
            .collect();
        let once = || {
            let runs = run_arms(&records, &spec, &BeliefSpec::default(), &arms, 4).expect("runs");
            report(&runs, &spec, 200)
        };
        let (a, b) = (once(), once());
        assert_eq!(a.text, b.text);
        assert_eq!(a.files, b.files);
        for words in [
            "sessions 1-5: cluster policy",
            "own model (learned covariance), guarded, from cluster",
            "Worst child-session against the cluster policy",
            "the best known model's optimal policy",
        ] {
            assert!(a.text.contains(words), "{words}: {}", a.text);
        }
        // 4 children x (cluster, optimum, per-user, 2 arms) x 3 seeds x 6 sessions.
        assert_eq!(a.files[0].1.lines().count(), 1 + 4 * 5 * 3 * 6);
        assert!(parse_arm("library-mean").is_err());
        assert!(parse_arm("learned-bounded-population").is_ok());
        assert!(parse_arm("own-greedy-cluster").is_err());
    }

    #[test]
    fn the_default_arms_are_the_chosen_rule_from_the_cluster_and_from_the_population() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: Args,
        }
        let cli = <Cli as clap::Parser>::try_parse_from(["per-child-belief"]).expect("defaults");
        let arms: Vec<BeliefArm> = cli
            .args
            .arms
            .iter()
            .map(|a| parse_arm(a).expect("an arm"))
            .collect();
        let chosen = |start| BeliefArm {
            representation: Representation::OwnModelLearned,
            planning: policy_lab::child_study::per_child_belief::DEFAULT_PLANNING,
            start,
        };
        assert_eq!(arms, [chosen(Start::Cluster), chosen(Start::Population)]);
        // The flags' defaults are the study's.
        assert_eq!(cli.args.guard_samples, BeliefSpec::default().guard_samples);
        assert_eq!(cli.args.chance_margin, BeliefSpec::default().chance_margin);
        assert_eq!(cli.args.chance_risk, BeliefSpec::default().chance_risk);
        assert_eq!(
            cli.args.covariance_scale,
            BeliefSpec::default().covariance_scale
        );
        assert_eq!(
            cli.args.baseline_sessions,
            BeliefSpec::default().baseline_sessions
        );
    }
}
