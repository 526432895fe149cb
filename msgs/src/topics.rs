//! The suite's topic and service names with their types and QoS, in one table, so every node,
//! the recorder and the README agree. Robot output uses QTrobot's own topic names.

use crate::definition::MessageDefinition;
use crate::hri_msgs::{EngagementLevel, IdsList};
use crate::messages::*;
use crate::services::{AssignCluster, DecideAction, PredictUser, ServiceDefinition};
use crate::standard::std_msgs::StringMsg;
use std::marker::PhantomData;

/// How a topic is delivered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum QosKind {
    /// Commands, results, decisions: reliable, volatile, keep last 100.
    Reliable,
    /// Latest state: reliable, transient-local, keep last 1 (late joiners get it).
    State,
    /// Results a restarted node must still learn from: reliable, transient-local, keep last
    /// 100, so a respawned subscriber gets the ones published while it was down.
    Durable,
    /// High-rate sensor data: best effort, volatile, keep last 10.
    Features,
}

impl QosKind {
    pub fn describe(self) -> &'static str {
        match self {
            QosKind::Reliable => "reliable, volatile, keep last 100",
            QosKind::State => "reliable, transient-local, keep last 1",
            QosKind::Durable => "reliable, transient-local, keep last 100",
            QosKind::Features => "best effort, volatile, keep last 10",
        }
    }
}

/// A typed topic of the suite.
#[derive(Debug)]
pub struct Topic<M> {
    pub name: &'static str,
    pub qos: QosKind,
    message: PhantomData<fn() -> M>,
}

impl<M> Clone for Topic<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for Topic<M> {}

impl<M: MessageDefinition> Topic<M> {
    pub const fn new(name: &'static str, qos: QosKind) -> Self {
        Topic {
            name,
            qos,
            message: PhantomData,
        }
    }

    pub fn info(&self) -> TopicInfo {
        TopicInfo {
            name: self.name,
            type_name: M::full_type_name(),
            package: M::PACKAGE,
            type_short_name: M::NAME,
            schema_text: M::schema_text(),
            qos: self.qos,
        }
    }
}

/// A typed service of the suite.
#[derive(Debug)]
pub struct Service<S> {
    pub name: &'static str,
    service: PhantomData<fn() -> S>,
}

impl<S> Clone for Service<S> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<S> Copy for Service<S> {}

impl<S: ServiceDefinition> Service<S> {
    pub const fn new(name: &'static str) -> Self {
        Service {
            name,
            service: PhantomData,
        }
    }
}

/// A topic's description without its Rust type, for the recorder and the docs.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicInfo {
    pub name: &'static str,
    /// `pkg/msg/Type`
    pub type_name: String,
    pub package: &'static str,
    pub type_short_name: &'static str,
    pub schema_text: String,
    pub qos: QosKind,
}

pub const OPENFACE_FEATURES: Topic<OpenFaceFeatures> =
    Topic::new("/qt_therapy/openface/features", QosKind::Features);
pub const ENGAGEMENT_ESTIMATE: Topic<EngagementEstimate> =
    Topic::new("/qt_therapy/engagement/estimate", QosKind::Features);
pub const EXPECTED_ENGAGEMENT: Topic<ExpectedEngagement> =
    Topic::new("/qt_therapy/engagement/expected", QosKind::Reliable);
pub const THERAPIST_COMMAND: Topic<TherapistCommand> =
    Topic::new("/qt_therapy/therapist/command", QosKind::Reliable);
pub const GAME_STATE: Topic<GameState> = Topic::new("/qt_therapy/game/state", QosKind::State);
pub const SEQUENCE_RESULT: Topic<SequenceResult> =
    Topic::new("/qt_therapy/game/sequence_result", QosKind::Durable);
/// Durable like results: the therapist page and the recorder get a proposal made while they
/// were (re)connecting, and the bag keeps every response.
pub const ACTION_PROPOSAL: Topic<ActionProposal> =
    Topic::new("/qt_therapy/game/proposal", QosKind::Durable);
pub const TABLET_TASK: Topic<TabletTask> = Topic::new("/qt_therapy/tablet/task", QosKind::State);
pub const TABLET_ANSWER: Topic<TabletAnswer> =
    Topic::new("/qt_therapy/tablet/answer", QosKind::Reliable);
// Durable, like results: a respawned recorder is sent the decisions made while it was down,
// so the bag keeps every decision's Q-values (the game manager gets its answer by the service).
pub const DECISION: Topic<Decision> = Topic::new("/qt_therapy/policy/decision", QosKind::Durable);
pub const USER_MODEL_INFO: Topic<UserModelInfo> =
    Topic::new("/qt_therapy/user_model/models", QosKind::State);
pub const HEARTBEAT: Topic<Heartbeat> = Topic::new("/qt_therapy/heartbeat", QosKind::Reliable);
/// QTrobot's text-to-speech.
pub const ROBOT_SPEECH: Topic<StringMsg> = Topic::new("/qt_robot/speech/say", QosKind::Reliable);
/// QTrobot's face animation, e.g. `QT/happy`.
pub const ROBOT_EMOTION: Topic<StringMsg> = Topic::new("/qt_robot/emotion/show", QosKind::Reliable);
/// QTrobot's recorded gestures, e.g. `QT/happy`.
pub const ROBOT_GESTURE: Topic<StringMsg> = Topic::new("/qt_robot/gesture/play", QosKind::Reliable);

/// ROS4HRI (REP-155): the ids of the persons tracked, latched as ROS4HRI's person manager does.
pub const PERSONS_TRACKED: Topic<IdsList> = Topic::new("/humans/persons/tracked", QosKind::State);

/// ROS4HRI (REP-155): a person's engagement, `/humans/persons/<person_id>/engagement_status`.
/// The name is made once per person and kept for the process's life (a few bytes each).
pub fn engagement_status(person_id: &str) -> Topic<EngagementLevel> {
    let name: &'static str =
        Box::leak(format!("/humans/persons/{person_id}/engagement_status").into_boxed_str());
    Topic::new(name, QosKind::Reliable)
}

/// A ROS4HRI person id from any id: `prefix_` and the id's letters and digits, every other
/// character an underscore (ROS names allow nothing else, no leading digit, no `__`).
pub fn person_id(prefix: &str, id: &str) -> String {
    let mut out = format!("{prefix}_");
    for c in id.chars() {
        let c = if c.is_ascii_alphanumeric() { c } else { '_' };
        if !(c == '_' && out.ends_with('_')) {
            out.push(c);
        }
    }
    out.trim_end_matches('_').to_string()
}

pub const PREDICT_USER: Service<PredictUser> = Service::new("/qt_therapy/user_model/predict");
pub const ASSIGN_CLUSTER: Service<AssignCluster> =
    Service::new("/qt_therapy/user_model/assign_cluster");
pub const DECIDE_ACTION: Service<DecideAction> = Service::new("/qt_therapy/policy/decide_action");
/// The node serving [`DECIDE_ACTION`], by the name its heartbeat carries: the game manager
/// tells a dead policy from a slow one by it.
pub const BEHAVIOUR_POLICY_NODE: &str = "behaviour_policy";

/// Every topic of the suite, for the recorder (`bag record --all`) and the docs.
pub fn all_topics() -> Vec<TopicInfo> {
    vec![
        OPENFACE_FEATURES.info(),
        ENGAGEMENT_ESTIMATE.info(),
        EXPECTED_ENGAGEMENT.info(),
        THERAPIST_COMMAND.info(),
        GAME_STATE.info(),
        SEQUENCE_RESULT.info(),
        ACTION_PROPOSAL.info(),
        TABLET_TASK.info(),
        TABLET_ANSWER.info(),
        DECISION.info(),
        USER_MODEL_INFO.info(),
        HEARTBEAT.info(),
        ROBOT_SPEECH.info(),
        ROBOT_EMOTION.info(),
        ROBOT_GESTURE.info(),
        PERSONS_TRACKED.info(),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn person_ids_are_ros_names() {
        assert_eq!(person_id("user", "1CZ1CL1P"), "user_1CZ1CL1P");
        assert_eq!(person_id("user", "sim-child-1"), "user_sim_child_1");
        assert_eq!(person_id("face", "cam front/0"), "face_cam_front_0");
        assert_eq!(person_id("user", "a__b--"), "user_a_b");
        let t = engagement_status(&person_id("user", "x"));
        assert_eq!(t.name, "/humans/persons/user_x/engagement_status");
    }
}
