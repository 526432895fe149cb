//! Writes a trained [`Booster`] in the JSON layout of xgboost 3.2's `save_model`, with the
//! preprocessing as a learner attribute, so Python's `xgb.Booster(model_file=...)` loads it.

use super::{Booster, TrainedTree};
use crate::features::{FEATURE_COUNT, model_feature_name};
use crate::preprocessing::PREPROCESSING_ATTRIBUTE;
use crate::xgboost_json::{
    GbtreeModel, GbtreeModelParam, Learner, LearnerModelParam, ModelFile, Tree, TreeParam,
    format_base_score,
};
use serde_json::json;
use std::collections::BTreeMap;

fn export_tree(id: usize, tree: &TrainedTree) -> Tree {
    let nodes = &tree.nodes;
    Tree {
        base_weights: nodes.iter().map(|n| n.base_weight).collect(),
        categories: Vec::new(),
        categories_nodes: Vec::new(),
        categories_segments: Vec::new(),
        categories_sizes: Vec::new(),
        default_left: nodes.iter().map(|n| u8::from(n.default_left)).collect(),
        id: id as i64,
        left_children: nodes.iter().map(|n| n.left).collect(),
        loss_changes: nodes.iter().map(|n| n.loss_change).collect(),
        parents: nodes.iter().map(|n| i64::from(n.parent)).collect(),
        right_children: nodes.iter().map(|n| n.right).collect(),
        split_conditions: nodes.iter().map(|n| n.value).collect(),
        split_indices: nodes.iter().map(|n| i64::from(n.feature)).collect(),
        split_type: vec![0; nodes.len()],
        sum_hessian: nodes.iter().map(|n| n.sum_hess).collect(),
        tree_param: TreeParam {
            num_deleted: "0".into(),
            num_feature: FEATURE_COUNT.to_string(),
            num_nodes: nodes.len().to_string(),
            size_leaf_vector: "1".into(),
        },
    }
}

/// The XGBoost JSON model of `booster`; `description` goes into an attribute for people.
pub fn to_model_file(booster: &Booster, description: &str) -> ModelFile {
    let n_trees = booster.trees.len();
    let mut attributes = BTreeMap::new();
    // Lets `XGBClassifier().load_model(...)` treat it as a classifier, as its own files do.
    attributes.insert(
        "scikit_learn".to_string(),
        r#"{"_estimator_type": "classifier"}"#.to_string(),
    );
    attributes.insert("description".to_string(), description.to_string());
    if let Some(pre) = &booster.preprocessing {
        let block = pre.to_block(&booster.model_columns);
        // Serialising plain numbers and strings cannot fail.
        let text = serde_json::to_string(&block).unwrap_or_default();
        attributes.insert(PREPROCESSING_ATTRIBUTE.to_string(), text);
    }
    let model = GbtreeModel {
        gbtree_model_param: GbtreeModelParam {
            num_parallel_tree: "1".into(),
            num_trees: n_trees.to_string(),
        },
        trees: booster
            .trees
            .iter()
            .enumerate()
            .map(|(i, t)| export_tree(i, t))
            .collect(),
        tree_info: vec![0; n_trees],
        iteration_indptr: Some((0..=n_trees as i64).collect()),
        cats: Some(json!({"enc": [], "feature_segments": [], "sorted_idx": []})),
    };
    ModelFile {
        learner: Learner {
            attributes,
            feature_names: booster
                .model_columns
                .iter()
                .map(|&c| model_feature_name(c))
                .collect(),
            feature_types: Vec::new(),
            gradient_booster: json!({"model": model, "name": "gbtree"}),
            learner_model_param: LearnerModelParam {
                base_score: format_base_score(booster.base_score),
                boost_from_average: "1".into(),
                num_class: "0".into(),
                num_feature: FEATURE_COUNT.to_string(),
                num_target: "1".into(),
            },
            objective: json!({
                "name": "binary:logistic",
                "reg_loss_param": {"scale_pos_weight": "1"}
            }),
        },
        version: vec![3, 2, 0],
    }
}
