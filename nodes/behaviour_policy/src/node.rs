//! The decision node's run loop, on any bus (`node_shell::Bus`: DDS on the robot, in process
//! in the cross-node tests). Answers DecideAction with an explained Decision (also
//! published), learns from every SequenceResult and saves that cluster's Q-table at once; a
//! request that comes before the result it follows waits for it (`LearnFirst`). A cluster
//! whose Q-table file is refused at start-up is unavailable (its calls are answered ok = false
//! naming the file) while the others serve. All logic is in
//! `ClusterPolicies`/`PersistentPolicy`/`PolicyCore`; this only moves messages.

use crate::child_beliefs::{BeliefSettings, ChildBeliefs};
use crate::learn_first::LearnFirst;
use crate::{BehaviourPolicyParams, ClusterPolicies};
use anyhow::Context;
use child_belief::OwnModelParams;
use child_belief::prior_file::PriorFile;
use node_shell::{Bus, ServiceCall};
use q_learning::training::Pretraining;
use q_learning::{Learning, QTable};
use qt_therapy_msgs::topics::{DECIDE_ACTION, DECISION, SEQUENCE_RESULT};
use qt_therapy_msgs::{DecideAction, DecideActionRequest, DecideActionResponse};
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
    let pretraining = Pretraining {
        epochs,
        runs,
        state_lags_result: params.pretrain_state_lags_result,
    };
    let best = pretraining
        .best_run(model, &learning, |r| {
            params.seed() ^ ((cluster as u64) << 32) ^ r as u64
        })
        .ok_or("pretraining made no run")?;
    let provenance = format!(
        "pretrained by the node: best of {runs} runs x {epochs} epochs x 100 sessions (return \
         {:.3}), reward {}, state lag {}, against {}",
        best.final_return,
        learning.reward.name(),
        params.pretrain_state_lags_result,
        params.user_model_file
    );
    Ok((best.q_table, provenance))
}

/// The per-child beliefs when `child_belief` is on: the rule and the prior covariance file
/// are checked at start-up (a bad one stops the node, naming it, as any parameter does).
fn child_beliefs(
    params: &BehaviourPolicyParams,
    params_file: &Path,
    learning: Learning,
    models: &[UserModelTable],
) -> anyhow::Result<Option<ChildBeliefs>> {
    let rule = params
        .child_belief_rule()
        .with_context(|| format!("parameter file {}", params_file.display()))?;
    if !params.child_belief {
        return Ok(None);
    }
    let prior_file = Path::new(&params.child_belief_prior_file);
    let (file, covariance) = PriorFile::load(prior_file).with_context(|| {
        format!(
            "child_belief_prior_file in {} (make one with `policy_lab child-belief-prior`)",
            params_file.display()
        )
    })?;
    tracing::info!(file = %prior_file.display(), children = file.children,
        "per-child beliefs on: {}", file.provenance);
    Ok(Some(ChildBeliefs::new(
        Path::new(&params.q_table_dir),
        BeliefSettings {
            covariance,
            own_model: OwnModelParams::default(),
            rule,
            learning,
            seed: params.seed(),
        },
        models.to_vec(),
    )))
}

/// Serves decisions with `params` (read from `params_file`, named in errors) until the node is
/// asked to stop. The caller holds the lock on `q_table_dir`
/// (`node_shell::instance_lock`).
pub async fn run(
    bus: &mut impl Bus,
    params: BehaviourPolicyParams,
    params_file: &Path,
) -> anyhow::Result<()> {
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
    .with_user_tables(params.per_user_q_tables)
    .with_child_beliefs(child_beliefs(&params, params_file, learning, &models)?);
    let mut calls = bus.serve(DECIDE_ACTION, |e| DecideActionResponse {
        ok: false,
        error: e.to_string(),
        ..Default::default()
    })?;
    let mut results = bus.subscribe(SEQUENCE_RESULT, 64)?;
    let decisions = bus.publisher(DECISION)?;
    let drops = bus.drops();
    let clock = bus.clock();
    let mut gate: LearnFirst<ServiceCall<DecideAction>> = LearnFirst::new(result_wait_ns);
    let stop = bus.shutdown_signal();
    tokio::pin!(stop);
    let decide = |policies: &mut ClusterPolicies, req: &DecideActionRequest| match policies
        .decide(req, clock.header_now())
    {
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
    };
    loop {
        let deadline = gate.next_deadline_ns();
        // Biased: what is ready is taken in this order, never by tokio's random pick, so a
        // run on the in-process bus is the same every time.
        tokio::select! {
            biased;
            _ = &mut stop => break,
            _ = clock.sleep_until(deadline.unwrap_or_default()), if deadline.is_some() => {
                for e in gate.expired(clock.steady_nanos()) {
                    tracing::warn!(session = %e.request.session_id, step = e.request.step,
                        "refused a decision: {}", e.reason);
                    e.call.respond(DecideActionResponse {
                        ok: false,
                        error: e.reason,
                        ..Default::default()
                    });
                }
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
            Some(call) = calls.recv() => {
                let learned = policies.last_learned(&call.request);
                let request = call.request.clone();
                let (session, after) = (request.session_id.clone(), request.after_sequence);
                let Some((call, req)) = gate.request(call, request, learned, clock.steady_nanos()) else {
                    tracing::info!(session = %session, "a decision request came before the \
                        result of sequence {after} it follows: held until it is learned");
                    continue;
                };
                let response = decide(&mut policies, &req);
                call.respond(response);
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
    Ok(())
}
