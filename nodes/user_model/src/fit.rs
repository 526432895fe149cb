//! Fitting, as the paper's "User Model" section: user vectors u_j = (P(success|L), mean E|L)
//! for L = 1..3, PCA to 2-D, K-means into c clusters, then per cluster the GPs F^p(L, F, PS) and
//! F^e(L, F, PS, O) on the authors' targets (success rate per observed (L, F, PS) group; mean E
//! per (L, F, PS, O) group, keeping groups with mean < 1.0).

use crate::clustering::{Pca, kmeans};
use crate::data::InteractionRecord;
use crate::gp::{GaussianProcess, Kernel};
use crate::model::*;
use sequence_game::{Level, ModelInput};
use std::collections::BTreeMap;

/// How to fit.
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    pub clusters: usize,
    pub seed: u64,
    pub kmeans_restarts: usize,
    /// Initial (or, with `optimise` false, fixed) kernel.
    pub kernel: Kernel,
    pub optimise: bool,
    pub optimiser_restarts: usize,
    pub noise: f64,
    pub bounds: (f64, f64),
    pub provenance: String,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            clusters: 2,
            seed: 7,
            kmeans_restarts: 10,
            kernel: Kernel::RationalQuadratic {
                length_scale: 1.0,
                alpha: 1.5,
            },
            optimise: true,
            optimiser_restarts: 0,
            noise: 1e-10,
            bounds: (1e-5, 1e5),
            provenance: String::new(),
        }
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn std(v: &[f64]) -> f64 {
    let m = mean(v);
    (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Each user's vector (P(s|L1), E1, P(s|L2), E2, P(s|L3), E3), in user-id order.
pub fn user_vectors(
    records: &[InteractionRecord],
) -> Result<Vec<(String, [f64; 6])>, UserModelError> {
    let mut by_user: BTreeMap<&str, Vec<&InteractionRecord>> = BTreeMap::new();
    for r in records {
        by_user.entry(&r.user_id).or_default().push(r);
    }
    let mut out = Vec::new();
    for (user, recs) in by_user {
        let mut v = [0.0; 6];
        for level in Level::ALL {
            let at: Vec<&&InteractionRecord> = recs.iter().filter(|r| r.level == level).collect();
            if at.is_empty() {
                return Err(UserModelError::MissingLevel {
                    user: user.into(),
                    level: level.get(),
                    what: "",
                });
            }
            let e: Vec<f64> = at.iter().filter_map(|r| r.engagement).collect();
            if e.is_empty() {
                return Err(UserModelError::MissingLevel {
                    user: user.into(),
                    level: level.get(),
                    what: " with engagement",
                });
            }
            v[2 * level.index()] =
                at.iter().filter(|r| r.outcome.sign() > 0).count() as f64 / at.len() as f64;
            v[2 * level.index() + 1] = mean(&e);
        }
        out.push((user.to_string(), v));
    }
    Ok(out)
}

fn component(
    inputs: Vec<Vec<f64>>,
    targets: Vec<f64>,
    options: &FitOptions,
    cluster: usize,
    name: &'static str,
    seed: u64,
) -> Result<GpComponent, UserModelError> {
    let d = inputs.first().map_or(0, Vec::len);
    let n = inputs.len().max(1) as f64;
    let input_mean: Vec<f64> = (0..d)
        .map(|j| inputs.iter().map(|x| x[j]).sum::<f64>() / n)
        .collect();
    let input_scale: Vec<f64> = (0..d)
        .map(|j| {
            (inputs
                .iter()
                .map(|x| (x[j] - input_mean[j]).powi(2))
                .sum::<f64>()
                / n
                + 1e-8)
                .sqrt()
        })
        .collect();
    let mut c = GpComponent {
        kernel: options.kernel,
        noise: options.noise,
        input_mean,
        input_scale,
        inputs,
        targets,
        log_marginal_likelihood: 0.0,
    };
    let x: Vec<Vec<f64>> = c.inputs.iter().map(|x| c.standardise(x)).collect();
    let err = |source| UserModelError::Gp {
        cluster,
        component: name,
        source,
    };
    let gp = if options.optimise {
        GaussianProcess::fit_optimised(
            x,
            &c.targets,
            options.kernel,
            options.noise,
            options.bounds,
            options.optimiser_restarts,
            seed,
        )
    } else {
        GaussianProcess::fit(x, &c.targets, options.kernel, options.noise)
    }
    .map_err(err)?;
    c.kernel = gp.kernel();
    c.log_marginal_likelihood = gp.log_marginal_likelihood();
    Ok(c)
}

/// Fits the user models of `records`.
pub fn fit(
    records: &[InteractionRecord],
    options: &FitOptions,
) -> Result<UserModelSet, UserModelError> {
    let users = user_vectors(records)?;
    if users.len() < 2 * options.clusters.max(1) {
        return Err(UserModelError::TooFewUsers {
            clusters: options.clusters,
            users: users.len(),
        });
    }
    let vectors: Vec<Vec<f64>> = users.iter().map(|(_, v)| v.to_vec()).collect();
    let pca = Pca::fit(&vectors, 2);
    let projected: Vec<Vec<f64>> = vectors.iter().map(|v| pca.project(v)).collect();
    let km = kmeans(
        &projected,
        options.clusters,
        options.kmeans_restarts,
        options.seed,
    );
    let mut clusters = Vec::new();
    for k in 0..options.clusters {
        let members: Vec<&str> = users
            .iter()
            .zip(&km.labels)
            .filter(|(_, l)| **l == k)
            .map(|((u, _), _)| u.as_str())
            .collect();
        if members.len() < 2 {
            return Err(UserModelError::ClusterTooSmall {
                cluster: k,
                users: members.len(),
            });
        }
        let recs: Vec<&InteractionRecord> = records
            .iter()
            .filter(|r| members.contains(&r.user_id.as_str()))
            .collect();
        // F^p targets: success rate per observed (L, F, PS).
        let mut success: BTreeMap<(u8, u8, i8), (f64, f64)> = BTreeMap::new();
        // F^e targets: mean E per observed (L, F, PS, O).
        let mut engagement: BTreeMap<(u8, u8, i8, i8), (f64, f64)> = BTreeMap::new();
        for r in &recs {
            let s = success
                .entry((r.level.get(), r.feedback as u8, r.previous_score))
                .or_default();
            s.0 += f64::from(u8::from(r.outcome.sign() > 0));
            s.1 += 1.0;
            if let Some(e) = r.engagement {
                let g = engagement
                    .entry((
                        r.level.get(),
                        r.feedback as u8,
                        r.previous_score,
                        r.outcome.sign(),
                    ))
                    .or_default();
                g.0 += e;
                g.1 += 1.0;
            }
        }
        let input = |l: u8, f: u8, ps: i8| -> Result<ModelInput, UserModelError> {
            let level =
                Level::new(l.into()).map_err(|e| UserModelError::UserVector(e.to_string()))?;
            let feedback = sequence_game::Feedback::new(f.into())
                .map_err(|e| UserModelError::UserVector(e.to_string()))?;
            ModelInput::new(level, feedback, ps)
                .map_err(|e| UserModelError::UserVector(e.to_string()))
        };
        let mut px = Vec::new();
        let mut py = Vec::new();
        for ((l, f, ps), (hits, n)) in &success {
            px.push(encode(input(*l, *f, *ps)?, None));
            py.push(hits / n);
        }
        let mut ex = Vec::new();
        let mut ey = Vec::new();
        for ((l, f, ps, o), (sum, n)) in &engagement {
            let m = sum / n;
            if m < 1.0 {
                let outcome = sequence_game::Outcome::new((*o).into())
                    .map_err(|e| UserModelError::UserVector(e.to_string()))?;
                ex.push(encode(input(*l, *f, *ps)?, Some(outcome)));
                ey.push(m);
            }
        }
        let seed = options.seed.wrapping_add(1000 * k as u64);
        let levels = Level::ALL
            .iter()
            .map(|l| {
                let member_vectors: Vec<&[f64; 6]> = users
                    .iter()
                    .filter(|(u, _)| members.contains(&u.as_str()))
                    .map(|(_, v)| v)
                    .collect();
                let p: Vec<f64> = member_vectors.iter().map(|v| v[2 * l.index()]).collect();
                let e: Vec<f64> = member_vectors
                    .iter()
                    .map(|v| v[2 * l.index() + 1])
                    .collect();
                LevelStats {
                    level: l.get(),
                    success_mean: mean(&p),
                    success_std: std(&p),
                    engagement_mean: mean(&e),
                    engagement_std: std(&e),
                }
            })
            .collect();
        clusters.push(ClusterModel {
            cluster: k,
            users: members.iter().map(|m| m.to_string()).collect(),
            levels,
            success: component(px, py, options, k, "F^p", seed)?,
            engagement: component(ex, ey, options, k, "F^e", seed + 1)?,
        });
    }
    let file = UserModelFile {
        format: FORMAT.into(),
        version: FORMAT_VERSION,
        provenance: options.provenance.clone(),
        pca,
        centres: km.centres,
        users: users
            .iter()
            .zip(&km.labels)
            .zip(&projected)
            .map(|(((u, v), l), p)| UserPoint {
                user: u.clone(),
                cluster: *l,
                vector: v.to_vec(),
                projection: p.clone(),
            })
            .collect(),
        clusters,
    };
    UserModelSet::from_file(file)
}
