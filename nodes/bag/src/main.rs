//! `bag`: records the suite's topics over DDS into an MCAP bag (`record`), publishes a bag's
//! messages back on their topics (`play`), and summarises a bag like `ros2 bag info` (`info`).

mod graph_topics;
mod info;
mod play;
mod record;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "bag",
    version,
    about = "Record, play and inspect MCAP bags of the suite"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Record topics over DDS into an MCAP file until SIGINT/SIGTERM.
    Record(record::RecordArgs),
    /// Publish a bag's messages on their topics over DDS.
    Play(play::PlayArgs),
    /// Summarise a bag: topics, types, counts, duration, damage.
    Info(info::InfoArgs),
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    match Cli::parse().command {
        Command::Record(args) => record::run(args).await,
        Command::Play(args) => play::run(args).await,
        Command::Info(args) => info::run(&args),
    }
}
