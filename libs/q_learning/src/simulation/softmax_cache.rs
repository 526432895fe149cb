//! Softmax weights of every state kept between visits, for the simulator's hot loop. A visit
//! changes one Q-value, so it costs one exp instead of one per action: the weights are
//! exp((Q − ref_s) / T_s) against a per-state reference, which gives the same probabilities as
//! subtracting the max (the paper's softmax, without overflow) as long as |Q − ref_s| / T_s
//! stays small; beyond that, and whenever T_s changes, the row is recomputed from scratch.

use crate::learning::{allowed_count, best};
use sequence_game::{ACTION_COUNT, STATE_COUNT, State};

/// How far (in units of T) a Q-value may drift from its row's reference before the row is
/// recomputed: e^±30 keeps every weight and their sum far from overflow and underflow.
const DRIFT: f64 = 30.0;

#[derive(Debug, Clone, PartialEq)]
pub struct SoftmaxCache {
    weights: [[f64; ACTION_COUNT]; STATE_COUNT],
    reference: [f64; STATE_COUNT],
    /// The temperature the row was computed at; NaN until the first visit.
    temperature: [f64; STATE_COUNT],
    allowed: [usize; STATE_COUNT],
}

impl Default for SoftmaxCache {
    fn default() -> Self {
        let mut allowed = [ACTION_COUNT; STATE_COUNT];
        allowed[State::START.index()] = allowed_count(State::START);
        SoftmaxCache {
            weights: [[0.0; ACTION_COUNT]; STATE_COUNT],
            reference: [0.0; STATE_COUNT],
            temperature: [f64::NAN; STATE_COUNT],
            allowed,
        }
    }
}

impl SoftmaxCache {
    /// The weights of row `state` (Q-values `row`) at temperature `t`.
    #[inline]
    pub fn weights(
        &mut self,
        state: usize,
        row: &[f64; ACTION_COUNT],
        t: f64,
    ) -> &[f64; ACTION_COUNT] {
        // NaN (never computed) is unequal to everything.
        if self.temperature[state] != t {
            self.refresh(state, row, t);
        }
        &self.weights[state]
    }

    /// Q(state, action) is now `row[action]`.
    #[inline]
    pub fn updated(&mut self, state: usize, action: usize, row: &[f64; ACTION_COUNT]) {
        let t = self.temperature[state];
        if t.is_nan() {
            return;
        }
        let d = (row[action] - self.reference[state]) / t;
        if d.abs() <= DRIFT {
            self.weights[state][action] = d.exp();
        } else {
            self.refresh(state, row, t);
        }
    }

    #[cold]
    fn refresh(&mut self, state: usize, row: &[f64; ACTION_COUNT], t: f64) {
        let allowed = self.allowed[state];
        let reference = best(row, allowed);
        for (w, q) in self.weights[state].iter_mut().zip(row).take(allowed) {
            *w = ((q - reference) / t).exp();
        }
        self.reference[state] = reference;
        self.temperature[state] = t;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learning::softmax_weights;

    #[test]
    fn cached_weights_give_the_softmax_probabilities() {
        let mut cache = SoftmaxCache::default();
        let mut row = [0.5, -1.0, 2.0, 0.0, 1.0];
        let s = 7;
        let probabilities = |w: &[f64; 5]| {
            let total: f64 = w.iter().sum();
            w.map(|x| x / total)
        };
        cache.weights(s, &row, 2.0);
        // Many small updates, one of them taking the lead, then a big jump and a new T.
        for (i, (a, q)) in [
            (0, 0.7),
            (2, 1.9),
            (1, 2.5),
            (3, 0.1),
            (1, 80.0),
            (4, -70.0),
        ]
        .into_iter()
        .enumerate()
        {
            row[a] = q;
            cache.updated(s, a, &row);
            let t = if i < 5 { 2.0 } else { 0.5 };
            let got = probabilities(cache.weights(s, &row, t));
            let exact = softmax_weights(&row, 5, t);
            for (a, (g, w)) in got.iter().zip(exact.weights).enumerate() {
                let want = w / exact.total;
                assert!((g - want).abs() <= 1e-14 * want.max(1e-300), "{i} {a}");
            }
        }
        // The start state only weighs a1..a3.
        let w = cache.weights(0, &[1.0, 2.0, 3.0, 9.0, 9.0], 1.0);
        assert_eq!((w[3], w[4]), (0.0, 0.0));
    }
}
