//! `behaviour_policy`: the decision node of the paper's behaviour model.
//!   behaviour_policy run                                     (the DDS decision node)
//!   behaviour_policy show-q-table out/q_tables/cluster_0.json (what a cluster's table holds)
//! The studies, their figures and training Q-table files are `policy_lab`'s
//! (`tools/policy_lab`).

mod commands;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(about = "Behaviour policy: the decision node, and its Q-table files in words")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the decision node over DDS.
    Run {
        #[command(flatten)]
        shell: node_shell::ShellOptions,
    },
    /// Print a Q-table file: per state its Q-values, greedy action, visits, temperature.
    ShowQTable(commands::show_q_table::Args),
}

fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    match Cli::parse().command {
        Command::Run { shell } => tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()?
            .block_on(commands::run::run(shell)),
        Command::ShowQTable(a) => commands::show_q_table::run(a),
    }
}
