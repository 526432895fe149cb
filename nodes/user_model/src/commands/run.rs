//! `user_model run`: the user-model node over DDS. Loads the model file of
//! `params/user_model.yaml`, tabulates every prediction, then answers PredictUser with a table
//! lookup and AssignCluster with a PCA projection and the nearest centre.

use anyhow::Context;
use node_shell::{NodeShell, ShellOptions, header_now};
use qt_therapy_msgs::topics::{ASSIGN_CLUSTER, PREDICT_USER, USER_MODEL_INFO};
use qt_therapy_msgs::{AssignClusterResponse, PredictUserResponse, UserModelInfo};
use sequence_game::{Feedback, Level, ModelInput, Outcome};
use user_model::UserModelParams;
use user_models::UserModelSet;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    shell: ShellOptions,
}

pub fn main(a: Args) -> anyhow::Result<()> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?
        .block_on(run(a.shell))
}

async fn run(shell_options: ShellOptions) -> anyhow::Result<()> {
    let (mut shell, params): (NodeShell, UserModelParams) =
        NodeShell::start("user_model", &shell_options)?;
    let set = UserModelSet::load(std::path::Path::new(&params.model_file)).with_context(|| {
        format!(
            "loading model_file from {}",
            shell_options.params_path(shell.name()).display()
        )
    })?;
    tracing::info!(model = %params.model_file, clusters = set.cluster_count(), "user models loaded, every prediction tabulated");
    {
        let info = shell.publisher(USER_MODEL_INFO)?;
        info.send(UserModelInfo {
            header: header_now(),
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
        let mut predict = shell.serve(PREDICT_USER, |e| PredictUserResponse {
            ok: false,
            error: e.to_string(),
            ..Default::default()
        })?;
        let mut assign = shell.serve(ASSIGN_CLUSTER, |e| AssignClusterResponse {
            ok: false,
            error: e.to_string(),
            cluster: -1,
            ..Default::default()
        })?;
        let stop = shell.shutdown_signal();
        tokio::pin!(stop);
        loop {
            tokio::select! {
                _ = &mut stop => break,
                Some(call) = predict.recv() => {
                    let r = &call.request;
                    let response = match (set.table(r.cluster.into()), Level::new(r.level.into()), Feedback::new(r.feedback.into()), Outcome::new(r.outcome.into())) {
                        (Ok(table), Ok(level), Ok(feedback), Ok(outcome)) => match ModelInput::new(level, feedback, r.previous_score) {
                            Ok(input) => {
                                let (p, e) = (table.success(input), table.engagement(input, outcome));
                                PredictUserResponse { ok: true, error: String::new(), success_probability: p.mean, success_std: p.std, engagement: e.mean, engagement_std: e.std }
                            }
                            Err(e) => PredictUserResponse { ok: false, error: e.to_string(), ..Default::default() },
                        },
                        (Err(e), ..) => PredictUserResponse { ok: false, error: e.to_string(), ..Default::default() },
                        _ => PredictUserResponse { ok: false, error: "input outside the state space".into(), ..Default::default() },
                    };
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
    }
    shell.stop().await;
    Ok(())
}
