//! `user_model run`: the user-model node over DDS (its run loop is the library's `node::run`).

use node_shell::{NodeShell, ShellOptions};
use user_model::UserModelParams;
use user_model::node::{NODE, run};

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    shell: ShellOptions,
}

pub fn main(a: Args) -> anyhow::Result<()> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?
        .block_on(async {
            let (mut shell, params): (NodeShell, UserModelParams) =
                NodeShell::start(NODE, &a.shell)?;
            let params_file = a.shell.params_path(shell.name());
            let outcome = run(&mut shell, params, &params_file).await;
            shell.stop().await;
            outcome
        })
}
