//! `behaviour_policy run`: the decision node over DDS. Answers DecideAction with an explained
//! Decision (also published), learns from every SequenceResult and saves that cluster's
//! Q-table at once. All logic is in `PersistentPolicy`/`PolicyCore`, the conversion of messages in
//! `behaviour_policy::messages`; this only moves them.

use anyhow::Context;
use behaviour_policy::experiments::{EpochScheme, RunSpec, best_run, train_run};
use behaviour_policy::messages::{decision_message, transition};
use behaviour_policy::simulation::{SessionSettings, SimulatedUser};
use behaviour_policy::{
    BehaviourPolicyParams, Learning, Mode, PersistentPolicy, QTable, QTableOwner,
};
use node_shell::{NodeShell, ShellOptions, header_now};
use qt_therapy_msgs::DecideActionResponse;
use qt_therapy_msgs::topics::{DECIDE_ACTION, DECISION, SEQUENCE_RESULT};
use sequence_game::UserModelTable;
use std::path::Path;

/// Pretrains a cluster's table when it has no file: the best of `runs` softmax runs.
fn pretrain(
    model: &UserModelTable,
    learning: Learning,
    params: &BehaviourPolicyParams,
    cluster: usize,
) -> anyhow::Result<(QTable, String)> {
    let (epochs, runs) = params.pretraining()?;
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
    let best = best_run(&all).context("no pretraining run")?;
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

/// Which Q-table made a decision, for the Decision message.
fn model_used(p: &PersistentPolicy) -> String {
    format!(
        "{} ({}, {} updates)",
        p.owner(),
        p.path().display(),
        p.core().updates()
    )
}

pub async fn run(options: ShellOptions) -> anyhow::Result<()> {
    let (mut shell, params): (NodeShell, BehaviourPolicyParams) =
        NodeShell::start("behaviour_policy", &options)?;
    let learning = params.learning()?;
    let set =
        user_model::UserModelSet::load(Path::new(&params.user_model_file)).with_context(|| {
            format!(
                "user_model_file in {}",
                options.params_path(shell.name()).display()
            )
        })?;
    let mut policies = Vec::new();
    for (k, model) in set.tables().iter().enumerate() {
        let mut pretrained = None;
        let (p, how) = PersistentPolicy::open(
            Path::new(&params.q_table_dir),
            QTableOwner::Cluster(k),
            learning,
            params.mode(),
            params.seed() ^ k as u64,
            || {
                let r = pretrain(model, learning, &params, k);
                let fallback = (QTable::default(), String::new());
                match r {
                    Ok(t) => t,
                    Err(e) => {
                        pretrained = Some(e);
                        fallback
                    }
                }
            },
        )?;
        if let Some(e) = pretrained {
            return Err(e);
        }
        tracing::info!(cluster = k, file = %p.path().display(), ?how, "Q-table ready");
        policies.push(p);
    }
    let count = policies.len();
    let default_cluster = params.default_cluster;
    let cluster_of = move |c: i32| -> anyhow::Result<usize> {
        let c = if c < 0 { default_cluster } else { i64::from(c) };
        usize::try_from(c)
            .ok()
            .filter(|k| *k < count)
            .with_context(|| format!("unknown user model cluster {c}: the policy holds {count}"))
    };
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
                    let answer = cluster_of(req.user_model_cluster).and_then(|k| {
                        let state = req.state.to_state().map_err(|e| anyhow::anyhow!("state: {}", e.reason))?;
                        let d = policies[k].decide(state, req.step)?;
                        Ok(decision_message(&d, header_now(), &req.session_id, model_used(&policies[k])))
                    });
                    let response = match answer {
                        Ok(d) => {
                            decisions.send(d.clone());
                            DecideActionResponse { ok: true, error: String::new(), decision: d }
                        }
                        Err(e) => {
                            tracing::warn!(session = %req.session_id, "refused a decision: {e:#}");
                            DecideActionResponse { ok: false, error: format!("{e:#}"), ..Default::default() }
                        }
                    };
                    call.respond(response);
                }
                Some(result) = results.recv() => {
                    let learned = cluster_of(result.user_model_cluster).and_then(|k| {
                        let learned = policies[k].learn_sequence(
                            &result.session_id,
                            result.sequence_index,
                            &transition(&result)?,
                        )?;
                        if learned.is_none() {
                            tracing::info!(session = %result.session_id, sequence = result.sequence_index,
                                "already learned from this sequence (sent again after a restart)");
                        }
                        Ok(())
                    });
                    if let Err(e) = learned {
                        drops.record(SEQUENCE_RESULT.name, &format!("not learned from: {e:#}"));
                    }
                }
            }
        }
    }
    shell.stop().await;
    Ok(())
}
