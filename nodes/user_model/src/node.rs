//! The user-model node's run loop, on any bus (`node_shell::Bus`: DDS on the robot, in process
//! in the cross-node tests): announces the model file (`UserModelInfo`, latched), then answers
//! PredictUser with a table lookup and AssignCluster with a PCA projection and the nearest
//! centre, until the node is asked to stop.

use crate::UserModelParams;
use anyhow::Context;
use node_shell::Bus;
use qt_therapy_msgs::topics::{ASSIGN_CLUSTER, PREDICT_USER, USER_MODEL_INFO};
use qt_therapy_msgs::{AssignClusterResponse, PredictUserResponse, UserModelInfo};
use sequence_game::{Feedback, Level, ModelInput, Outcome};
use std::path::Path;
use user_models::UserModelSet;

/// The node's name on the graph (and its parameter file's).
pub const NODE: &str = "user_model";

/// Loads the model file of `params` (read from `params_file`, named in errors), tabulates
/// every prediction, and serves them until the node is asked to stop.
pub async fn run(
    bus: &mut impl Bus,
    params: UserModelParams,
    params_file: &Path,
) -> anyhow::Result<()> {
    let set = UserModelSet::load(Path::new(&params.model_file))
        .with_context(|| format!("loading model_file from {}", params_file.display()))?;
    tracing::info!(model = %params.model_file, clusters = set.cluster_count(), "user models loaded, every prediction tabulated");
    let info = bus.publisher(USER_MODEL_INFO)?;
    info.send(UserModelInfo {
        header: bus.clock().header_now(),
        model_file: params.model_file.clone(),
        format_version: set.file().version,
        clusters: set
            .file()
            .clusters
            .iter()
            .map(|c| c.cluster as i32)
            .collect(),
        cluster_sizes: set
            .file()
            .clusters
            .iter()
            .map(|c| c.users.len() as u32)
            .collect(),
        kernel: set
            .file()
            .clusters
            .first()
            .map(|c| c.success.kernel.name().to_string())
            .unwrap_or_default(),
    });
    let mut predict = bus.serve(PREDICT_USER, |e| PredictUserResponse {
        ok: false,
        error: e.to_string(),
        ..Default::default()
    })?;
    let mut assign = bus.serve(ASSIGN_CLUSTER, |e| AssignClusterResponse {
        ok: false,
        error: e.to_string(),
        cluster: -1,
        ..Default::default()
    })?;
    let stop = bus.shutdown_signal();
    tokio::pin!(stop);
    loop {
        // Biased: what is ready is taken in this order, never by tokio's random pick, so a
        // run on the in-process bus is the same every time.
        tokio::select! {
            biased;
            _ = &mut stop => break,
            Some(call) = predict.recv() => {
                let response = prediction(&set, &call.request);
                call.respond(response);
            }
            Some(call) = assign.recv() => {
                let v: Result<[f64; 6], _> = call.request.user_vector.as_slice().try_into();
                let response = match v {
                    Ok(v) => match set.assign_cluster(&v) {
                        Ok(c) => AssignClusterResponse { ok: true, error: String::new(), cluster: c as i32, projection: set.project(&v) },
                        Err(e) => AssignClusterResponse { ok: false, error: e.to_string(), cluster: -1, projection: vec![] },
                    },
                    Err(_) => AssignClusterResponse { ok: false, error: "user_vector must have 6 values".into(), cluster: -1, projection: vec![] },
                };
                call.respond(response);
            }
        }
    }
    Ok(())
}

/// F^p and F^e of the request's cluster and input, or why not.
fn prediction(set: &UserModelSet, r: &qt_therapy_msgs::PredictUserRequest) -> PredictUserResponse {
    let refused = |error: String| PredictUserResponse {
        ok: false,
        error,
        ..Default::default()
    };
    match (
        set.table(r.cluster.into()),
        Level::new(r.level.into()),
        Feedback::new(r.feedback.into()),
        Outcome::new(r.outcome.into()),
    ) {
        (Ok(table), Ok(level), Ok(feedback), Ok(outcome)) => {
            match ModelInput::new(level, feedback, r.previous_score) {
                Ok(input) => {
                    let (p, e) = (table.success(input), table.engagement(input, outcome));
                    PredictUserResponse {
                        ok: true,
                        error: String::new(),
                        success_probability: p.mean,
                        success_std: p.std,
                        engagement: e.mean,
                        engagement_std: e.std,
                    }
                }
                Err(e) => refused(e.to_string()),
            }
        }
        (Err(e), ..) => refused(e.to_string()),
        _ => refused("input outside the state space".into()),
    }
}
