//! The simulated child, sans-IO: it follows the game through `GameState`, "hears" the sequence
//! through the robot's emotion topic, answers each `TabletTask` right with probability
//! F^p(L, F, PS) of its user-model cluster after a realistic delay, and shows the camera a face
//! at 30 fps whose engagement follows F^e(L, F, PS, O) while the robot talks and drops while it
//! looks down at the tablet. Faces come from the engagement classifier's SYNTHETIC generator, so
//! the real classifier turns them back into engagement: a whole session exercises every node.
//!
//! Every random draw comes from a stream of its own, keyed by what it belongs to (`Draw`): the
//! answer of a sequence by its session and index, a camera frame by its index on the child's
//! frame clock. So the same seed and the same game give the same answers however many frames a
//! loaded machine let the child publish in between.
//!
//! Its times (`now_ns`, the frame clock, answer delays) are the node's steady clock, which a
//! step of the wall clock does not move; what it stamps (frames, answers) is on the wall clock,
//! that time plus the wall clock's offset ([`SimulatedChild::set_wall_offset`]).

/// The child's run loop on a bus (DDS or in process).
pub mod node;

use openface::synthetic::{SyntheticSpec, generate};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{GamePhase, GameState, OpenFaceFeatures, TabletAnswer, TabletTask};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sequence_game::{Emotion, Feedback, Level, ModelInput, Outcome, UserModelTable};
use std::collections::{BTreeSet, VecDeque};

/// How the simulated child behaves. Defaults follow the study (REFERENCE.md).
#[derive(
    Debug, Clone, serde::Deserialize, serde::Serialize, node_shell::parameters::DescribedParameters,
)]
#[serde(deny_unknown_fields, default)]
pub struct ChildParams {
    /// The user-model file whose cluster drives the child.
    pub user_model_file: String,
    /// The cluster C_k the child behaves like.
    pub cluster: i64,
    /// Seed of every draw (outcomes, mistakes, delays, faces), each kind on its own keyed stream.
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
    /// OpenFace face id of the child's face.
    pub face_id: String,
    /// The camera frame in every frame's header.
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

/// What a random draw belongs to. Each kind draws from a ChaCha8 stream of its own whose key is
/// (seed, kind, what it belongs to), so no draw depends on how many others were made before it:
/// a loaded machine that publishes fewer frames still gives each sequence the same answer, and
/// each frame it does publish the same looks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Draw {
    /// Right or wrong, for (session, sequence index): one uniform against F^p.
    Outcome { session: u64, sequence: u8 },
    /// What the child taps for (session, sequence index): emotions guessed for words it did not
    /// hear, then the places it gets wrong.
    Answer { session: u64, sequence: u8 },
    /// How long the child takes to answer (session, sequence index).
    ResponseTime { session: u64, sequence: u8 },
    /// Camera frame n of the child's frame clock: whether a gaze stretch starts there, where
    /// that stretch looks, whether OpenFace loses the face.
    Frame(u64),
}

impl Draw {
    fn rng(self, seed: u64) -> ChaCha8Rng {
        let (kind, a, b) = match self {
            Draw::Outcome { session, sequence } => (1, session, u64::from(sequence)),
            Draw::Answer { session, sequence } => (2, session, u64::from(sequence)),
            Draw::ResponseTime { session, sequence } => (3, session, u64::from(sequence)),
            Draw::Frame(n) => (4, n, 0),
        };
        // The four words are ChaCha's 256-bit key as they are: distinct keys, distinct streams.
        let mut key = [0u8; 32];
        for (bytes, word) in key.chunks_exact_mut(8).zip([seed, kind, a, b]) {
            bytes.copy_from_slice(&word.to_le_bytes());
        }
        ChaCha8Rng::from_seed(key)
    }
}

/// The child's plan for the sequence the robot is presenting.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Plan {
    session_sequence: (u64, u8),
    outcome: Outcome,
    engagement: f64,
}

/// A task the child is answering: its answer goes out at `due`.
#[derive(Debug, Clone, PartialEq)]
struct PendingAnswer {
    due: i64,
    task: TabletTask,
    response_time_s: f64,
}

/// What one camera frame draws, in this order from its own stream.
struct FrameDraws {
    starts_stretch: bool,
    look: f64,
    lost: f64,
}

/// The longest sequence (level 3): the child remembers this many of the robot's last faces.
const LONGEST_SEQUENCE: usize = 7;

/// The simulated child.
pub struct SimulatedChild {
    params: ChildParams,
    model: UserModelTable,
    seed: u64,
    engaged_faces: Vec<[f32; 32]>,
    away_faces: Vec<[f32; 32]>,
    session_key: u64,
    session_id: String,
    /// The robot's last faces, newest last: the sequence is the last `length` of them.
    heard: VecDeque<Emotion>,
    plan: Option<Plan>,
    answered: BTreeSet<(String, u32)>,
    pending: Option<PendingAnswer>,
    target_engagement: f64,
    looking: bool,
    /// The frame clock: frame n is due at `frame_origin_ns + n * period`.
    frame_origin_ns: Option<i64>,
    next_frame: u64,
    /// The last frame put out, if any.
    last_frame: Option<u64>,
    /// The wall clock minus the steady clock, added to every stamp (0: one clock).
    wall_offset_ns: i64,
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
            seed,
            params,
            model,
            engaged_faces,
            away_faces,
            session_key: 0,
            session_id: String::new(),
            heard: VecDeque::with_capacity(LONGEST_SEQUENCE + 1),
            plan: None,
            answered: BTreeSet::new(),
            pending: None,
            target_engagement: 0.0,
            looking: true,
            frame_origin_ns: None,
            wall_offset_ns: 0,
            next_frame: 0,
            last_frame: None,
        })
    }

    /// The engagement the face currently aims at (for logs and tests).
    pub fn target_engagement(&self) -> f64 {
        self.target_engagement
    }

    /// Follows the game: at the first state of a sequence it sees (feedback, words or the
    /// task), decide how that sequence will go.
    pub fn on_game_state(&mut self, state: &GameState) {
        if state.session_id != self.session_id {
            self.session_id = state.session_id.clone();
            self.session_key = sequence_game::stable_id_hash(&state.session_id);
            self.plan = None;
        }
        let phase = GamePhase::try_from(state.phase).ok();
        let presenting = matches!(
            phase,
            Some(GamePhase::GivingFeedback | GamePhase::SayingSequence)
        );
        let key = (self.session_key, state.sequence_index);
        // The task's own state counts too: GameState keeps only its last sample, so a loaded
        // child may never see the presentation's.
        let of_a_sequence = presenting || phase == Some(GamePhase::WaitingForAnswer);
        if of_a_sequence && self.plan.is_none_or(|p| p.session_sequence != key) {
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
            let draw = Draw::Outcome {
                session: key.0,
                sequence: key.1,
            };
            let outcome = Outcome::from_correct(draw.rng(self.seed).random::<f64>() <= p);
            let engagement = self.model.engagement(input, outcome).mean;
            self.plan = Some(Plan {
                session_sequence: key,
                outcome,
                engagement,
            });
            self.target_engagement = engagement;
        }
        match phase {
            Some(GamePhase::WaitingForAnswer) => {
                self.target_engagement = self.params.engagement_while_answering
            }
            _ if presenting => self.target_engagement = self.plan.map_or(0.0, |p| p.engagement),
            _ => {}
        }
    }

    /// The robot showed a face (`QT/happy` ...): the child remembers the last few. Whatever the
    /// phase: DDS does not order the face after the GameState that announced the words, and
    /// the feedback's face comes before the words, so the sequence is the last `length` faces.
    pub fn on_robot_emotion(&mut self, shown: &str) {
        if let Ok(e) = shown.trim_start_matches("QT/").parse::<Emotion>() {
            if self.heard.len() == LONGEST_SEQUENCE {
                self.heard.pop_front();
            }
            self.heard.push_back(e);
        }
    }

    /// The wall clock's offset from the steady clock now (wall - steady): what the stamps add
    /// to the child's times. The node sets it before each `poll`.
    pub fn set_wall_offset(&mut self, wall_minus_steady_ns: i64) {
        self.wall_offset_ns = wall_minus_steady_ns;
    }

    /// A task on the tablet: answer it once, after a delay.
    pub fn on_task(&mut self, task: &TabletTask, now_ns: i64) {
        let key = (task.session_id.clone(), task.sequence_id);
        if self.answered.contains(&key)
            || self.pending.as_ref().is_some_and(|p| {
                p.task.sequence_id == task.sequence_id && p.task.session_id == task.session_id
            })
        {
            return;
        }
        let length = usize::from(task.length);
        let level_index = (length.saturating_sub(1) / 2).clamp(1, 3) - 1;
        let mean = self.params.answer_time_mean_s[level_index];
        let mut rng = Draw::ResponseTime {
            session: sequence_game::stable_id_hash(&task.session_id),
            sequence: task.sequence_index,
        }
        .rng(self.seed);
        let z: f64 = {
            let u1 = 1.0 - rng.random::<f64>();
            let u2 = rng.random::<f64>();
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        };
        let sigma = self.params.answer_time_spread;
        let seconds = (mean * (sigma * z - sigma * sigma / 2.0).exp()).clamp(1.0, 5.0 * mean)
            * self.params.time_scale;
        self.pending = Some(PendingAnswer {
            due: now_ns + (seconds * 1e9) as i64,
            task: task.clone(),
            response_time_s: seconds,
        });
    }

    /// The plan of the pending task's sequence, once the child has seen a GameState of it.
    fn plan_of_pending(&self) -> Option<Plan> {
        let pending = self.pending.as_ref()?;
        let key = (
            sequence_game::stable_id_hash(&pending.task.session_id),
            pending.task.sequence_index,
        );
        self.plan.filter(|p| p.session_sequence == key)
    }

    /// The answer to the pending task: the faces heard, wrong in one or two places if the plan
    /// says so. Built when it is due, so a face that came late still counts.
    fn answer(&self, pending: &PendingAnswer, outcome: Outcome) -> TabletAnswer {
        let task = &pending.task;
        let length = usize::from(task.length);
        let mut rng = Draw::Answer {
            session: sequence_game::stable_id_hash(&task.session_id),
            sequence: task.sequence_index,
        }
        .rng(self.seed);
        let mut answer: Vec<Emotion> = self
            .heard
            .iter()
            .rev()
            .take(length)
            .rev()
            .copied()
            .collect();
        while answer.len() < length {
            answer.push(Emotion::ALL[rng.random_range(0..4)]);
        }
        if outcome == Outcome::Failure {
            // Get one or two places wrong.
            let mistakes = 1 + usize::from(length > 3 && rng.random_bool(0.4));
            for _ in 0..mistakes {
                let at = rng.random_range(0..length);
                let shift = rng.random_range(1..4);
                let idx = Emotion::ALL
                    .iter()
                    .position(|e| *e == answer[at])
                    .unwrap_or(0);
                answer[at] = Emotion::ALL[(idx + shift) % 4];
            }
        }
        TabletAnswer {
            header: Header::at(Time::from_nanos(pending.due + self.wall_offset_ns)),
            session_id: task.session_id.clone(),
            sequence_id: task.sequence_id,
            answer: answer.iter().map(|e| e.name().to_string()).collect(),
            response_time: pending.response_time_s as f32,
        }
    }

    /// Everything due up to `now_ns`: camera frames at the frame rate and a due answer (held
    /// until the child has seen a GameState of its sequence, which decides right or wrong).
    pub fn poll(&mut self, now_ns: i64) -> Vec<ChildOutput> {
        let mut out = Vec::new();
        let period = self.frame_period_ns();
        let origin = *self.frame_origin_ns.get_or_insert(now_ns);
        // After a stall, do not flood: skip frames older than one second (their indices stay
        // theirs: the frames after them are the same as without the stall).
        if now_ns - (origin + self.next_frame as i64 * period) > 1_000_000_000 {
            self.next_frame = ((now_ns - origin) / period) as u64;
        }
        while origin + self.next_frame as i64 * period <= now_ns {
            let n = self.next_frame;
            out.push(ChildOutput::Frame(
                self.frame(n, origin + n as i64 * period),
            ));
            self.next_frame += 1;
        }
        if let Some(pending) = &self.pending
            && pending.due <= now_ns
            && let Some(plan) = self.plan_of_pending()
        {
            let answer = self.answer(pending, plan.outcome);
            self.pending = None;
            self.answered
                .insert((answer.session_id.clone(), answer.sequence_id));
            out.push(ChildOutput::Answer(answer));
        }
        out
    }

    /// When `poll` next has something to do.
    pub fn next_wakeup(&self) -> Option<i64> {
        let frame = self
            .frame_origin_ns
            .map(|o| o + self.next_frame as i64 * self.frame_period_ns());
        // An answer held for its sequence's GameState waits for that, not for a time.
        let answer = self
            .pending
            .as_ref()
            .filter(|_| self.plan_of_pending().is_some())
            .map(|p| p.due);
        match (answer, frame) {
            (Some(a), Some(f)) => Some(a.min(f)),
            (a, f) => a.or(f),
        }
    }

    fn frame_period_ns(&self) -> i64 {
        (1e9 / self.params.fps) as i64
    }

    /// Frame `n`'s own draws. A stretch of looking at or away starts at a frame with
    /// probability 1 / (its mean length in frames): geometric stretches, decided frame by frame,
    /// so where they start does not depend on which frames were published.
    fn frame_draws(&self, n: u64) -> FrameDraws {
        let mean_frames = (self.params.gaze_dwell_s * self.params.fps).max(1.0);
        let mut rng = Draw::Frame(n).rng(self.seed);
        FrameDraws {
            starts_stretch: rng.random::<f64>() < 1.0 / mean_frames,
            look: rng.random::<f64>(),
            lost: rng.random::<f64>(),
        }
    }

    fn frame(&mut self, n: u64, stamp_ns: i64) -> OpenFaceFeatures {
        // The start of the stretch frame n is in, if it began after the last frame put out
        // (frame 0 begins the first). A stall skips at most a second or so of frames, but
        // more after a suspend: past ~40 mean stretches one has begun all but surely.
        let draws = self.frame_draws(n);
        let since = self.last_frame.map_or(0, |l| l + 1);
        let limit = (40.0 * self.params.gaze_dwell_s * self.params.fps).ceil() as u64;
        let look = if n == 0 || draws.starts_stretch {
            Some(draws.look)
        } else {
            (since.max(n.saturating_sub(limit))..n)
                .rev()
                .map(|k| (k, self.frame_draws(k)))
                .find(|(k, d)| *k == 0 || d.starts_stretch)
                .map(|(_, d)| d.look)
        };
        if let Some(look) = look {
            // Look at the robot with probability (1 + E) / 2: the expected per-second label
            // mean is then E.
            let p_look = ((1.0 + self.target_engagement) / 2.0).clamp(0.0, 1.0);
            self.looking = look < p_look;
        }
        self.last_frame = Some(n);
        let header = Header {
            stamp: Time::from_nanos(stamp_ns + self.wall_offset_ns),
            frame_id: self.params.camera_frame.clone(),
        };
        if draws.lost < self.params.face_lost_rate {
            return OpenFaceFeatures {
                header,
                face_id: self.params.face_id.clone(),
                confidence: 0.0,
                success: false,
                features: vec![0.0; 32],
            };
        }
        // The faces of one kind in their generated order, by frame index.
        let pool = if self.looking {
            &self.engaged_faces
        } else {
            &self.away_faces
        };
        let features = pool[(n % pool.len() as u64) as usize].to_vec();
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
