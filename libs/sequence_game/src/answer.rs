//! The rules of an answer: every tapped word is one of the four emotions, there are as many as
//! the task asked for, and the response time is a number of seconds in 0..=3600; and its score:
//! right only if every emotion is in the right place (RE = L, else -1; next PS = L * O). The
//! game manager scores with these, the tablet bridge checks a tablet's answer with them, and
//! message validation uses the same limits.

use crate::{Emotion, Level, Outcome};

/// The most emotions a sequence (and so an answer or a task's choices) holds: level 3's seven.
pub const MAX_SEQUENCE_LENGTH: usize = 7;

/// The longest response time and task timeout accepted, in seconds.
pub const MAX_RESPONSE_TIME_S: f64 = 3600.0;

/// Why an answer cannot be scored.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AnswerError {
    #[error("answer[{index}] = {value:?} is not happy, disgusted, sad or angry")]
    UnknownEmotion { index: usize, value: String },
    #[error("answer has {got} emotions, the task asked for {expected}")]
    WrongLength { got: usize, expected: usize },
    #[error("response_time = {0} is not a number of seconds in [0, 3600]")]
    ResponseTime(f64),
}

/// The emotions named by `words`, or the first word that names none (cut to 20 characters).
pub fn parse_emotions(words: &[String]) -> Result<Vec<Emotion>, AnswerError> {
    words
        .iter()
        .enumerate()
        .map(|(index, w)| {
            w.parse::<Emotion>()
                .map_err(|_| AnswerError::UnknownEmotion {
                    index,
                    value: w.chars().take(20).collect(),
                })
        })
        .collect()
}

/// Whether `seconds` is an acceptable response time (or task timeout).
pub fn response_time_ok(seconds: f64) -> bool {
    seconds.is_finite() && (0.0..=MAX_RESPONSE_TIME_S).contains(&seconds)
}

/// The tapped emotions, if the answer is well formed for a task of `expected` emotions.
pub fn parse_answer(
    answer: &[String],
    response_time: f64,
    expected: usize,
) -> Result<Vec<Emotion>, AnswerError> {
    let emotions = parse_emotions(answer)?;
    if emotions.len() != expected {
        return Err(AnswerError::WrongLength {
            got: emotions.len(),
            expected,
        });
    }
    if !response_time_ok(response_time) {
        return Err(AnswerError::ResponseTime(response_time));
    }
    Ok(emotions)
}

/// The score of one sequence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Score {
    pub outcome: Outcome,
    /// RE: L on success, -1 on failure.
    pub activity_result: f64,
    /// L * O: the next state's PS.
    pub score: i8,
}

/// Scores `answer` (None: timed out) against the sequence the robot said.
pub fn score(level: Level, said: &[Emotion], answer: Option<&[Emotion]>) -> Score {
    let outcome = Outcome::from_correct(answer == Some(said));
    Score {
        outcome,
        activity_result: outcome.activity_result(level),
        score: outcome.score(level),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_an_exact_answer_is_right() {
        use Emotion::*;
        let said = [Happy, Sad, Angry];
        let right = score(Level::ONE, &said, Some(&[Happy, Sad, Angry]));
        assert_eq!(
            (right.outcome, right.activity_result, right.score),
            (Outcome::Success, 1.0, 1)
        );
        let swapped = score(Level::THREE, &said, Some(&[Sad, Happy, Angry]));
        assert_eq!(
            (swapped.outcome, swapped.activity_result, swapped.score),
            (Outcome::Failure, -1.0, -3)
        );
        assert_eq!(score(Level::TWO, &said, None).score, -2);
    }

    #[test]
    fn malformed_answers_say_what_is_wrong() {
        let words = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(
            parse_answer(&words(&["happy", "joyful", "sad"]), 3.0, 3),
            Err(AnswerError::UnknownEmotion {
                index: 1,
                value: "joyful".into()
            })
        );
        assert_eq!(
            parse_answer(&words(&["happy", "sad"]), 3.0, 3),
            Err(AnswerError::WrongLength {
                got: 2,
                expected: 3
            })
        );
        assert!(parse_answer(&words(&["happy"]), f64::NAN, 1).is_err());
        assert!(parse_answer(&words(&["happy"]), 3600.5, 1).is_err());
        assert_eq!(
            parse_answer(&words(&["angry"]), 2.0, 1),
            Ok(vec![Emotion::Angry])
        );
    }
}
