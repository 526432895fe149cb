//! User models of the paper ("User Model" section): interaction records, user vectors of
//! success and engagement per level, PCA to 2-D and K-means clusters, and per cluster two
//! Gaussian processes, F^p(L, F, PS) -> P(success) and F^e(L, F, PS, O) -> engagement, saved
//! as one versioned JSON file and tabulated over the finite input space. The fitting core is
//! plain data in, data out; files are read and written only at the edges (`data` readers,
//! `UserModelSet::load` / `save`, `plot`). The command line and the DDS node are the binary's
//! `commands/` modules.

pub mod clustering;
pub mod data;
pub mod fit;
pub mod gp;
pub mod model;
pub mod plot;
pub mod simulate;

pub use data::{DataError, InteractionRecord};
pub use fit::{FitOptions, fit};
pub use gp::{GaussianProcess, Kernel, OptimiserOptions};
pub use model::{UserModelError, UserModelSet};

/// Parameters of the user-model node (`params/user_model.yaml`).
#[derive(Debug, Clone, serde::Deserialize)]
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
