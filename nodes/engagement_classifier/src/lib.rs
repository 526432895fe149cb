//! Engagement classifier of the QTrobot suite (paper: E: R^32 -> {-1, 1} from OpenFace head
//! pose, action units and gaze, then expected engagement per second). Sans-IO core: XGBoost
//! JSON models evaluated and trained in Rust, the per-frame -> per-second logic, and the
//! offline tools' building blocks (training, cross-validation, the study's engagement). OpenFace
//! tables and synthetic frames are the `openface` library's, the plots `figures`'; they are
//! re-exported under their old names here.

pub mod aggregate;
pub mod cross_validation;
pub mod estimator;
pub mod messages;
pub mod model;
pub mod node;
pub mod params;
pub mod preprocessing;
pub mod ros4hri;
pub mod smoothing;
pub mod study;
pub mod train;
pub mod xgboost_json;

pub use figures::engagement as plot;
pub use openface::{features, repair, synthetic, table};

pub use aggregate::{
    AggregateError, AggregatorConfig, EngagementSecond, SecondAggregator, SourceId,
};
pub use estimator::{
    EngagementEstimator, FaceFrame, FrameError, FrameOutcome, MissingReason, SetupError,
};
pub use features::{FEATURE_COUNT, OPENFACE_FEATURES};
pub use model::{EngagementModel, ModelError, Prediction};
pub use params::{EngagementClassifierParams, ParamsError};
