//! `engagement_classifier`: the engagement node's offline tools, one module per subcommand
//! under `cli/` (train, cross-validate, predict, synthesize, plot-study), and the DDS node,
//! `run`.

mod commands;

use clap::Parser;

#[derive(Parser)]
#[command(name = "engagement_classifier", version, about)]
struct Cli {
    #[command(subcommand)]
    command: commands::Command,
}

fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    let cli = Cli::parse();
    // The node sets up its own logging (stderr and /rosout) in the node shell.
    if let commands::Command::Run(args) = cli.command {
        return commands::run::run(args);
    }
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    cli.command.run()
}
