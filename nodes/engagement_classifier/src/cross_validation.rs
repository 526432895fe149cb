//! Leave-one-participant-out cross-validation, as the paper reports it: for each participant,
//! fit the preprocessing and the trees on everyone else, and count how many of the held-out
//! participant's frames get the right label.

use crate::features::FEATURE_COUNT;
use crate::model::Prediction;
use crate::preprocessing::Preprocessing;
use crate::table::FeatureTable;
use crate::train::{Booster, TrainParams, TrainingData, train_prepared};

/// One fold's inputs, prepared exactly as the trees see them (model column order, f32).
pub struct Fold {
    pub participant: String,
    pub train: TrainingData,
    pub test_rows: Vec<[f32; FEATURE_COUNT]>,
    /// +1 / -1.
    pub test_labels: Vec<i8>,
    pub preprocessing: Preprocessing,
}

impl Fold {
    /// Splits `table` into everyone but `participant` (training) and `participant` (test);
    /// the preprocessing is fitted on the training part only.
    pub fn new(table: &FeatureTable, participant: &str) -> Fold {
        let (test, train): (Vec<usize>, Vec<usize>) =
            (0..table.len()).partition(|&i| table.participants[i] == participant);
        let train_table = table.select(&train);
        let test_table = table.select(&test);
        let preprocessing = Preprocessing::fit(&train_table.rows);
        let test_data = TrainingData::new(&test_table, Some(&preprocessing));
        Fold {
            participant: participant.to_string(),
            train: TrainingData::new(&train_table, Some(&preprocessing)),
            test_rows: test_data.rows,
            test_labels: test_table.labels,
            preprocessing,
        }
    }
}

/// The outcome of one fold.
#[derive(Debug, Clone, PartialEq)]
pub struct FoldResult {
    pub participant: String,
    pub train_rows: usize,
    pub test_rows: usize,
    pub correct: usize,
    /// Probability of engagement for each test row, in the table's order.
    pub probabilities: Vec<f32>,
}

impl FoldResult {
    pub fn accuracy(&self) -> f64 {
        self.correct as f64 / self.test_rows.max(1) as f64
    }
}

/// Margin of a prepared row (model column order) under a trained booster.
pub fn booster_margin(booster: &Booster, row: &[f32; FEATURE_COUNT]) -> f32 {
    let mut margin = crate::model::logit_like_xgboost(booster.base_score);
    for tree in &booster.trees {
        let mut i = 0usize;
        loop {
            let node = tree.nodes[i];
            if node.left == -1 {
                margin += node.value;
                break;
            }
            let v = row[node.feature as usize];
            let go_left = if v.is_nan() {
                node.default_left
            } else {
                v < node.value
            };
            i = if go_left { node.left } else { node.right } as usize;
        }
    }
    margin
}

/// Trains on the fold and scores its test rows.
pub fn run_fold(fold: &Fold, params: &TrainParams, on_tree: impl FnMut(usize)) -> FoldResult {
    let booster = train_prepared(&fold.train, params, on_tree);
    let probabilities: Vec<f32> = fold
        .test_rows
        .iter()
        .map(|r| Prediction::from_margin(booster_margin(&booster, r)).probability)
        .collect();
    let correct = probabilities
        .iter()
        .zip(&fold.test_labels)
        .filter(|&(&p, &l)| (p > 0.5) == (l > 0))
        .count();
    FoldResult {
        participant: fold.participant.clone(),
        train_rows: fold.train.len(),
        test_rows: fold.test_rows.len(),
        correct,
        probabilities,
    }
}

/// Mean of the per-fold accuracies (the paper's "validation accuracy").
pub fn mean_accuracy(results: &[FoldResult]) -> f64 {
    if results.is_empty() {
        return f64::NAN;
    }
    results.iter().map(FoldResult::accuracy).sum::<f64>() / results.len() as f64
}
