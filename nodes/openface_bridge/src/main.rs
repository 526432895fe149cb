//! `openface_bridge`: follows the CSV OpenFace 2's FeatureExtraction writes (or standard input)
//! and publishes each face and frame on /qt_therapy/openface/features.
//!   openface_bridge --csv /home/qtrobot/openface/webcam.csv
//!   FeatureExtraction -device 0 -pose -aus -gaze -out_dir /tmp/of -of webcam  (writes it)

use clap::Parser;
use node_shell::{NodeShell, ShellOptions};
use openface_bridge::node::{NODE, run};
use openface_bridge::{Bridge, OpenFaceBridgeParams};

#[derive(Parser)]
#[command(
    about = "Publish OpenFace's CSV (FeatureExtraction output, followed as it grows) as OpenFaceFeatures messages"
)]
struct Cli {
    /// The CSV to follow, or - for standard input (overrides csv_path of the parameter file).
    #[arg(long)]
    csv: Option<String>,
    /// The CSV is a finished recording: publish it on OpenFace's own clock at this multiple
    /// of it (1: real time) and end at its end (overrides replay_rate).
    #[arg(long, value_name = "RATE")]
    rate: Option<f64>,
    #[command(flatten)]
    shell: ShellOptions,
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    let mut cli = Cli::parse();
    // As the parameters' overrides, so ROS 2 tools see (and `ros2 param dump` writes) what the
    // bridge runs with. The path single-quoted (its quotes doubled): a YAML string, whatever
    // it looks like.
    if let Some(csv) = &cli.csv {
        let value = csv.replace('\'', "''");
        cli.shell
            .param_overrides
            .push(format!("csv_path:='{value}'"));
    }
    if let Some(rate) = cli.rate {
        cli.shell
            .param_overrides
            .push(format!("replay_rate:={rate:?}"));
    }
    let (mut shell, params): (NodeShell, OpenFaceBridgeParams) =
        NodeShell::start(NODE, &cli.shell)?;
    let params_file = cli.shell.params_path(shell.name());
    let outcome = match params.validate() {
        Ok(stamp) => run(&mut shell, &params, Bridge::new(&params, stamp)).await,
        Err(e) => Err(anyhow::Error::new(e).context(format!(
            "parameter file {} (or --csv, --rate)",
            params_file.display()
        ))),
    };
    shell.stop().await;
    outcome
}
