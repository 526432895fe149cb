//! `engagement_classifier`: the engagement node's offline tools, one module per subcommand
//! under `cli/` (train, cross-validate, predict, synthesize, plot-study). The DDS node will
//! be one more subcommand, `run`.

mod cli;

use clap::Parser;

#[derive(Parser)]
#[command(name = "engagement_classifier", version, about)]
struct Cli {
    #[command(subcommand)]
    command: cli::Command,
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    Cli::parse().command.run()
}
