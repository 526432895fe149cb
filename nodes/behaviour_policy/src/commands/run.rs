//! `behaviour_policy run`: the decision node over DDS (its run loop is the library's
//! `node::run`).

use anyhow::Context;
use behaviour_policy::BehaviourPolicyParams;
use node_shell::instance_lock::InstanceLock;
use node_shell::{NodeShell, ShellOptions};
use qt_therapy_msgs::topics::BEHAVIOUR_POLICY_NODE;
use std::path::Path;

pub async fn run(options: ShellOptions) -> anyhow::Result<()> {
    // Held while the node runs: a second policy on the same tables would overwrite its
    // learning. Taken before joining the graph, so a refused copy never beats under our name.
    let (params, _): (BehaviourPolicyParams, _) = options.parameters(BEHAVIOUR_POLICY_NODE)?;
    let _q_table_dir = InstanceLock::acquire(
        Path::new(&params.q_table_dir),
        BEHAVIOUR_POLICY_NODE,
        "Q-tables",
    )
    .context("q_table_dir")?;
    let (mut shell, params): (NodeShell, BehaviourPolicyParams) =
        NodeShell::start(BEHAVIOUR_POLICY_NODE, &options)?;
    let params_file = options.params_path(shell.name());
    let outcome = behaviour_policy::node::run(&mut shell, params, &params_file).await;
    shell.stop().await;
    outcome
}
