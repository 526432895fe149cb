//! Hand-made user-model tables from the per-level numbers in `../shared/REFERENCE.md` (the
//! authors' clusters: P(success | L) and mean E per level). NOT fitted models: every (F, PS, O)
//! gets its level's value. For unit tests and for trying the policy without a fitted file.

use sequence_game::{Prediction, UserModelTable};

/// Cluster 0 (high engagement) and cluster 1 (low engagement): (P(success), mean E) per level.
pub const PER_LEVEL_REFERENCE: [[(f64, f64); 3]; 2] = [
    [(0.943, 0.508), (0.854, 0.641), (0.529, 0.569)],
    [(0.970, -0.610), (0.935, -0.512), (0.462, -0.708)],
];

/// What the tables are, for printouts and file provenance.
pub const PER_LEVEL_REFERENCE_NAME: &str =
    "per-level reference numbers from REFERENCE.md (hand-made tables, not a fitted user model)";

/// Both clusters' tables; E does not depend on the outcome, F or PS.
pub fn per_level_reference_tables() -> Vec<UserModelTable> {
    PER_LEVEL_REFERENCE
        .iter()
        .enumerate()
        .map(|(cluster, levels)| {
            UserModelTable::tabulate(
                cluster,
                |i| Prediction {
                    mean: levels[i.level.index()].0,
                    std: 0.0,
                },
                |i, _| Prediction {
                    mean: levels[i.level.index()].1,
                    std: 0.0,
                },
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_are_valid_and_carry_the_reference_numbers() {
        let t = per_level_reference_tables();
        assert_eq!(t.len(), 2);
        for (k, table) in t.iter().enumerate() {
            table.validate().expect("valid");
            assert_eq!(table.cluster, k);
        }
        assert_eq!(t[1].success[62].mean, 0.462);
        assert_eq!(t[0].engagement[0].mean, 0.508);
    }
}
