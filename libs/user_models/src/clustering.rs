//! Users in 2-D and in clusters: PCA by singular value decomposition of the centred user
//! vectors (as scikit-learn's PCA, signs fixed so the largest loading of each component is
//! positive), and K-means with k-means++ seeding and seeded restarts (best inertia wins).

use nalgebra::DMatrix;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// A fitted projection to `components.len()` dimensions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pca {
    pub mean: Vec<f64>,
    /// One row per component, in the original space.
    pub components: Vec<Vec<f64>>,
    pub explained_variance: Vec<f64>,
}

impl Pca {
    /// Fits `dims` components to `rows` (at least two rows).
    pub fn fit(rows: &[Vec<f64>], dims: usize) -> Pca {
        let n = rows.len();
        let d = rows.first().map_or(0, Vec::len);
        let mean: Vec<f64> = (0..d)
            .map(|j| rows.iter().map(|r| r[j]).sum::<f64>() / n as f64)
            .collect();
        let centred = DMatrix::from_fn(n, d, |i, j| rows[i][j] - mean[j]);
        let svd = centred.svd(false, true);
        let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
        order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
        let v_t = svd.v_t.unwrap_or_else(|| DMatrix::zeros(0, d));
        let mut components = Vec::new();
        let mut explained_variance = Vec::new();
        for &k in order.iter().take(dims) {
            let mut c: Vec<f64> = v_t.row(k).iter().copied().collect();
            // A deterministic sign: the loading largest in magnitude is positive.
            let big = c
                .iter()
                .copied()
                .fold(0.0f64, |m, v| if v.abs() > m.abs() { v } else { m });
            if big < 0.0 {
                c.iter_mut().for_each(|v| *v = -*v);
            }
            components.push(c);
            let s = svd.singular_values[k];
            explained_variance.push(s * s / (n.max(2) - 1) as f64);
        }
        Pca {
            mean,
            components,
            explained_variance,
        }
    }

    pub fn project(&self, row: &[f64]) -> Vec<f64> {
        self.components
            .iter()
            .map(|c| {
                c.iter()
                    .zip(row)
                    .zip(&self.mean)
                    .map(|((w, x), m)| w * (x - m))
                    .sum()
            })
            .collect()
    }
}

fn sq(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum()
}

/// The result of K-means.
#[derive(Debug, Clone, PartialEq)]
pub struct KMeans {
    pub centres: Vec<Vec<f64>>,
    pub labels: Vec<usize>,
    pub inertia: f64,
}

/// Index of the centre nearest to `p`.
pub fn nearest(centres: &[Vec<f64>], p: &[f64]) -> usize {
    centres
        .iter()
        .enumerate()
        .min_by(|a, b| sq(a.1, p).total_cmp(&sq(b.1, p)))
        .map_or(0, |(i, _)| i)
}

/// K-means (Lloyd) from `restarts` k-means++ seedings; clusters are numbered by their first
/// member so the same partition always gets the same labels.
pub fn kmeans(points: &[Vec<f64>], k: usize, restarts: usize, seed: u64) -> KMeans {
    if k == 0 || points.len() < k {
        // Nothing to cluster; the caller checks the sizes and reports them.
        return KMeans {
            centres: vec![],
            labels: vec![0; points.len()],
            inertia: f64::INFINITY,
        };
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut best: Option<KMeans> = None;
    for _ in 0..restarts.max(1) {
        // k-means++: each next centre drawn with probability proportional to D(x)^2.
        let mut centres = vec![points[rng.random_range(0..points.len())].clone()];
        while centres.len() < k {
            let d: Vec<f64> = points
                .iter()
                .map(|p| {
                    centres
                        .iter()
                        .map(|c| sq(c, p))
                        .fold(f64::INFINITY, f64::min)
                })
                .collect();
            let total: f64 = d.iter().sum();
            let mut pick = rng.random::<f64>() * total;
            let mut chosen = points.len() - 1;
            for (i, di) in d.iter().enumerate() {
                if pick < *di {
                    chosen = i;
                    break;
                }
                pick -= di;
            }
            centres.push(points[chosen].clone());
        }
        let mut labels = vec![0; points.len()];
        for _ in 0..300 {
            let new: Vec<usize> = points.iter().map(|p| nearest(&centres, p)).collect();
            let changed = new != labels;
            labels = new;
            for (c, centre) in centres.iter_mut().enumerate() {
                let members: Vec<&Vec<f64>> = points
                    .iter()
                    .zip(&labels)
                    .filter(|(_, l)| **l == c)
                    .map(|(p, _)| p)
                    .collect();
                if !members.is_empty() {
                    *centre = (0..centre.len())
                        .map(|j| members.iter().map(|m| m[j]).sum::<f64>() / members.len() as f64)
                        .collect();
                }
            }
            if !changed {
                break;
            }
        }
        let inertia = points
            .iter()
            .zip(&labels)
            .map(|(p, l)| sq(p, &centres[*l]))
            .sum();
        if best.as_ref().is_none_or(|b| inertia < b.inertia - 1e-12) {
            best = Some(KMeans {
                centres,
                labels,
                inertia,
            });
        }
    }
    let mut result = best.unwrap_or(KMeans {
        centres: vec![],
        labels: vec![],
        inertia: 0.0,
    });
    // Renumber clusters in order of first appearance.
    let mut order: Vec<usize> = Vec::new();
    for l in &result.labels {
        if !order.contains(l) {
            order.push(*l);
        }
    }
    for c in 0..result.centres.len() {
        if !order.contains(&c) {
            order.push(c);
        }
    }
    result.labels = result
        .labels
        .iter()
        .map(|l| order.iter().position(|o| o == l).unwrap_or(0))
        .collect();
    result.centres = order.iter().map(|&o| result.centres[o].clone()).collect();
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pca_finds_the_long_axis_and_kmeans_the_two_groups() {
        let mut rows = Vec::new();
        for i in 0..10 {
            let t = f64::from(i) / 10.0;
            rows.push(vec![t, 2.0 * t, 0.0]);
            rows.push(vec![t + 5.0, 2.0 * t + 10.0, 0.1]);
        }
        let pca = Pca::fit(&rows, 2);
        let axis = &pca.components[0];
        assert!((axis[1] / axis[0] - 2.0).abs() < 0.05, "{axis:?}");
        let projected: Vec<Vec<f64>> = rows.iter().map(|r| pca.project(r)).collect();
        let km = kmeans(&projected, 2, 5, 3);
        for (i, l) in km.labels.iter().enumerate() {
            assert_eq!(*l, i % 2, "point {i}");
        }
        assert_eq!(kmeans(&projected, 2, 5, 3), km);
    }
}
