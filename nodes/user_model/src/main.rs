//! `user_model`: fit user models, print their predictions, write a synthetic study, or run the
//! user-model node. One module per subcommand under `commands/`.
//!   user_model fit --data ../shared/data/migrave-study --clusters 2 --output models/m.json
//!   user_model predict --model models/m.json > predictions.csv
//!   user_model simulate-study --output out/synthetic_study.csv

mod commands;
mod plot;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(about = "User models: fit, predict, simulate a study, or run the node")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fit user models from interaction data (a study directory, our CSV, or session bags).
    Fit(commands::fit::Args),
    /// Print F^p and F^e (mean, std) of every cluster and input of a model file as CSV.
    Predict(commands::predict::Args),
    /// Write a SYNTHETIC study (20 users, two behaviour groups) in our CSV format.
    SimulateStudy(commands::simulate_study::Args),
    /// Run the user-model node over DDS.
    Run(commands::run::Args),
}

fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    match Cli::parse().command {
        Command::Fit(a) => commands::fit::main(a),
        Command::Predict(a) => commands::predict::main(a),
        Command::SimulateStudy(a) => commands::simulate_study::main(a),
        Command::Run(a) => commands::run::main(a),
    }
}
