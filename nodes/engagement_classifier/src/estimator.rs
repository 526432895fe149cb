//! The engagement node's core, sans-IO: an OpenFace frame in, its label and probability out,
//! and once per second of message time each source's expected engagement (through `emit`).
//! The DDS shell only converts messages and publishes what comes out.

use crate::aggregate::{
    AggregateError, AggregatorConfig, EngagementSecond, SecondAggregator, SourceId,
};
use crate::features::{FEATURE_COUNT, OPENFACE_FEATURES};
use crate::model::{EngagementModel, ModelError, Prediction};
use crate::params::{EngagementClassifierParams, ParamsError};
use std::path::Path;

/// One face in one camera frame, features in the canonical order of `OPENFACE_FEATURES`.
#[derive(Debug, Clone, Copy)]
pub struct FaceFrame<'a> {
    pub stamp_ns: i64,
    pub source: SourceId,
    pub detection_success: bool,
    pub confidence: f32,
    pub features: &'a [f32],
}

/// Why a frame has no label.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MissingReason {
    DetectionFailed,
    LowConfidence,
}

/// What one frame gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrameOutcome {
    Classified(Prediction),
    /// Counted as a frame without a face (never as disengaged).
    Missing(MissingReason),
}

/// A frame the estimator refused; the caller logs it and skips the frame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    #[error("frame of source {source_id} at {stamp_ns} ns has {got} features, expected 32")]
    FeatureCount {
        source_id: SourceId,
        stamp_ns: i64,
        got: usize,
    },
    #[error("frame of source {source_id} at {stamp_ns} ns: feature {feature} is {value}")]
    NotFinite {
        source_id: SourceId,
        stamp_ns: i64,
        feature: &'static str,
        value: f32,
    },
    #[error(transparent)]
    Aggregate(#[from] AggregateError),
}

/// Why an estimator could not be set up from its parameters.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    #[error(transparent)]
    Params(#[from] ParamsError),
    #[error(transparent)]
    Model(#[from] ModelError),
}

/// Model + per-second aggregation.
#[derive(Debug, Clone)]
pub struct EngagementEstimator {
    model: EngagementModel,
    aggregator: SecondAggregator,
    min_confidence: f32,
}

impl EngagementEstimator {
    pub fn new(model: EngagementModel, min_confidence: f64, config: AggregatorConfig) -> Self {
        EngagementEstimator {
            model,
            aggregator: SecondAggregator::new(config),
            min_confidence: min_confidence as f32,
        }
    }

    /// Validates `params` and loads `model_file` (relative paths from `base_dir`, the
    /// workspace root in this repository).
    pub fn from_params(
        params: &EngagementClassifierParams,
        base_dir: &Path,
    ) -> Result<Self, SetupError> {
        params.validate()?;
        let model = EngagementModel::load(&base_dir.join(&params.model_file))?;
        Ok(EngagementEstimator::new(
            model,
            params.min_confidence,
            params.aggregator_config(),
        ))
    }

    pub fn model(&self) -> &EngagementModel {
        &self.model
    }

    /// A new `min_confidence` (a change while running): it applies from the next frame.
    pub fn set_min_confidence(&mut self, min_confidence: f64) {
        self.min_confidence = min_confidence as f32;
    }

    /// Classifies one frame and counts it; seconds that close are passed to `emit`.
    pub fn on_frame(
        &mut self,
        frame: &FaceFrame<'_>,
        emit: &mut impl FnMut(&EngagementSecond),
    ) -> Result<FrameOutcome, FrameError> {
        let (source, stamp_ns) = (frame.source, frame.stamp_ns);
        let outcome = if !frame.detection_success {
            FrameOutcome::Missing(MissingReason::DetectionFailed)
        } else if frame.confidence.is_nan() || frame.confidence < self.min_confidence {
            FrameOutcome::Missing(MissingReason::LowConfidence)
        } else {
            let features: &[f32; FEATURE_COUNT] =
                frame
                    .features
                    .try_into()
                    .map_err(|_| FrameError::FeatureCount {
                        source_id: source,
                        stamp_ns,
                        got: frame.features.len(),
                    })?;
            if let Some(c) = features.iter().position(|v| !v.is_finite()) {
                return Err(FrameError::NotFinite {
                    source_id: source,
                    stamp_ns,
                    feature: OPENFACE_FEATURES[c],
                    value: features[c],
                });
            }
            FrameOutcome::Classified(self.model.predict_f32(features))
        };
        let label = match outcome {
            FrameOutcome::Classified(p) => Some(p.label),
            FrameOutcome::Missing(_) => None,
        };
        self.aggregator.add(source, stamp_ns, label, emit)?;
        Ok(outcome)
    }

    /// Message time reached `stamp_ns` without frames (e.g. from a clock message).
    pub fn advance_to(&mut self, stamp_ns: i64, emit: &mut impl FnMut(&EngagementSecond)) {
        self.aggregator.advance_to(stamp_ns, emit);
    }

    /// The frames' clock was stepped to `stamp_ns`: the open seconds are reported and counting
    /// starts again there (`SecondAggregator::restart_at`).
    pub fn restart_at(&mut self, stamp_ns: i64, emit: &mut impl FnMut(&EngagementSecond)) {
        self.aggregator.restart_at(stamp_ns, emit);
    }

    /// End of the stream: report the seconds still open.
    pub fn flush(&mut self, emit: &mut impl FnMut(&EngagementSecond)) {
        self.aggregator.flush(emit);
    }
}
