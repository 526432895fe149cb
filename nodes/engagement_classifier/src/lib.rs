//! Engagement classifier of the QTrobot suite (paper: E: R^32 -> {-1, 1} from OpenFace head
//! pose, action units and gaze, then expected engagement per second). Sans-IO core: XGBoost
//! JSON models evaluated and trained in Rust, the per-frame -> per-second logic, and the
//! offline tools' building blocks (tables, cross-validation, synthetic data, plots).

pub mod aggregate;
pub mod cross_validation;
pub mod estimator;
pub mod features;
pub mod messages;
pub mod model;
pub mod params;
pub mod plot;
pub mod preprocessing;
pub mod repair;
pub mod smoothing;
pub mod study;
pub mod synthetic;
pub mod table;
pub mod train;
pub mod xgboost_json;

pub use aggregate::{
    AggregateError, AggregatorConfig, EngagementSecond, SecondAggregator, SourceId,
};
pub use estimator::{
    EngagementEstimator, FaceFrame, FrameError, FrameOutcome, MissingReason, SetupError,
};
pub use features::{FEATURE_COUNT, OPENFACE_FEATURES};
pub use model::{EngagementModel, ModelError, Prediction};
pub use params::{EngagementClassifierParams, ParamsError};

use std::io::Write;
use std::path::Path;

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename, so
/// readers never see a half-written file.
pub fn atomic_write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir)?;
    let mut tmp = tempfile::NamedTempFile::new_in(dir)?;
    // The temporary file is private (0600); what we write is meant to be read by others.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644))?;
    }
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}
