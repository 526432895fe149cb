//! The statistics of the policy's studies: quantiles, Student's t, the percentile bootstrap
//! of a mean, an exact sign test, and the paired comparison of two policies over units
//! (children): per unit the difference, wins / ties / losses, a t and a bootstrap interval
//! over units, the median, and the result without the most influential unit.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

/// The p-quantile (0..1) of sorted values, linearly interpolated.
pub fn quantile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let x = p * (sorted.len() - 1) as f64;
    let (lo, hi) = (x.floor() as usize, x.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (x - lo as f64)
}

pub fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len().max(1) as f64
}

/// The sample standard deviation (n − 1); 0 for fewer than two values.
pub fn sample_std(values: &[f64]) -> f64 {
    if values.len() < 2 {
        return 0.0;
    }
    let m = mean(values);
    (values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (values.len() - 1) as f64).sqrt()
}

pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    quantile(&v, 0.5)
}

/// ln Γ(x) for x > 0 (Lanczos, g = 7, nine terms: about 15 digits).
fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Γ(x) Γ(1 − x) = π / sin(πx).
        return (std::f64::consts::PI / (std::f64::consts::PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let t = x + 7.5;
    let series = G[1..]
        .iter()
        .enumerate()
        .fold(G[0], |s, (i, g)| s + g / (x + i as f64 + 1.0));
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + series.ln()
}

/// The continued fraction of the incomplete beta function (modified Lentz).
fn beta_fraction(a: f64, b: f64, x: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < TINY {
        d = TINY;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..300 {
        let m = f64::from(m);
        let m2 = 2.0 * m;
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1.0 + aa * d;
        d = if d.abs() < TINY { TINY } else { d };
        c = 1.0 + aa / c;
        c = if c.abs() < TINY { TINY } else { c };
        d = 1.0 / d;
        h *= d * c;
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1.0 + aa * d;
        d = if d.abs() < TINY { TINY } else { d };
        c = 1.0 + aa / c;
        c = if c.abs() < TINY { TINY } else { c };
        d = 1.0 / d;
        let delta = d * c;
        h *= delta;
        if (delta - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// The regularised incomplete beta function I_x(a, b).
fn incomplete_beta(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let front =
        (ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln()).exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        front * beta_fraction(a, b, x) / a
    } else {
        1.0 - front * beta_fraction(b, a, 1.0 - x) / b
    }
}

/// P(T <= t) for Student's t with `df` degrees of freedom.
pub fn t_cdf(t: f64, df: f64) -> f64 {
    let tail = 0.5 * incomplete_beta(df / 2.0, 0.5, df / (df + t * t));
    if t >= 0.0 { 1.0 - tail } else { tail }
}

/// The p-quantile of Student's t with `df` degrees of freedom (bisection on the CDF).
pub fn t_quantile(p: f64, df: f64) -> f64 {
    if p == 0.5 {
        return 0.0;
    }
    if p < 0.5 {
        return -t_quantile(1.0 - p, df);
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    while t_cdf(hi, df) < p && hi < 1e12 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if t_cdf(mid, df) < p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// A 95 % interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Interval {
    pub low: f64,
    pub high: f64,
}

impl Interval {
    pub fn contains(&self, x: f64) -> bool {
        self.low <= x && x <= self.high
    }
}

/// The 95 % t interval of the mean of `values`; `None` below two values.
pub fn t_interval(values: &[f64]) -> Option<Interval> {
    if values.len() < 2 {
        return None;
    }
    let m = mean(values);
    let half = t_quantile(0.975, (values.len() - 1) as f64) * sample_std(values)
        / (values.len() as f64).sqrt();
    Some(Interval {
        low: m - half,
        high: m + half,
    })
}

/// The 95 % percentile-bootstrap interval of the mean of `values`: `resamples` resamples
/// with replacement drawn from `seed`; `None` below two values.
pub fn bootstrap_interval(values: &[f64], resamples: usize, seed: u64) -> Option<Interval> {
    if values.len() < 2 || resamples == 0 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = values.len();
    let mut means: Vec<f64> = (0..resamples)
        .map(|_| (0..n).map(|_| values[rng.random_range(0..n)]).sum::<f64>() / n as f64)
        .collect();
    means.sort_by(f64::total_cmp);
    Some(Interval {
        low: quantile(&means, 0.025),
        high: quantile(&means, 0.975),
    })
}

/// The two-sided exact sign test: the probability of a split at least as uneven as
/// `wins` : `losses` if each were a coin toss (ties left out); 1 when there are none.
pub fn sign_test(wins: usize, losses: usize) -> f64 {
    let n = wins + losses;
    if n == 0 {
        return 1.0;
    }
    let k = wins.min(losses);
    // Σ_{i<=k} C(n, i) / 2^n: term by term from 2^-n while that is a normal number, in logs
    // beyond.
    let tail: f64 = if n <= 1000 {
        let mut term = 0.5f64.powi(n as i32);
        let mut sum = 0.0;
        for i in 0..=k {
            sum += term;
            term *= (n - i) as f64 / (i + 1) as f64;
        }
        sum
    } else {
        let ln_choose = |i: usize| {
            ln_gamma(n as f64 + 1.0) - ln_gamma(i as f64 + 1.0) - ln_gamma((n - i) as f64 + 1.0)
        };
        (0..=k)
            .map(|i| (ln_choose(i) - n as f64 * std::f64::consts::LN_2).exp())
            .sum()
    };
    (2.0 * tail).min(1.0)
}

/// How one unit came out of a paired comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Verdict {
    /// The first policy did better: the unit's 95 % interval over repetitions lies above 0.
    Win,
    /// Not told apart: the unit's interval holds 0 (exactly 0 when both played alike in every
    /// repetition).
    Tie,
    Loss,
}

/// One unit's difference between two policies.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UnitDifference {
    pub unit: String,
    /// The mean over repetitions of first − second.
    pub difference: f64,
    /// Its 95 % t interval over repetitions (`None` with one repetition).
    pub interval: Option<Interval>,
    pub verdict: Verdict,
}

impl UnitDifference {
    /// `per_repetition`: the unit's difference in each repetition (seed).
    pub fn new(unit: &str, per_repetition: &[f64]) -> Self {
        let difference = mean(per_repetition);
        let interval = t_interval(per_repetition);
        let verdict = match interval {
            _ if difference == 0.0 && per_repetition.iter().all(|d| *d == 0.0) => Verdict::Tie,
            Some(i) if i.low > 0.0 => Verdict::Win,
            Some(i) if i.high < 0.0 => Verdict::Loss,
            Some(_) => Verdict::Tie,
            None if difference > 0.0 => Verdict::Win,
            None => Verdict::Loss,
        };
        UnitDifference {
            unit: unit.to_string(),
            difference,
            interval,
            verdict,
        }
    }
}

/// The paired differences of a set of units, summarised.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairedSummary {
    pub units: usize,
    /// Mean of the units' differences (each unit weighs the same).
    pub mean: f64,
    /// Standard error of that mean over units.
    pub standard_error: f64,
    pub t_interval: Option<Interval>,
    pub bootstrap_interval: Option<Interval>,
    pub median: f64,
    pub wins: usize,
    pub ties: usize,
    pub losses: usize,
    /// Units whose difference is exactly 0 (both policies played alike in every repetition).
    pub exactly_zero: usize,
    /// Two-sided exact sign test of wins against losses.
    pub sign_test_p: f64,
}

impl PairedSummary {
    pub fn of(units: &[UnitDifference], resamples: usize, seed: u64) -> Self {
        let d: Vec<f64> = units.iter().map(|u| u.difference).collect();
        let count = |v: Verdict| units.iter().filter(|u| u.verdict == v).count();
        let (wins, losses) = (count(Verdict::Win), count(Verdict::Loss));
        PairedSummary {
            units: d.len(),
            mean: mean(&d),
            standard_error: sample_std(&d) / (d.len().max(1) as f64).sqrt(),
            t_interval: t_interval(&d),
            bootstrap_interval: bootstrap_interval(&d, resamples, seed),
            median: median(&d),
            wins,
            ties: count(Verdict::Tie),
            losses,
            exactly_zero: d.iter().filter(|x| **x == 0.0).count(),
            sign_test_p: sign_test(wins, losses),
        }
    }
}

/// A paired comparison over units, with the result once the unit that moves the mean most
/// (the one furthest from it) is left out.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairedComparison {
    pub per_unit: Vec<UnitDifference>,
    pub all: PairedSummary,
    /// The most influential unit and the summary without it (`None` below three units).
    pub most_influential: Option<(UnitDifference, PairedSummary)>,
}

impl PairedComparison {
    /// `units`: per unit its name and its differences per repetition; the bootstrap draws
    /// `resamples` resamples from `seed`.
    pub fn of(units: &[(String, Vec<f64>)], resamples: usize, seed: u64) -> Self {
        let per_unit: Vec<UnitDifference> = units
            .iter()
            .map(|(name, d)| UnitDifference::new(name, d))
            .collect();
        let all = PairedSummary::of(&per_unit, resamples, seed);
        let most_influential = (per_unit.len() >= 3)
            .then(|| {
                let (i, _) = per_unit.iter().enumerate().max_by(|a, b| {
                    (a.1.difference - all.mean)
                        .abs()
                        .total_cmp(&(b.1.difference - all.mean).abs())
                        // Among equals the first, not the last.
                        .then(b.0.cmp(&a.0))
                })?;
                let rest: Vec<UnitDifference> = per_unit
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, u)| u.clone())
                    .collect();
                Some((
                    per_unit[i].clone(),
                    PairedSummary::of(&rest, resamples, seed),
                ))
            })
            .flatten();
        PairedComparison {
            per_unit,
            all,
            most_influential,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn students_t_quantiles_match_the_tables() {
        // Two-sided 95 % critical values (any statistics table).
        for (df, t) in [
            (1.0, 12.706_204_736),
            (2.0, 4.302_652_730),
            (9.0, 2.262_157_163),
            (19.0, 2.093_024_054),
            (29.0, 2.045_229_642),
            (1000.0, 1.962_339_071),
        ] {
            let got = t_quantile(0.975, df);
            assert!((got - t).abs() < 1e-8, "df {df}: {got} vs {t}");
            assert!((t_cdf(-got, df) - 0.025).abs() < 1e-12);
        }
        assert!((t_quantile(0.995, 19.0) - 2.860_934_606).abs() < 1e-8);
        assert_eq!(t_quantile(0.5, 5.0), 0.0);
    }

    #[test]
    fn the_sign_test_is_the_binomial_tail() {
        assert_eq!(sign_test(0, 0), 1.0);
        // 9 wins of 10: 2 * (1 + 10) / 1024.
        assert!((sign_test(9, 1) - 22.0 / 1024.0).abs() < 1e-12);
        assert!((sign_test(1, 9) - 22.0 / 1024.0).abs() < 1e-12);
        assert_eq!(sign_test(5, 5), 1.0);
        assert!((sign_test(3, 0) - 0.25).abs() < 1e-12);
        // Beyond 1,000 units, in logs (exact values from Python's math.comb).
        assert!((sign_test(1100, 1000) - 0.030_720_707_864_242_296).abs() < 1e-10);
        assert!((sign_test(1001, 999) - 0.982_160_988_854_145_7).abs() < 1e-10);
    }

    #[test]
    fn a_paired_comparison_counts_ties_and_leaves_out_the_most_influential_unit() {
        let units: Vec<(String, Vec<f64>)> = [
            ("a", vec![0.0, 0.0, 0.0]),
            ("b", vec![1.0, 1.2, 0.8]),
            ("c", vec![-0.5, 0.5, 0.1]),
            ("d", vec![-2.0, -2.1, -1.9]),
            ("e", vec![30.0, 28.0, 29.0]),
        ]
        .into_iter()
        .map(|(n, v)| (n.to_string(), v))
        .collect();
        let c = PairedComparison::of(&units, 2000, 1);
        let verdicts: Vec<Verdict> = c.per_unit.iter().map(|u| u.verdict).collect();
        use Verdict::*;
        assert_eq!(verdicts, [Tie, Win, Tie, Loss, Win]);
        assert_eq!((c.all.wins, c.all.ties, c.all.losses), (2, 2, 1));
        assert_eq!(c.all.exactly_zero, 1);
        let d = [0.0, 1.0, 1.0 / 30.0, -2.0, 29.0];
        assert!((c.all.mean - mean(&d)).abs() < 1e-12);
        assert!((c.all.median - 1.0 / 30.0).abs() < 1e-12);
        let t = c.all.t_interval.expect("five units");
        let half = 2.776_445_105 * sample_std(&d) / 5f64.sqrt();
        assert!((t.low - (mean(&d) - half)).abs() < 1e-6, "{t:?}");
        let b = c.all.bootstrap_interval.expect("five units");
        assert!(b.low < c.all.mean && c.all.mean < b.high, "{b:?}");
        // Same seed, same interval.
        assert_eq!(PairedComparison::of(&units, 2000, 1), c);
        let (unit, without) = c.most_influential.expect("five units");
        assert_eq!(unit.unit, "e");
        assert_eq!(without.units, 4);
        assert!((without.mean - mean(&d[..4])).abs() < 1e-12);
        assert_eq!((without.wins, without.ties, without.losses), (1, 2, 1));
    }
}
