//! Exponential smoothing of the per-second expected engagement, as the authors smooth it
//! (`pandas.Series.ewm(alpha=0.75).mean()`, whose default `adjust=True` divides by the sum of
//! the weights, so the first values are not pulled towards 0). Seconds without a face are
//! skipped, as they are absent from the authors' per-second table.

/// Streaming exponential smoother; O(1) per value, no allocation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExponentialSmoother {
    alpha: f64,
    adjust: bool,
    /// adjust: weighted sum of values and of weights; otherwise the last smoothed value.
    numerator: f64,
    denominator: f64,
}

impl ExponentialSmoother {
    /// `alpha` in (0, 1]; 1 turns smoothing off. `adjust` as in pandas.
    pub fn new(alpha: f64, adjust: bool) -> ExponentialSmoother {
        ExponentialSmoother {
            alpha,
            adjust,
            numerator: 0.0,
            denominator: 0.0,
        }
    }

    /// Adds the next value and returns the smoothed value.
    pub fn push(&mut self, x: f64) -> f64 {
        let keep = 1.0 - self.alpha;
        if self.adjust {
            self.numerator = x + keep * self.numerator;
            self.denominator = 1.0 + keep * self.denominator;
        } else if self.denominator == 0.0 {
            self.numerator = x;
            self.denominator = 1.0;
        } else {
            self.numerator = self.alpha * x + keep * self.numerator;
        }
        self.numerator / self.denominator
    }

    /// Forgets the history (a new session or face).
    pub fn reset(&mut self) {
        self.numerator = 0.0;
        self.denominator = 0.0;
    }
}

/// Smooths a whole series (NaN entries are skipped and stay NaN).
pub fn smooth_series(values: &[f64], alpha: f64, adjust: bool) -> Vec<f64> {
    let mut s = ExponentialSmoother::new(alpha, adjust);
    values
        .iter()
        .map(|&v| if v.is_nan() { f64::NAN } else { s.push(v) })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_authors_published_smoothed_values() {
        // Participant 03DEQR1O's first five seconds: raw per-second engagement and the
        // smoothed values printed in the authors' merger notebook (ewm(alpha=0.75).mean()).
        let raw = [-1.0 / 3.0, -1.0, 0.6, 1.0, 1.0];
        let printed = [-0.333333, -0.866667, 0.250794, 0.814902, 0.953861];
        let smoothed = smooth_series(&raw, 0.75, true);
        for (s, p) in smoothed.iter().zip(printed) {
            assert!((s - p).abs() < 5e-7, "{s} vs {p}");
        }
    }

    #[test]
    fn unadjusted_is_the_plain_recursion_and_alpha_one_is_identity() {
        let s = smooth_series(&[1.0, -1.0, f64::NAN, 1.0], 0.75, false);
        assert_eq!(s[0], 1.0);
        assert_eq!(s[1], -0.75 + 0.25);
        assert!(s[2].is_nan());
        assert_eq!(s[3], 0.75 + 0.25 * s[1]);
        assert_eq!(smooth_series(&[0.3, -0.2], 1.0, true), vec![0.3, -0.2]);
    }
}
