//! `session_report`: a recorded session (MCAP bag) → one HTML page with its figures.
//!   session_report out/session/session.mcap --output out/session/report.html

use anyhow::Context;
use clap::Parser;
use session_report::{SessionLog, report_html};
use std::path::PathBuf;

#[derive(Parser)]
#[command(about = "Write the HTML report of a session recorded in a bag")]
struct Cli {
    /// The bag (.mcap) the session was recorded in.
    bag: PathBuf,
    /// Where to write the report [default: report.html beside the bag].
    #[arg(long)]
    output: Option<PathBuf>,
    /// Which session, if the bag holds several [default: the last one].
    #[arg(long)]
    session: Option<String>,
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let reader = bag_file::BagReader::open(&cli.bag)
        .with_context(|| format!("reading {}", cli.bag.display()))?;
    if let Some(damage) = reader.damage() {
        eprintln!("warning: {damage}; reporting what was recorded before it");
    }
    let log = SessionLog::from_bag(&reader, cli.session.as_deref())
        .with_context(|| format!("decoding {}", cli.bag.display()))?;
    let html =
        report_html(&log).with_context(|| format!("making the report of {}", cli.bag.display()))?;
    let output = cli
        .output
        .unwrap_or_else(|| cli.bag.with_file_name("report.html"));
    atomic_file::write(&output, html.as_bytes())
        .with_context(|| format!("writing {}", output.display()))?;
    let s = log.summary()?;
    println!(
        "session {}: {} sequences, score {} of {}, report {}",
        s.session_id,
        s.tally.sequences,
        s.tally.score,
        s.tally.max_score,
        output.display()
    );
    Ok(())
}
