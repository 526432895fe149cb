//! The suite's message types, type-erased so a bag tool can handle a topic by its rosbag2 type
//! name: its schema text and a check that a CDR payload decodes as it. The list of types is
//! here once; the DDS recorder and player (`nodes/bag`) build their taps and publishers from it
//! through [`PerType`], so this crate never links DDS.

use crate::cdr::{self, CdrError};
use crate::writer::Stamp;
use qt_therapy_msgs::*;
use std::marker::PhantomData;

/// One recorded message on its way to the writer.
#[derive(Debug, Clone)]
pub struct Sample {
    pub channel_id: u16,
    pub stamp: Stamp,
    pub payload: Vec<u8>,
}

/// One message type of the suite, type-erased.
pub trait SuiteType: Send + Sync {
    /// `pkg/msg/Type`
    fn type_name(&self) -> String;
    /// The rosbag2 schema text (`ros2msg`, dependencies appended).
    fn schema_text(&self) -> String;
    /// Whether `payload` decodes as this type.
    fn check_cdr(&self, payload: &[u8]) -> Result<(), CdrError>;
}

/// Makes one value per message type of the suite (see [`for_each_suite_type`]).
pub trait PerType {
    type Made;
    fn make<M: MessageDefinition>(&self) -> Self::Made;
}

/// `per.make::<M>()` for every message type that travels on one of the suite's topics.
pub fn for_each_suite_type<P: PerType>(per: &P) -> Vec<P::Made> {
    vec![
        per.make::<OpenFaceFeatures>(),
        per.make::<EngagementEstimate>(),
        per.make::<ExpectedEngagement>(),
        per.make::<TherapistCommand>(),
        per.make::<GameState>(),
        per.make::<SequenceResult>(),
        per.make::<TabletTask>(),
        per.make::<TabletAnswer>(),
        per.make::<Decision>(),
        per.make::<ActionProposal>(),
        per.make::<UserModelInfo>(),
        per.make::<Heartbeat>(),
        per.make::<std_msgs::StringMsg>(),
        per.make::<hri_msgs::IdsList>(),
    ]
}

struct Typed<M>(PhantomData<fn() -> M>);

impl<M: MessageDefinition> SuiteType for Typed<M> {
    fn type_name(&self) -> String {
        M::full_type_name()
    }

    fn schema_text(&self) -> String {
        M::schema_text()
    }

    fn check_cdr(&self, payload: &[u8]) -> Result<(), CdrError> {
        cdr::decode::<M>(payload).map(|_| ())
    }
}

struct Erased;

impl PerType for Erased {
    type Made = Box<dyn SuiteType>;
    fn make<M: MessageDefinition>(&self) -> Box<dyn SuiteType> {
        Box::new(Typed::<M>(PhantomData))
    }
}

/// Every message type that travels on one of the suite's topics.
pub fn suite_types() -> Vec<Box<dyn SuiteType>> {
    for_each_suite_type(&Erased)
}

/// The suite type named `type_name` (`pkg/msg/Type`).
pub fn suite_type(type_name: &str) -> Option<Box<dyn SuiteType>> {
    suite_types()
        .into_iter()
        .find(|t| t.type_name() == type_name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use qt_therapy_msgs::topics::all_topics;

    #[test]
    fn every_topic_of_the_suite_has_its_type_here() {
        for topic in all_topics() {
            let t = suite_type(&topic.type_name).unwrap_or_else(|| {
                panic!("{} ({}) has no suite type", topic.name, topic.type_name)
            });
            assert_eq!(t.schema_text(), topic.schema_text);
        }
        assert!(suite_type("geometry_msgs/msg/Twist").is_none());
    }

    #[test]
    fn check_cdr_tells_types_apart() {
        let m = std_msgs::StringMsg { data: "hi".into() };
        let payload = cdr::encode(&m).expect("encodes");
        let string = suite_type("std_msgs/msg/String").expect("known");
        assert!(string.check_cdr(&payload).is_ok());
        let decision = suite_type("qt_therapy_msgs/msg/Decision").expect("known");
        assert!(decision.check_cdr(&payload).is_err());
    }
}
