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
    let cli = Cli::parse();
    let (mut shell, mut params): (NodeShell, OpenFaceBridgeParams) =
        NodeShell::start(NODE, &cli.shell)?;
    if let Some(csv) = &cli.csv {
        params.csv_path = csv.clone();
    }
    if let Some(rate) = cli.rate {
        params.replay_rate = rate;
    }
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
