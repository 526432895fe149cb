//! OpenFace frames as the suite reads them: the 32 features of `OpenFaceFeatures.msg` and the
//! mapping of column names onto them (`features`), tables of labelled frames read from and
//! written to CSV, with the repair of the study data's damaged decimals (`table`, `repair`),
//! and a seeded generator of SYNTHETIC frames for simulations and tests (`synthetic`). Plain
//! data; used by the engagement classifier, the simulated child and the tests.

pub mod features;
pub mod repair;
pub mod synthetic;
pub mod table;

pub use features::{FEATURE_COUNT, OPENFACE_FEATURES};
