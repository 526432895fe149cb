//! Fitting, as the paper's "User Model" section: user vectors u_j = (P(success|L), mean E|L)
//! for L = 1..3, PCA to 2-D, K-means into c clusters, then per cluster the GPs F^p(L, F, PS) and
//! F^e(L, F, PS, O) on the authors' targets (success rate per observed (L, F, PS) group; mean E
//! per observed (L, F, PS, O) group, keeping groups with mean < 1.0).

use crate::clustering::{Pca, kmeans};
use crate::data::{InteractionRecord, validate_all};
use crate::gp::{Kernel, OptimiserOptions};
use crate::model::{
    ClusterModel, FORMAT, FORMAT_VERSION, GpComponent, LevelStats, UserModelError, UserModelFile,
    UserModelSet, UserPoint, encode,
};
use sequence_game::{Level, ModelInput, Outcome};
use std::collections::BTreeMap;

/// What the GPs' noise term is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NoiseModel {
    /// The paper's: `noise` (1e-10) on every target. The GP passes through each observed
    /// group's target, so σ is about 0 at every input the data saw, whatever it rests on (one
    /// sequence or thirty), and large only where the data has nothing.
    #[default]
    Fixed,
    /// Each target is the mean of its group's n sequences, so it gets σ² / n on the diagonal,
    /// with σ² (the noise of one sequence) maximising the log marginal likelihood beside the
    /// kernel's hyperparameters. σ of a prediction then says how well the data pin it down.
    FittedPerSequence,
}

/// The initial noise variance of one sequence when it is fitted: about a success's variance
/// p (1 − p) at p = 0.9, or an engagement's spread.
pub const INITIAL_FITTED_NOISE: f64 = 0.1;

/// How to fit.
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// Number of clusters c.
    pub clusters: usize,
    /// Seeds K-means and the hyperparameter restarts.
    pub seed: u64,
    /// K-means runs from different k-means++ seedings; the lowest inertia wins.
    pub kmeans_restarts: usize,
    /// Initial (or, with `optimise` false, fixed) kernel of every GP.
    pub kernel: Kernel,
    /// Maximise the log marginal likelihood (else keep `kernel` as given).
    pub optimise: bool,
    /// Seeded log-uniform starts of the search besides the initial values.
    pub optimiser_restarts: usize,
    /// Added to the kernel diagonal (scikit-learn's `alpha`) with `NoiseModel::Fixed`.
    pub noise: f64,
    /// The paper's fixed noise, or a noise fitted per sequence.
    pub noise_model: NoiseModel,
    /// Bounds of every hyperparameter.
    pub bounds: (f64, f64),
    /// Stored in the file: where the data came from and how it was fitted.
    pub provenance: String,
}

impl Default for FitOptions {
    /// The authors' settings (RationalQuadratic, l = 1, α = 1.5 initial, noise 1e-10, bounds
    /// 1e-5..1e5), with 10 K-means restarts and no optimiser restarts.
    fn default() -> Self {
        FitOptions {
            clusters: 2,
            seed: 7,
            kmeans_restarts: 10,
            kernel: Kernel::AUTHORS,
            optimise: true,
            optimiser_restarts: 0,
            noise: 1e-10,
            noise_model: NoiseModel::Fixed,
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

/// Each user's vector (P(s|L1), E1, P(s|L2), E2, P(s|L3), E3), in user-id order: per level the
/// user's success rate and mean E over their sequences of that level.
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
            let e: Vec<f64> = at.iter().filter_map(|r| r.engagement).collect();
            if e.is_empty() {
                return Err(UserModelError::MissingLevel {
                    user: user.into(),
                    level: level.get(),
                });
            }
            v[2 * level.index()] = at.iter().filter(|r| r.outcome == Outcome::Success).count()
                as f64
                / at.len() as f64;
            v[2 * level.index() + 1] = mean(&e);
        }
        out.push((user.to_string(), v));
    }
    Ok(out)
}

/// One GP's training set, grouped as the authors group it: per observed group its encoded
/// input, its target (the group's mean) and how many records it is the mean of.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TrainingSet {
    pub inputs: Vec<Vec<f64>>,
    pub targets: Vec<f64>,
    pub group_sizes: Vec<u32>,
}

/// The authors' targets for one cluster's records: F^p's, then F^e's.
pub fn training_sets(records: &[&InteractionRecord]) -> (TrainingSet, TrainingSet) {
    // Sums and counts per observed group, in table order.
    let mut success: BTreeMap<usize, (ModelInput, f64, f64)> = BTreeMap::new();
    let mut engagement: BTreeMap<usize, (ModelInput, Outcome, f64, f64)> = BTreeMap::new();
    for r in records {
        let input = ModelInput {
            level: r.level,
            feedback: r.feedback,
            previous_score: r.previous_score,
        };
        let s = success.entry(input.index()).or_insert((input, 0.0, 0.0));
        s.1 += f64::from(u8::from(r.outcome == Outcome::Success));
        s.2 += 1.0;
        if let Some(e) = r.engagement {
            let g = engagement
                .entry(input.engagement_index(r.outcome))
                .or_insert((input, r.outcome, 0.0, 0.0));
            g.2 += e;
            g.3 += 1.0;
        }
    }
    let mut p = TrainingSet::default();
    for (input, hits, n) in success.values() {
        p.inputs.push(encode(*input, None));
        p.targets.push(hits / n);
        p.group_sizes.push(*n as u32);
    }
    let mut e = TrainingSet::default();
    for (input, outcome, sum, n) in engagement.values() {
        // The authors keep only groups whose mean engagement is below 1.0.
        if sum / n < 1.0 {
            e.inputs.push(encode(*input, Some(*outcome)));
            e.targets.push(sum / n);
            e.group_sizes.push(*n as u32);
        }
    }
    (p, e)
}

/// Fits the user models of `records`.
pub fn fit(
    records: &[InteractionRecord],
    options: &FitOptions,
) -> Result<UserModelSet, UserModelError> {
    validate_all(records)?;
    if options.clusters == 0 {
        return Err(UserModelError::Options(
            "clusters must be at least 1".into(),
        ));
    }
    let users = user_vectors(records)?;
    if users.len() < 2 * options.clusters {
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
                users: members.iter().map(|m| m.to_string()).collect(),
            });
        }
        clusters.push(fit_cluster(k, &members, &users, records, options)?);
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

/// One cluster's model from its members' records: the GPs on the authors' targets and the
/// per-level numbers of Fig. 3b.
fn fit_cluster(
    k: usize,
    members: &[&str],
    users: &[(String, [f64; 6])],
    records: &[InteractionRecord],
    options: &FitOptions,
) -> Result<ClusterModel, UserModelError> {
    let recs: Vec<&InteractionRecord> = records
        .iter()
        .filter(|r| members.contains(&r.user_id.as_str()))
        .collect();
    let (p, e) = training_sets(&recs);
    let member_vectors: Vec<&[f64; 6]> = users
        .iter()
        .filter(|(u, _)| members.contains(&u.as_str()))
        .map(|(_, v)| v)
        .collect();
    // Fig. 3b: means over the cluster's sequences (the authors' per-cluster numbers),
    // spread across its users.
    let levels = Level::ALL
        .iter()
        .map(|l| {
            let at: Vec<&&InteractionRecord> = recs.iter().filter(|r| r.level == *l).collect();
            let s: Vec<f64> = at
                .iter()
                .map(|r| f64::from(u8::from(r.outcome == Outcome::Success)))
                .collect();
            let e: Vec<f64> = at.iter().filter_map(|r| r.engagement).collect();
            let user_s: Vec<f64> = member_vectors.iter().map(|v| v[2 * l.index()]).collect();
            let user_e: Vec<f64> = member_vectors
                .iter()
                .map(|v| v[2 * l.index() + 1])
                .collect();
            LevelStats {
                level: l.get(),
                sequences: at.len(),
                success_mean: mean(&s),
                success_std: std(&user_s),
                engagement_mean: mean(&e),
                engagement_std: std(&user_e),
            }
        })
        .collect();
    let seed = options.seed.wrapping_add(1000 * k as u64);
    let optimiser = |seed| {
        options.optimise.then_some(OptimiserOptions {
            bounds: options.bounds,
            restarts: options.optimiser_restarts,
            seed,
        })
    };
    let gp_err = |component| {
        move |source| UserModelError::Gp {
            cluster: k,
            component,
            source,
        }
    };
    let component = |set: TrainingSet, seed: u64| match options.noise_model {
        NoiseModel::Fixed => GpComponent::fit(
            set.inputs,
            set.targets,
            options.kernel,
            options.noise,
            optimiser(seed),
        ),
        // The noise is a hyperparameter: it is always searched for.
        NoiseModel::FittedPerSequence => GpComponent::fit_noise_per_sequence(
            set.inputs,
            set.targets,
            set.group_sizes,
            options.kernel,
            INITIAL_FITTED_NOISE,
            OptimiserOptions {
                bounds: options.bounds,
                restarts: options.optimiser_restarts,
                seed,
            },
        ),
    };
    Ok(ClusterModel {
        cluster: k,
        users: members.iter().map(|m| m.to_string()).collect(),
        levels,
        success: component(p, seed).map_err(gp_err("F^p"))?,
        engagement: component(e, seed + 1).map_err(gp_err("F^e"))?,
    })
}

/// One user's own model, fitted from their records alone as a cluster of one (the GPs on
/// their groups), tabulated. What a per-child study simulates the child with.
pub fn fit_user(
    user: &str,
    records: &[InteractionRecord],
    options: &FitOptions,
) -> Result<sequence_game::UserModelTable, UserModelError> {
    let own: Vec<InteractionRecord> = records
        .iter()
        .filter(|r| r.user_id == user)
        .cloned()
        .collect();
    validate_all(&own)?;
    let users = user_vectors(&own)?;
    if users.is_empty() {
        return Err(UserModelError::Options(format!(
            "no records of user {user:?}"
        )));
    }
    fit_cluster(0, &[user], &users, &own, options)?.tabulate()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::{StudySpec, simulate_study};
    use sequence_game::Feedback;

    #[test]
    fn targets_are_group_means_and_engagement_groups_at_one_are_dropped() {
        let mut records = simulate_study(&StudySpec::default());
        records.truncate(10);
        for r in records.iter_mut() {
            r.level = Level::ONE;
            r.feedback = Feedback::None;
            r.previous_score = 0;
        }
        for (i, r) in records.iter_mut().enumerate() {
            r.outcome = if i < 4 {
                Outcome::Success
            } else {
                Outcome::Failure
            };
            r.score = r.outcome.score(r.level);
            r.engagement = Some(if i < 4 { 1.0 } else { 0.25 });
        }
        let refs: Vec<&InteractionRecord> = records.iter().collect();
        let (p, e) = training_sets(&refs);
        assert_eq!(p.inputs, [vec![1.0 / 3.0, 1.0, 0.0, 0.0, 0.0]]);
        assert_eq!((p.targets, p.group_sizes), (vec![0.4], vec![10]));
        // The success group has mean engagement 1.0 and is dropped.
        assert_eq!(e.inputs, [vec![1.0 / 3.0, 1.0, 0.0, 0.0, 0.0, -1.0]]);
        assert_eq!((e.targets, e.group_sizes), (vec![0.25], vec![6]));
    }

    #[test]
    fn fitting_is_deterministic_for_a_seed() {
        let records = simulate_study(&StudySpec::default());
        let a = fit(&records, &FitOptions::default()).expect("fits");
        let b = fit(&records, &FitOptions::default()).expect("fits");
        assert_eq!(a.file(), b.file());
        assert_eq!(a.tables(), b.tables());
    }
}
