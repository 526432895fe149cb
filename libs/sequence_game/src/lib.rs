//! The vocabulary of the emotion-sequence memorisation game, shared by every node: difficulty
//! levels, robot feedback, the MDP state (L, F, PS) and the actions a1..a5 of the paper's
//! behaviour model, the outcome of a sequence and the four emotions.
//!
//! Numbering follows the authors' implementation (`../shared/REFERENCE.md`): levels 1..3 are
//! sequence lengths 3/5/7; feedback 0 none, 1 encouraging, 2 challenging; the start state is
//! (0, 0, 0); action indices 0..2 set the level, 3 encourages and 4 challenges.

use serde::{Deserialize, Serialize};

pub mod answer;
pub mod user_model_table;
pub use answer::{AnswerError, Score, parse_answer, score};
use std::fmt;
pub use user_model_table::{ModelInput, Prediction, UserModelTable};

/// Number of difficulty levels `l` in the paper.
pub const LEVEL_COUNT: usize = 3;
/// Number of actions `l + 2`.
pub const ACTION_COUNT: usize = LEVEL_COUNT + 2;
/// Number of states: L x F x PS plus the start state.
pub const STATE_COUNT: usize = 1 + LEVEL_COUNT * 3 * 7;
/// Sequences in one session (the paper's omega).
pub const SEQUENCES_PER_SESSION: usize = 10;

/// A value that does not belong to the game's vocabulary.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GameError {
    #[error("level {0} is outside 1..=3")]
    Level(i64),
    #[error("sequence length {0} is not 3, 5 or 7")]
    SequenceLength(i64),
    #[error("feedback {0} is not 0 (none), 1 (encouraging) or 2 (challenging)")]
    Feedback(i64),
    #[error("previous score {0} is outside -3..=3")]
    PreviousScore(i64),
    #[error("state (L={level}, F={feedback}, PS={previous_score}) is not in the state space")]
    State {
        level: i64,
        feedback: i64,
        previous_score: i64,
    },
    #[error("action index {0} is outside 0..=4")]
    Action(i64),
    #[error("outcome {0} is not 1 (success) or -1 (failure)")]
    Outcome(i64),
    #[error("emotion {0:?} is not one of happy, disgusted, sad, angry")]
    Emotion(String),
    #[error("state index {0} is outside 0..{STATE_COUNT}")]
    StateIndex(usize),
}

/// Difficulty level L: 1, 2 or 3, played as sequences of 3, 5 or 7 emotions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(try_from = "u8", into = "u8")]
pub struct Level(u8);

impl Level {
    pub const ONE: Level = Level(1);
    pub const TWO: Level = Level(2);
    pub const THREE: Level = Level(3);
    pub const ALL: [Level; LEVEL_COUNT] = [Level::ONE, Level::TWO, Level::THREE];

    pub fn new(level: i64) -> Result<Self, GameError> {
        match level {
            1..=3 => Ok(Level(level as u8)),
            _ => Err(GameError::Level(level)),
        }
    }

    /// The level whose sequences have `length` emotions.
    pub fn from_sequence_length(length: i64) -> Result<Self, GameError> {
        match length {
            3 => Ok(Level::ONE),
            5 => Ok(Level::TWO),
            7 => Ok(Level::THREE),
            _ => Err(GameError::SequenceLength(length)),
        }
    }

    pub fn get(self) -> u8 {
        self.0
    }

    /// Number of emotions in a sequence of this level.
    pub fn sequence_length(self) -> usize {
        2 * self.0 as usize + 1
    }

    /// Zero-based index, for tables.
    pub fn index(self) -> usize {
        self.0 as usize - 1
    }
}

impl TryFrom<u8> for Level {
    type Error = GameError;
    fn try_from(v: u8) -> Result<Self, GameError> {
        Level::new(v.into())
    }
}

impl From<Level> for u8 {
    fn from(l: Level) -> u8 {
        l.0
    }
}

impl fmt::Display for Level {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "L{}", self.0)
    }
}

/// Robot feedback F given before a sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(try_from = "u8", into = "u8")]
pub enum Feedback {
    None = 0,
    Encouraging = 1,
    Challenging = 2,
}

impl Feedback {
    pub const ALL: [Feedback; 3] = [Feedback::None, Feedback::Encouraging, Feedback::Challenging];

    pub fn new(v: i64) -> Result<Self, GameError> {
        match v {
            0 => Ok(Feedback::None),
            1 => Ok(Feedback::Encouraging),
            2 => Ok(Feedback::Challenging),
            _ => Err(GameError::Feedback(v)),
        }
    }

    pub fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        match self {
            Feedback::None => "none",
            Feedback::Encouraging => "encouraging",
            Feedback::Challenging => "challenging",
        }
    }
}

impl TryFrom<u8> for Feedback {
    type Error = GameError;
    fn try_from(v: u8) -> Result<Self, GameError> {
        Feedback::new(v.into())
    }
}

impl From<Feedback> for u8 {
    fn from(f: Feedback) -> u8 {
        f as u8
    }
}

/// Outcome O of one sequence: the child reproduced it exactly, or not.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "i8", into = "i8")]
pub enum Outcome {
    Success,
    Failure,
}

impl Outcome {
    pub const ALL: [Outcome; 2] = [Outcome::Failure, Outcome::Success];

    pub fn new(v: i64) -> Result<Self, GameError> {
        match v {
            1 => Ok(Outcome::Success),
            -1 => Ok(Outcome::Failure),
            _ => Err(GameError::Outcome(v)),
        }
    }

    pub fn from_correct(correct: bool) -> Self {
        if correct {
            Outcome::Success
        } else {
            Outcome::Failure
        }
    }

    /// +1 or -1, as the paper writes O.
    pub fn sign(self) -> i8 {
        match self {
            Outcome::Success => 1,
            Outcome::Failure => -1,
        }
    }

    /// Index for tables: failure 0, success 1.
    pub fn index(self) -> usize {
        match self {
            Outcome::Failure => 0,
            Outcome::Success => 1,
        }
    }

    /// The score CS = L * O that becomes the next state's PS.
    pub fn score(self, level: Level) -> i8 {
        self.sign() * level.get() as i8
    }

    /// The activity result RE of the paper: L on success, -1 on failure.
    pub fn activity_result(self, level: Level) -> f64 {
        match self {
            Outcome::Success => f64::from(level.get()),
            Outcome::Failure => -1.0,
        }
    }
}

impl TryFrom<i8> for Outcome {
    type Error = GameError;
    fn try_from(v: i8) -> Result<Self, GameError> {
        Outcome::new(v.into())
    }
}

impl From<Outcome> for i8 {
    fn from(o: Outcome) -> i8 {
        o.sign()
    }
}

/// MDP state s = (L, F, PS): the level of the sequence just played, the feedback given before
/// it, and the score of the sequence before it. The start of a session is (0, 0, 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct State {
    /// 0 only in the start state, else 1..=3.
    pub level: u8,
    pub feedback: Feedback,
    /// -3..=3; 0 only in the start state (the authors' table keeps PS = 0 for every level).
    pub previous_score: i8,
}

impl State {
    pub const START: State = State {
        level: 0,
        feedback: Feedback::None,
        previous_score: 0,
    };

    /// A validated state; (0, 0, 0) is the start state.
    pub fn new(level: i64, feedback: i64, previous_score: i64) -> Result<Self, GameError> {
        let bad = || GameError::State {
            level,
            feedback,
            previous_score,
        };
        if level == 0 {
            return if feedback == 0 && previous_score == 0 {
                Ok(State::START)
            } else {
                Err(bad())
            };
        }
        let level = Level::new(level).map_err(|_| bad())?;
        let feedback = Feedback::new(feedback).map_err(|_| bad())?;
        if !(-3..=3).contains(&previous_score) {
            return Err(bad());
        }
        Ok(State {
            level: level.get(),
            feedback,
            previous_score: previous_score as i8,
        })
    }

    pub fn is_start(self) -> bool {
        self.level == 0
    }

    /// The level, or `None` in the start state.
    pub fn level(self) -> Option<Level> {
        Level::new(self.level.into()).ok()
    }

    /// Row of this state in a Q-table: start 0, then L-major, F, PS+3.
    pub fn index(self) -> usize {
        match self.level() {
            None => 0,
            Some(l) => {
                1 + l.index() * 21 + self.feedback.index() * 7 + (self.previous_score + 3) as usize
            }
        }
    }

    pub fn from_index(index: usize) -> Result<Self, GameError> {
        if index == 0 {
            return Ok(State::START);
        }
        if index >= STATE_COUNT {
            return Err(GameError::StateIndex(index));
        }
        let i = index - 1;
        State::new(
            (i / 21 + 1) as i64,
            ((i / 7) % 3) as i64,
            (i % 7) as i64 - 3,
        )
    }

    /// Every state, in index order.
    pub fn all() -> impl Iterator<Item = State> {
        (0..STATE_COUNT).filter_map(|i| State::from_index(i).ok())
    }

    /// Actions allowed here: only a1..a3 in the start state (no context for feedback).
    pub fn allowed_actions(self) -> &'static [Action] {
        if self.is_start() {
            &Action::ALL[..LEVEL_COUNT]
        } else {
            &Action::ALL
        }
    }

    /// The state after taking `action` here and seeing `outcome` on the sequence it sets up.
    /// Returns `None` for a feedback action in the start state.
    pub fn next(self, action: Action, outcome: Outcome) -> Option<(State, Level)> {
        let (level, feedback) = action.apply(self)?;
        Some((State::after(level, feedback, outcome), level))
    }

    /// The state after a sequence played at `level` with `feedback` ended in `outcome`: its
    /// level and feedback, and PS = its score L * O.
    pub fn after(level: Level, feedback: Feedback, outcome: Outcome) -> State {
        State {
            level: level.get(),
            feedback,
            previous_score: outcome.score(level),
        }
    }
}

impl fmt::Display for State {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "(L={}, F={}, PS={:+})",
            self.level, self.feedback as u8, self.previous_score
        )
    }
}

/// Robot action a1..a5 (indices 0..4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "u8", into = "u8")]
pub enum Action {
    /// a1..a3: play the next sequence at this level, no feedback.
    SetLevel(Level),
    /// a4: say encouraging feedback and repeat the level.
    Encourage,
    /// a5: say challenging feedback and repeat the level.
    Challenge,
}

impl Action {
    pub const ALL: [Action; ACTION_COUNT] = [
        Action::SetLevel(Level::ONE),
        Action::SetLevel(Level::TWO),
        Action::SetLevel(Level::THREE),
        Action::Encourage,
        Action::Challenge,
    ];

    pub fn new(index: i64) -> Result<Self, GameError> {
        usize::try_from(index)
            .ok()
            .and_then(|i| Action::ALL.get(i).copied())
            .ok_or(GameError::Action(index))
    }

    pub fn index(self) -> usize {
        match self {
            Action::SetLevel(l) => l.index(),
            Action::Encourage => LEVEL_COUNT,
            Action::Challenge => LEVEL_COUNT + 1,
        }
    }

    pub fn is_feedback(self) -> bool {
        matches!(self, Action::Encourage | Action::Challenge)
    }

    /// Level and feedback of the next sequence when taken in `state`; `None` for feedback in
    /// the start state, where there is no level to repeat.
    pub fn apply(self, state: State) -> Option<(Level, Feedback)> {
        match self {
            Action::SetLevel(l) => Some((l, Feedback::None)),
            Action::Encourage => state.level().map(|l| (l, Feedback::Encouraging)),
            Action::Challenge => state.level().map(|l| (l, Feedback::Challenging)),
        }
    }

    /// The action as pages and translations key it: `level_1`, `level_2`, `level_3`,
    /// `encourage`, `challenge`.
    pub fn key(self) -> &'static str {
        match self {
            Action::SetLevel(l) if l == Level::ONE => "level_1",
            Action::SetLevel(l) if l == Level::TWO => "level_2",
            Action::SetLevel(_) => "level_3",
            Action::Encourage => "encourage",
            Action::Challenge => "challenge",
        }
    }

    /// The action in words for a line of text: `level 1` .. `challenge`.
    pub fn label(self) -> String {
        self.key().replace('_', " ")
    }

    /// The paper's name: `a1 level 1` .. `a5 challenge`.
    pub fn name(self) -> &'static str {
        match self {
            Action::SetLevel(l) if l == Level::ONE => "a1 level 1",
            Action::SetLevel(l) if l == Level::TWO => "a2 level 2",
            Action::SetLevel(_) => "a3 level 3",
            Action::Encourage => "a4 encourage",
            Action::Challenge => "a5 challenge",
        }
    }
}

impl TryFrom<u8> for Action {
    type Error = GameError;
    fn try_from(v: u8) -> Result<Self, GameError> {
        Action::new(v.into())
    }
}

impl From<Action> for u8 {
    fn from(a: Action) -> u8 {
        a.index() as u8
    }
}

impl fmt::Display for Action {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The four emotions a sequence is drawn from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Emotion {
    Happy,
    Disgusted,
    Sad,
    Angry,
}

impl Emotion {
    pub const ALL: [Emotion; 4] = [
        Emotion::Happy,
        Emotion::Disgusted,
        Emotion::Sad,
        Emotion::Angry,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Emotion::Happy => "happy",
            Emotion::Disgusted => "disgusted",
            Emotion::Sad => "sad",
            Emotion::Angry => "angry",
        }
    }

    /// The authors' tablet codes (SAD=1, ANGRY=2, DISGUSTED=3, HAPPY=4).
    pub fn migrave_code(self) -> u8 {
        match self {
            Emotion::Sad => 1,
            Emotion::Angry => 2,
            Emotion::Disgusted => 3,
            Emotion::Happy => 4,
        }
    }

    /// QTrobot's emotion animation for this word (`/qt_robot/emotion/show`).
    pub fn qtrobot_emotion(self) -> &'static str {
        match self {
            Emotion::Happy => "QT/happy",
            Emotion::Disgusted => "QT/disgusted",
            Emotion::Sad => "QT/sad",
            Emotion::Angry => "QT/angry",
        }
    }
}

impl std::str::FromStr for Emotion {
    type Err = GameError;
    fn from_str(s: &str) -> Result<Self, GameError> {
        Emotion::ALL
            .into_iter()
            .find(|e| e.name() == s)
            .ok_or_else(|| GameError::Emotion(s.chars().take(40).collect()))
    }
}

impl fmt::Display for Emotion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// FNV-1a of `id`: a stable number for a session or user id (std's hasher is seeded at random),
/// so a seeded draw keyed by an id is the same in every process and release.
pub fn stable_id_hash(id: &str) -> u64 {
    id.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// A session or user id as a file-name stem: anything but ASCII letters, digits, '-', '_' and
/// '.' becomes '_', and no leading '.' (ids may hold any printable character, names may not).
/// One rule, so the files the game manager names are the files a child's tools find. May be
/// empty (an id of dots only); the caller names that case.
pub fn id_file_stem(id: &str) -> String {
    let stem: String = id
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    stem.trim_start_matches('.').to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_id_becomes_a_safe_file_stem() {
        assert_eq!(id_file_stem("../a b"), "_a_b");
        assert_eq!(id_file_stem("child-7_x.y"), "child-7_x.y");
        assert_eq!(id_file_stem("Jörg/1"), "J_rg_1");
        assert_eq!(id_file_stem("..."), "");
    }

    #[test]
    fn state_index_round_trips_over_the_whole_space() {
        let all: Vec<State> = State::all().collect();
        assert_eq!(all.len(), STATE_COUNT);
        for (i, s) in all.iter().enumerate() {
            assert_eq!(s.index(), i);
            assert_eq!(State::from_index(i), Ok(*s));
        }
        assert!(State::from_index(STATE_COUNT).is_err());
    }

    #[test]
    fn start_state_allows_only_level_actions() {
        assert_eq!(State::START.allowed_actions().len(), 3);
        assert!(Action::Encourage.apply(State::START).is_none());
        let s = State::new(2, 0, -2).expect("valid");
        assert_eq!(s.allowed_actions().len(), 5);
        assert_eq!(
            Action::Challenge.apply(s),
            Some((Level::TWO, Feedback::Challenging))
        );
    }

    #[test]
    fn next_state_carries_level_times_outcome() {
        let s = State::new(3, 0, 3).expect("valid");
        let (n, l) = s
            .next(Action::Encourage, Outcome::Failure)
            .expect("allowed");
        assert_eq!(l, Level::THREE);
        assert_eq!(n, State::new(3, 1, -3).expect("valid"));
        assert_eq!(Outcome::Failure.activity_result(Level::THREE), -1.0);
        assert_eq!(Outcome::Success.activity_result(Level::TWO), 2.0);
    }

    #[test]
    fn out_of_range_values_are_named() {
        assert_eq!(
            State::new(4, 0, 1),
            Err(GameError::State {
                level: 4,
                feedback: 0,
                previous_score: 1
            })
        );
        assert!(State::new(0, 1, 0).is_err());
        assert!(State::new(1, 3, 0).is_err());
        assert!(State::new(1, 0, 4).is_err());
        assert_eq!(Action::new(5), Err(GameError::Action(5)));
        assert!(Level::from_sequence_length(4).is_err());
        assert!("joyful".parse::<Emotion>().is_err());
        assert!(serde_json::from_str::<Level>("0").is_err());
        assert_eq!(
            serde_json::from_str::<Action>("4").ok(),
            Some(Action::Challenge)
        );
    }

    #[test]
    fn stable_id_hash_is_fnv_1a() {
        // FNV-1a's published test vectors: the same in every process, unlike std's hasher.
        assert_eq!(stable_id_hash(""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(stable_id_hash("a"), 0xaf63_dc4c_8601_ec8c);
    }

    #[test]
    fn actions_have_one_key_and_label_each() {
        let keys: Vec<_> = Action::ALL.iter().map(|a| a.key()).collect();
        assert_eq!(
            keys,
            ["level_1", "level_2", "level_3", "encourage", "challenge"]
        );
        assert_eq!(Action::SetLevel(Level::TWO).label(), "level 2");
    }
}
