//! `behaviour_policy run`: the decision node over DDS. Answers DecideAction with an explained
//! Decision (also published), learns from every SequenceResult and saves that cluster's
//! Q-table at once; a request that comes before the result it follows waits for it
//! (`LearnFirst`). A cluster whose Q-table file is refused at start-up is unavailable (its
//! calls are answered ok = false naming the file) while the others serve. All logic is in
//! `ClusterPolicies`/`PersistentPolicy`/`PolicyCore`; this only moves messages.

use anyhow::Context;
use behaviour_policy::experiments::{EpochScheme, RunSpec, best_run, train_run};
use behaviour_policy::learn_first::LearnFirst;
use behaviour_policy::simulation::{SessionSettings, SimulatedUser};
use behaviour_policy::{BehaviourPolicyParams, ClusterPolicies, Learning, Mode, QTable};
use node_shell::instance_lock::InstanceLock;
use node_shell::{NodeShell, ShellOptions, header_now, now_nanos};
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
    let result_wait_ns = params.result_wait_ns().with_context(in_file)?;
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
        let mut gate: LearnFirst<node_shell::ServiceCall<qt_therapy_msgs::DecideAction>> =
            LearnFirst::new(result_wait_ns);
        let stop = shell.shutdown_signal();
        tokio::pin!(stop);
        let decide = |policies: &mut ClusterPolicies,
                      req: &qt_therapy_msgs::DecideActionRequest| {
            match policies.decide(req, header_now()) {
                Ok(d) => {
                    decisions.send(d.clone());
                    DecideActionResponse {
                        ok: true,
                        error: String::new(),
                        decision: d,
                    }
                }
                Err(e) => {
                    tracing::warn!(session = %req.session_id, "refused a decision: {e}");
                    DecideActionResponse {
                        ok: false,
                        error: e.to_string(),
                        ..Default::default()
                    }
                }
            }
        };
        loop {
            let wait = gate
                .next_deadline_ns()
                .map(|d| std::time::Duration::from_nanos((d - now_nanos()).max(0) as u64));
            tokio::select! {
                _ = &mut stop => break,
                _ = tokio::time::sleep(wait.unwrap_or_default()), if wait.is_some() => {
                    for e in gate.expired(now_nanos()) {
                        tracing::warn!(session = %e.request.session_id, step = e.request.step,
                            "refused a decision: {}", e.reason);
                        e.call.respond(DecideActionResponse {
                            ok: false,
                            error: e.reason,
                            ..Default::default()
                        });
                    }
                }
                Some(call) = calls.recv() => {
                    let learned = policies.last_learned(&call.request);
                    let request = call.request.clone();
                    let (session, after) = (request.session_id.clone(), request.after_sequence);
                    let Some((call, req)) = gate.request(call, request, learned, now_nanos()) else {
                        tracing::info!(session = %session, "a decision request came before the \
                            result of sequence {after} it follows: held until it is learned");
                        continue;
                    };
                    let response = decide(&mut policies, &req);
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
                    // Learned (or refused) first, then the decisions that waited for it.
                    for (call, req) in gate.result_seen(&result.session_id, result.sequence_index) {
                        let response = decide(&mut policies, &req);
                        call.respond(response);
                    }
                }
            }
        }
        let c = gate.counts();
        if c.held > 0 {
            tracing::info!(
                "decision requests that came before their result: {} held, {} answered once it \
                 was learned, {} refused after result_wait_s",
                c.held,
                c.released,
                c.refused
            );
        }
    }
    shell.stop().await;
    Ok(())
}
