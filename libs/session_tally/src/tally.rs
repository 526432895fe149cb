//! What a session's results add up to, read off `SequenceResult`s with the game's own rules:
//! right answers, timeouts, the paper's accumulated score out of the best possible, mean
//! engagement. The game manager's session summary, the session report and the tablet's
//! result view all count with this.

use qt_therapy_msgs::SequenceResult;

/// A session's results counted.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Tally {
    pub sequences: usize,
    pub correct: usize,
    pub timeouts: usize,
    /// Sum of L·O: the paper's accumulated score.
    pub score: i32,
    /// Sum of L: the best score possible with these levels.
    pub max_score: i32,
    /// Mean engagement over the sequences in which a face was seen; None if none was.
    pub mean_engagement: Option<f64>,
}

impl Tally {
    pub fn of(results: &[SequenceResult]) -> Tally {
        let seen: Vec<f64> = results
            .iter()
            .filter_map(SequenceResult::seen_engagement)
            .collect();
        Tally {
            sequences: results.len(),
            correct: results.iter().filter(|r| r.is_right()).count(),
            timeouts: results.iter().filter(|r| r.timed_out).count(),
            score: results.iter().map(SequenceResult::score).sum(),
            max_score: results.iter().map(|r| i32::from(r.level)).sum(),
            mean_engagement: (!seen.is_empty())
                .then(|| seen.iter().sum::<f64>() / seen.len() as f64),
        }
    }

    /// Score over the best possible, 0 for no sequence.
    pub fn ratio(&self) -> f64 {
        if self.max_score > 0 {
            f64::from(self.score) / f64::from(self.max_score)
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(level: u8, outcome: i8, timed_out: bool, engagement: Option<f32>) -> SequenceResult {
        SequenceResult {
            level,
            outcome,
            timed_out,
            engagement: engagement.unwrap_or(0.0),
            engagement_per_second: engagement.map(|e| vec![e; 3]).unwrap_or_default(),
            ..Default::default()
        }
    }

    #[test]
    fn the_tally_counts_as_the_paper_does() {
        let results = [
            result(2, 1, false, Some(0.5)),
            result(3, -1, false, None),
            result(1, -1, true, Some(-0.1)),
        ];
        assert_eq!(
            results.iter().map(|r| r.score()).collect::<Vec<_>>(),
            [2, -3, -1]
        );
        let t = Tally::of(&results);
        assert_eq!(
            (t.sequences, t.correct, t.timeouts, t.score, t.max_score),
            (3, 1, 1, -2, 6)
        );
        assert!((t.mean_engagement.expect("seen") - 0.2).abs() < 1e-6);
        assert!((t.ratio() + 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(Tally::of(&[]).mean_engagement, None);
    }
}
