//! `behaviour_policy run`: the decision node over DDS. Answers DecideAction with an explained
//! Decision (also published), learns from every SequenceResult and saves that cluster's
//! Q-table at once. A cluster whose Q-table file is refused at start-up is unavailable (its
//! calls are answered ok = false naming the file) while the others serve. All logic is in
//! `ClusterPolicies`/`PersistentPolicy`/`PolicyCore`; this only moves messages.

use anyhow::Context;
use behaviour_policy::experiments::{EpochScheme, RunSpec, best_run, train_run};
use behaviour_policy::simulation::{SessionSettings, SimulatedUser};
use behaviour_policy::{BehaviourPolicyParams, ClusterPolicies, Learning, Mode, QTable};
use node_shell::instance_lock::InstanceLock;
use node_shell::{NodeShell, ShellOptions, header_now};
use qt_therapy_msgs::DecideActionResponse;
use qt_therapy_msgs::topics::{BEHAVIOUR_POLICY_NODE, DECIDE_ACTION, DECISION, SEQUENCE_RESULT};
use sequence_game::UserModelTable;
use std::path::Path;

/// Pretrains a cluster's table when it has no file: the best of `runs` softmax runs.
fn pretrain(
    model: &UserModelTable,
    learning: Learning,
    params: &BehaviourPolicyParams,
    (epochs, runs): (usize, usize),
    cluster: usize,
) -> Result<(QTable, String), String> {
    let settings = SessionSettings {
        learning,
        mode: Mode::Explore,
        state_lags_result: params.pretrain_state_lags_result,
    };
    let spec = RunSpec {
        epochs,
        sessions_per_epoch: 100,
        scheme: EpochScheme::Blocks,
        state_lags_result: params.pretrain_state_lags_result,
    };
    let user = SimulatedUser::new(model, &learning);
    let all: Vec<_> = (0..runs)
        .map(|r| {
            let seed = params.seed() ^ ((cluster as u64) << 32) ^ r as u64;
            train_run(&user, &settings, QTable::default(), &spec, seed)
        })
        .collect();
    let best = best_run(&all).ok_or("pretraining made no run")?;
    let provenance = format!(
        "pretrained by the node: best of {runs} runs x {epochs} epochs x 100 sessions (return \
         {:.3}), reward {}, state lag {}, against {}",
        all[best].final_return,
        learning.reward.name(),
        params.pretrain_state_lags_result,
        params.user_model_file
    );
    Ok((all[best].q_table.clone(), provenance))
}

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
    let in_file = || format!("parameter file {}", params_file.display());
    let learning = params.learning().with_context(in_file)?;
    let set = user_models::UserModelSet::load(Path::new(&params.user_model_file))
        .with_context(|| format!("user_model_file in {}", params_file.display()))?;
    // Parameter errors stop the node; a bad Q-table file only makes its cluster unavailable.
    let pretraining = params.pretraining().with_context(in_file)?;
    let models = set.tables();
    let mut policies = ClusterPolicies::open(
        Path::new(&params.q_table_dir),
        models.len(),
        learning,
        params.mode(),
        params.seed(),
        params.default_cluster,
        |k| pretrain(&models[k], learning, &params, pretraining, k),
    )
    .with_user_tables(params.per_user_q_tables);
    {
        let mut calls = shell.serve(DECIDE_ACTION, |e| DecideActionResponse {
            ok: false,
            error: e.to_string(),
            ..Default::default()
        })?;
        let mut results = shell.subscribe(SEQUENCE_RESULT, 64)?;
        let decisions = shell.publisher(DECISION)?;
        let drops = shell.drops();
        let stop = shell.shutdown_signal();
        tokio::pin!(stop);
        loop {
            tokio::select! {
                _ = &mut stop => break,
                Some(call) = calls.recv() => {
                    let req = &call.request;
                    let response = match policies.decide(req, header_now()) {
                        Ok(d) => {
                            decisions.send(d.clone());
                            DecideActionResponse { ok: true, error: String::new(), decision: d }
                        }
                        Err(e) => {
                            tracing::warn!(session = %req.session_id, "refused a decision: {e}");
                            DecideActionResponse { ok: false, error: e.to_string(), ..Default::default() }
                        }
                    };
                    call.respond(response);
                }
                Some(result) = results.recv() => {
                    match policies.learn(&result) {
                        Ok(Some(_)) => {}
                        Ok(None) => tracing::info!(session = %result.session_id,
                            sequence = result.sequence_index,
                            "already learned from this sequence (sent again after a restart)"),
                        // Logged once per topic and kind of reason (e.g. per unavailable
                        // cluster), then only counted: a session's results cannot flood the log.
                        Err(e) => {
                            drops.record(SEQUENCE_RESULT.name, &format!("not learned from: {e}"));
                        }
                    }
                }
            }
        }
    }
    shell.stop().await;
    Ok(())
}
