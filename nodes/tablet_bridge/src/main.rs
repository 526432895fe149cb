//! `tablet_bridge`: serves the child tablet (/child) and the therapist tablet (/therapist),
//! over HTTPS where its parameters name a certificate, and bridges them to DDS.
//!   tablet_bridge                      (reads params/tablet_bridge.yaml)
//!   QT_TABLET_PIN=8642 tablet_bridge --params-file my.yaml

use anyhow::Context as _;
use clap::Parser;
use node_shell::{NodeShell, ShellOptions};
use tablet_bridge::TabletBridgeParams;
use tablet_bridge::node::{EVENT_QUEUE, NODE};
use tablet_bridge::server::{bind, serve_pages, tls_config};
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

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    let cli = Cli::parse();
    if cli.check {
        let (mut params, path) = cli.shell.parameters::<TabletBridgeParams>(NODE)?;
        checked(&mut params, &path)?;
        node_shell::domain_id_from_env()?;
        println!("{}: parameters and environment valid", path.display());
        return Ok(());
    }
    let (mut shell, mut params): (NodeShell, TabletBridgeParams) =
        NodeShell::start(NODE, &cli.shell)?;
    // The file actually read (--params-file, QT_PARAMS_DIR or params/) is named, not the default.
    let outcome = async {
        checked(&mut params, &cli.shell.params_path(shell.name()))?;
        let listener = bind(&params).await?;
        let (events, pages) = mpsc::channel(EVENT_QUEUE);
        let server = serve_pages(listener, params.clone(), events, shell.shutdown_signal());
        let node = tablet_bridge::node::run(&mut shell, params, pages);
        // Both end at SIGINT/SIGTERM (the server returns Ok only then); a server that fails
        // ends the node.
        tokio::pin!(server, node);
        tokio::select! {
            served = &mut server => {
                served.context("the tablet pages' server")?;
                node.await
            }
            ran = &mut node => {
                ran?;
                server.await.context("the tablet pages' server")
            }
        }
    }
    .await;
    shell.stop().await;
    outcome
}
