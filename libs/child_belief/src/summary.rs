//! What a belief says per level, in the therapist's terms: the chance of a right answer at
//! that level without feedback and the engagement expected there, each with its posterior
//! standard deviation (averaged over the previous scores the level can follow).

use sequence_game::{Feedback, Level, ModelInput, Outcome, UserModelTable};
use serde::{Deserialize, Serialize};

/// The belief at one level.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LevelBelief {
    pub level: u8,
    pub success: f64,
    pub success_sd: f64,
    pub engagement: f64,
    pub engagement_sd: f64,
}

/// Per level, from a predictive table (means, and the standard deviations it carries): the
/// means over PS = −3..3 of P(success | L, no feedback, PS), of E weighted by the outcome's
/// probability, and of their standard deviations.
pub fn level_summary(table: &UserModelTable) -> [LevelBelief; 3] {
    Level::ALL.map(|level| {
        let (mut s, mut ssd, mut e, mut esd) = (0.0, 0.0, 0.0, 0.0);
        for ps in -3i8..=3 {
            let input = ModelInput {
                level,
                feedback: Feedback::None,
                previous_score: ps,
            };
            let p = table.success(input);
            s += p.mean;
            ssd += p.std;
            for o in Outcome::ALL {
                let po = match o {
                    Outcome::Success => p.mean,
                    Outcome::Failure => 1.0 - p.mean,
                };
                let x = table.engagement(input, o);
                e += po * x.mean;
                esd += po * x.std;
            }
        }
        LevelBelief {
            level: level.get(),
            success: s / 7.0,
            success_sd: ssd / 7.0,
            engagement: e / 7.0,
            engagement_sd: esd / 7.0,
        }
    })
}
