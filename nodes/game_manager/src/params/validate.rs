//! The parameters' checks, group by group, each naming the key at fault; the game manager
//! refuses to start on the first one that fails, in the file's order.

use super::{
    DiskParams, FileParams, GameManagerParams, LineParams, ReliabilityParams, RobotParams,
    SessionParams, SupervisionParams, TimingParams,
};

/// A parameter the game manager cannot work with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("game_manager parameter {key}: {reason}")]
pub struct ParamError {
    pub key: &'static str,
    pub reason: String,
}

fn bad(key: &'static str, reason: impl Into<String>) -> Result<(), ParamError> {
    Err(ParamError {
        key,
        reason: reason.into(),
    })
}

fn seconds(key: &'static str, v: f64, low: f64, high: f64) -> Result<(), ParamError> {
    if !(v.is_finite() && v >= low && v <= high) {
        return bad(
            key,
            format!("{v} is not a number of seconds in [{low}, {high}]"),
        );
    }
    Ok(())
}

impl GameManagerParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        self.session.validate()?;
        self.timing.validate()?;
        self.files.validate()?;
        self.disk.validate()?;
        self.lines.validate()?;
        self.reliability.validate()?;
        self.robot.validate()?;
        self.supervision.validate()
    }
}

impl DiskParams {
    /// The floor under the warning, both sizes; retention's kinds known.
    pub fn validate(&self) -> Result<(), ParamError> {
        let mb = |key, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                bad(key, format!("{v} is not a size in MB (0 or more)"))
            }
        };
        mb("disk_warning_free_mb", self.disk_warning_free_mb)?;
        mb("disk_floor_free_mb", self.disk_floor_free_mb)?;
        mb("retention_budget_mb", self.retention_budget_mb)?;
        if self.disk_floor_free_mb > self.disk_warning_free_mb {
            return bad(
                "disk_floor_free_mb",
                format!(
                    "{} is above disk_warning_free_mb ({}): the page would not warn before a \
                     start is refused",
                    self.disk_floor_free_mb, self.disk_warning_free_mb
                ),
            );
        }
        seconds(
            "disk_check_interval_s",
            self.disk_check_interval_s,
            0.1,
            3600.0,
        )?;
        for kind in &self.retention_removes {
            if crate::retention::Removable::parse(kind).is_none() {
                return bad(
                    "retention_removes",
                    format!("{kind:?} is not \"bags\", \"reports\" or \"logs\""),
                );
            }
        }
        Ok(())
    }
}

impl SessionParams {
    /// Sequences and runs within their ranges.
    pub fn validate(&self) -> Result<(), ParamError> {
        if !(1..=10).contains(&self.sequences_per_session) {
            return bad("sequences_per_session", "must be in 1..=10");
        }
        if !(1..=7).contains(&self.max_identical_in_a_row) {
            return bad("max_identical_in_a_row", "must be in 1..=7");
        }
        Ok(())
    }
}

impl TimingParams {
    /// Every time a number of seconds in its range.
    pub fn validate(&self) -> Result<(), ParamError> {
        seconds(
            "speaking_time_per_emotion_s",
            self.speaking_time_per_emotion_s,
            0.0,
            60.0,
        )?;
        seconds(
            "speaking_time_base_s",
            self.speaking_time_base_s,
            -60.0,
            60.0,
        )?;
        if self.speaking_time_base_s + 3.0 * self.speaking_time_per_emotion_s <= 0.0 {
            return bad(
                "speaking_time_base_s",
                "base + 3 * per_emotion must be positive (the shortest sequence takes time)",
            );
        }
        seconds("intro_time_s", self.intro_time_s, 0.0, 600.0)?;
        seconds("feedback_time_s", self.feedback_time_s, 0.0, 600.0)?;
        seconds("reaction_time_s", self.reaction_time_s, 0.0, 600.0)?;
        if !(self.time_scale.is_finite() && self.time_scale > 0.0 && self.time_scale <= 10.0) {
            return bad(
                "time_scale",
                format!("{} is not in (0, 10]", self.time_scale),
            );
        }
        // The task's timeout is checked with the answer rules' limit by every reader.
        let max = sequence_game::answer::MAX_RESPONSE_TIME_S;
        seconds("answer_timeout_s", self.answer_timeout_s, 0.001, max)?;
        if self.answer_timeout_s * self.time_scale > max {
            return bad(
                "answer_timeout_s",
                "times time_scale must be at most 3600 s",
            );
        }
        seconds("policy_deadline_s", self.policy_deadline_s, 0.001, 60.0)?;
        seconds(
            "policy_startup_wait_s",
            self.policy_startup_wait_s,
            0.0,
            600.0,
        )?;
        seconds("engagement_wait_s", self.engagement_wait_s, 0.0, 10.0)?;
        Ok(())
    }
}

impl FileParams {
    /// A sessions directory named.
    pub fn validate(&self) -> Result<(), ParamError> {
        if self.sessions_dir.trim().is_empty() {
            return bad("sessions_dir", "is empty");
        }
        Ok(())
    }
}

impl LineParams {
    /// A known language, and every line and word there.
    pub fn validate(&self) -> Result<(), ParamError> {
        if !matches!(self.language.as_str(), "en" | "de") {
            return bad(
                "language",
                format!("{:?} is not \"en\" or \"de\"", self.language),
            );
        }
        let lines: [(&'static str, &[String]); 4] = [
            ("encouraging_en", &self.encouraging_en),
            ("encouraging_de", &self.encouraging_de),
            ("challenging_en", &self.challenging_en),
            ("challenging_de", &self.challenging_de),
        ];
        for (key, list) in lines {
            if list.is_empty() || list.iter().any(|l| l.trim().is_empty()) {
                return bad(key, "needs at least one line and no empty lines");
            }
        }
        for (key, words) in [
            ("emotion_words_en", &self.emotion_words_en),
            ("emotion_words_de", &self.emotion_words_de),
        ] {
            if words.len() != 4 || words.iter().any(|w| w.trim().is_empty()) {
                return bad(key, "needs 4 words: happy, disgusted, sad, angry");
            }
        }
        Ok(())
    }
}

impl ReliabilityParams {
    /// Timeouts in range, and each watched node a node, once.
    pub fn validate(&self) -> Result<(), ParamError> {
        seconds("node_loss_timeout_s", self.node_loss_timeout_s, 0.2, 600.0)?;
        seconds(
            "recovery_max_age_s",
            self.recovery_max_age_s,
            0.0,
            30.0 * 86_400.0,
        )?;
        for (i, name) in self.watched_nodes.iter().enumerate() {
            if name.trim().is_empty() || name == "game_manager" {
                return bad(
                    "watched_nodes",
                    format!("{name:?} is not a node the game manager can watch"),
                );
            }
            if self.watched_nodes[..i].contains(name) {
                return bad("watched_nodes", format!("{name:?} is listed twice"));
            }
        }
        Ok(())
    }
}

impl RobotParams {
    /// A known backend, its timings, and the stop namespace a ROS namespace.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.backend()?;
        seconds(
            "robot_call_timeout_s",
            self.robot_call_timeout_s,
            0.1,
            3600.0,
        )?;
        seconds("robot_gesture_speed", self.robot_gesture_speed, 0.0, 10.0)?;
        let ns = &self.qtrobot_ros2_stop_namespace;
        // "" or /name[/name...], each name a ROS name token.
        let namespace = ns.starts_with('/')
            && ns.split('/').skip(1).all(|part| {
                part.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
                    && part.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            });
        if !(ns.is_empty() || namespace) {
            return bad(
                "qtrobot_ros2_stop_namespace",
                format!(
                    "{ns:?} is not a ROS namespace such as \"/qtrobot_stop\" (or \"\" for none)"
                ),
            );
        }
        Ok(())
    }
}

impl SupervisionParams {
    /// Limits that are numbers, and a countdown in range.
    pub fn validate(&self) -> Result<(), ParamError> {
        if !(self.propose_above_temperature.is_finite() && self.propose_above_temperature >= 0.0) {
            return bad(
                "propose_above_temperature",
                format!(
                    "{} is not a temperature >= 0",
                    self.propose_above_temperature
                ),
            );
        }
        if !(self.propose_above_success_std.is_finite() && self.propose_above_success_std >= 0.0) {
            return bad(
                "propose_above_success_std",
                format!(
                    "{} is not a standard deviation >= 0",
                    self.propose_above_success_std
                ),
            );
        }
        seconds(
            "proposal_countdown_s",
            self.proposal_countdown_s,
            0.1,
            3600.0,
        )?;
        Ok(())
    }
}
