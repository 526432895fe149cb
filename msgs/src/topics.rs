//! The suite's topic and service names with their types and QoS, in one table, so every node,
//! the recorder and the README agree. Robot output uses QTrobot's own topic names.

use crate::definition::MessageDefinition;
use crate::hri_msgs::{EngagementLevel, IdsList};
use crate::messages::*;
use crate::services::{AssignCluster, DecideAction, PredictUser, ServiceDefinition};
use crate::standard::std_msgs::{BoolMsg, StringMsg};
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

/// ROS4HRI (REP-155): the ids of the persons seen now. Latched as ROS4HRI's person manager
/// publishes it (`hri_person_manager`: transient-local, reliable); libhri subscribes with the
/// system defaults (volatile), so the classifier also sends it again every second.
pub const PERSONS_TRACKED: Topic<IdsList> = Topic::new("/humans/persons/tracked", QosKind::State);

/// ROS4HRI (REP-155): the ids of every person known, tracked or not; libhri's `getPersons()`
/// is built from it. Not recorded: the classifier's persons are anonymous and forgotten once
/// lost, as the person manager forgets anonymous persons, so this holds the tracked ids.
pub const PERSONS_KNOWN: Topic<IdsList> = Topic::new("/humans/persons/known", QosKind::State);

/// `/humans/persons/<person_id>/<leaf>`. The name is made once per person and kept for the
/// process's life (a person lasts at least `ros4hri_tracked_timeout_s`, so a few hundred
/// bytes an encounter).
fn person_topic_name(person_id: &str, leaf: &str) -> &'static str {
    Box::leak(format!("/humans/persons/{person_id}/{leaf}").into_boxed_str())
}

/// ROS4HRI (REP-155): a person's engagement, `/humans/persons/<person_id>/engagement_status`
/// (libhri reads it with the system defaults: volatile).
pub fn engagement_status(person_id: &str) -> Topic<EngagementLevel> {
    Topic::new(
        person_topic_name(person_id, "engagement_status"),
        QosKind::Reliable,
    )
}

/// ROS4HRI (REP-155): whether a person is anonymous (not identified, no permanent id),
/// `/humans/persons/<person_id>/anonymous`, the one per-person topic REP-155 requires.
/// Latched: libhri subscribes transient-local and reliable only once the person is listed,
/// after the value was published.
pub fn person_anonymous(person_id: &str) -> Topic<BoolMsg> {
    Topic::new(person_topic_name(person_id, "anonymous"), QosKind::State)
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
    fn person_topics_are_under_the_persons_namespace() {
        let t = engagement_status("anonymous_person_1a2b3c4d");
        assert_eq!(
            t.name,
            "/humans/persons/anonymous_person_1a2b3c4d/engagement_status"
        );
        let a = person_anonymous("anonymous_person_1a2b3c4d");
        assert_eq!(
            a.name,
            "/humans/persons/anonymous_person_1a2b3c4d/anonymous"
        );
        assert_eq!(a.qos, QosKind::State);
        assert_eq!(a.info().type_name, "std_msgs/msg/Bool");
        assert_eq!(PERSONS_KNOWN.info().type_name, "hri_msgs/msg/IdsList");
    }
}
