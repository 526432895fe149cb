//! The user-model node and its command line (`user_model`): the models themselves, their
//! fitting and their file are the `user_model` library's (`libs/user_model`); the node's run
//! loop, on any bus, is `node`.

pub mod node;

/// Parameters of the user-model node (`params/user_model.yaml`).
#[derive(
    Debug, Clone, serde::Deserialize, serde::Serialize, node_shell::parameters::DescribedParameters,
)]
#[serde(deny_unknown_fields, default)]
pub struct UserModelParams {
    /// The fitted model file the node serves.
    pub model_file: String,
}

impl Default for UserModelParams {
    fn default() -> Self {
        UserModelParams {
            model_file: "nodes/user_model/models/migrave_study_c2.json".into(),
        }
    }
}
