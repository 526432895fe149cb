//! `tablet_bridge`: serves the child tablet (/child) and the therapist tablet (/therapist),
//! over HTTPS where its parameters name a certificate, and bridges them to DDS.
//!   tablet_bridge                      (reads params/tablet_bridge.yaml)
//!   QT_TABLET_PIN=8642 tablet_bridge --params-file my.yaml

use anyhow::Context as _;
use clap::Parser;
use node_shell::{NodeShell, ShellOptions};
use qt_therapy_msgs::topics::{
    ACTION_PROPOSAL, DECISION, EXPECTED_ENGAGEMENT, GAME_STATE, HEARTBEAT, SEQUENCE_RESULT,
    TABLET_ANSWER, TABLET_TASK, THERAPIST_COMMAND,
};
use tablet_bridge::server::{Publish, serve, tls_config};
use tablet_bridge::{DdsInput, TabletBridgeParams};
use tokio::sync::mpsc;

#[derive(Parser)]
#[command(
    about = "The child and therapist tablets as web pages, bridged to the suite's DDS topics"
)]
struct Cli {
    /// Check the parameters (the file, --param overrides, QT_TABLET_PIN, the certificate and
    /// key they name) and ROS_DOMAIN_ID, say what is wrong, and exit without starting (the
    /// installed service's start script runs this before it starts the suite).
    #[arg(long)]
    check: bool,
    #[command(flatten)]
    shell: ShellOptions,
}

/// The bridge's parameters as it runs with them: the file, the overrides, then QT_TABLET_PIN,
/// validated, and the certificate and key they name loaded; errors name the file read.
fn checked(params: &mut TabletBridgeParams, path: &std::path::Path) -> anyhow::Result<()> {
    if let Ok(pin) = std::env::var("QT_TABLET_PIN") {
        params.pin = pin;
    }
    params
        .validate()
        .with_context(|| format!("{} (or QT_TABLET_PIN for the pin)", path.display()))?;
    tls_config(params).with_context(|| format!("the certificate named in {}", path.display()))?;
    Ok(())
}

/// Moves one subscription's messages into the bridge's single DDS input channel.
fn forward<M: Send + 'static>(
    mut rx: mpsc::Receiver<M>,
    tx: mpsc::Sender<DdsInput>,
    wrap: fn(M) -> DdsInput,
) {
    tokio::spawn(async move {
        while let Some(m) = rx.recv().await {
            if tx.send(wrap(m)).await.is_err() {
                break;
            }
        }
    });
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    if cli.check {
        let (mut params, path) = cli
            .shell
            .parameters::<TabletBridgeParams>("tablet_bridge")?;
        checked(&mut params, &path)?;
        node_shell::domain_id_from_env()?;
        println!("{}: parameters and environment valid", path.display());
        return Ok(());
    }
    let (mut shell, mut params): (NodeShell, TabletBridgeParams) =
        NodeShell::start("tablet_bridge", &cli.shell)?;
    // The file actually read (--params-file, QT_PARAMS_DIR or params/) is named, not the default.
    checked(&mut params, &cli.shell.params_path(shell.name()))?;
    let result = {
        let commands = shell.publisher(THERAPIST_COMMAND)?;
        let answers = shell.publisher(TABLET_ANSWER)?;
        let (dds_tx, dds_rx) = mpsc::channel(256);
        forward(
            shell.subscribe(GAME_STATE, 16)?,
            dds_tx.clone(),
            DdsInput::GameState,
        );
        forward(
            shell.subscribe(TABLET_TASK, 16)?,
            dds_tx.clone(),
            DdsInput::Task,
        );
        forward(
            shell.subscribe(DECISION, 64)?,
            dds_tx.clone(),
            DdsInput::Decision,
        );
        forward(
            shell.subscribe(SEQUENCE_RESULT, 64)?,
            dds_tx.clone(),
            DdsInput::Result,
        );
        forward(
            shell.subscribe(ACTION_PROPOSAL, 64)?,
            dds_tx.clone(),
            DdsInput::Proposal,
        );
        forward(
            shell.subscribe(EXPECTED_ENGAGEMENT, 64)?,
            dds_tx.clone(),
            DdsInput::Engagement,
        );
        // Every node's heartbeat; the core watches the game manager's.
        forward(shell.subscribe(HEARTBEAT, 64)?, dds_tx, DdsInput::Heartbeat);
        let (publish_tx, mut publish_rx) = mpsc::channel(256);
        let server = tokio::spawn(serve(params, dds_rx, publish_tx, shell.shutdown_signal()));
        // The server holds the only sender: this loop ends when the server does.
        while let Some(p) = publish_rx.recv().await {
            match p {
                Publish::Command(c) => commands.send(c),
                Publish::Answer(a) => answers.send(a),
            };
        }
        server.await.context("the HTTP server task")?
    };
    shell.stop().await;
    result
}
