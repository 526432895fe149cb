//! What the robot says and shows, in the language the parameters choose: introduction,
//! encouraging and challenging feedback, the emotion words, "well done", "let's try again",
//! goodbye, and the QTrobot face animations and gestures that go with them.

use crate::params::LineParams;
use sequence_game::{Emotion, Feedback};

/// One thing the robot does: a line to say, and optionally a face and a gesture.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RobotAct {
    pub speech: String,
    pub emotion: Option<String>,
    pub gesture: Option<String>,
}

/// The robot's lines in one language.
#[derive(Debug, Clone, PartialEq)]
pub struct Utterances {
    pub language: String,
    intro: String,
    encouraging: Vec<String>,
    challenging: Vec<String>,
    well_done: String,
    try_again: String,
    goodbye: String,
    emotion_words: Vec<String>,
    intro_gesture: String,
    encouraging_emotion: String,
    encouraging_gesture: String,
    challenging_emotion: String,
    challenging_gesture: String,
    well_done_emotion: String,
    try_again_emotion: String,
    goodbye_gesture: String,
}

fn some(s: &str) -> Option<String> {
    (!s.trim().is_empty()).then(|| s.to_string())
}

impl Utterances {
    /// The lines of `p.language` (validated parameters: "en" or "de").
    pub fn from_params(p: &LineParams) -> Self {
        let de = p.language == "de";
        let pick = |en: &String, de_: &String| if de { de_.clone() } else { en.clone() };
        let pick_list =
            |en: &Vec<String>, de_: &Vec<String>| if de { de_.clone() } else { en.clone() };
        Utterances {
            language: p.language.clone(),
            intro: pick(&p.intro_en, &p.intro_de),
            encouraging: pick_list(&p.encouraging_en, &p.encouraging_de),
            challenging: pick_list(&p.challenging_en, &p.challenging_de),
            well_done: pick(&p.well_done_en, &p.well_done_de),
            try_again: pick(&p.try_again_en, &p.try_again_de),
            goodbye: pick(&p.goodbye_en, &p.goodbye_de),
            emotion_words: pick_list(&p.emotion_words_en, &p.emotion_words_de),
            intro_gesture: p.intro_gesture.clone(),
            encouraging_emotion: p.encouraging_emotion.clone(),
            encouraging_gesture: p.encouraging_gesture.clone(),
            challenging_emotion: p.challenging_emotion.clone(),
            challenging_gesture: p.challenging_gesture.clone(),
            well_done_emotion: p.well_done_emotion.clone(),
            try_again_emotion: p.try_again_emotion.clone(),
            goodbye_gesture: p.goodbye_gesture.clone(),
        }
    }

    pub fn intro(&self) -> RobotAct {
        RobotAct {
            speech: self.intro.clone(),
            emotion: Some(Emotion::Happy.qtrobot_emotion().to_string()),
            gesture: some(&self.intro_gesture),
        }
    }

    /// How many lines there are for this feedback (0 for none).
    pub fn feedback_line_count(&self, feedback: Feedback) -> usize {
        match feedback {
            Feedback::None => 0,
            Feedback::Encouraging => self.encouraging.len(),
            Feedback::Challenging => self.challenging.len(),
        }
    }

    /// Feedback line number `line` (wrapped), with its face and gesture; None for no feedback.
    pub fn feedback(&self, feedback: Feedback, line: usize) -> Option<RobotAct> {
        let (lines, emotion, gesture) = match feedback {
            Feedback::None => return None,
            Feedback::Encouraging => (
                &self.encouraging,
                &self.encouraging_emotion,
                &self.encouraging_gesture,
            ),
            Feedback::Challenging => (
                &self.challenging,
                &self.challenging_emotion,
                &self.challenging_gesture,
            ),
        };
        let speech = lines.get(line % lines.len().max(1))?.clone();
        Some(RobotAct {
            speech,
            emotion: some(emotion),
            gesture: some(gesture),
        })
    }

    /// One word of a sequence: the word in this language and the matching face, `QT/<emotion>`.
    pub fn emotion_word(&self, emotion: Emotion) -> RobotAct {
        let index = Emotion::ALL.iter().position(|e| *e == emotion).unwrap_or(0);
        RobotAct {
            speech: self
                .emotion_words
                .get(index)
                .cloned()
                .unwrap_or_else(|| emotion.name().to_string()),
            emotion: Some(emotion.qtrobot_emotion().to_string()),
            gesture: None,
        }
    }

    /// "Well done" or "let's try again", and on the last sequence the goodbye with it.
    pub fn reaction(&self, correct: bool, last: bool) -> RobotAct {
        let (line, emotion) = if correct {
            (&self.well_done, &self.well_done_emotion)
        } else {
            (&self.try_again, &self.try_again_emotion)
        };
        RobotAct {
            speech: if last {
                format!("{line} {}", self.goodbye)
            } else {
                line.clone()
            },
            emotion: some(emotion),
            gesture: if last {
                some(&self.goodbye_gesture)
            } else {
                None
            },
        }
    }

    /// The goodbye alone (a therapist stop).
    pub fn goodbye(&self) -> RobotAct {
        RobotAct {
            speech: self.goodbye.clone(),
            emotion: None,
            gesture: some(&self.goodbye_gesture),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn language_parameter_chooses_the_lines() {
        let en = Utterances::from_params(&LineParams::default());
        let de = Utterances::from_params(&LineParams {
            language: "de".into(),
            ..Default::default()
        });
        assert_eq!(en.emotion_word(Emotion::Sad).speech, "sad");
        assert_eq!(de.emotion_word(Emotion::Sad).speech, "traurig");
        assert_eq!(
            de.emotion_word(Emotion::Sad).emotion.as_deref(),
            Some("QT/sad")
        );
        assert_eq!(de.reaction(true, false).speech, "Gut gemacht!");
        assert!(
            en.reaction(false, true)
                .speech
                .starts_with("Let's try again. That was")
        );
        assert!(en.feedback(Feedback::None, 0).is_none());
        let c = de.feedback(Feedback::Challenging, 3).expect("a line");
        assert_eq!(c.speech, LineParams::default().challenging_de[1]);
        assert_eq!(c.gesture.as_deref(), Some("QT/challenge"));
    }
}
