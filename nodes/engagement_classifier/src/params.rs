//! The node's parameters (`params/engagement_classifier.yaml`, ROS 2 form) with defaults equal
//! to that file, their validation, and the settings each part of the crate derives from them.

use crate::aggregate::AggregatorConfig;
use crate::repair::DecimalRepair;
use crate::table::{LoadOptions, NeutralLabel};
use crate::train::TrainParams;
use node_shell::parameters::DescribedParameters;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Parameters of the engagement classifier node and its offline tools. `min_confidence` and
/// the two ROS4HRI thresholds change while the node runs (`ros2 param set`:
/// [`EngagementClassifierParams::change`]); the rest are read at start-up.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, DescribedParameters)]
#[serde(deny_unknown_fields, default)]
pub struct EngagementClassifierParams {
    /// XGBoost JSON model (optionally with the preprocessing attribute).
    pub model_file: String,
    /// Frames whose OpenFace confidence is below this count as missing; a change while
    /// running applies from the next frame.
    #[parameter(writable)]
    pub min_confidence: f64,
    /// Exponential smoothing of the per-second value; 1.0 turns it off.
    pub smoothing_alpha: f64,
    /// pandas `ewm(adjust=...)`; the authors used the default, true.
    pub smoothing_adjust: bool,
    /// How late (message time) a frame may arrive and still count, in [0, 1) s.
    pub max_lateness_s: f64,
    /// A source without frames for this long stops reporting, s.
    pub source_timeout_s: f64,
    /// Most sources (cameras x faces) tracked at once.
    pub max_sources: i64,
    /// Training: number of trees.
    pub n_estimators: i64,
    /// Training: maximum tree depth.
    pub max_depth: i64,
    /// Training: learning rate (eta).
    pub learning_rate: f64,
    /// Training: minimum hessian sum in a child.
    pub min_child_weight: f64,
    /// Training: L2 regularisation of leaf weights.
    pub reg_lambda: f64,
    /// Training data: what label 0 (neutral) becomes: engaged, disengaged or drop.
    pub neutral_label: String,
    /// Training data: continuous values that lost their decimal point: magnitude, missing
    /// or keep.
    pub decimal_repair: String,
    /// Seed of the synthetic generator.
    pub seed: i64,
    /// Also publish each camera face as a ROS4HRI person (REP-155): its `anonymous`, its
    /// per-second `engagement_status`, and the tracked and known lists.
    pub ros4hri: bool,
    /// Smoothed expected engagement at or above this: ENGAGED (a change while running
    /// applies from the next second).
    #[parameter(writable)]
    pub ros4hri_engaged_threshold: f64,
    /// At or below this: DISENGAGED; between the two, ENGAGING when it rose since the
    /// person's last second, DISENGAGING when it fell (a change while running applies from
    /// the next second).
    #[parameter(writable)]
    pub ros4hri_disengaged_threshold: f64,
    /// A person whose face was not seen for this long ends (leaves /humans/persons/tracked
    /// and known; its topics go); the face seen again is a new person, s.
    pub ros4hri_tracked_timeout_s: f64,
}

impl Default for EngagementClassifierParams {
    fn default() -> Self {
        EngagementClassifierParams {
            model_file: "nodes/engagement_classifier/models/synthetic_engagement.json".into(),
            min_confidence: 0.75,
            smoothing_alpha: 0.75,
            smoothing_adjust: true,
            max_lateness_s: 0.2,
            source_timeout_s: 5.0,
            max_sources: 8,
            n_estimators: 100,
            max_depth: 6,
            learning_rate: 0.3,
            min_child_weight: 1.0,
            reg_lambda: 1.0,
            neutral_label: "engaged".into(),
            decimal_repair: "magnitude".into(),
            seed: 7,
            ros4hri: true,
            ros4hri_engaged_threshold: 0.5,
            ros4hri_disengaged_threshold: -0.5,
            ros4hri_tracked_timeout_s: 5.0,
        }
    }
}

/// A parameter value out of range, or a parameter file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ParamsError {
    #[error("parameter {name} = {value}: {expected}")]
    OutOfRange {
        name: &'static str,
        value: String,
        expected: &'static str,
    },
    #[error("parameter {0}")]
    BadChoice(String),
    #[error(transparent)]
    File(#[from] node_shell::params::ParamsError),
}

fn check(
    ok: bool,
    name: &'static str,
    value: impl ToString,
    expected: &'static str,
) -> Result<(), ParamsError> {
    if ok {
        Ok(())
    } else {
        Err(ParamsError::OutOfRange {
            name,
            value: value.to_string(),
            expected,
        })
    }
}

impl EngagementClassifierParams {
    /// Reads and checks the `engagement_classifier` section of a ROS 2 parameter file, as the
    /// node does (node_shell's reader: `/**` sections, nested keys), for the offline tools.
    pub fn from_yaml_file(path: &Path) -> Result<EngagementClassifierParams, ParamsError> {
        let params: EngagementClassifierParams =
            node_shell::params::load_parameters(path, "engagement_classifier")?;
        params.validate()?;
        Ok(params)
    }

    /// Checks every value; the error names the parameter.
    pub fn validate(&self) -> Result<(), ParamsError> {
        let unit = "in [0, 1]";
        check(
            (0.0..=1.0).contains(&self.min_confidence),
            "min_confidence",
            self.min_confidence,
            unit,
        )?;
        let a = self.smoothing_alpha;
        check(a > 0.0 && a <= 1.0, "smoothing_alpha", a, "in (0, 1]")?;
        let l = self.max_lateness_s;
        check((0.0..1.0).contains(&l), "max_lateness_s", l, "in [0, 1)")?;
        let t = self.source_timeout_s;
        check(t > 0.0 && t.is_finite(), "source_timeout_s", t, "> 0")?;
        check(
            (1..=1024).contains(&self.max_sources),
            "max_sources",
            self.max_sources,
            "in 1..=1024",
        )?;
        check(
            self.n_estimators >= 1,
            "n_estimators",
            self.n_estimators,
            ">= 1",
        )?;
        check(
            (1..=16).contains(&self.max_depth),
            "max_depth",
            self.max_depth,
            "in 1..=16",
        )?;
        let eta = self.learning_rate;
        check(eta > 0.0 && eta <= 1.0, "learning_rate", eta, "in (0, 1]")?;
        let mcw = self.min_child_weight;
        check(
            mcw >= 0.0 && mcw.is_finite(),
            "min_child_weight",
            mcw,
            ">= 0",
        )?;
        let lambda = self.reg_lambda;
        check(
            lambda >= 0.0 && lambda.is_finite(),
            "reg_lambda",
            lambda,
            ">= 0",
        )?;
        let (up, down) = (
            self.ros4hri_engaged_threshold,
            self.ros4hri_disengaged_threshold,
        );
        check(
            (-1.0..=1.0).contains(&up),
            "ros4hri_engaged_threshold",
            up,
            "in [-1, 1]",
        )?;
        check(
            (-1.0..=up).contains(&down),
            "ros4hri_disengaged_threshold",
            down,
            "in [-1, ros4hri_engaged_threshold]",
        )?;
        let t = self.ros4hri_tracked_timeout_s;
        check(
            t > 0.0 && t.is_finite(),
            "ros4hri_tracked_timeout_s",
            t,
            "> 0",
        )?;
        self.load_options()?;
        Ok(())
    }

    /// A change asked for while the node runs (`ros2 param set`): `new` may differ from
    /// `self` only in `min_confidence` and the ROS4HRI thresholds, and is checked as at
    /// start-up. On success `self` is `new`; the estimator and the persons take the values
    /// (`EngagementEstimator::set_min_confidence`, `PersonEngagement::set_thresholds`).
    pub fn change(&mut self, new: EngagementClassifierParams) -> Result<(), String> {
        let only_writable = EngagementClassifierParams {
            min_confidence: new.min_confidence,
            ros4hri_engaged_threshold: new.ros4hri_engaged_threshold,
            ros4hri_disengaged_threshold: new.ros4hri_disengaged_threshold,
            ..self.clone()
        };
        if only_writable != new {
            return Err("only min_confidence, ros4hri_engaged_threshold and \
                 ros4hri_disengaged_threshold change while the classifier runs"
                .into());
        }
        new.validate().map_err(|e| e.to_string())?;
        *self = new;
        Ok(())
    }

    pub fn aggregator_config(&self) -> AggregatorConfig {
        AggregatorConfig {
            smoothing_alpha: self.smoothing_alpha,
            smoothing_adjust: self.smoothing_adjust,
            max_lateness_ns: (self.max_lateness_s * 1e9) as i64,
            source_timeout_ns: (self.source_timeout_s * 1e9) as i64,
            max_sources: self.max_sources.max(1) as usize,
        }
    }

    pub fn train_params(&self) -> TrainParams {
        TrainParams {
            n_estimators: self.n_estimators.max(1) as usize,
            max_depth: self.max_depth.clamp(1, 16) as usize,
            learning_rate: self.learning_rate as f32,
            min_child_weight: self.min_child_weight as f32,
            reg_lambda: self.reg_lambda as f32,
        }
    }

    pub fn load_options(&self) -> Result<LoadOptions, ParamsError> {
        Ok(LoadOptions {
            neutral_label: self
                .neutral_label
                .parse::<NeutralLabel>()
                .map_err(ParamsError::BadChoice)?,
            decimal_repair: self
                .decimal_repair
                .parse::<DecimalRepair>()
                .map_err(ParamsError::BadChoice)?,
        })
    }
}
