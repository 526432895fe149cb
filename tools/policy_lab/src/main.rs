//! `policy_lab`: the studies of the paper's behaviour model from the command line.
//!   policy_lab experiments --epochs 400 --runs 30 --output out/policy
//!   policy_lab train --cluster 1 --transfer-from 0     (a Q-table file for the node)
//!   policy_lab evaluate --bags bags --q-table NEW.json  (judge a policy on old sessions)
//!   policy_lab per-child                               (leave-one-child-out adaptation)
//!   policy_lab per-child-belief                        (the same with a belief about the child)
//!   policy_lab supervision                             (supervised autonomy's rules, measured)
//! The decision node itself, and a look at its Q-table files, is `behaviour_policy`.

mod commands;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    about = "Policy lab: the behaviour model's experiments, Q-tables trained in simulation, and \
             studies of the policy"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Every user model x reward (and both transfers) in simulation: CSV and Figs. 4, 5.
    Experiments(commands::experiments::Args),
    /// Pretrain (or transfer) one cluster's Q-table in simulation and write its file.
    Train(commands::train::Args),
    /// Judge a Q-table's policy on recorded sessions (off-policy importance sampling), or
    /// refuse where the sessions cannot tell.
    Evaluate(commands::evaluate::Args),
    /// Check `evaluate`'s estimators where the truth is known: sessions logged against a user
    /// model, the judged policy's exact value beside the estimates, over many seeds.
    EvaluateInSimulation(commands::evaluate::SimulationArgs),
    /// Per-child adaptation: leave one study child out, compare the cluster's policy, a
    /// per-user table started from it, a table learned from scratch on the child and the
    /// optimal policy for the child's model, on the same draws, child by child.
    PerChild(commands::per_child::Args),
    /// Per-child adaptation by a belief about the child (a posterior over known models, or
    /// the child's own model), planned on before each sequence, beside `per-child`'s
    /// policies on the same draws.
    PerChildBelief(commands::per_child_belief::Args),
    /// The prior covariance of a child's own model for the behaviour policy node
    /// (`child_belief: true`), learned from a study's children against their clusters.
    ChildBeliefPrior(commands::child_belief_prior::Args),
    /// Supervised autonomy's proposal rules on the study's children, leave one child out:
    /// proposals per session and the score a therapist who knows the child protects, against
    /// the policy alone and proposals at random at the same rate, paired by child.
    Supervision(commands::supervision::Args),
}

fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    match Cli::parse().command {
        Command::Experiments(a) => commands::experiments::run(a),
        Command::Train(a) => commands::train::run(a),
        Command::Evaluate(a) => commands::evaluate::run(a),
        Command::EvaluateInSimulation(a) => commands::evaluate::run_in_simulation(a),
        Command::PerChild(a) => commands::per_child::run(a),
        Command::PerChildBelief(a) => commands::per_child_belief::run(a),
        Command::ChildBeliefPrior(a) => commands::child_belief_prior::run(a),
        Command::Supervision(a) => commands::supervision::run(a),
    }
}
