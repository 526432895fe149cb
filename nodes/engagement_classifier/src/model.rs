//! Inference for an XGBoost `binary:logistic` gbtree model loaded from its JSON file: the
//! trees are flattened into one node array indexed by canonical feature, so one prediction is
//! a few hundred compares with no allocation. Arithmetic follows xgboost's CPU predictor
//! (f32 inputs, `x < threshold` goes left, NaN takes the default branch, f32 sums in tree
//! order from logit(base_score), its f32 sigmoid) so margins and probabilities match Python.
//!
//! Speed: a walk down one tree is a chain of dependent loads, so we walk [`LANES`] trees in
//! lockstep. Leaves loop onto themselves (they read an always-missing input slot and default
//! left to their own index), so every lane can take the same number of steps without a branch.

use crate::features::{FEATURE_COUNT, canonical_index};
use crate::preprocessing::{
    PREPROCESSING_ATTRIBUTE, Preprocessing, PreprocessingBlock, PreprocessingError,
};
use crate::xgboost_json::{GbtreeModel, ModelFile, Tree, parse_base_score};
use std::path::{Path, PathBuf};

/// Why a model file cannot be used. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("reading model {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("model {path} is not an XGBoost JSON model (save_model(\"model.json\")): {reason}")]
    NotXgboostJson { path: PathBuf, reason: String },
    #[error("model {path} has objective {objective:?}; only binary:logistic is supported")]
    Objective { path: PathBuf, objective: String },
    #[error("model {path} uses booster {booster:?}; only gbtree is supported")]
    Booster { path: PathBuf, booster: String },
    #[error("model {path} has {got} features; the engagement classifier needs exactly 32")]
    FeatureCount { path: PathBuf, got: usize },
    #[error(
        "model {path} has no feature_names; features are matched by name (of_AU01_c ... of_pose_Rz)"
    )]
    NoFeatureNames { path: PathBuf },
    #[error("model {path}: feature name {name:?} is not one of the 32 OpenFace features")]
    UnknownFeature { path: PathBuf, name: String },
    #[error("model {path}: feature name {name:?} appears twice")]
    DuplicateFeature { path: PathBuf, name: String },
    #[error("model {path}: {what} is not supported")]
    Unsupported { path: PathBuf, what: String },
    #[error("model {path}: tree {tree}: {reason}")]
    BadTree {
        path: PathBuf,
        tree: usize,
        reason: String,
    },
    #[error("model {path}: attribute {PREPROCESSING_ATTRIBUTE}: {source}")]
    Preprocessing {
        path: PathBuf,
        source: PreprocessingError,
    },
}

/// One flattened node. Children of a split are adjacent (`left`, `left + 1`); a leaf's
/// `left` is itself.
#[derive(Debug, Clone, Copy)]
struct Node {
    /// Split threshold, or the leaf value for a leaf.
    value: f32,
    /// Canonical feature index; [`MISSING_SLOT`] for a leaf.
    feature: u16,
    default_left: bool,
    left: u32,
}

/// Index of the input slot that is always NaN: leaves read it and stay where they are.
const MISSING_SLOT: u16 = FEATURE_COUNT as u16;
/// Trees walked in lockstep.
const LANES: usize = 8;
/// Node 0 is a leaf worth 0 that pads the last group of trees.
const PAD: Node = Node {
    value: 0.0,
    feature: MISSING_SLOT,
    default_left: true,
    left: 0,
};

/// Margin, probability of engagement, and the label xgboost's classifier would output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    pub margin: f32,
    pub probability: f32,
    /// +1 engaged, -1 disengaged (`XGBClassifier.predict`: engaged iff probability > 0.5).
    pub label: i8,
}

/// A loaded engagement model: trees plus the preprocessing stored with them.
#[derive(Debug, Clone)]
pub struct EngagementModel {
    nodes: Vec<Node>,
    roots: Vec<u32>,
    /// Depth of each tree (steps from root to its deepest leaf).
    depths: Vec<u8>,
    base_margin: f32,
    preprocessing: Option<Preprocessing>,
    /// Canonical feature index of each model column, in the model's column order.
    model_columns: Vec<usize>,
}

impl EngagementModel {
    /// Reads and validates a model file.
    pub fn load(path: &Path) -> Result<EngagementModel, ModelError> {
        let text = std::fs::read_to_string(path).map_err(|source| ModelError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        EngagementModel::from_json(&text, path)
    }

    /// Parses a model from JSON text; `path` only names the source in errors.
    pub fn from_json(text: &str, path: &Path) -> Result<EngagementModel, ModelError> {
        let p = || path.to_path_buf();
        let not_xgb = |reason: String| ModelError::NotXgboostJson { path: p(), reason };
        let file: ModelFile = serde_json::from_str(text).map_err(|e| not_xgb(e.to_string()))?;
        let learner = &file.learner;
        let objective = learner.objective.get("name").and_then(|n| n.as_str());
        let objective = objective.ok_or_else(|| not_xgb("objective has no name".into()))?;
        if objective != "binary:logistic" {
            return Err(ModelError::Objective {
                path: p(),
                objective: objective.to_string(),
            });
        }
        let booster = learner
            .gradient_booster
            .get("name")
            .and_then(|n| n.as_str());
        let booster = booster.ok_or_else(|| not_xgb("gradient_booster has no name".into()))?;
        if booster != "gbtree" {
            return Err(ModelError::Booster {
                path: p(),
                booster: booster.to_string(),
            });
        }
        let param = &learner.learner_model_param;
        let num_feature: usize = param
            .num_feature
            .parse()
            .map_err(|_| not_xgb(format!("num_feature {:?}", param.num_feature)))?;
        if num_feature != FEATURE_COUNT {
            return Err(ModelError::FeatureCount {
                path: p(),
                got: num_feature,
            });
        }
        if param.num_class.trim() != "0" || param.num_target.trim() != "1" {
            let what = format!(
                "num_class {} / num_target {} (multi-output)",
                param.num_class, param.num_target
            );
            return Err(ModelError::Unsupported { path: p(), what });
        }
        let base_score = parse_base_score(&param.base_score)
            .ok_or_else(|| not_xgb(format!("base_score {:?}", param.base_score)))?;
        let model_columns = match_feature_names(&learner.feature_names, path)?;
        let gbtree = learner
            .gradient_booster
            .get("model")
            .ok_or_else(|| not_xgb("gradient_booster has no model".into()))?;
        let gbtree: GbtreeModel =
            serde_json::from_value(gbtree.clone()).map_err(|e| not_xgb(e.to_string()))?;
        if gbtree.gbtree_model_param.num_parallel_tree.trim() != "1" {
            let what = "num_parallel_tree > 1 (random forest)".to_string();
            return Err(ModelError::Unsupported { path: p(), what });
        }
        let mut model = EngagementModel {
            nodes: vec![PAD],
            roots: Vec::with_capacity(gbtree.trees.len()),
            depths: Vec::with_capacity(gbtree.trees.len()),
            base_margin: logit_like_xgboost(base_score),
            preprocessing: None,
            model_columns,
        };
        for (t, tree) in gbtree.trees.iter().enumerate() {
            model.add_tree(tree).map_err(|reason| ModelError::BadTree {
                path: p(),
                tree: t,
                reason,
            })?;
        }
        if let Some(text) = learner.attributes.get(PREPROCESSING_ATTRIBUTE) {
            let block: PreprocessingBlock =
                serde_json::from_str(text).map_err(|e| ModelError::Preprocessing {
                    path: p(),
                    source: PreprocessingError::Parse(e.to_string()),
                })?;
            let pre = Preprocessing::from_block(&block)
                .map_err(|source| ModelError::Preprocessing { path: p(), source })?;
            model.preprocessing = Some(pre);
        }
        Ok(model)
    }

    /// Appends one tree, renumbering its nodes breadth-first so siblings are adjacent.
    fn add_tree(&mut self, tree: &Tree) -> Result<(), String> {
        let n = tree.left_children.len();
        if n == 0 {
            return Err("no nodes".into());
        }
        let lens = [
            tree.right_children.len(),
            tree.split_conditions.len(),
            tree.split_indices.len(),
            tree.default_left.len(),
        ];
        if lens.iter().any(|&l| l != n) {
            return Err(format!("node arrays differ in length ({n} vs {lens:?})"));
        }
        if tree.split_type.iter().any(|&t| t != 0) || !tree.categories.is_empty() {
            return Err("categorical splits are not supported".into());
        }
        if tree
            .tree_param
            .size_leaf_vector
            .trim()
            .parse::<u32>()
            .unwrap_or(1)
            > 1
        {
            return Err("vector leaves are not supported".into());
        }
        let root = self.nodes.len();
        // queue of (original id, flat slot, depth); slots are reserved two at a time.
        let mut queue = std::collections::VecDeque::from([(0usize, root, 0u8)]);
        self.nodes.push(PAD);
        let (mut visited, mut depth) = (0usize, 0u8);
        while let Some((id, slot, d)) = queue.pop_front() {
            visited += 1;
            if visited > n || d == u8::MAX {
                return Err("node graph has a cycle".into());
            }
            depth = depth.max(d);
            let value = tree.split_conditions[id];
            let left = tree.left_children[id];
            if left == -1 {
                self.nodes[slot] = Node {
                    value,
                    left: slot as u32,
                    ..PAD
                };
                continue;
            }
            let right = tree.right_children[id];
            let child = |c: i32| usize::try_from(c).ok().filter(|&c| c < n && c != id);
            let (Some(l), Some(r)) = (child(left), child(right)) else {
                return Err(format!(
                    "node {id} has children {left}, {right} out of range"
                ));
            };
            let column = usize::try_from(tree.split_indices[id])
                .ok()
                .and_then(|j| self.model_columns.get(j).copied())
                .ok_or_else(|| format!("node {id} splits on feature {}", tree.split_indices[id]))?;
            let left_slot = self.nodes.len();
            self.nodes.extend([PAD; 2]);
            self.nodes[slot] = Node {
                value,
                feature: column as u16,
                default_left: tree.default_left[id] != 0,
                left: left_slot as u32,
            };
            queue.push_back((l, left_slot, d + 1));
            queue.push_back((r, left_slot + 1, d + 1));
        }
        self.roots.push(root as u32);
        self.depths.push(depth);
        Ok(())
    }

    /// Number of trees.
    pub fn tree_count(&self) -> usize {
        self.roots.len()
    }

    /// The stored preprocessing, if the model carries one.
    pub fn preprocessing(&self) -> Option<&Preprocessing> {
        self.preprocessing.as_ref()
    }

    /// Canonical index of each model column, in the model's own column order.
    pub fn model_columns(&self) -> &[usize] {
        &self.model_columns
    }

    /// Turns a raw canonical row into the f32 inputs the trees compare against.
    #[inline]
    pub fn prepare(&self, raw: &[f64; FEATURE_COUNT], out: &mut [f32; FEATURE_COUNT]) {
        match &self.preprocessing {
            Some(p) => p.apply(raw, out),
            None => {
                for (o, r) in out.iter_mut().zip(raw) {
                    *o = *r as f32;
                }
            }
        }
    }

    /// Margin (log-odds of engagement) of already prepared inputs.
    #[inline]
    pub fn margin_of_prepared(&self, x: &[f32; FEATURE_COUNT]) -> f32 {
        let mut slots = [f32::NAN; FEATURE_COUNT + 1];
        slots[..FEATURE_COUNT].copy_from_slice(x);
        let mut margin = self.base_margin;
        for (roots, depths) in self.roots.chunks(LANES).zip(self.depths.chunks(LANES)) {
            let mut at = [0u32; LANES];
            at[..roots.len()].copy_from_slice(roots);
            let steps = depths.iter().copied().max().unwrap_or(0);
            for _ in 0..steps {
                for i in &mut at {
                    let node = self.nodes[*i as usize];
                    let v = slots[node.feature as usize];
                    // `|` and `&`, not `||` and `&&`: no branch to mispredict.
                    let go_left = (v < node.value) | (v.is_nan() & node.default_left);
                    *i = node.left + u32::from(!go_left);
                }
            }
            // Leaves added one by one in tree order: the same f32 sum as xgboost's.
            for &i in &at[..roots.len()] {
                margin += self.nodes[i as usize].value;
            }
        }
        margin
    }

    /// Predicts from a raw canonical row given as f64 (CSV input).
    #[inline]
    pub fn predict(&self, raw: &[f64; FEATURE_COUNT]) -> Prediction {
        let mut x = [0f32; FEATURE_COUNT];
        self.prepare(raw, &mut x);
        Prediction::from_margin(self.margin_of_prepared(&x))
    }

    /// Predicts from a raw canonical row given as f32 (OpenFace messages).
    #[inline]
    pub fn predict_f32(&self, raw: &[f32; FEATURE_COUNT]) -> Prediction {
        let mut wide = [0f64; FEATURE_COUNT];
        for (w, r) in wide.iter_mut().zip(raw) {
            *w = f64::from(*r);
        }
        self.predict(&wide)
    }
}

impl Prediction {
    /// Applies xgboost's sigmoid and decision rule to a margin.
    #[inline]
    pub fn from_margin(margin: f32) -> Prediction {
        let probability = sigmoid_like_xgboost(margin);
        let label = if probability > 0.5 { 1 } else { -1 };
        Prediction {
            margin,
            probability,
            label,
        }
    }
}

/// xgboost's `common::Sigmoid(float)`: clamps the exponent and adds 1e-16 to the denominator.
#[inline]
pub fn sigmoid_like_xgboost(x: f32) -> f32 {
    let e = (-x).min(88.7).exp();
    1.0 / (e + 1.0 + 1e-16)
}

/// xgboost's logistic `ProbToMargin`: clamp to [1e-6, 1 - 1e-6], then `-log(1/p - 1)` in f32.
pub fn logit_like_xgboost(p: f32) -> f32 {
    let p = p.clamp(1e-6, 1.0 - 1e-6);
    -(1.0 / p - 1.0).ln()
}

/// Maps each model column to a canonical feature by its name (`of_<name>` or `<name>`).
fn match_feature_names(names: &[String], path: &Path) -> Result<Vec<usize>, ModelError> {
    if names.is_empty() {
        return Err(ModelError::NoFeatureNames {
            path: path.to_path_buf(),
        });
    }
    if names.len() != FEATURE_COUNT {
        return Err(ModelError::FeatureCount {
            path: path.to_path_buf(),
            got: names.len(),
        });
    }
    let mut seen = [false; FEATURE_COUNT];
    names
        .iter()
        .map(|name| {
            let c = canonical_index(name).ok_or_else(|| ModelError::UnknownFeature {
                path: path.to_path_buf(),
                name: name.clone(),
            })?;
            if std::mem::replace(&mut seen[c], true) {
                return Err(ModelError::DuplicateFeature {
                    path: path.to_path_buf(),
                    name: name.clone(),
                });
            }
            Ok(c)
        })
        .collect()
}
