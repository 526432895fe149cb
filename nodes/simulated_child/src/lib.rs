//! The simulated child, sans-IO: it follows the game through `GameState`, "hears" the sequence
//! through the robot's emotion topic, answers each `TabletTask` right with probability
//! F^p(L, F, PS) of its user-model cluster after a realistic delay, and shows the camera a face
//! at 30 fps whose engagement follows F^e(L, F, PS, O) while the robot talks and drops while it
//! looks down at the tablet. Faces come from the engagement classifier's SYNTHETIC generator, so
//! the real classifier turns them back into engagement: a whole session exercises every node.

use openface::synthetic::{SyntheticSpec, generate};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{GameState, OpenFaceFeatures, TabletAnswer, TabletTask};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sequence_game::{Emotion, Feedback, Level, ModelInput, Outcome, UserModelTable};
use std::collections::BTreeSet;

/// How the simulated child behaves. Defaults follow the study (REFERENCE.md).
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ChildParams {
    /// The user-model file whose cluster drives the child.
    pub user_model_file: String,
    /// The cluster C_k the child behaves like.
    pub cluster: i64,
    /// Seed of every draw (outcomes, delays, faces).
    pub seed: i64,
    /// Camera frames per second.
    pub fps: f64,
    /// Mean answer time in seconds for levels 1, 2, 3 (the study: 8.5, 13.3, 16.5).
    pub answer_time_mean_s: Vec<f64>,
    /// Spread of answer times as a fraction of the mean (log-normal).
    pub answer_time_spread: f64,
    /// Multiplies every delay, so a simulated session can run faster than real time.
    pub time_scale: f64,
    /// Expected engagement while the child looks down at the tablet to answer.
    pub engagement_while_answering: f64,
    /// Mean length (s) of a stretch of looking at or away from the robot.
    pub gaze_dwell_s: f64,
    /// Share of frames where OpenFace loses the face.
    pub face_lost_rate: f64,
    /// OpenFace face id and camera frame.
    pub face_id: String,
    pub camera_frame: String,
}

impl Default for ChildParams {
    fn default() -> Self {
        ChildParams {
            user_model_file: "nodes/user_model/models/migrave_study_c2.json".into(),
            cluster: 0,
            seed: 7,
            fps: 30.0,
            answer_time_mean_s: vec![8.5, 13.3, 16.5],
            answer_time_spread: 0.3,
            time_scale: 1.0,
            engagement_while_answering: -0.6,
            gaze_dwell_s: 0.5,
            face_lost_rate: 0.02,
            face_id: "0".into(),
            camera_frame: "camera_color_optical_frame".into(),
        }
    }
}

/// A parameter the child cannot work with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChildError {
    #[error("simulated_child parameter {key}: {reason}")]
    Parameter { key: &'static str, reason: String },
}

impl ChildParams {
    pub fn validate(&self) -> Result<(), ChildError> {
        let bad = |key, reason: &str| {
            Err(ChildError::Parameter {
                key,
                reason: reason.into(),
            })
        };
        if !(self.fps.is_finite() && self.fps > 0.0 && self.fps <= 240.0) {
            return bad("fps", "must be in (0, 240]");
        }
        if self.answer_time_mean_s.len() != 3
            || self
                .answer_time_mean_s
                .iter()
                .any(|t| !(t.is_finite() && *t > 0.0))
        {
            return bad(
                "answer_time_mean_s",
                "must be 3 positive seconds (levels 1, 2, 3)",
            );
        }
        if !(self.answer_time_spread.is_finite() && (0.0..=2.0).contains(&self.answer_time_spread))
        {
            return bad("answer_time_spread", "must be in [0, 2]");
        }
        if !(self.time_scale.is_finite() && self.time_scale > 0.0) {
            return bad("time_scale", "must be positive");
        }
        if !(-1.0..=1.0).contains(&self.engagement_while_answering) {
            return bad("engagement_while_answering", "must be in [-1, 1]");
        }
        if !(self.gaze_dwell_s.is_finite() && self.gaze_dwell_s > 0.0) {
            return bad("gaze_dwell_s", "must be positive");
        }
        if !(0.0..1.0).contains(&self.face_lost_rate) {
            return bad("face_lost_rate", "must be in [0, 1)");
        }
        Ok(())
    }
}

/// What the child does.
#[derive(Debug, Clone, PartialEq)]
pub enum ChildOutput {
    Frame(OpenFaceFeatures),
    Answer(TabletAnswer),
}

/// The child's plan for the sequence the robot is presenting.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Plan {
    session_sequence: (u64, u8),
    outcome: Outcome,
    engagement: f64,
}

/// The simulated child.
pub struct SimulatedChild {
    params: ChildParams,
    model: UserModelTable,
    rng: ChaCha8Rng,
    engaged_faces: Vec<[f32; 32]>,
    away_faces: Vec<[f32; 32]>,
    face_cursor: [usize; 2],
    session_key: u64,
    session_id: String,
    phase: u8,
    heard: Vec<Emotion>,
    plan: Option<Plan>,
    answered: BTreeSet<(String, u32)>,
    pending: Option<(i64, TabletAnswer)>,
    target_engagement: f64,
    looking: bool,
    frames_left_in_stretch: u32,
    next_frame_ns: Option<i64>,
}

impl SimulatedChild {
    pub fn new(params: ChildParams, model: UserModelTable) -> Result<Self, ChildError> {
        params.validate()?;
        let seed = params.seed as u64;
        // One synthetic person, frames without label noise, split by what the face does.
        let table = generate(&SyntheticSpec {
            participants: 1,
            frames_per_participant: 3000,
            fps: params.fps,
            label_noise: 0.0,
            seed: seed ^ 0x5eed,
        });
        let mut engaged_faces = Vec::new();
        let mut away_faces = Vec::new();
        for (row, label) in table.rows.iter().zip(&table.labels) {
            let face: [f32; 32] = std::array::from_fn(|i| row[i] as f32);
            if *label > 0 {
                engaged_faces.push(face)
            } else {
                away_faces.push(face)
            }
        }
        if engaged_faces.is_empty() || away_faces.is_empty() {
            return Err(ChildError::Parameter {
                key: "seed",
                reason: "the face generator gave one kind of face only".into(),
            });
        }
        Ok(SimulatedChild {
            rng: ChaCha8Rng::seed_from_u64(seed),
            params,
            model,
            engaged_faces,
            away_faces,
            face_cursor: [0, 0],
            session_key: 0,
            session_id: String::new(),
            phase: GameState::IDLE,
            heard: Vec::new(),
            plan: None,
            answered: BTreeSet::new(),
            pending: None,
            target_engagement: 0.0,
            looking: true,
            frames_left_in_stretch: 0,
            next_frame_ns: None,
        })
    }

    /// The engagement the face currently aims at (for logs and tests).
    pub fn target_engagement(&self) -> f64 {
        self.target_engagement
    }

    /// Follows the game: when the robot starts presenting a sequence, decide how it will go.
    pub fn on_game_state(&mut self, state: &GameState) {
        if state.session_id != self.session_id {
            self.session_id = state.session_id.clone();
            self.session_key = sequence_game::stable_id_hash(&state.session_id);
            self.plan = None;
        }
        let presenting = matches!(
            state.phase,
            GameState::GIVING_FEEDBACK | GameState::SAYING_SEQUENCE
        );
        if state.phase == GameState::SAYING_SEQUENCE && self.phase != GameState::SAYING_SEQUENCE {
            self.heard.clear();
        }
        self.phase = state.phase;
        let key = (self.session_key, state.sequence_index);
        if presenting && self.plan.is_none_or(|p| p.session_sequence != key) {
            let (Ok(level), Ok(feedback)) = (
                Level::new(state.level.into()),
                Feedback::new(state.feedback.into()),
            ) else {
                return;
            };
            let Ok(input) = ModelInput::new(level, feedback, state.last_score) else {
                return;
            };
            let p = self.model.success(input).mean;
            let outcome = Outcome::from_correct(self.rng.random::<f64>() <= p);
            let engagement = self.model.engagement(input, outcome).mean;
            self.plan = Some(Plan {
                session_sequence: key,
                outcome,
                engagement,
            });
            self.target_engagement = engagement;
        }
        match state.phase {
            GameState::WAITING_FOR_ANSWER => {
                self.target_engagement = self.params.engagement_while_answering
            }
            _ if presenting => self.target_engagement = self.plan.map_or(0.0, |p| p.engagement),
            _ => {}
        }
    }

    /// The robot showed an emotion (`QT/happy` ...): the child remembers the sequence.
    pub fn on_robot_emotion(&mut self, shown: &str) {
        if self.phase != GameState::SAYING_SEQUENCE {
            return;
        }
        if let Ok(e) = shown.trim_start_matches("QT/").parse::<Emotion>() {
            self.heard.push(e);
        }
    }

    /// A task on the tablet: answer it once, after a delay.
    pub fn on_task(&mut self, task: &TabletTask, now_ns: i64) {
        let key = (task.session_id.clone(), task.sequence_id);
        if self.answered.contains(&key)
            || self.pending.as_ref().is_some_and(|(_, a)| {
                a.sequence_id == task.sequence_id && a.session_id == task.session_id
            })
        {
            return;
        }
        let length = usize::from(task.length);
        let level_index = (length.saturating_sub(1) / 2).clamp(1, 3) - 1;
        let outcome = self.plan.map_or(Outcome::Failure, |p| p.outcome);
        let mut answer: Vec<Emotion> = self
            .heard
            .iter()
            .rev()
            .take(length)
            .rev()
            .copied()
            .collect();
        while answer.len() < length {
            answer.push(Emotion::ALL[self.rng.random_range(0..4)]);
        }
        if outcome == Outcome::Failure {
            // Get one or two places wrong.
            let mistakes = 1 + usize::from(length > 3 && self.rng.random_bool(0.4));
            for _ in 0..mistakes {
                let at = self.rng.random_range(0..length);
                let shift = self.rng.random_range(1..4);
                let idx = Emotion::ALL
                    .iter()
                    .position(|e| *e == answer[at])
                    .unwrap_or(0);
                answer[at] = Emotion::ALL[(idx + shift) % 4];
            }
        }
        let mean = self.params.answer_time_mean_s[level_index];
        let z: f64 = {
            let u1 = 1.0 - self.rng.random::<f64>();
            let u2 = self.rng.random::<f64>();
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        };
        let sigma = self.params.answer_time_spread;
        let seconds = (mean * (sigma * z - sigma * sigma / 2.0).exp()).clamp(1.0, 5.0 * mean)
            * self.params.time_scale;
        let due = now_ns + (seconds * 1e9) as i64;
        let reply = TabletAnswer {
            header: Header::at(Time::from_nanos(due)),
            session_id: task.session_id.clone(),
            sequence_id: task.sequence_id,
            answer: answer.iter().map(|e| e.name().to_string()).collect(),
            response_time: seconds as f32,
        };
        self.pending = Some((due, reply));
    }

    /// Everything due up to `now_ns`: camera frames at the frame rate and a due answer.
    pub fn poll(&mut self, now_ns: i64) -> Vec<ChildOutput> {
        let mut out = Vec::new();
        let period = (1e9 / self.params.fps) as i64;
        let mut t = self.next_frame_ns.unwrap_or(now_ns);
        // After a stall, do not flood: skip frames older than one second.
        if now_ns - t > 1_000_000_000 {
            t = now_ns - (now_ns - t) % period;
        }
        while t <= now_ns {
            out.push(ChildOutput::Frame(self.frame(t)));
            t += period;
        }
        self.next_frame_ns = Some(t);
        if let Some((due, _)) = &self.pending
            && *due <= now_ns
            && let Some((_, answer)) = self.pending.take()
        {
            self.answered
                .insert((answer.session_id.clone(), answer.sequence_id));
            out.push(ChildOutput::Answer(answer));
        }
        out
    }

    /// When `poll` next has something to do.
    pub fn next_wakeup(&self) -> Option<i64> {
        let frame = self.next_frame_ns;
        match (&self.pending, frame) {
            (Some((due, _)), Some(f)) => Some((*due).min(f)),
            (Some((due, _)), None) => Some(*due),
            (None, f) => f,
        }
    }

    fn frame(&mut self, stamp_ns: i64) -> OpenFaceFeatures {
        if self.frames_left_in_stretch == 0 {
            // Look at the robot with probability (1 + E) / 2 for a stretch of about
            // gaze_dwell_s: the expected per-second label mean is then E.
            let p_look = ((1.0 + self.target_engagement) / 2.0).clamp(0.0, 1.0);
            self.looking = self.rng.random_bool(p_look);
            let mean_frames = (self.params.gaze_dwell_s * self.params.fps).max(1.0);
            let u = 1.0 - self.rng.random::<f64>();
            self.frames_left_in_stretch = (-u.ln() * mean_frames).ceil().max(1.0) as u32;
        }
        self.frames_left_in_stretch -= 1;
        let header = Header {
            stamp: Time::from_nanos(stamp_ns),
            frame_id: self.params.camera_frame.clone(),
        };
        if self.rng.random_bool(self.params.face_lost_rate) {
            return OpenFaceFeatures {
                header,
                face_id: self.params.face_id.clone(),
                confidence: 0.0,
                success: false,
                features: vec![0.0; 32],
            };
        }
        let (pool, cursor) = if self.looking {
            (&self.engaged_faces, &mut self.face_cursor[0])
        } else {
            (&self.away_faces, &mut self.face_cursor[1])
        };
        let features = pool[*cursor % pool.len()].to_vec();
        *cursor += 1;
        OpenFaceFeatures {
            header,
            face_id: self.params.face_id.clone(),
            confidence: 0.97,
            success: true,
            features,
        }
    }
}

#[cfg(test)]
mod tests;
