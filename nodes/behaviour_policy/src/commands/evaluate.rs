//! `behaviour_policy evaluate`: judges a new Q-table on recorded sessions before it meets a
//! child (counterfactual evaluation from the bags' decisions, results and game states), or
//! refuses where the sessions cannot tell (too few, or a new policy that leaves the logged
//! actions: `off_policy::Limits`); it names damaged bags and the share of sessions left out; and
//! `behaviour_policy evaluate-in-simulation`: the same estimators where the truth is known
//! (sessions logged against a user model, the new policy's exact value beside the estimates).

use super::{LearningArgs, parse_reward, progress_bar, user_models};
use anyhow::{Context, bail};
use behaviour_policy::evaluation_plot::{evaluation_svg, validation_svg};
use behaviour_policy::off_policy::{
    EstimatorCheck, Evaluation, Limits, ScoreCloseness, Validation, evaluate, validate,
};
use behaviour_policy::recorded::{LeftOut, LeftOutKind, LoggedSessions, logged_sessions};
use q_learning::mdp::{ExactValue, TargetPolicy, TargetTemperature};
use q_learning::{Learning, QTable, QTableFile, Reward};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// How the judged policy picks from its table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Temperature {
    Greedy,
    PerState,
    Fixed(f64),
    /// ε-greedy: the live policy's logged exploration.
    Epsilon(f64),
}

fn parse_temperature(s: &str) -> Result<Temperature, String> {
    let bad = || {
        format!(
            "{s:?} is not `greedy`, `per-state`, a positive temperature or `epsilon:E` with E \
             in [0, 1]"
        )
    };
    match s {
        "greedy" => Ok(Temperature::Greedy),
        "per-state" => Ok(Temperature::PerState),
        _ => match s.strip_prefix("epsilon:") {
            Some(e) => match e.parse::<f64>() {
                Ok(e) if (0.0..=1.0).contains(&e) => Ok(Temperature::Epsilon(e)),
                _ => Err(bad()),
            },
            None => match s.parse::<f64>() {
                Ok(t) if t.is_finite() && t > 0.0 => Ok(Temperature::Fixed(t)),
                _ => Err(bad()),
            },
        },
    }
}

impl Temperature {
    fn target(self, learning: &Learning) -> TargetTemperature {
        match self {
            Temperature::Greedy => TargetTemperature::Greedy,
            Temperature::PerState => TargetTemperature::PerState(learning.temperature),
            Temperature::Fixed(t) => TargetTemperature::Fixed(t),
            Temperature::Epsilon(e) => TargetTemperature::EpsilonGreedy(e),
        }
    }

    fn describe(self) -> String {
        match self {
            Temperature::Greedy => "greedy, as in real sessions".into(),
            Temperature::PerState => "softmax at each state's T_s".into(),
            Temperature::Fixed(t) => format!("softmax at T = {t}"),
            Temperature::Epsilon(e) => format!("ε-greedy, ε = {e}"),
        }
    }

    /// Short form for tables and files: `T=2`, `eps=0.1`.
    fn short(self) -> String {
        match self {
            Temperature::Greedy => "greedy".into(),
            Temperature::PerState => "per-state".into(),
            Temperature::Fixed(t) => format!("T={t}"),
            Temperature::Epsilon(e) => format!("eps={e}"),
        }
    }
}

/// The policy judged and the reward it is judged by (both commands).
#[derive(Debug, Clone, clap::Args)]
pub struct Judged {
    /// The Q-table file of the policy to judge.
    #[arg(long)]
    q_table: PathBuf,
    /// How it picks: `greedy` (real sessions), `per-state` (softmax at each state's T_s from
    /// its visits) or a fixed softmax temperature.
    #[arg(long, default_value = "greedy", value_parser = parse_temperature)]
    temperature: Temperature,
    #[arg(long, default_value = "RE+bE", value_parser = parse_reward)]
    reward: Reward,
    #[command(flatten)]
    learning: LearningArgs,
}

impl Judged {
    /// The learning constants (γ, reward) and the judged policy.
    fn load(&self) -> anyhow::Result<(Learning, TargetPolicy)> {
        let learning = self.learning.learning(self.reward)?;
        let file = QTableFile::load(&self.q_table).context("the policy to evaluate (--q-table)")?;
        let target = TargetPolicy::new(file.table, self.temperature.target(&learning))?;
        Ok((learning, target))
    }
}

#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Bags (.mcap) or folders searched for them (recursively).
    #[arg(long, required = true, num_args = 1..)]
    bags: Vec<PathBuf>,
    #[command(flatten)]
    judged: Judged,
    /// Bootstrap resamples of the sessions for the 95 % intervals.
    #[arg(long, default_value_t = 2000)]
    bootstrap: usize,
    /// Seed of the bootstrap's draws.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Refuse when the new policy would leave the logged actions in more than this share of
    /// its sessions (0..1): what the log cannot show would bias every estimate.
    #[arg(long, default_value_t = Limits::default().max_sessions_leaving_support, value_parser = parse_share)]
    max_off_support: f64,
    /// Refuse with fewer whole sessions played by the policy than this (at least 2).
    #[arg(long, default_value_t = Limits::default().min_sessions, value_parser = parse_min_sessions)]
    min_sessions: usize,
    /// No interval for the weighted estimate below this effective sample size.
    #[arg(long, default_value_t = Limits::default().min_effective_sessions)]
    min_effective_sessions: f64,
    /// Where evaluation.json, .svg and .png go.
    #[arg(long, default_value = "out/evaluate")]
    output: PathBuf,
}

fn parse_min_sessions(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n >= 2 => Ok(n),
        _ => Err(format!(
            "{s:?} is not a whole number of at least 2 (one session gives no interval)"
        )),
    }
}

fn parse_share(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if (0.0..=1.0).contains(&x) => Ok(x),
        _ => Err(format!("{s:?} is not a share between 0 and 1")),
    }
}

/// Every .mcap under the given paths, sorted, each once.
fn bag_files(paths: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> anyhow::Result<()> {
        let entries =
            std::fs::read_dir(dir).with_context(|| format!("reading folder {}", dir.display()))?;
        for entry in entries {
            let path = entry
                .with_context(|| format!("reading folder {}", dir.display()))?
                .path();
            if path.is_dir() {
                walk(&path, out)?;
            } else if path.extension().is_some_and(|e| e == "mcap") {
                out.push(path);
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            walk(p, &mut out)?;
        } else if p.exists() {
            out.push(p.clone());
        } else {
            bail!("{}: no such bag or folder", p.display());
        }
    }
    out.sort();
    out.dedup();
    Ok(out)
}

/// What the bags gave.
#[derive(Debug, Default, serde::Serialize)]
struct BagsRead {
    read: usize,
    /// Bags that could not be read at all: (bag, why).
    skipped: Vec<(PathBuf, String)>,
    /// Bags read only up to damage, or never closed: (bag, what is wrong).
    damaged: Vec<(PathBuf, String)>,
}

/// The decisions, results and game states of every readable bag, taken through the suite's
/// rule for what arrives twice (`session_log`): a message delivered again is taken once, in a
/// bag or across bags. A bag that cannot be read, or holds a message that contradicts one
/// taken before (same identity, other content), is named and skipped; a damaged one is read
/// up to the damage, and the damage named.
fn read_bags(files: &[PathBuf]) -> (LoggedSessions, BagsRead) {
    let mut rule = session_log::SessionReader::new();
    let mut messages = session_log::Messages::default();
    let mut bags = BagsRead::default();
    for f in files {
        let read = bag_file::BagReader::open(f)
            .map_err(session_log::SessionLogError::from)
            .and_then(|reader| rule.read_bag(&reader));
        match read {
            Ok(log) => {
                let (d, r) = (log.messages.decisions.len(), log.messages.results.len());
                let damage = match (&log.damage, log.complete) {
                    (Some(e), _) => Some(format!(
                        "{e}; read up to it ({d} decisions, {r} results), nothing after"
                    )),
                    (None, false) => Some(format!(
                        "{}: not closed cleanly (no footer: the recording was cut off); read to \
                         its last whole record ({d} decisions, {r} results)",
                        log.source
                    )),
                    (None, true) => None,
                };
                if let Some(repeats) = log.repeats_warning() {
                    tracing::info!("{repeats}");
                }
                messages.extend(log.messages);
                bags.read += 1;
                if let Some(why) = damage {
                    bags.damaged.push((f.clone(), why));
                }
            }
            Err(e) => bags.skipped.push((f.clone(), e.to_string())),
        }
    }
    (logged_sessions(&messages), bags)
}

/// One estimate as it may be shown: its interval, or why there is none.
#[derive(Debug, Clone, serde::Serialize)]
struct Shown {
    estimator: &'static str,
    quantity: &'static str,
    value: f64,
    interval: Option<[f64; 2]>,
    no_interval: Option<String>,
}

/// The estimates with the intervals that mean nothing withheld: the weighted estimate's below
/// the effective sessions required, and any of zero width.
fn shown(e: &Evaluation, limits: &Limits) -> Vec<Shown> {
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
fn estimates_table(e: &Evaluation, rows: &[Shown]) -> String {
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
fn support_line(e: &Evaluation) -> String {
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
fn left_out_lines(log: &LoggedSessions) -> String {
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

fn write_outputs(
    dir: &Path,
    name: &str,
    json: &impl serde::Serialize,
    svg: Result<String, String>,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(format!("{name}.json"));
    atomic_file::write(&path, serde_json::to_string_pretty(json)?.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    let svg = svg.map_err(|e| anyhow::anyhow!("drawing {name}: {e}"))?;
    let (svg, png) = figures::write_svg_and_png(&dir.join(name), &svg)?;
    println!(
        "wrote {}, {} and {}",
        path.display(),
        svg.display(),
        png.display()
    );
    Ok(())
}

/// What `evaluate` writes to evaluation.json.
#[derive(Debug, serde::Serialize)]
struct Report<'a> {
    q_table: &'a Path,
    temperature: String,
    limits: Limits,
    bags: &'a BagsRead,
    sessions_recorded: usize,
    sessions_evaluated: usize,
    left_out: &'a [LeftOut],
    estimates: Vec<Shown>,
    effective_sample_size: f64,
    sessions_with_weight: usize,
    mean_new_probability: f64,
    sessions_leaving_support: Option<f64>,
    mass_outside_support: Option<f64>,
    weights: &'a [f64],
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let (learning, target) = a.judged.load()?;
    if !(a.min_effective_sessions.is_finite() && a.min_effective_sessions >= 0.0) {
        bail!("--min-effective-sessions must be a number at least 0");
    }
    let limits = Limits {
        max_sessions_leaving_support: a.max_off_support,
        min_sessions: a.min_sessions,
        min_effective_sessions: a.min_effective_sessions,
    };
    let files = bag_files(&a.bags)?;
    if files.is_empty() {
        bail!("no .mcap bag found under {:?}", a.bags);
    }
    let (log, bags) = read_bags(&files);
    println!(
        "bags: {} read ({} damaged), {} skipped",
        bags.read,
        bags.damaged.len(),
        bags.skipped.len()
    );
    for (bag, why) in &bags.skipped {
        println!("  skipped {}: {why}", bag.display());
    }
    for (_, why) in &bags.damaged {
        println!("  damaged: {why}");
    }
    print!("{}", left_out_lines(&log));
    if log.sessions.is_empty() {
        bail!("no whole session played by the policy in the bags: nothing to evaluate");
    }
    let e = evaluate(
        &log.sessions,
        Some(&log.distributions),
        &target,
        &learning,
        a.bootstrap,
        a.seed,
    )?;
    println!(
        "new policy: {} ({}); reward {}, γ {}; {} bootstrap resamples, seed {}",
        a.judged.q_table.display(),
        a.judged.temperature.describe(),
        learning.reward,
        learning.gamma,
        a.bootstrap,
        a.seed
    );
    println!("{}", support_line(&e));
    let refusals = e.refusals(&limits);
    if !refusals.is_empty() {
        bail!(
            "refusing to estimate: {}",
            refusals
                .iter()
                .map(|r| r.to_string())
                .collect::<Vec<_>>()
                .join("; and ")
        );
    }
    let rows = shown(&e, &limits);
    println!();
    print!("{}", estimates_table(&e, &rows));
    let report = Report {
        q_table: &a.judged.q_table,
        temperature: a.judged.temperature.describe(),
        limits,
        bags: &bags,
        sessions_recorded: log.seen(),
        sessions_evaluated: e.sessions,
        left_out: &log.left_out,
        effective_sample_size: e.effective_sample_size,
        sessions_with_weight: e.sessions_with_weight,
        mean_new_probability: e.mean_new_probability,
        sessions_leaving_support: e.sessions_leaving_support,
        mass_outside_support: e.mass_outside_support,
        weights: &e.weights,
        estimates: rows.clone(),
    };
    // The figure draws no bar where the printout gives no interval.
    let mut drawn = e.clone();
    for q in [&mut drawn.discounted_return, &mut drawn.score] {
        if let Some(w) = q.weighted_is.as_mut()
            && !e.weighted_interval_holds(&limits)
        {
            (w.low, w.high) = (w.value, w.value);
        }
        if !e.per_decision_interval_holds() {
            let p = &mut q.per_decision_is;
            (p.low, p.high) = (p.value, p.value);
        }
    }
    let subtitle = format!(
        "{} judged on {} recorded session(s) ({}); reward {}, 95 % bootstrap intervals (none \
         drawn where none holds)",
        a.judged.q_table.display(),
        e.sessions,
        a.judged.temperature.describe(),
        learning.reward
    );
    write_outputs(
        &a.output,
        "evaluation",
        &report,
        evaluation_svg(&drawn, &subtitle),
    )
}

#[derive(Debug, Clone, clap::Args)]
pub struct SimulationArgs {
    #[arg(long, default_value = "nodes/user_model/models/migrave_study_c2.json")]
    user_models: PathBuf,
    #[arg(long)]
    per_level_reference: bool,
    /// The user model (cluster) the simulated children come from.
    #[arg(long, default_value_t = 0)]
    cluster: usize,
    /// The Q-table of the policy that plays and logs the sessions.
    #[arg(long)]
    logging_q_table: PathBuf,
    /// How the logging policy picks (it must explore for the estimates to see other actions):
    /// a softmax temperature, `per-state`, `greedy`, or `epsilon:E` (the live policy's logged
    /// exploration, `exploration_epsilon`). Several, comma-separated, make a sweep.
    #[arg(long, default_value = "2", value_parser = parse_temperature, value_delimiter = ',')]
    logging_temperature: Vec<Temperature>,
    #[command(flatten)]
    judged: Judged,
    /// Logged sessions per seed; several, comma-separated, make a sweep (a seed's first N
    /// sessions are the same whatever the number after them, and the same uniforms drive
    /// every logging policy).
    #[arg(long, default_value = "200", value_delimiter = ',')]
    sessions: Vec<usize>,
    /// Seeds 0..N, each its own logged sessions and estimate.
    #[arg(long, default_value_t = 100)]
    seeds: u64,
    #[arg(long, default_value_t = 1000)]
    bootstrap: usize,
    /// Points of score: how often is the judged policy's score judged within ± this?
    #[arg(long, default_value_t = 1.0)]
    tolerance: f64,
    #[arg(long, default_value = "out/evaluate-in-simulation")]
    output: PathBuf,
}

/// The lines saying how often the score was judged within the tolerance.
fn closeness_lines(v: &Validation, tolerance: f64) -> String {
    let c = v.score_closeness(tolerance);
    let mut out = String::new();
    for (name, x) in [
        ("weighted IS, score", c.weighted_is),
        ("per-decision IS, score", c.per_decision_is),
    ] {
        let _ = writeln!(
            out,
            "{name:<34} estimate within ±{tolerance} of the truth in {:.1} % of seeds; \
             interval shown in {:.1} %, inside truth ±{tolerance} in {:.1} %{}",
            100.0 * x.estimate_within,
            100.0 * x.interval_shown,
            100.0 * x.interval_within,
            x.median_half_width
                .map(|h| format!(" (median half-width {h:.2})"))
                .unwrap_or_default()
        );
    }
    out
}

/// One case of a sweep, as `sweep.json` and `sweep.csv` hold it.
#[derive(Debug, serde::Serialize)]
struct SweepCase {
    logging: String,
    sessions: usize,
    seeds: usize,
    logging_truth: ExactValue,
    truth: ExactValue,
    mean_effective_sample_size: f64,
    weighted_is_score: EstimatorCheck,
    per_decision_is_score: EstimatorCheck,
    closeness: ScoreCloseness,
}

fn sweep_csv(cases: &[SweepCase]) -> String {
    let mut out = String::from(
        "logging,sessions,seeds,logging_true_score,judged_true_score,mean_effective_sessions,\
         wis_seeds,wis_bias,wis_rmse,wis_coverage,wis_within,wis_interval_shown,wis_interval_within,\
         wis_median_half_width,pdis_bias,pdis_rmse,pdis_coverage,pdis_within,pdis_interval_shown,\
         pdis_interval_within,pdis_median_half_width\n",
    );
    let half = |h: Option<f64>| h.map(|h| format!("{h:.4}")).unwrap_or_default();
    for c in cases {
        let (w, p) = (c.closeness.weighted_is, c.closeness.per_decision_is);
        let _ = writeln!(
            out,
            "{},{},{},{:.4},{:.4},{:.2},{},{:.4},{:.4},{:.3},{:.3},{:.3},{:.3},{},{:.4},{:.4},{:.3},{:.3},{:.3},{:.3},{}",
            c.logging,
            c.sessions,
            c.seeds,
            c.logging_truth.score,
            c.truth.score,
            c.mean_effective_sample_size,
            c.weighted_is_score.seeds,
            c.weighted_is_score.bias,
            c.weighted_is_score.rmse,
            c.weighted_is_score.coverage,
            w.estimate_within,
            w.interval_shown,
            w.interval_within,
            half(w.median_half_width),
            c.per_decision_is_score.bias,
            c.per_decision_is_score.rmse,
            c.per_decision_is_score.coverage,
            p.estimate_within,
            p.interval_shown,
            p.interval_within,
            half(p.median_half_width),
        );
    }
    out
}

pub fn run_in_simulation(a: SimulationArgs) -> anyhow::Result<()> {
    let (learning, target) = a.judged.load()?;
    let (tables, source) = user_models::load(&a.user_models, a.per_level_reference)?;
    user_models::check_clusters(&tables, &[a.cluster], &source)?;
    let logging_table = QTableFile::load(&a.logging_q_table)
        .context("the logging policy (--logging-q-table)")?
        .table;
    if a.sessions.contains(&0) || a.seeds == 0 {
        bail!("--sessions and --seeds must be at least 1");
    }
    if !(a.tolerance.is_finite() && a.tolerance > 0.0) {
        bail!("--tolerance must be a positive number of points");
    }
    if a.logging_temperature.len() > 1 || a.sessions.len() > 1 {
        return run_sweep(
            &a,
            &learning,
            &target,
            (&tables[a.cluster], &source),
            logging_table,
        );
    }
    let (logging_temperature, sessions) = (a.logging_temperature[0], a.sessions[0]);
    let logging = TargetPolicy::new(logging_table, logging_temperature.target(&learning))?;
    println!(
        "children: cluster {} of {source}; logging: {} ({}); judged: {} ({}); {} sessions per \
         seed, {} seeds, {} bootstrap resamples",
        a.cluster,
        a.logging_q_table.display(),
        logging_temperature.describe(),
        a.judged.q_table.display(),
        a.judged.temperature.describe(),
        sessions,
        a.seeds,
        a.bootstrap
    );
    let bar = progress_bar(a.seeds);
    let v = validate(
        &tables[a.cluster],
        &logging,
        &target,
        &learning,
        sessions,
        0..a.seeds,
        a.bootstrap,
        &|| bar.inc(1),
    )?;
    bar.finish_and_clear();
    println!(
        "exact value per session (backward induction over the user model): judged policy \
         return {:.3}, score {:.3}; logging policy return {:.3}, score {:.3}",
        v.truth.discounted_return,
        v.truth.score,
        v.logging_truth.discounted_return,
        v.logging_truth.score
    );
    println!(
        "{:<34} {:>8} {:>8} {:>15}",
        "estimator", "bias", "RMSE", "95 % coverage"
    );
    for (name, c) in [
        ("weighted IS, return", v.weighted_is_return),
        ("per-decision IS, return", v.per_decision_is_return),
        ("weighted IS, score", v.weighted_is_score),
        ("per-decision IS, score", v.per_decision_is_score),
        (
            "weighted IS, return, where shown",
            v.weighted_is_return_where_shown,
        ),
    ] {
        if c.seeds == 0 {
            println!("{name:<34} (no seed gave one)");
            continue;
        }
        println!(
            "{name:<34} {:>+8.3} {:>8.3} {:>8.1} % of {}",
            c.bias,
            c.rmse,
            100.0 * c.coverage,
            c.seeds
        );
    }
    println!(
        "mean effective sample size: {:.1} of {} sessions",
        v.mean_effective_sample_size, v.sessions
    );
    print!("{}", closeness_lines(&v, a.tolerance));
    let subtitle = format!(
        "{} sessions logged by {} ({}) against cluster {}; judged: {} ({})",
        sessions,
        a.logging_q_table.display(),
        logging_temperature.describe(),
        a.cluster,
        a.judged.q_table.display(),
        a.judged.temperature.describe()
    );
    write_outputs(&a.output, "validation", &v, validation_svg(&v, &subtitle))
}

/// Every (logging policy, sessions) pair on the same seeds: a table of how often the score is
/// judged within the tolerance, `sweep.csv` and `sweep.json`.
fn run_sweep(
    a: &SimulationArgs,
    learning: &Learning,
    target: &TargetPolicy,
    (model, source): (&sequence_game::UserModelTable, &str),
    table: QTable,
) -> anyhow::Result<()> {
    println!(
        "children: cluster {} of {source}; logging: {} ({}); judged: {} ({}); sessions per \
         seed {:?}, {} seeds (the same for every case), {} bootstrap resamples; score judged \
         within ±{} point(s)",
        a.cluster,
        a.logging_q_table.display(),
        a.logging_temperature
            .iter()
            .map(|t| t.describe())
            .collect::<Vec<_>>()
            .join(" | "),
        a.judged.q_table.display(),
        a.judged.temperature.describe(),
        a.sessions,
        a.seeds,
        a.bootstrap,
        a.tolerance
    );
    let total = (a.logging_temperature.len() * a.sessions.len()) as u64 * a.seeds;
    let bar = progress_bar(total);
    let mut cases = Vec::new();
    for t in &a.logging_temperature {
        let logging = TargetPolicy::new(table.clone(), t.target(learning))?;
        for &sessions in &a.sessions {
            let v = validate(
                model,
                &logging,
                target,
                learning,
                sessions,
                0..a.seeds,
                a.bootstrap,
                &|| bar.inc(1),
            )?;
            cases.push(SweepCase {
                logging: t.short(),
                sessions,
                seeds: v.seeds,
                logging_truth: v.logging_truth,
                truth: v.truth,
                mean_effective_sample_size: v.mean_effective_sample_size,
                weighted_is_score: v.weighted_is_score,
                per_decision_is_score: v.per_decision_is_score,
                closeness: v.score_closeness(a.tolerance),
            });
        }
    }
    bar.finish_and_clear();
    if let Some(c) = cases.first() {
        println!(
            "exact score per session (backward induction over the user model): judged policy \
             {:.3} (return {:.3})",
            c.truth.score, c.truth.discounted_return
        );
    }
    let pct = |x: f64| format!("{:.0} %", 100.0 * x);
    let half = |h: Option<f64>| h.map_or_else(|| "-".into(), |h| format!("{h:.2}"));
    println!(
        "{:<9} {:>8} {:>8} {:>9} | {:>8} {:>6} {:>6} {:>6} {:>7} | {:>8} {:>6} {:>6} {:>6} {:>7}",
        "logging",
        "sessions",
        "log score",
        "eff. ses.",
        "WIS RMSE",
        "cover",
        "±tol",
        "CI in",
        "½ width",
        "PDIS RMSE",
        "cover",
        "±tol",
        "CI in",
        "½ width"
    );
    for c in &cases {
        let (w, p) = (c.closeness.weighted_is, c.closeness.per_decision_is);
        let (wc, pc) = (c.weighted_is_score, c.per_decision_is_score);
        let rmse = |e: EstimatorCheck| {
            if e.seeds == 0 {
                "-".into()
            } else {
                format!("{:.2}", e.rmse)
            }
        };
        println!(
            "{:<9} {:>8} {:>8.2} {:>9.1} | {:>8} {:>6} {:>6} {:>6} {:>7} | {:>8} {:>6} {:>6} {:>6} {:>7}",
            c.logging,
            c.sessions,
            c.logging_truth.score,
            c.mean_effective_sample_size,
            rmse(wc),
            pct(wc.coverage),
            pct(w.estimate_within),
            pct(w.interval_within),
            half(w.median_half_width),
            rmse(pc),
            pct(pc.coverage),
            pct(p.estimate_within),
            pct(p.interval_within),
            half(p.median_half_width)
        );
    }
    println!(
        "log score: the logging policy's exact score; RMSE and cover (95 % intervals holding the \
         truth) over the seeds with an estimate; ±tol: seeds whose estimate of the score is \
         within ±{0} of the truth; CI in: seeds where evaluate shows a 95 % interval lying \
         inside the truth ±{0}; ½ width: the shown intervals' median half-width",
        a.tolerance
    );
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let json = a.output.join("sweep.json");
    atomic_file::write(&json, serde_json::to_string_pretty(&cases)?.as_bytes())
        .with_context(|| format!("writing {}", json.display()))?;
    let csv = a.output.join("sweep.csv");
    atomic_file::write(&csv, sweep_csv(&cases).as_bytes())
        .with_context(|| format!("writing {}", csv.display()))?;
    println!("wrote {} and {}", json.display(), csv.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn temperatures_parse_or_say_what_is_expected() {
        assert_eq!(parse_temperature("greedy"), Ok(Temperature::Greedy));
        assert_eq!(parse_temperature("per-state"), Ok(Temperature::PerState));
        assert_eq!(parse_temperature("0.5"), Ok(Temperature::Fixed(0.5)));
        assert_eq!(
            parse_temperature("epsilon:0.1"),
            Ok(Temperature::Epsilon(0.1))
        );
        for bad in [
            "0",
            "-1",
            "nan",
            "hot",
            "epsilon:1.5",
            "epsilon:",
            "epsilon:nan",
        ] {
            let e = parse_temperature(bad).unwrap_err();
            assert!(e.contains("greedy"), "{e}");
        }
    }
}
