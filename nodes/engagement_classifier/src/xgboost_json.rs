//! The JSON model format Python xgboost writes with `save_model("model.json")` (gbtree,
//! scalar output), as serde types we both read and write, so models cross between Python
//! and Rust in either direction.

use serde::{Deserialize, Deserializer, Serialize};
use std::collections::BTreeMap;

/// Root of a model file: `{"learner": {...}, "version": [3, 2, 0]}`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelFile {
    pub learner: Learner,
    #[serde(default)]
    pub version: Vec<u32>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Learner {
    /// Free string attributes; xgboost keeps keys it does not know, which is where we keep
    /// the preprocessing (see `preprocessing::PREPROCESSING_ATTRIBUTE`).
    #[serde(default)]
    pub attributes: BTreeMap<String, String>,
    #[serde(default)]
    pub feature_names: Vec<String>,
    #[serde(default)]
    pub feature_types: Vec<String>,
    /// Kept as raw JSON: a `dart` or `gblinear` booster has another shape, and we want to name
    /// the booster in the error rather than report a missing field.
    pub gradient_booster: serde_json::Value,
    pub learner_model_param: LearnerModelParam,
    pub objective: serde_json::Value,
}

/// xgboost writes these numbers as strings.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LearnerModelParam {
    pub base_score: String,
    #[serde(default = "zero_string")]
    pub boost_from_average: String,
    #[serde(default = "zero_string")]
    pub num_class: String,
    pub num_feature: String,
    #[serde(default = "one_string")]
    pub num_target: String,
}

fn zero_string() -> String {
    "0".to_string()
}

fn one_string() -> String {
    "1".to_string()
}

/// `gradient_booster.model` of a gbtree booster.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GbtreeModel {
    pub gbtree_model_param: GbtreeModelParam,
    pub trees: Vec<Tree>,
    #[serde(default)]
    pub tree_info: Vec<i64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iteration_indptr: Option<Vec<i64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cats: Option<serde_json::Value>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GbtreeModelParam {
    pub num_parallel_tree: String,
    pub num_trees: String,
}

/// One regression tree in xgboost's structure-of-arrays layout. A node is a leaf when its
/// left child is -1; a leaf's value sits in `split_conditions`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Tree {
    #[serde(default)]
    pub base_weights: Vec<f32>,
    #[serde(default)]
    pub categories: Vec<i64>,
    #[serde(default)]
    pub categories_nodes: Vec<i64>,
    #[serde(default)]
    pub categories_segments: Vec<i64>,
    #[serde(default)]
    pub categories_sizes: Vec<i64>,
    /// 0/1 in xgboost >= 1.6 files, booleans in some older ones.
    #[serde(deserialize_with = "flags")]
    pub default_left: Vec<u8>,
    #[serde(default)]
    pub id: i64,
    pub left_children: Vec<i32>,
    #[serde(default)]
    pub loss_changes: Vec<f32>,
    #[serde(default)]
    pub parents: Vec<i64>,
    pub right_children: Vec<i32>,
    pub split_conditions: Vec<f32>,
    pub split_indices: Vec<i64>,
    #[serde(default)]
    pub split_type: Vec<u8>,
    #[serde(default)]
    pub sum_hessian: Vec<f32>,
    pub tree_param: TreeParam,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TreeParam {
    #[serde(default = "zero_string")]
    pub num_deleted: String,
    pub num_feature: String,
    pub num_nodes: String,
    #[serde(default = "one_string")]
    pub size_leaf_vector: String,
}

fn flags<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<u8>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Flag {
        Bool(bool),
        Int(i64),
    }
    let raw = Vec::<Flag>::deserialize(d)?;
    Ok(raw
        .into_iter()
        .map(|f| match f {
            Flag::Bool(b) => u8::from(b),
            Flag::Int(i) => u8::from(i != 0),
        })
        .collect())
}

/// Parses xgboost's `base_score` string: `"[4.59E-1]"` (xgboost >= 3) or `"5E-1"` (older).
pub fn parse_base_score(text: &str) -> Option<f32> {
    let t = text.trim();
    let t = t
        .strip_prefix(['[', '('])
        .and_then(|t| t.strip_suffix([']', ')']))
        .unwrap_or(t);
    let mut values = t.split(',').map(|v| v.trim().parse::<f32>());
    let first = values.next()?.ok()?;
    // A vector intercept is for multi-output models, which we reject elsewhere.
    values.next().is_none().then_some(first)
}

/// Writes `base_score` the way xgboost >= 3 does: a one-element JSON array in a string.
pub fn format_base_score(p: f32) -> String {
    format!("[{p:E}]")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base_score_forms() {
        assert_eq!(parse_base_score("[4.59E-1]"), Some(0.459));
        assert_eq!(parse_base_score("5E-1"), Some(0.5));
        assert_eq!(parse_base_score(" [0.25] "), Some(0.25));
        assert_eq!(parse_base_score("[0.2,0.3]"), None);
        assert_eq!(parse_base_score("abc"), None);
        let p = 0.387_654_3_f32;
        assert_eq!(parse_base_score(&format_base_score(p)), Some(p));
    }

    #[test]
    fn default_left_accepts_bools_and_ints() {
        let tree = r#"{"default_left":[true,0,1],"left_children":[1,-1,-1],
            "right_children":[2,-1,-1],"split_conditions":[0.5,1.0,-1.0],
            "split_indices":[3,0,0],"tree_param":{"num_feature":"4","num_nodes":"3"}}"#;
        let t: Tree = serde_json::from_str(tree).expect("parses");
        assert_eq!(t.default_left, vec![1, 0, 1]);
        assert!(t.split_type.is_empty());
    }
}
