//! When supervised autonomy proposes a decision to the therapist instead of playing it: the
//! rule the game manager applies and the supervision study measures, in one place. A decision
//! is unsure when its state is little visited (its softmax temperature, T_s = 300 − 5 ·
//! visits with the authors' schedule, is above a limit: a limit on the state's visits), or when
//! the user model's σ of P(success) for the sequence it sets up is above a limit.
//!
//! What σ means depends on how the model was fitted (`fit::NoiseModel`). With the paper's
//! noise (1e-10) the GP passes through every observed group's success rate, so σ is about 0 at
//! every (L, F, PS) the study saw, even once, and 0.25–0.39 where it saw nothing: a σ limit
//! then means "never seen in the study", not "uncertain". With the noise fitted per sequence,
//! σ says how well the data pin P(success) down (smaller where many sequences agree).

use sequence_game::{ModelInput, UserModelTable};

/// The limits above which a decision is proposed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProposalRule {
    /// The state's softmax temperature (few visits: hot).
    pub above_temperature: f64,
    /// σ of P(success) for the sequence the decision sets up.
    pub above_success_std: f64,
}

/// Why a decision is unsure, in the words the therapist reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Unsure {
    LittleVisited { temperature: f64, limit: f64 },
    UnsureOfSuccess { std: f64, limit: f64 },
}

impl std::fmt::Display for Unsure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Unsure::LittleVisited { temperature, limit } => write!(
                f,
                "the state is little visited (temperature {temperature:.1} > {limit})"
            ),
            Unsure::UnsureOfSuccess { std, limit } => write!(
                f,
                "the user model is unsure of success (σ {std:.2} > {limit})"
            ),
        }
    }
}

impl ProposalRule {
    /// Every reason the decision is unsure (none: it plays at once). `success_std` is None
    /// without user models.
    pub fn reasons(&self, temperature: f64, success_std: Option<f64>) -> Vec<Unsure> {
        let mut out = Vec::new();
        if temperature > self.above_temperature {
            out.push(Unsure::LittleVisited {
                temperature,
                limit: self.above_temperature,
            });
        }
        if let Some(std) = success_std.filter(|s| *s > self.above_success_std) {
            out.push(Unsure::UnsureOfSuccess {
                std,
                limit: self.above_success_std,
            });
        }
        out
    }
}

/// σ of F^p at `input` for `cluster`; the largest over the clusters when the cluster is
/// unknown (-1, or none of `tables`): not knowing the child is a reason for caution. None
/// without tables.
pub fn success_std(tables: &[UserModelTable], cluster: i64, input: ModelInput) -> Option<f64> {
    let own = usize::try_from(cluster)
        .ok()
        .and_then(|c| tables.iter().find(|t| t.cluster == c));
    match own {
        Some(t) => Some(t.success(input).std),
        None => tables.iter().map(|t| t.success(input).std).reduce(f64::max),
    }
}

/// σ of P(success) over the inputs that rest on a given number of the cluster's sequences.
#[derive(Debug, Clone, PartialEq)]
pub struct SupportBucket {
    /// How many sequences: "none", "1", "2-4", "5 or more".
    pub label: &'static str,
    /// How many of the 63 (L, F, PS) inputs rest on that many.
    pub inputs: usize,
    /// σ's smallest, largest and mean over those inputs (0 without inputs).
    pub min: f64,
    pub max: f64,
    pub mean: f64,
}

/// σ of P(success) at every (L, F, PS) of `table`, grouped by how many of `records` are at
/// that input: what σ rests on. With the paper's fit the groups with data are all about 0.
pub fn sigma_by_support(
    table: &UserModelTable,
    records: &[&crate::InteractionRecord],
) -> Vec<SupportBucket> {
    const BUCKETS: [(&str, usize, usize); 4] = [
        ("none", 0, 0),
        ("1", 1, 1),
        ("2-4", 2, 4),
        ("5 or more", 5, usize::MAX),
    ];
    let mut count = vec![0usize; ModelInput::all().count()];
    for r in records {
        if let Ok(input) = ModelInput::new(r.level, r.feedback, r.previous_score) {
            count[input.index()] += 1;
        }
    }
    BUCKETS
        .iter()
        .map(|&(label, lo, hi)| {
            let sigmas: Vec<f64> = ModelInput::all()
                .filter(|i| (lo..=hi).contains(&count[i.index()]))
                .map(|i| table.success(i).std)
                .collect();
            let n = sigmas.len();
            SupportBucket {
                label,
                inputs: n,
                min: sigmas.iter().copied().reduce(f64::min).unwrap_or(0.0),
                max: sigmas.iter().copied().reduce(f64::max).unwrap_or(0.0),
                mean: if n == 0 {
                    0.0
                } else {
                    sigmas.iter().sum::<f64>() / n as f64
                },
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use sequence_game::{Feedback, Level, Prediction};

    #[test]
    fn a_decision_is_unsure_above_either_limit_and_says_why() {
        let rule = ProposalRule {
            above_temperature: 100.0,
            above_success_std: 0.3,
        };
        assert!(
            rule.reasons(100.0, Some(0.3)).is_empty(),
            "the limits themselves pass"
        );
        assert!(rule.reasons(0.5, None).is_empty());
        let r = rule.reasons(250.0, Some(0.34));
        let words: Vec<String> = r.iter().map(|u| u.to_string()).collect();
        assert_eq!(
            words,
            [
                "the state is little visited (temperature 250.0 > 100)",
                "the user model is unsure of success (σ 0.34 > 0.3)"
            ]
        );
    }

    #[test]
    fn sigma_is_grouped_by_the_sequences_at_its_input() {
        use crate::InteractionRecord;
        let seen = ModelInput::new(Level::TWO, Feedback::None, -2).expect("input");
        let once = ModelInput::new(Level::ONE, Feedback::None, 1).expect("input");
        // σ 0.01 where there are data, 0.3 elsewhere.
        let table = UserModelTable::tabulate(
            0,
            |i| Prediction {
                mean: 0.5,
                std: if i == seen || i == once { 0.01 } else { 0.3 },
            },
            |_, _| Prediction {
                mean: 0.0,
                std: 0.1,
            },
        );
        let record = |input: ModelInput| InteractionRecord {
            level: input.level,
            feedback: input.feedback,
            previous_score: input.previous_score,
            ..crate::simulate::simulate_study(&Default::default())[0].clone()
        };
        let records: Vec<InteractionRecord> =
            (0..6).map(|_| record(seen)).chain([record(once)]).collect();
        let refs: Vec<&InteractionRecord> = records.iter().collect();
        let b = sigma_by_support(&table, &refs);
        let all = ModelInput::all().count();
        let summary: Vec<(&str, usize, f64, f64)> = b
            .iter()
            .map(|b| (b.label, b.inputs, b.min, b.max))
            .collect();
        assert_eq!(
            summary,
            [
                ("none", all - 2, 0.3, 0.3),
                ("1", 1, 0.01, 0.01),
                ("2-4", 0, 0.0, 0.0),
                ("5 or more", 1, 0.01, 0.01)
            ]
        );
    }

    #[test]
    fn sigma_is_the_clusters_or_the_largest_when_the_cluster_is_unknown() {
        let table = |cluster: usize, std: f64| {
            UserModelTable::tabulate(
                cluster,
                |_| Prediction { mean: 0.5, std },
                |_, _| Prediction {
                    mean: 0.0,
                    std: 0.1,
                },
            )
        };
        let tables = [table(0, 0.1), table(1, 0.45)];
        let input = ModelInput::new(Level::TWO, Feedback::None, -2).expect("input");
        assert_eq!(success_std(&tables, 0, input), Some(0.1));
        assert_eq!(success_std(&tables, 1, input), Some(0.45));
        assert_eq!(success_std(&tables, -1, input), Some(0.45));
        assert_eq!(success_std(&tables, 7, input), Some(0.45));
        assert_eq!(success_std(&[], 0, input), None);
    }
}
