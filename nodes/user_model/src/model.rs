//! The fitted user models M_k = (F^p_k, F^e_k) of every cluster, as one versioned JSON file:
//! the PCA basis, the cluster centres, and per cluster the GP training data and
//! hyperparameters. Loading refits the GPs from exactly that data, so predictions are identical;
//! every prediction over the finite input space is then tabulated once.

use crate::clustering::{Pca, nearest};
use crate::gp::{GaussianProcess, GpError, Kernel};
use sequence_game::{ModelInput, Outcome, Prediction, UserModelTable};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub const FORMAT: &str = "qt_therapy user models";
pub const FORMAT_VERSION: u32 = 1;

/// Anything that goes wrong fitting, saving or loading user models, naming the culprit.
#[derive(Debug, thiserror::Error)]
pub enum UserModelError {
    #[error(transparent)]
    Data(#[from] crate::data::DataError),
    #[error("{users} users cannot make {clusters} clusters of at least 2 users each")]
    TooFewUsers { clusters: usize, users: usize },
    #[error(
        "cluster {cluster} has {users} user(s): a user model needs at least 2 (try fewer clusters)"
    )]
    ClusterTooSmall { cluster: usize, users: usize },
    #[error(
        "user {user} played no level-{level} sequence{what}: the user vector needs every level"
    )]
    MissingLevel {
        user: String,
        level: u8,
        what: &'static str,
    },
    #[error("cluster {cluster}, {component}: {source}")]
    Gp {
        cluster: usize,
        component: &'static str,
        source: GpError,
    },
    #[error("{path}: {reason}")]
    File { path: PathBuf, reason: String },
    #[error("{path} is format version {found}; this program reads version {FORMAT_VERSION}")]
    Version { path: PathBuf, found: u32 },
    #[error("user vector: {0}")]
    UserVector(String),
    #[error("cluster {cluster} does not exist (the model file has {count})")]
    NoSuchCluster { cluster: i64, count: usize },
}

/// A GP component as stored: inputs before standardisation, targets, kernel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GpComponent {
    pub kernel: Kernel,
    pub noise: f64,
    /// Per input dimension: the training mean and sqrt(variance + 1e-8) used to standardise.
    pub input_mean: Vec<f64>,
    pub input_scale: Vec<f64>,
    /// Encoded inputs [L/3, F one-hot (3), PS/3 (, O)], one row per training group.
    pub inputs: Vec<Vec<f64>>,
    pub targets: Vec<f64>,
    pub log_marginal_likelihood: f64,
}

impl GpComponent {
    pub fn standardise(&self, x: &[f64]) -> Vec<f64> {
        x.iter()
            .zip(&self.input_mean)
            .zip(&self.input_scale)
            .map(|((v, m), s)| (v - m) / s)
            .collect()
    }

    pub fn build(&self) -> Result<GaussianProcess, GpError> {
        GaussianProcess::fit(
            self.inputs.iter().map(|x| self.standardise(x)).collect(),
            &self.targets,
            self.kernel,
            self.noise,
        )
    }
}

/// Per level, across a cluster's users: mean and std of P(success|L) and of E|L (Fig. 3).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LevelStats {
    pub level: u8,
    pub success_mean: f64,
    pub success_std: f64,
    pub engagement_mean: f64,
    pub engagement_std: f64,
}

/// One cluster's users and model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClusterModel {
    pub cluster: usize,
    pub users: Vec<String>,
    pub levels: Vec<LevelStats>,
    pub success: GpComponent,
    pub engagement: GpComponent,
}

/// The whole file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
pub struct UserPoint {
    pub user: String,
    pub cluster: usize,
    pub vector: Vec<f64>,
    pub projection: Vec<f64>,
}

/// The encoded GP input of (L, F, PS) (and O for engagement).
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

/// Loaded user models, ready to answer.
#[derive(Debug, Clone)]
pub struct UserModelSet {
    file: UserModelFile,
    tables: Vec<UserModelTable>,
}

impl UserModelSet {
    /// Builds the GPs of `file` and tabulates every prediction.
    pub fn from_file(file: UserModelFile) -> Result<UserModelSet, UserModelError> {
        let mut tables = Vec::new();
        for c in &file.clusters {
            let gp_err = |component| {
                move |source| UserModelError::Gp {
                    cluster: c.cluster,
                    component,
                    source,
                }
            };
            let success = c.success.build().map_err(gp_err("F^p"))?;
            let engagement = c.engagement.build().map_err(gp_err("F^e"))?;
            let mut failure = None;
            let table = UserModelTable::tabulate(
                c.cluster,
                |i| match success.predict(&c.success.standardise(&encode(i, None))) {
                    Ok((m, s)) => Prediction {
                        mean: m.clamp(0.0, 1.0),
                        std: s,
                    },
                    Err(e) => {
                        failure = Some(e);
                        Prediction {
                            mean: 0.0,
                            std: 0.0,
                        }
                    }
                },
                |i, o| match engagement.predict(&c.engagement.standardise(&encode(i, Some(o)))) {
                    Ok((m, s)) => Prediction {
                        mean: m.clamp(-1.0, 1.0),
                        std: s,
                    },
                    Err(_) => Prediction {
                        mean: 0.0,
                        std: 0.0,
                    },
                },
            );
            if let Some(e) = failure {
                return Err(UserModelError::Gp {
                    cluster: c.cluster,
                    component: "F^p",
                    source: e,
                });
            }
            tables.push(table);
        }
        Ok(UserModelSet { file, tables })
    }

    /// Reads and checks a model file.
    pub fn load(path: &Path) -> Result<UserModelSet, UserModelError> {
        let bad = |reason: String| UserModelError::File {
            path: path.into(),
            reason,
        };
        let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
        let value: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| bad(format!("not JSON (truncated?): {e}")))?;
        if value.get("format").and_then(|f| f.as_str()) != Some(FORMAT) {
            return Err(bad(format!(
                "not a user-model file (its \"format\" is not {FORMAT:?})"
            )));
        }
        let version = value.get("version").and_then(|v| v.as_u64()).unwrap_or(0) as u32;
        if version != FORMAT_VERSION {
            return Err(UserModelError::Version {
                path: path.into(),
                found: version,
            });
        }
        let file: UserModelFile = serde_json::from_value(value).map_err(|e| bad(e.to_string()))?;
        if file.clusters.is_empty() || file.centres.len() != file.clusters.len() {
            return Err(bad(format!(
                "{} clusters but {} centres",
                file.clusters.len(),
                file.centres.len()
            )));
        }
        let set = UserModelSet::from_file(file)?;
        for t in &set.tables {
            t.validate().map_err(|e| bad(e.to_string()))?;
        }
        Ok(set)
    }

    /// Writes the file through a temporary file and a rename: never half a file.
    pub fn save(&self, path: &Path) -> Result<(), UserModelError> {
        let bad = |reason: String| UserModelError::File {
            path: path.into(),
            reason,
        };
        let text = serde_json::to_string_pretty(&self.file).map_err(|e| bad(e.to_string()))?;
        let dir = path
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        std::fs::create_dir_all(dir).map_err(|e| bad(e.to_string()))?;
        let tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| bad(e.to_string()))?;
        std::fs::write(tmp.path(), text + "\n").map_err(|e| bad(e.to_string()))?;
        // The temporary file is private; the model is meant to be read by every node.
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o644))
            .map_err(|e| bad(e.to_string()))?;
        tmp.persist(path).map_err(|e| bad(e.error.to_string()))?;
        Ok(())
    }

    pub fn file(&self) -> &UserModelFile {
        &self.file
    }

    pub fn cluster_count(&self) -> usize {
        self.tables.len()
    }

    /// Every prediction of every cluster, precomputed.
    pub fn tables(&self) -> Vec<UserModelTable> {
        self.tables.clone()
    }

    pub fn table(&self, cluster: i64) -> Result<&UserModelTable, UserModelError> {
        usize::try_from(cluster)
            .ok()
            .and_then(|c| self.tables.get(c))
            .ok_or(UserModelError::NoSuchCluster {
                cluster,
                count: self.tables.len(),
            })
    }

    /// The cluster of a new user from their vector (P(s|L1), E1, P(s|L2), E2, P(s|L3), E3).
    pub fn assign_cluster(&self, user_vector: &[f64; 6]) -> Result<usize, UserModelError> {
        for (i, v) in user_vector.iter().enumerate() {
            let (lo, hi) = if i % 2 == 0 { (0.0, 1.0) } else { (-1.0, 1.0) };
            if !(v.is_finite() && *v >= lo && *v <= hi) {
                return Err(UserModelError::UserVector(format!(
                    "value {i} = {v} is outside [{lo}, {hi}]"
                )));
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
