//! Decision time of the belief policy (`child_belief::planner::BeliefPolicy`: the child's own model
//! with the learned covariance, planned on before each sequence, the chosen guard
//! (`per_child_belief::DEFAULT_PLANNING` with `BeliefSpec::default()`'s numbers) judging each
//! deviation from the cluster's table on models drawn from the belief), beside the current
//! policy's (`PolicyCore::decide` on the cluster's table, greedy, and its update), in the same
//! run, on the same simulated sessions of the synthetic study's children (no real data needed).
//!
//!   cargo bench -p policy_lab --bench belief_decision [-- --children 6 --sessions 20]
//!
//! Prints per decision the 50th and 99th percentile and the largest time, one thread, by the
//! wall clock and by the thread's CPU clock (the machine is shared: the wall clock also counts
//! the time other programs had the processor), and the ratios of the belief policy's to the
//! current policy's.

use child_belief::planner::{Baseline, BeliefPolicy};
use child_belief::{Observation, OwnModel};
use policy_lab::child_study::per_child::{StudySpec, cases, cluster_table};
use policy_lab::child_study::per_child_belief::{
    BeliefArm, BeliefSpec, DEFAULT_PLANNING, Representation, Start, learned_prior, library_cases,
    planning_rule,
};
use policy_lab::stats::quantile;
use q_learning::mdp::transition;
use q_learning::policy_core::{PolicyCore, Transition};
use q_learning::simulation::{SessionDraws, answers_right};
use q_learning::{Learning, Mode, Reward};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sequence_game::{Outcome, SEQUENCES_PER_SESSION, State};
use std::time::Instant;
use user_models::simulate::{StudySpec as SyntheticStudy, simulate_study};

/// A wall-clock and a thread-CPU-clock stopwatch, in µs.
struct Stopwatch {
    wall: Instant,
    cpu: f64,
}

fn thread_cpu_us() -> f64 {
    nix::time::clock_gettime(nix::time::ClockId::CLOCK_THREAD_CPUTIME_ID).map_or(f64::NAN, |t| {
        t.tv_sec() as f64 * 1e6 + t.tv_nsec() as f64 / 1e3
    })
}

impl Stopwatch {
    fn start() -> Self {
        Stopwatch {
            wall: Instant::now(),
            cpu: thread_cpu_us(),
        }
    }

    /// (wall, CPU) µs since the start.
    fn read(&self) -> (f64, f64) {
        (
            self.wall.elapsed().as_secs_f64() * 1e6,
            thread_cpu_us() - self.cpu,
        )
    }
}

fn arg(name: &str, default: usize) -> usize {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// p50, p99 and the largest of `times` (µs).
fn summary(times: &mut [f64]) -> (f64, f64, f64) {
    times.sort_by(f64::total_cmp);
    (
        quantile(times, 0.5),
        quantile(times, 0.99),
        times.last().copied().unwrap_or(f64::NAN),
    )
}

fn main() -> anyhow::Result<()> {
    let children = arg("--children", 6);
    let sessions = arg("--sessions", 20);
    let records = simulate_study(&SyntheticStudy::default());
    let spec = StudySpec {
        fit: user_models::FitOptions::default(),
        learning: Learning {
            reward: Reward::RePlusBetaE,
            ..Learning::default()
        },
        pretrain_epochs: 100,
        pretrain_runs: 5,
        sessions,
        seeds: 1,
        seed: 7,
    };
    let belief_spec = BeliefSpec::default();
    let all = cases(&records, &spec.fit)?;
    let library = library_cases(&records, &all, &spec.fit)?;
    // Per decision (wall µs, CPU µs) of each policy.
    let (mut current, mut belief) = ((Vec::new(), Vec::new()), (Vec::new(), Vec::new()));
    for (i, case) in library.iter().take(children).enumerate() {
        let table = cluster_table(&case.case, i, &spec);
        let (prior, covariance) = learned_prior(&library, i, Start::Cluster, &belief_spec)?;
        let own = OwnModel::with_covariance(prior, &covariance, belief_spec.own_model)?;
        let mut policy = BeliefPolicy::new(
            own,
            Some(Baseline::of_table(&table)),
            spec.learning,
            planning_rule(DEFAULT_PLANNING, &belief_spec),
        );
        let mut core = PolicyCore::new(table, spec.learning, Mode::Exploit, 7, 0);
        let child = &case.case.child_model;
        let mut rng = ChaCha8Rng::seed_from_u64(i as u64);
        for k in 0..sessions {
            let draws = SessionDraws::new((i * 1000 + k) as u64);
            policy.start_session(&mut rng);
            let (mut s_belief, mut s_core) = (State::START, State::START);
            for j in 0..SEQUENCES_PER_SESSION {
                let step = j as u8 + 1;
                // The belief policy: decide, then learn from the child's answer.
                let t = Stopwatch::start();
                let action = policy
                    .decide(s_belief, step, draws.action[j], &mut rng)
                    .action;
                let decided = t.read();
                let Some((input, _)) = transition(s_belief, action, Outcome::Success) else {
                    anyhow::bail!("the plan left the mask at {s_belief}");
                };
                let outcome = Outcome::from_correct(answers_right(
                    draws.answer[j],
                    child.success(input).mean,
                ));
                let e = child.engagement(input, outcome).mean.clamp(-1.0, 1.0);
                let t = Stopwatch::start();
                policy.observe(&Observation::new(input, outcome, e)?);
                let observed = t.read();
                belief.0.push(decided.0 + observed.0);
                belief.1.push(decided.1 + observed.1);
                s_belief = transition(s_belief, action, outcome).map_or(s_belief, |(_, n)| n);
                // The current policy on the same draws.
                let t = Stopwatch::start();
                let d = core.decide(s_core, step)?;
                let Some((input, next)) = transition(s_core, d.action, Outcome::Success) else {
                    anyhow::bail!("the table left the mask at {s_core}");
                };
                let outcome = Outcome::from_correct(answers_right(
                    draws.answer[j],
                    child.success(input).mean,
                ));
                let next = transition(s_core, d.action, outcome).map_or(next, |(_, n)| n);
                core.learn(&Transition {
                    state: s_core,
                    action: d.action,
                    activity_result: outcome.activity_result(input.level),
                    engagement: child.engagement(input, outcome).mean.clamp(-1.0, 1.0),
                    next_state: next,
                    is_last: step as usize == SEQUENCES_PER_SESSION,
                })?;
                let (wall, cpu) = t.read();
                current.0.push(wall);
                current.1.push(cpu);
                s_core = next;
            }
        }
    }
    println!(
        "{} decisions each ({} children x {} sessions x 10), one thread, µs per decision with its \
         update:",
        belief.0.len(),
        children.min(library.len()),
        sessions
    );
    let arm = BeliefArm {
        representation: Representation::OwnModelLearned,
        planning: DEFAULT_PLANNING,
        start: Start::Cluster,
    };
    println!(
        "belief policy: {}; {:?}",
        arm.name(),
        planning_rule(DEFAULT_PLANNING, &belief_spec)
    );
    println!("{:<56} {:>9} {:>9} {:>9}", "", "p50", "p99", "max");
    // [policy][clock]: p50 and p99.
    let (mut p50s, mut p99) = ([[0.0; 2]; 2], [[0.0; 2]; 2]);
    for (clock, c) in [("wall", 0), ("thread CPU", 1)] {
        for (who, times, w) in [
            ("current policy (cluster table, greedy)", &mut current, 0),
            ("belief policy", &mut belief, 1),
        ] {
            let t = if c == 0 { &mut times.0 } else { &mut times.1 };
            let (p50, p99_, max) = summary(t);
            p50s[w][c] = p50;
            p99[w][c] = p99_;
            println!(
                "{:<56} {p50:>9.2} {p99_:>9.2} {max:>9.2}",
                format!("{who}, {clock}")
            );
        }
    }
    println!(
        "belief policy p99: {:.2} ms wall, {:.2} ms CPU (target < 10 ms); ratio to the current \
         policy's p50: {:.0}x wall, {:.0}x CPU; p99: {:.0}x wall, {:.0}x CPU",
        p99[1][0] / 1000.0,
        p99[1][1] / 1000.0,
        p50s[1][0] / p50s[0][0],
        p50s[1][1] / p50s[0][1],
        p99[1][0] / p99[0][0],
        p99[1][1] / p99[0][1]
    );
    Ok(())
}
