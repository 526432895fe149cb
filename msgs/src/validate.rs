//! Checks a received message against the ranges its `.msg` file documents, so a node can drop
//! nonsense (level 4, 31 features, an unknown command) with a reason instead of acting on it.

use crate::messages::*;
use crate::services::*;
use sequence_game::answer::{MAX_RESPONSE_TIME_S, MAX_SEQUENCE_LENGTH, parse_emotions};
use sequence_game::{Level, State};

/// Why a message was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}: {reason}")]
pub struct InvalidMessage {
    pub message: &'static str,
    pub reason: String,
}

/// A message that can be checked after decoding.
pub trait Validate {
    fn validate(&self) -> Result<(), InvalidMessage>;
}

/// Longest id string we accept (session, user, face ids).
pub const MAX_ID_LEN: usize = 128;

fn fail<T>(message: &'static str, reason: impl Into<String>) -> Result<T, InvalidMessage> {
    Err(InvalidMessage {
        message,
        reason: reason.into(),
    })
}

fn check_id(
    message: &'static str,
    field: &str,
    id: &str,
    required: bool,
) -> Result<(), InvalidMessage> {
    if required && id.is_empty() {
        return fail(message, format!("{field} is empty"));
    }
    if id.len() > MAX_ID_LEN || id.chars().any(char::is_control) {
        return fail(
            message,
            format!("{field} is longer than {MAX_ID_LEN} bytes or has control characters"),
        );
    }
    Ok(())
}

fn check_range<T: PartialOrd + std::fmt::Display + Copy>(
    message: &'static str,
    field: &str,
    v: T,
    low: T,
    high: T,
) -> Result<(), InvalidMessage> {
    if v < low || v > high {
        return fail(message, format!("{field} = {v} is outside {low}..={high}"));
    }
    Ok(())
}

fn check_unit(
    message: &'static str,
    field: &str,
    v: f32,
    low: f32,
    high: f32,
) -> Result<(), InvalidMessage> {
    if !v.is_finite() || v < low || v > high {
        return fail(
            message,
            format!("{field} = {v} is not a number in [{low}, {high}]"),
        );
    }
    Ok(())
}

/// A response time or task timeout: seconds in 0..=3600, as the answer rules say.
fn check_response_time(message: &'static str, field: &str, v: f32) -> Result<(), InvalidMessage> {
    check_unit(message, field, v, 0.0, MAX_RESPONSE_TIME_S as f32)
}

fn check_emotions(
    message: &'static str,
    field: &str,
    words: &[String],
) -> Result<(), InvalidMessage> {
    if words.len() > MAX_SEQUENCE_LENGTH {
        return fail(
            message,
            format!(
                "{field} has {} emotions, at most {MAX_SEQUENCE_LENGTH} allowed",
                words.len()
            ),
        );
    }
    // The answer rules' own message names the word, as `answer[i]`; name the field here.
    parse_emotions(words).map(|_| ()).or_else(|e| {
        fail(
            message,
            e.to_string().replacen("answer[", &format!("{field}["), 1),
        )
    })
}

impl BehaviourState {
    /// The validated game state.
    pub fn to_state(&self) -> Result<State, InvalidMessage> {
        State::new(
            self.level.into(),
            self.feedback.into(),
            self.previous_score.into(),
        )
        .or_else(|e| fail("BehaviourState", e.to_string()))
    }

    pub fn from_state(s: State) -> Self {
        BehaviourState {
            level: s.level,
            feedback: s.feedback as u8,
            previous_score: s.previous_score,
        }
    }
}

impl Validate for BehaviourState {
    fn validate(&self) -> Result<(), InvalidMessage> {
        self.to_state().map(|_| ())
    }
}

impl Validate for OpenFaceFeatures {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "OpenFaceFeatures";
        check_id(M, "face_id", &self.face_id, false)?;
        if self.features.len() != usize::from(Self::FEATURE_COUNT) {
            return fail(
                M,
                format!(
                    "has {} features, expected {}",
                    self.features.len(),
                    Self::FEATURE_COUNT
                ),
            );
        }
        if !self.confidence.is_finite() {
            return fail(M, "confidence is not a number");
        }
        if self.success
            && let Some(i) = self.features.iter().position(|f| !f.is_finite())
        {
            return fail(
                M,
                format!(
                    "feature {} ({}) is {}",
                    i,
                    crate::OPENFACE_FEATURES[i],
                    self.features[i]
                ),
            );
        }
        Ok(())
    }
}

impl Validate for EngagementEstimate {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "EngagementEstimate";
        check_range(M, "label", self.label, -1, 1)?;
        if self.label != Self::MISSING {
            check_unit(M, "probability", self.probability, 0.0, 1.0)?;
        }
        Ok(())
    }
}

impl Validate for ExpectedEngagement {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "ExpectedEngagement";
        check_id(M, "source", &self.source, false)?;
        check_unit(M, "mean", self.mean, -1.0, 1.0)?;
        check_unit(M, "smoothed", self.smoothed, -1.0, 1.0)?;
        if self.window_end.to_nanos() < self.window_start.to_nanos() {
            return fail(M, "window_end is before window_start");
        }
        Ok(())
    }
}

impl Validate for TherapistCommand {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "TherapistCommand";
        check_range(
            M,
            "command",
            self.command,
            Self::START,
            Self::ACCEPT_PROPOSAL,
        )?;
        check_id(M, "session_id", &self.session_id, true)?;
        check_id(M, "user_id", &self.user_id, self.command == Self::START)?;
        check_range(M, "user_model_cluster", self.user_model_cluster, -1, 63)?;
        if self.command == Self::OVERRIDE_LEVEL {
            check_range(M, "level", self.level, 1, 3)?;
        }
        Ok(())
    }
}

impl Validate for ActionProposal {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "ActionProposal";
        check_id(M, "session_id", &self.session_id, true)?;
        check_range(M, "step", self.step, 1, 10)?;
        self.state
            .validate()
            .or_else(|e| fail(M, format!("state: {}", e.reason)))?;
        check_range(M, "status", self.status, Self::PROPOSED, Self::WITHDRAWN)?;
        check_range(M, "action", self.action, 0, 4)?;
        check_range(M, "level", self.level, 1, 3)?;
        check_range(M, "feedback", self.feedback, 0, 2)?;
        // Settled and played: what played is an action too.
        if matches!(
            self.status,
            Self::ACCEPTED | Self::REPLACED | Self::TIMED_OUT
        ) {
            check_range(M, "played_action", self.played_action, 0, 4)?;
            check_range(M, "played_level", self.played_level, 1, 3)?;
            check_range(M, "played_feedback", self.played_feedback, 0, 2)?;
        }
        if !(self.temperature.is_finite() && self.temperature > 0.0) {
            return fail(
                M,
                format!("temperature {} is not positive", self.temperature),
            );
        }
        if !(self.success_std.is_finite() && (self.success_std >= 0.0 || self.success_std == -1.0))
        {
            return fail(
                M,
                format!("success_std {} is not >= 0 or -1", self.success_std),
            );
        }
        if !(self.countdown.is_finite() && self.countdown >= 0.0) {
            return fail(M, format!("countdown {} is not >= 0", self.countdown));
        }
        if !(self.response_time.is_finite() && self.response_time >= 0.0) {
            return fail(
                M,
                format!("response_time {} is not >= 0", self.response_time),
            );
        }
        Ok(())
    }
}

impl Validate for GameState {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "GameState";
        check_range(M, "phase", self.phase, Self::IDLE, Self::EMERGENCY_STOPPED)?;
        check_range(M, "sequence_index", self.sequence_index, 0, 10)?;
        check_range(M, "level", self.level, 0, 3)?;
        check_range(M, "feedback", self.feedback, 0, 2)?;
        check_range(M, "last_score", self.last_score, -3, 3)?;
        check_range(M, "sequences_planned", self.sequences_planned, 0, 10)?;
        check_id(M, "command_session_id", &self.command_session_id, false)?;
        check_range(
            M,
            "command_outcome",
            self.command_outcome,
            Self::COMMAND_NONE,
            Self::COMMAND_ALREADY_CARRIED_OUT,
        )
    }
}

impl Validate for SequenceResult {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "SequenceResult";
        check_id(M, "session_id", &self.session_id, true)?;
        check_id(M, "user_id", &self.user_id, false)?;
        check_range(M, "sequence_index", self.sequence_index, 1, 10)?;
        check_range(M, "sequences_planned", self.sequences_planned, 1, 10)?;
        if self.sequence_index > self.sequences_planned {
            return fail(
                M,
                format!(
                    "sequence_index {} is past the session's {} sequences",
                    self.sequence_index, self.sequences_planned
                ),
            );
        }
        self.state
            .validate()
            .or_else(|e| fail(M, format!("state: {}", e.reason)))?;
        check_range(M, "action", self.action, 0, 4)?;
        check_range(M, "level", self.level, 1, 3)?;
        check_range(M, "feedback", self.feedback, 0, 2)?;
        check_emotions(M, "sequence", &self.sequence)?;
        check_emotions(M, "answer", &self.answer)?;
        if Level::new(self.level.into()).map(Level::sequence_length) != Ok(self.sequence.len()) {
            return fail(
                M,
                format!(
                    "sequence has {} emotions for level {}",
                    self.sequence.len(),
                    self.level
                ),
            );
        }
        if self.outcome != 1 && self.outcome != -1 {
            return fail(M, format!("outcome = {} is not 1 or -1", self.outcome));
        }
        check_unit(M, "engagement", self.engagement, -1.0, 1.0)?;
        if self.engagement_period_start.to_nanos() > self.engagement_period_end.to_nanos() {
            return fail(
                M,
                "engagement_period_start is after engagement_period_end".to_string(),
            );
        }
        if let Some(e) = self
            .engagement_per_second
            .iter()
            .find(|e| !(e.is_finite() && (-1.0..=1.0).contains(*e)))
        {
            return fail(M, format!("engagement_per_second holds {e}"));
        }
        check_response_time(M, "response_time", self.response_time)
    }
}

impl Validate for TabletTask {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "TabletTask";
        check_id(M, "session_id", &self.session_id, true)?;
        if Level::from_sequence_length(self.length.into()).is_err() {
            return fail(M, format!("length = {} is not 3, 5 or 7", self.length));
        }
        check_emotions(M, "choices", &self.choices)?;
        check_response_time(M, "timeout", self.timeout)
    }
}

impl Validate for TabletAnswer {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "TabletAnswer";
        check_id(M, "session_id", &self.session_id, true)?;
        check_emotions(M, "answer", &self.answer)?;
        check_response_time(M, "response_time", self.response_time)
    }
}

impl Validate for Decision {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "Decision";
        self.state
            .validate()
            .or_else(|e| fail(M, format!("state: {}", e.reason)))?;
        check_range(M, "step", self.step, 1, 10)?;
        check_range(M, "action", self.action, 0, 4)?;
        check_range(M, "level", self.level, 1, 3)?;
        check_range(M, "feedback", self.feedback, 0, 2)?;
        if self.q_values.len() != 5 || self.q_values.iter().any(|q| !q.is_finite()) {
            return fail(M, "q_values must be 5 finite numbers");
        }
        check_range(M, "baseline_action", self.baseline_action, 0, 4)?;
        let levels = [
            ("belief_success", &self.belief_success, 0.0, 1.0),
            ("belief_success_sd", &self.belief_success_sd, 0.0, f64::MAX),
            ("belief_engagement", &self.belief_engagement, -1.0, 1.0),
            (
                "belief_engagement_sd",
                &self.belief_engagement_sd,
                0.0,
                f64::MAX,
            ),
        ];
        for (field, values, lo, hi) in levels {
            let expected = if self.planned_on_belief { 3 } else { 0 };
            if values.len() != expected || values.iter().any(|v| !(lo..=hi).contains(v)) {
                return fail(
                    M,
                    format!(
                        "{field} must hold {expected} numbers in [{lo}, {hi}] (planned_on_belief \
                         {})",
                        self.planned_on_belief
                    ),
                );
            }
        }
        Ok(())
    }
}

impl Validate for UserModelInfo {
    fn validate(&self) -> Result<(), InvalidMessage> {
        if self.clusters.len() != self.cluster_sizes.len() {
            return fail(
                "UserModelInfo",
                "clusters and cluster_sizes differ in length",
            );
        }
        Ok(())
    }
}

impl Validate for Heartbeat {
    fn validate(&self) -> Result<(), InvalidMessage> {
        check_id("Heartbeat", "node_name", &self.node_name, true)
    }
}

impl Validate for crate::hri_msgs::EngagementLevel {
    fn validate(&self) -> Result<(), InvalidMessage> {
        check_range(
            "EngagementLevel",
            "level",
            self.level,
            Self::UNKNOWN,
            Self::DISENGAGING,
        )
    }
}

impl Validate for crate::hri_msgs::IdsList {
    fn validate(&self) -> Result<(), InvalidMessage> {
        for id in &self.ids {
            check_id("IdsList", "ids[]", id, true)?;
        }
        Ok(())
    }
}

/// QTrobot's service halves: any text and name; a gesture's speed a finite factor.
macro_rules! valid_as_is {
    ($($t:ty),*) => {$(
        impl Validate for $t {
            fn validate(&self) -> Result<(), InvalidMessage> {
                Ok(())
            }
        }
    )*};
}
valid_as_is!(
    crate::qt_robot_interface::SpeechSayRequest,
    crate::qt_robot_interface::SpeechSayResponse,
    crate::qt_robot_interface::SpeechStopRequest,
    crate::qt_robot_interface::SpeechStopResponse,
    crate::qt_robot_interface::EmotionShowRequest,
    crate::qt_robot_interface::EmotionShowResponse,
    crate::qt_robot_interface::GesturePlayResponse,
    crate::qtrobot_interfaces::TtsEngineSayTextRequest,
    crate::qtrobot_interfaces::TtsEngineSayTextResponse,
    crate::qtrobot_interfaces::TtsEngineCancelRequest,
    crate::qtrobot_interfaces::TtsEngineCancelResponse,
    crate::qtrobot_interfaces::FaceEmotionShowRequest,
    crate::qtrobot_interfaces::FaceEmotionShowResponse,
    crate::qtrobot_interfaces::GestureFilePlayRequest,
    crate::qtrobot_interfaces::GestureFilePlayResponse
);

impl Validate for crate::qt_robot_interface::GesturePlayRequest {
    fn validate(&self) -> Result<(), InvalidMessage> {
        if !(self.speed.is_finite() && self.speed >= 0.0) {
            return fail(
                "GesturePlay request",
                format!("speed = {} is not a factor >= 0", self.speed),
            );
        }
        Ok(())
    }
}

impl Validate for crate::std_msgs::StringMsg {
    fn validate(&self) -> Result<(), InvalidMessage> {
        Ok(())
    }
}

impl Validate for crate::std_msgs::BoolMsg {
    fn validate(&self) -> Result<(), InvalidMessage> {
        Ok(())
    }
}

impl Validate for PredictUserRequest {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "PredictUser request";
        check_range(M, "cluster", self.cluster, 0, 63)?;
        check_range(M, "level", self.level, 1, 3)?;
        check_range(M, "feedback", self.feedback, 0, 2)?;
        check_range(M, "previous_score", self.previous_score, -3, 3)?;
        if self.outcome != 1 && self.outcome != -1 {
            return fail(M, format!("outcome = {} is not 1 or -1", self.outcome));
        }
        Ok(())
    }
}

impl Validate for AssignClusterRequest {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "AssignCluster request";
        if self.user_vector.len() != 6 {
            return fail(
                M,
                format!(
                    "user_vector has {} values, expected 6",
                    self.user_vector.len()
                ),
            );
        }
        for (i, v) in self.user_vector.iter().enumerate() {
            let (low, high) = if i % 2 == 0 { (0.0, 1.0) } else { (-1.0, 1.0) };
            if !v.is_finite() || *v < low || *v > high {
                return fail(
                    M,
                    format!("user_vector[{i}] = {v} is outside [{low}, {high}]"),
                );
            }
        }
        Ok(())
    }
}

impl Validate for DecideActionRequest {
    fn validate(&self) -> Result<(), InvalidMessage> {
        const M: &str = "DecideAction request";
        check_id(M, "session_id", &self.session_id, true)?;
        check_id(M, "user_id", &self.user_id, false)?;
        check_range(M, "user_model_cluster", self.user_model_cluster, -1, 63)?;
        check_range(M, "step", self.step, 1, 10)?;
        if self.after_sequence >= self.step {
            return fail(
                M,
                format!(
                    "after_sequence {} is not before step {}",
                    self.after_sequence, self.step
                ),
            );
        }
        let state = self
            .state
            .to_state()
            .or_else(|e| fail(M, format!("state: {}", e.reason)))?;
        if (self.step == 1) != state.is_start() {
            return fail(
                M,
                format!(
                    "step {} does not fit state {state}: only step 1 starts from (0, 0, 0)",
                    self.step
                ),
            );
        }
        Ok(())
    }
}

impl Validate for PredictUserResponse {
    fn validate(&self) -> Result<(), InvalidMessage> {
        Ok(())
    }
}
impl Validate for AssignClusterResponse {
    fn validate(&self) -> Result<(), InvalidMessage> {
        Ok(())
    }
}
impl Validate for DecideActionResponse {
    fn validate(&self) -> Result<(), InvalidMessage> {
        if self.ok {
            self.decision.validate()
        } else {
            Ok(())
        }
    }
}
