//! The fitted user models M_k = (F^p_k, F^e_k) of every cluster, as one versioned JSON file:
//! the PCA basis, the cluster centres, and per cluster the GP training data and
//! hyperparameters. Loading refits the GPs from exactly that data, so predictions are identical;
//! every prediction over the finite input space is then tabulated once.

use crate::clustering::{Pca, nearest};
use crate::gp::{GaussianProcess, GpError, Kernel, OptimiserOptions};
use sequence_game::{ModelInput, Outcome, Prediction, UserModelTable};
use serde::{Deserialize, Serialize};
use std::path::Path;
use versioned_json::{FileError, Kind};

pub const FORMAT: &str = "qt_therapy user models";
/// 2: per-level stats gained `sequences`; their std is across users (1 had no `sequences`).
pub const FORMAT_VERSION: u32 = 2;
/// The file's kind, read and written as the suite's other versioned files (`versioned_json`).
pub const KIND: Kind = Kind {
    format: FORMAT,
    version: FORMAT_VERSION,
    name: "user-model",
};

/// Anything that goes wrong fitting, saving or loading user models, naming the culprit.
#[derive(Debug, thiserror::Error)]
pub enum UserModelError {
    #[error(transparent)]
    Data(#[from] crate::data::DataError),
    #[error("{users} users cannot make {clusters} clusters of at least 2 users each")]
    TooFewUsers { clusters: usize, users: usize },
    #[error(
        "cluster {cluster} has {} user(s) ({}): a user model needs at least 2 (try fewer clusters)",
        users.len(),
        users.join(", ")
    )]
    ClusterTooSmall { cluster: usize, users: Vec<String> },
    #[error(
        "user {user} has no level-{level} sequence with engagement: the user vector needs every level"
    )]
    MissingLevel { user: String, level: u8 },
    #[error("cluster {cluster}, {component}: {source}")]
    Gp {
        cluster: usize,
        component: &'static str,
        source: GpError,
    },
    #[error("fit options: {0}")]
    Options(String),
    /// The file, its layout or a field of it (named), as read or written.
    #[error(transparent)]
    File(#[from] FileError),
    #[error("user vector, value {index} = {value}: must be finite and in [{low}, {high}]")]
    UserVector {
        index: usize,
        value: f64,
        low: f64,
        high: f64,
    },
    #[error("cluster {cluster} does not exist (the model has {count})")]
    NoSuchCluster { cluster: i64, count: usize },
}

/// A GP component as stored: inputs before standardisation, targets, kernel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GpComponent {
    pub kernel: Kernel,
    pub noise: f64,
    /// Per input dimension: the training mean and sqrt(variance + 1e-8) used to standardise.
    pub input_mean: Vec<f64>,
    pub input_scale: Vec<f64>,
    /// Encoded inputs [L/3, F one-hot (3), PS/3 (, O)], one row per training group.
    pub inputs: Vec<Vec<f64>>,
    pub targets: Vec<f64>,
    /// With a noise fitted per sequence (`NoiseModel::FittedPerSequence`): how many values
    /// each target is the mean of; target i then has noise variance `noise / group_sizes[i]`.
    /// Absent (the paper's fit): `noise` on every target.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub group_sizes: Option<Vec<u32>>,
    pub log_marginal_likelihood: f64,
}

impl GpComponent {
    /// Fits one GP on raw encoded `inputs`: z-scores them with their population mean and
    /// variance (+1e-8), as the authors do, then fits `kernel` as given (`optimiser` None) or
    /// with the hyperparameters that maximise the log marginal likelihood.
    pub fn fit(
        inputs: Vec<Vec<f64>>,
        targets: Vec<f64>,
        kernel: Kernel,
        noise: f64,
        optimiser: Option<OptimiserOptions>,
    ) -> Result<GpComponent, GpError> {
        let mut c = GpComponent::standardised(inputs, targets, kernel, noise, None)?;
        let x: Vec<Vec<f64>> = c.inputs.iter().map(|x| c.standardise(x)).collect();
        let gp = match optimiser {
            Some(o) => GaussianProcess::fit_optimised(x, &c.targets, kernel, noise, &o),
            None => GaussianProcess::fit(x, &c.targets, kernel, noise),
        }?;
        c.kernel = gp.kernel();
        c.log_marginal_likelihood = gp.log_marginal_likelihood();
        Ok(c)
    }

    /// Fits one GP whose targets are means of `group_sizes` values each: the noise variance
    /// of one value, σ², is a hyperparameter beside the kernel's (from `initial_noise`), and
    /// target i gets σ² / n_i on the diagonal. The posterior σ then says how well the data
    /// pin the value down (few values, or values that disagree: wide), where the paper's
    /// fixed 1e-10 makes the GP pass through every target (σ ≈ 0 at every input seen).
    pub fn fit_noise_per_sequence(
        inputs: Vec<Vec<f64>>,
        targets: Vec<f64>,
        group_sizes: Vec<u32>,
        kernel: Kernel,
        initial_noise: f64,
        optimiser: OptimiserOptions,
    ) -> Result<GpComponent, GpError> {
        let mut c =
            GpComponent::standardised(inputs, targets, kernel, initial_noise, Some(group_sizes))?;
        let x: Vec<Vec<f64>> = c.inputs.iter().map(|x| c.standardise(x)).collect();
        let gp = GaussianProcess::fit_optimised_with_noise(
            x,
            &c.targets,
            kernel,
            initial_noise,
            c.noise_scale(),
            &optimiser,
        )?;
        c.kernel = gp.kernel();
        c.noise = gp.noise();
        c.log_marginal_likelihood = gp.log_marginal_likelihood();
        Ok(c)
    }

    /// Per target, what multiplies `noise` on the diagonal: 1 / group size, or 1.
    pub fn noise_scale(&self) -> Vec<f64> {
        match &self.group_sizes {
            Some(n) => n.iter().map(|n| 1.0 / f64::from((*n).max(1))).collect(),
            None => vec![1.0; self.targets.len()],
        }
    }

    /// The component before fitting: inputs z-scored as the authors do.
    fn standardised(
        inputs: Vec<Vec<f64>>,
        targets: Vec<f64>,
        kernel: Kernel,
        noise: f64,
        group_sizes: Option<Vec<u32>>,
    ) -> Result<GpComponent, GpError> {
        let d = inputs.first().map_or(0, Vec::len);
        if let Some(index) = inputs.iter().position(|x| x.len() != d) {
            return Err(GpError::Ragged {
                index,
                expected: d,
                found: inputs[index].len(),
            });
        }
        let n = inputs.len().max(1) as f64;
        let input_mean: Vec<f64> = (0..d)
            .map(|j| {
                inputs
                    .iter()
                    .map(|x| x.get(j).copied().unwrap_or(0.0))
                    .sum::<f64>()
                    / n
            })
            .collect();
        let input_scale: Vec<f64> = (0..d)
            .map(|j| {
                let var = inputs
                    .iter()
                    .map(|x| (x.get(j).copied().unwrap_or(0.0) - input_mean[j]).powi(2))
                    .sum::<f64>()
                    / n;
                (var + 1e-8).sqrt()
            })
            .collect();
        if let Some(n) = &group_sizes
            && n.len() != targets.len()
        {
            return Err(GpError::Shape {
                inputs: targets.len(),
                targets: n.len(),
            });
        }
        Ok(GpComponent {
            kernel,
            noise,
            input_mean,
            input_scale,
            inputs,
            targets,
            group_sizes,
            log_marginal_likelihood: 0.0,
        })
    }

    pub fn standardise(&self, x: &[f64]) -> Vec<f64> {
        x.iter()
            .zip(&self.input_mean)
            .zip(&self.input_scale)
            .map(|((v, m), s)| (v - m) / s)
            .collect()
    }

    pub fn build(&self) -> Result<GaussianProcess, GpError> {
        GaussianProcess::fit_scaled(
            self.inputs.iter().map(|x| self.standardise(x)).collect(),
            &self.targets,
            self.kernel,
            self.noise,
            self.noise_scale(),
        )
    }
}

/// Per level, one cluster's numbers for Fig. 3b: the means over the cluster's sequences of that
/// level (the authors' per-cluster numbers), the standard deviations across the cluster's users
/// (of each user's own success rate and mean E at that level).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LevelStats {
    pub level: u8,
    pub sequences: usize,
    pub success_mean: f64,
    pub success_std: f64,
    pub engagement_mean: f64,
    pub engagement_std: f64,
}

/// One cluster's users and model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClusterModel {
    pub cluster: usize,
    pub users: Vec<String>,
    pub levels: Vec<LevelStats>,
    pub success: GpComponent,
    pub engagement: GpComponent,
}

impl ClusterModel {
    /// Builds the cluster's GPs and tabulates every prediction (clamped to [0, 1] and
    /// [-1, 1]).
    pub fn tabulate(&self) -> Result<UserModelTable, UserModelError> {
        let c = self;
        let gp_err = |component| {
            move |source| UserModelError::Gp {
                cluster: c.cluster,
                component,
                source,
            }
        };
        let success = c.success.build().map_err(gp_err("F^p"))?;
        let engagement = c.engagement.build().map_err(gp_err("F^e"))?;
        let mut failure: Option<UserModelError> = None;
        let mut note = |component: &'static str, e: GpError| {
            failure.get_or_insert(UserModelError::Gp {
                cluster: c.cluster,
                component,
                source: e,
            });
            Prediction {
                mean: 0.0,
                std: 0.0,
            }
        };
        let mut predictions = Vec::new();
        for input in ModelInput::all() {
            predictions.push(
                match success.predict(&c.success.standardise(&encode(input, None))) {
                    Ok((m, s)) => Prediction {
                        mean: m.clamp(0.0, 1.0),
                        std: s,
                    },
                    Err(e) => note("F^p", e),
                },
            );
        }
        let mut engagement_predictions = Vec::new();
        for input in ModelInput::all() {
            for o in Outcome::ALL {
                let x = c.engagement.standardise(&encode(input, Some(o)));
                engagement_predictions.push(match engagement.predict(&x) {
                    Ok((m, s)) => Prediction {
                        mean: m.clamp(-1.0, 1.0),
                        std: s,
                    },
                    Err(e) => note("F^e", e),
                });
            }
        }
        if let Some(e) = failure {
            return Err(e);
        }
        // Built in table order: ModelInput::all(), then Outcome::ALL within each input.
        Ok(UserModelTable {
            cluster: c.cluster,
            success: predictions,
            engagement: engagement_predictions,
        })
    }
}

/// The whole file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UserModelFile {
    pub format: String,
    pub version: u32,
    /// Where the data came from and how it was fitted.
    pub provenance: String,
    pub pca: Pca,
    pub centres: Vec<Vec<f64>>,
    /// Users with their 6-D vector and 2-D projection, for plots.
    pub users: Vec<UserPoint>,
    pub clusters: Vec<ClusterModel>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UserPoint {
    pub user: String,
    pub cluster: usize,
    pub vector: Vec<f64>,
    pub projection: Vec<f64>,
}

/// The encoded GP input [L/3, one-hot F, PS/3] of (L, F, PS), with O (±1) appended for F^e.
pub fn encode(input: ModelInput, outcome: Option<Outcome>) -> Vec<f64> {
    let mut x = vec![
        f64::from(input.level.get()) / 3.0,
        0.0,
        0.0,
        0.0,
        f64::from(input.previous_score) / 3.0,
    ];
    x[1 + input.feedback.index()] = 1.0;
    if let Some(o) = outcome {
        x.push(f64::from(o.sign()));
    }
    x
}

/// Width of the encoded F^p input; F^e adds the outcome.
pub const SUCCESS_INPUT_WIDTH: usize = 5;

/// Loaded user models, ready to answer: every prediction already tabulated.
#[derive(Debug, Clone)]
pub struct UserModelSet {
    file: UserModelFile,
    tables: Vec<UserModelTable>,
}

/// Where a loaded file does not make sense: (field path, reason).
type Problem = (String, String);

fn finite_all(field: String, values: &[f64]) -> Result<(), Problem> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err((
            format!("{field}[{i}]"),
            format!("{} is not finite", values[i]),
        )),
        None => Ok(()),
    }
}

fn length(field: String, found: usize, expected: usize) -> Result<(), Problem> {
    if found == expected {
        Ok(())
    } else {
        Err((field, format!("has {found} values, expected {expected}")))
    }
}

impl GpComponent {
    /// Checks the stored shape and values; `width` is the encoded input width.
    /// `max_rows` is the number of distinct groups: refitting is cubic in the rows, so a
    /// file with more would only make loading hang (fuzz/regressions/user_model_file).
    fn check(
        &self,
        field: &str,
        width: usize,
        max_rows: usize,
        range: (f64, f64),
    ) -> Result<(), Problem> {
        self.kernel
            .validate()
            .map_err(|e| (format!("{field}.kernel"), e.to_string()))?;
        if !(self.noise.is_finite() && self.noise >= 0.0) {
            return Err((
                format!("{field}.noise"),
                format!("{} must be >= 0", self.noise),
            ));
        }
        length(format!("{field}.input_mean"), self.input_mean.len(), width)?;
        length(
            format!("{field}.input_scale"),
            self.input_scale.len(),
            width,
        )?;
        finite_all(format!("{field}.input_mean"), &self.input_mean)?;
        if let Some(i) = self
            .input_scale
            .iter()
            .position(|v| !(v.is_finite() && *v > 0.0))
        {
            return Err((
                format!("{field}.input_scale[{i}]"),
                format!("{} must be > 0", self.input_scale[i]),
            ));
        }
        if self.inputs.is_empty() {
            return Err((format!("{field}.inputs"), "is empty".into()));
        }
        if self.inputs.len() > max_rows {
            return Err((
                format!("{field}.inputs"),
                format!(
                    "has {} rows; a model has at most one per input group ({max_rows})",
                    self.inputs.len()
                ),
            ));
        }
        length(
            format!("{field}.targets"),
            self.targets.len(),
            self.inputs.len(),
        )?;
        if let Some(n) = &self.group_sizes {
            length(format!("{field}.group_sizes"), n.len(), self.inputs.len())?;
            if let Some(i) = n.iter().position(|n| *n == 0) {
                return Err((
                    format!("{field}.group_sizes[{i}]"),
                    "is 0: a target is the mean of at least one value".into(),
                ));
            }
        }
        for (i, x) in self.inputs.iter().enumerate() {
            length(format!("{field}.inputs[{i}]"), x.len(), width)?;
            finite_all(format!("{field}.inputs[{i}]"), x)?;
        }
        if let Some(i) = self
            .targets
            .iter()
            .position(|t| !(t.is_finite() && *t >= range.0 && *t <= range.1))
        {
            return Err((
                format!("{field}.targets[{i}]"),
                format!("{} is outside [{}, {}]", self.targets[i], range.0, range.1),
            ));
        }
        Ok(())
    }
}

impl UserModelFile {
    /// Checks everything the types do not: lengths, finiteness, cluster numbering.
    fn check(&self) -> Result<(), Problem> {
        let dims = 2 * sequence_game::LEVEL_COUNT;
        length("pca.mean".into(), self.pca.mean.len(), dims)?;
        finite_all("pca.mean".into(), &self.pca.mean)?;
        length("pca.components".into(), self.pca.components.len(), 2)?;
        for (i, c) in self.pca.components.iter().enumerate() {
            length(format!("pca.components[{i}]"), c.len(), dims)?;
            finite_all(format!("pca.components[{i}]"), c)?;
        }
        if self.clusters.is_empty() {
            return Err(("clusters".into(), "is empty".into()));
        }
        length("centres".into(), self.centres.len(), self.clusters.len())?;
        for (i, c) in self.centres.iter().enumerate() {
            length(format!("centres[{i}]"), c.len(), 2)?;
            finite_all(format!("centres[{i}]"), c)?;
        }
        let groups = ModelInput::all().count();
        for (i, c) in self.clusters.iter().enumerate() {
            if c.cluster != i {
                return Err((
                    format!("clusters[{i}].cluster"),
                    format!(
                        "is {}, expected {i} (clusters are numbered in order)",
                        c.cluster
                    ),
                ));
            }
            c.success.check(
                &format!("clusters[{i}].success"),
                SUCCESS_INPUT_WIDTH,
                groups,
                (0.0, 1.0),
            )?;
            c.engagement.check(
                &format!("clusters[{i}].engagement"),
                SUCCESS_INPUT_WIDTH + 1,
                groups * Outcome::ALL.len(),
                (-1.0, 1.0),
            )?;
        }
        for (i, u) in self.users.iter().enumerate() {
            if u.cluster >= self.clusters.len() {
                return Err((
                    format!("users[{i}].cluster"),
                    format!("{} does not exist", u.cluster),
                ));
            }
        }
        Ok(())
    }
}

impl UserModelSet {
    /// Builds the GPs of `file` and tabulates every prediction (clamped to [0, 1] and
    /// [-1, 1]).
    pub fn from_file(file: UserModelFile) -> Result<UserModelSet, UserModelError> {
        let tables = file
            .clusters
            .iter()
            .map(ClusterModel::tabulate)
            .collect::<Result<Vec<_>, _>>()?;
        Ok(UserModelSet { file, tables })
    }

    /// Reads and checks a model file, naming the field at fault.
    pub fn load(path: &Path) -> Result<UserModelSet, UserModelError> {
        UserModelSet::checked(KIND.load(path)?, path)
    }

    /// As [`UserModelSet::load`], from the file's text (`path` only names it in errors).
    pub fn from_json_str(text: &str, path: &Path) -> Result<UserModelSet, UserModelError> {
        UserModelSet::checked(KIND.from_json_str(text, path)?, path)
    }

    /// The models of a file that has the layout, once its content is checked.
    fn checked(file: UserModelFile, path: &Path) -> Result<UserModelSet, UserModelError> {
        file.check()
            .map_err(|(field, reason)| FileError::field(path, field, reason))?;
        let set = UserModelSet::from_file(file)?;
        for t in &set.tables {
            t.validate().map_err(|e| FileError::file(path, e))?;
        }
        Ok(set)
    }

    /// Writes the file through a temporary file and a rename: never half a file.
    pub fn save(&self, path: &Path) -> Result<(), UserModelError> {
        Ok(KIND.save(path, &self.file)?)
    }

    pub fn file(&self) -> &UserModelFile {
        &self.file
    }

    pub fn cluster_count(&self) -> usize {
        self.tables.len()
    }

    /// Every prediction of every cluster, precomputed: a query is a table lookup.
    pub fn tables(&self) -> Vec<UserModelTable> {
        self.tables.clone()
    }

    /// The table of one cluster.
    pub fn table(&self, cluster: i64) -> Result<&UserModelTable, UserModelError> {
        usize::try_from(cluster)
            .ok()
            .and_then(|c| self.tables.get(c))
            .ok_or(UserModelError::NoSuchCluster {
                cluster,
                count: self.tables.len(),
            })
    }

    /// The cluster of a new user from their vector (P(s|L1), E1, P(s|L2), E2, P(s|L3), E3):
    /// PCA-projected, then the nearest cluster centre.
    pub fn assign_cluster(&self, user_vector: &[f64; 6]) -> Result<usize, UserModelError> {
        for (index, value) in user_vector.iter().enumerate() {
            let (low, high) = if index % 2 == 0 {
                (0.0, 1.0)
            } else {
                (-1.0, 1.0)
            };
            if !(value.is_finite() && *value >= low && *value <= high) {
                return Err(UserModelError::UserVector {
                    index,
                    value: *value,
                    low,
                    high,
                });
            }
        }
        Ok(nearest(
            &self.file.centres,
            &self.file.pca.project(user_vector),
        ))
    }

    /// The user's position in the 2-D PCA space.
    pub fn project(&self, user_vector: &[f64; 6]) -> Vec<f64> {
        self.file.pca.project(user_vector)
    }
}
