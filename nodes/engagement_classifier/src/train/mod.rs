//! Gradient-boosted trees with logistic loss, grown like xgboost's `exact` method
//! (`grow_colmaker`): depth-wise, every split point of every feature enumerated, missing values
//! sent both ways and the better default direction kept. We follow its float types and
//! tie-breaking, so a model trained here is (up to summation order) the model xgboost trains.

mod export;
mod tree;

pub use export::to_model_file;
pub use tree::{GradStats, TrainedTree, TreeNode};

use crate::features::{AUTHORS_FEATURE_ORDER, FEATURE_COUNT};
use crate::model::{logit_like_xgboost, sigmoid_like_xgboost};
use crate::preprocessing::Preprocessing;
use crate::table::FeatureTable;

/// Boosting hyperparameters (xgboost names; defaults are the authors': 100 trees, depth 6,
/// eta 0.3, xgboost's min_child_weight 1 and lambda 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrainParams {
    pub n_estimators: usize,
    pub max_depth: usize,
    pub learning_rate: f32,
    pub min_child_weight: f32,
    pub reg_lambda: f32,
}

impl Default for TrainParams {
    fn default() -> Self {
        TrainParams {
            n_estimators: 100,
            max_depth: 6,
            learning_rate: 0.3,
            min_child_weight: 1.0,
            reg_lambda: 1.0,
        }
    }
}

/// A trained ensemble, ready to be written as an XGBoost JSON model.
#[derive(Debug, Clone)]
pub struct Booster {
    /// Intercept in probability space, as xgboost stores it.
    pub base_score: f32,
    pub trees: Vec<TrainedTree>,
    /// Canonical feature index of each model column (the authors' order).
    pub model_columns: Vec<usize>,
    pub preprocessing: Option<Preprocessing>,
}

/// Training inputs in model column order, sorted per column once for all trees.
pub struct TrainingData {
    /// `rows[i][j]`: row i, model column j, as the f32 xgboost compares (NaN = missing).
    pub rows: Vec<[f32; FEATURE_COUNT]>,
    /// 1.0 engaged, 0.0 disengaged.
    pub targets: Vec<f32>,
    /// Per column: (value, row) of the non-missing entries, ascending by value.
    pub(crate) sorted: Vec<Vec<(f32, u32)>>,
}

impl TrainingData {
    /// Prepares a labelled table: applies `preprocessing` and orders the columns like the
    /// authors' models.
    pub fn new(table: &FeatureTable, preprocessing: Option<&Preprocessing>) -> TrainingData {
        let pre = preprocessing.copied().unwrap_or(Preprocessing::IDENTITY);
        let rows: Vec<[f32; FEATURE_COUNT]> = table
            .rows
            .iter()
            .map(|raw| {
                let mut canonical = [0f32; FEATURE_COUNT];
                pre.apply(raw, &mut canonical);
                AUTHORS_FEATURE_ORDER.map(|c| canonical[c])
            })
            .collect();
        let sorted = (0..FEATURE_COUNT)
            .map(|j| {
                let mut col: Vec<(f32, u32)> = rows
                    .iter()
                    .enumerate()
                    .filter(|(_, r)| !r[j].is_nan())
                    .map(|(i, r)| (r[j], i as u32))
                    .collect();
                col.sort_by(|a, b| a.0.total_cmp(&b.0));
                col
            })
            .collect();
        let targets = table
            .labels
            .iter()
            .map(|&l| if l > 0 { 1.0 } else { 0.0 })
            .collect();
        TrainingData {
            rows,
            targets,
            sorted,
        }
    }

    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }
}

/// Fits the preprocessing on `table`, then boosts `params.n_estimators` trees. `on_tree` is
/// called after each tree (for a progress bar).
pub fn train(table: &FeatureTable, params: &TrainParams, on_tree: impl FnMut(usize)) -> Booster {
    let preprocessing = Preprocessing::fit(&table.rows);
    let data = TrainingData::new(table, Some(&preprocessing));
    let mut booster = train_prepared(&data, params, on_tree);
    booster.preprocessing = Some(preprocessing);
    booster
}

/// Boosts on prepared data; the result carries no preprocessing.
pub fn train_prepared(
    data: &TrainingData,
    params: &TrainParams,
    mut on_tree: impl FnMut(usize),
) -> Booster {
    // xgboost's intercept for logistic loss: the label mean, summed as y/n in f64.
    let n = data.len().max(1) as f64;
    let base_score = data.targets.iter().map(|&y| f64::from(y) / n).sum::<f64>() as f32;
    let base_margin = logit_like_xgboost(base_score);
    let mut margins = vec![base_margin; data.len()];
    let mut gradients = vec![GradStats::default(); data.len()];
    let mut trees = Vec::with_capacity(params.n_estimators);
    for t in 0..params.n_estimators {
        for ((g, &m), &y) in gradients.iter_mut().zip(&margins).zip(&data.targets) {
            let p = sigmoid_like_xgboost(m);
            let grad = p - y;
            let hess = (p * (1.0 - p)).max(1e-16);
            *g = GradStats {
                grad: f64::from(grad),
                hess: f64::from(hess),
            };
        }
        let (tree, leaf_of_row) = tree::grow(data, &gradients, params);
        for (m, leaf) in margins.iter_mut().zip(&leaf_of_row) {
            *m += tree.nodes[*leaf as usize].value;
        }
        trees.push(tree);
        on_tree(t + 1);
    }
    Booster {
        base_score,
        trees,
        model_columns: AUTHORS_FEATURE_ORDER.to_vec(),
        preprocessing: None,
    }
}
