//! User models of the paper ("User Model" section): interaction records, user vectors of
//! success and engagement per level, PCA to 2-D and K-means clusters, and per cluster two
//! Gaussian processes, F^p(L, F, PS) -> P(success) and F^e(L, F, PS, O) -> engagement, saved
//! as one versioned JSON file and tabulated over the finite input space. The fitting core is
//! plain data in, data out; files are read and written only at the edges (`data` readers,
//! `UserModelSet::load` / `save`). The command line, its figures and the DDS node are the
//! `user_model` binary's (`nodes/user_model`).

pub mod clustering;
pub mod data;
pub mod fit;
pub mod gp;
pub mod model;
pub mod simulate;
pub mod supervision;

pub use data::{DataError, InteractionRecord};
pub use fit::{FitOptions, NoiseModel, fit};
pub use gp::{GaussianProcess, Kernel, OptimiserOptions};
pub use model::{UserModelError, UserModelSet};
