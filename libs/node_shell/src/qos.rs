//! The DDS QoS of each topic class of the suite (`QosKind`) and of its services, the same on
//! both sides of every topic. The in-process bus models the same classes (see `in_process`).

use qt_therapy_msgs::topics::QosKind;
use ros2_client::QosProfile;
use ros2_client::qos::{Durability, History, Reliability, WhenFull};
use std::time::Duration;

/// The QoS a topic class gets, the same on both sides.
pub fn qos_profile(kind: QosKind) -> QosProfile {
    let reliable = Reliability::Reliable {
        when_full: WhenFull::Wait(Duration::from_millis(100)),
    };
    match kind {
        QosKind::Reliable => QosProfile::publisher_default()
            .reliability(reliable)
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth: 100 }),
        QosKind::State => QosProfile::publisher_default()
            .reliability(reliable)
            .durability(Durability::TransientLocal)
            .history(History::KeepLast { depth: 1 }),
        QosKind::Durable => QosProfile::publisher_default()
            .reliability(reliable)
            .durability(Durability::TransientLocal)
            .history(History::KeepLast { depth: 100 }),
        QosKind::Features => QosProfile::subscription_default()
            .reliability(Reliability::BestEffort)
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth: 10 }),
    }
}

/// The QoS of the suite's services' request and response topics, the same on both sides.
pub fn service_qos() -> QosProfile {
    qos_profile(QosKind::Reliable).history(History::KeepLast { depth: 10 })
}
