//! The prior covariance of a child's own model as a file: how far known children's own models
//! lay from their cluster's, learned offline from a study (`policy_lab child-belief-prior`)
//! and read by the behaviour policy node, which has no study beside it. Only the covariance
//! over the known children is kept, never a child's own model. Read as the suite's other
//! versioned files (`versioned_json`), refused whole with the field at fault.

use crate::LearnedCovariance;
use nalgebra::DMatrix;
use sequence_game::user_model_table::{ENGAGEMENT_INPUTS, SUCCESS_INPUTS};
use serde::{Deserialize, Serialize};
use std::path::Path;
use versioned_json::{FileError, Kind};

/// The file's kind.
pub const PRIOR_FILE: Kind = Kind {
    format: "qt_therapy child_belief_prior",
    version: 1,
    name: "child belief prior",
};

/// A learned prior covariance with what it was learned from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PriorFile {
    pub format: String,
    pub version: u32,
    /// The study and the user-model file whose clusters the deviations were taken from.
    pub provenance: String,
    /// Known children the covariance averages over.
    pub children: usize,
    /// Shrinkage of the correlations towards 0, the least variance, and the scale applied.
    pub shrinkage: f64,
    pub variance_floor: f64,
    pub scale: f64,
    /// The covariance of P(success) over the 63 inputs (L, F, PS), rows in table order.
    pub success: Vec<Vec<f64>>,
    /// The covariance of engagement over the 126 (input, outcome) pairs, in table order.
    pub engagement: Vec<Vec<f64>>,
}

impl PriorFile {
    /// The file of `covariance` (values rounded to 1e-6: the file stays small and the
    /// rounding is far below any variance it holds).
    pub fn new(
        covariance: &LearnedCovariance,
        provenance: String,
        children: usize,
        (shrinkage, variance_floor, scale): (f64, f64, f64),
    ) -> PriorFile {
        let rows = |m: &DMatrix<f64>| -> Vec<Vec<f64>> {
            (0..m.nrows())
                .map(|i| {
                    (0..m.ncols())
                        .map(|j| (m[(i, j)] * 1e6).round() / 1e6)
                        .collect()
                })
                .collect()
        };
        PriorFile {
            format: PRIOR_FILE.format.into(),
            version: PRIOR_FILE.version,
            provenance,
            children,
            shrinkage,
            variance_floor,
            scale,
            success: rows(&covariance.success),
            engagement: rows(&covariance.engagement),
        }
    }

    /// Reads `path` and checks each matrix: its size, finite, symmetric, a positive diagonal,
    /// and positive definite (a Cholesky factor exists), naming the field at fault.
    pub fn load(path: &Path) -> Result<(PriorFile, LearnedCovariance), FileError> {
        let file: PriorFile = PRIOR_FILE.load(path)?;
        let success = matrix(path, "success", &file.success, SUCCESS_INPUTS)?;
        let engagement = matrix(path, "engagement", &file.engagement, ENGAGEMENT_INPUTS)?;
        Ok((
            file,
            LearnedCovariance {
                success,
                engagement,
            },
        ))
    }

    pub fn save(&self, path: &Path) -> Result<(), FileError> {
        PRIOR_FILE.save(path, self)
    }
}

fn matrix(
    path: &Path,
    field: &str,
    rows: &[Vec<f64>],
    n: usize,
) -> Result<DMatrix<f64>, FileError> {
    if rows.len() != n {
        return Err(FileError::field(
            path,
            field,
            format!("has {} rows, expected {n}", rows.len()),
        ));
    }
    if let Some(i) = rows.iter().position(|r| r.len() != n) {
        return Err(FileError::field(
            path,
            format!("{field}[{i}]"),
            format!("has {} values, expected {n}", rows[i].len()),
        ));
    }
    let m = DMatrix::from_fn(n, n, |i, j| rows[i][j]);
    for i in 0..n {
        if !(m[(i, i)].is_finite() && m[(i, i)] > 0.0) {
            return Err(FileError::field(
                path,
                format!("{field}[{i}][{i}]"),
                format!("variance {} must be a number > 0", m[(i, i)]),
            ));
        }
        for j in 0..i {
            if !m[(i, j)].is_finite() || (m[(i, j)] - m[(j, i)]).abs() > 1e-9 {
                return Err(FileError::field(
                    path,
                    format!("{field}[{i}][{j}]"),
                    format!(
                        "{} against {} at [{j}][{i}]: the covariance must be finite and symmetric",
                        m[(i, j)],
                        m[(j, i)]
                    ),
                ));
            }
        }
    }
    if m.clone().cholesky().is_none() {
        return Err(FileError::field(
            path,
            field,
            "is not positive definite: no child's model could be drawn from it",
        ));
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sequence_game::{Prediction, UserModelTable};

    fn flat(p: f64, e: f64) -> UserModelTable {
        UserModelTable::tabulate(
            0,
            |_| Prediction { mean: p, std: 0.0 },
            |_, _| Prediction { mean: e, std: 0.0 },
        )
    }

    fn covariance() -> LearnedCovariance {
        let prior = flat(0.6, 0.1);
        let a = flat(0.8, 0.3);
        let b = flat(0.4, -0.2);
        LearnedCovariance::from_children(&[(&a, &prior), (&b, &prior)], 0.5, 0.01).expect("learned")
    }

    #[test]
    fn a_prior_file_reads_back_what_was_written() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("prior.json");
        let c = covariance();
        PriorFile::new(&c, "test".into(), 2, (0.5, 0.01, 1.0))
            .save(&path)
            .expect("saves");
        let (file, read) = PriorFile::load(&path).expect("loads");
        assert_eq!(file.children, 2);
        assert!((read.success.clone() - c.success).amax() < 1e-6);
        assert!((read.engagement.clone() - c.engagement).amax() < 1e-6);
    }

    #[test]
    fn a_broken_prior_file_is_refused_naming_the_field() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("prior.json");
        let mut file = PriorFile::new(&covariance(), "test".into(), 2, (0.5, 0.01, 1.0));
        file.success[3][1] += 0.5;
        file.save(&path).expect("saves");
        let e = PriorFile::load(&path).expect_err("asymmetric").to_string();
        assert!(
            e.contains("field success[3][1]") && e.contains("symmetric"),
            "{e}"
        );

        let mut file = PriorFile::new(&covariance(), "test".into(), 2, (0.5, 0.01, 1.0));
        file.engagement[7][7] = -1.0;
        file.save(&path).expect("saves");
        let e = PriorFile::load(&path).expect_err("negative").to_string();
        assert!(e.contains("engagement[7][7]") && e.contains("> 0"), "{e}");

        let mut file = PriorFile::new(&covariance(), "test".into(), 2, (0.5, 0.01, 1.0));
        file.success.pop();
        file.save(&path).expect("saves");
        let e = PriorFile::load(&path).expect_err("short").to_string();
        assert!(e.contains("has 62 rows, expected 63"), "{e}");

        let whole = std::fs::read(&path).expect("reads");
        std::fs::write(&path, &whole[..whole.len() / 2]).expect("cuts");
        let e = PriorFile::load(&path).expect_err("cut").to_string();
        assert!(e.contains("not JSON"), "{e}");
    }
}
