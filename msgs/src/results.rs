//! A `SequenceResult`'s codes read with the game's own vocabulary (`sequence_game`): its
//! score L·O, whether the answer was right, and its engagement if a face was seen. What a
//! session's results add up to is `session_tally::Tally`'s.

use crate::SequenceResult;
use sequence_game::{Level, Outcome};

impl SequenceResult {
    /// The paper's score of this sequence, L·O (the next state's PS); 0 for a result whose
    /// level or outcome is not the game's (validation refuses such a result on receipt).
    pub fn score(&self) -> i32 {
        match (
            Level::new(self.level.into()),
            Outcome::new(self.outcome.into()),
        ) {
            (Ok(level), Ok(outcome)) => outcome.score(level).into(),
            _ => 0,
        }
    }

    /// Whether the child tapped the sequence back right.
    pub fn is_right(&self) -> bool {
        self.outcome == Outcome::Success.sign()
    }

    /// The engagement of this sequence, if a face was seen while the robot talked.
    pub fn seen_engagement(&self) -> Option<f64> {
        (!self.engagement_per_second.is_empty()).then(|| f64::from(self.engagement))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_score_is_level_times_outcome() {
        let result = |level: u8, outcome: i8| SequenceResult {
            level,
            outcome,
            ..Default::default()
        };
        assert_eq!(
            [result(2, 1), result(3, -1), result(1, -1)].map(|r| r.score()),
            [2, -3, -1]
        );
        assert!(result(2, 1).is_right() && !result(2, -1).is_right());
        assert_eq!(result(4, 1).score(), 0, "not a level");
    }
}
