//! `launch`: starts the suite's node processes from a ROS 2 YAML launch file in
//! `launch_scripts/`, e.g. `launch launch_scripts/session.launch.yaml seed:=7`.

use launcher::description;
mod supervisor;
mod watchdog;

use anyhow::Context;
use clap::Parser;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

#[derive(Parser)]
#[command(about = "Start node processes from a ROS 2 YAML launch file; Ctrl-C stops them all")]
struct Cli {
    /// The launch file (ROS 2 YAML format: launch: - arg / set_env / executable).
    file: PathBuf,
    /// Launch arguments as NAME:=VALUE.
    arguments: Vec<String>,
    /// Seconds a node gets to exit after SIGINT before it is killed.
    #[arg(long, default_value_t = 5.0)]
    grace: f64,
    /// Print the processes that would start, and exit.
    #[arg(long)]
    print: bool,
    /// Where the processes with `output: log` (or `both`) write `<name>.log`; default
    /// `$ROS_LOG_DIR`, else `$ROS_HOME/log`, else `~/.ros/log`, as ROS 2 does.
    #[arg(long)]
    log_dir: Option<PathBuf>,
}

/// ROS 2's log directory: `$ROS_LOG_DIR`, `$ROS_HOME/log`, or `~/.ros/log`.
fn default_log_dir() -> PathBuf {
    let var = |name| {
        std::env::var_os(name)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    var("ROS_LOG_DIR")
        .or_else(|| var("ROS_HOME").map(|h| h.join("log")))
        .or_else(|| var("HOME").map(|h| h.join(".ros/log")))
        .unwrap_or_else(|| PathBuf::from(".ros/log"))
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    let cli = Cli::parse();
    let mut overrides = BTreeMap::new();
    for a in &cli.arguments {
        let (k, v) = a
            .split_once(":=")
            .with_context(|| format!("launch argument {a:?} is not NAME:=VALUE"))?;
        overrides.insert(k.to_string(), v.to_string());
    }
    let text = std::fs::read_to_string(&cli.file)
        .with_context(|| format!("reading launch file {}", cli.file.display()))?;
    let specs = description::parse_launch(&text, &cli.file, &overrides)?;
    if cli.print {
        for s in &specs {
            println!("{}: {} {}", s.name, s.program, s.args.join(" "));
        }
        return Ok(());
    }
    if !(cli.grace.is_finite() && cli.grace >= 0.0) {
        anyhow::bail!("--grace {} is not a number of seconds", cli.grace);
    }
    let log_dir = cli.log_dir.unwrap_or_else(default_log_dir);
    let watchdog = watchdog::Watchdog::from_env().context("systemd's watchdog")?;
    let code = supervisor::run(
        specs,
        Duration::from_secs_f64(cli.grace),
        &log_dir,
        watchdog,
    )
    .await?;
    std::process::exit(code);
}
