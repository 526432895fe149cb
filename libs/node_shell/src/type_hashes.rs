//! The RIHS01 type hash every endpoint announces in its USER_DATA, as a Jazzy rmw does
//! (`rmw_fastrtps_cpp/src/publisher.cpp` and `rmw_service.cpp`: the type's hash from its type
//! support, written by `rmw_dds_common::encode_type_hash_for_user_data_qos` as
//! `typehash=RIHS01_<hex>;`), so that `ros2 topic info -v` shows each endpoint's hash and a
//! Jazzy peer can tell matching types apart. The hashes are computed from the `.msg`/`.srv`
//! text (`qt_therapy_msgs::type_description`): the suite's own types when a node first uses
//! them, and the ROS 2 types ros2-client's own endpoints carry (`ros_discovery_info`,
//! `/parameter_events`, `/rosout`, its `/clock` reader, the parameter services) from the
//! upstream files restated in `interfaces/`. RustDDS announces what the participant holds for
//! a type (`DomainParticipant::set_endpoint_user_data`, third_party/README.md).

use qt_therapy_msgs::MessageDefinition;
use qt_therapy_msgs::services::ServiceDefinition;
use qt_therapy_msgs::type_description::{DescriptionError, TypeDescription, TypeHash};
use rustdds::DomainParticipant;

/// A ROS 2 interface a builtin endpoint uses: `pkg/msg/Type` (or `pkg/srv/Type`) and its text.
struct Interface {
    name: &'static str,
    text: &'static str,
}

macro_rules! interface {
    ($pkg:literal, msg, $ty:literal) => {
        Interface {
            name: concat!($pkg, "/msg/", $ty),
            text: include_str!(concat!("../../../interfaces/", $pkg, "/msg/", $ty, ".msg")),
        }
    };
    ($pkg:literal, srv, $ty:literal) => {
        Interface {
            name: concat!($pkg, "/srv/", $ty),
            text: include_str!(concat!("../../../interfaces/", $pkg, "/srv/", $ty, ".srv")),
        }
    };
}

/// Upstream Jazzy interfaces (Apache-2.0, restated in `interfaces/`).
const MESSAGES: &[Interface] = &[
    interface!("rmw_dds_common", msg, "Gid"),
    interface!("rmw_dds_common", msg, "NodeEntitiesInfo"),
    interface!("rmw_dds_common", msg, "ParticipantEntitiesInfo"),
    interface!("rcl_interfaces", msg, "Log"),
    interface!("rcl_interfaces", msg, "ParameterEvent"),
    interface!("rcl_interfaces", msg, "Parameter"),
    interface!("rcl_interfaces", msg, "ParameterValue"),
    interface!("rcl_interfaces", msg, "ParameterDescriptor"),
    interface!("rcl_interfaces", msg, "FloatingPointRange"),
    interface!("rcl_interfaces", msg, "IntegerRange"),
    interface!("rcl_interfaces", msg, "ListParametersResult"),
    interface!("rcl_interfaces", msg, "SetParametersResult"),
    interface!("rosgraph_msgs", msg, "Clock"),
    Interface {
        name: "builtin_interfaces/msg/Time",
        text: "int32 sec\nuint32 nanosec\n",
    },
];

const SERVICES: &[Interface] = &[
    interface!("rcl_interfaces", srv, "ListParameters"),
    interface!("rcl_interfaces", srv, "GetParameters"),
    interface!("rcl_interfaces", srv, "GetParameterTypes"),
    interface!("rcl_interfaces", srv, "SetParameters"),
    interface!("rcl_interfaces", srv, "SetParametersAtomically"),
    interface!("rcl_interfaces", srv, "DescribeParameters"),
];

/// `pkg/msg/Type` (or `pkg/srv/Type_Request`) as DDS names the type: `pkg::msg::dds_::Type_`.
pub fn dds_type_name(ros_type_name: &str) -> String {
    match ros_type_name.splitn(3, '/').collect::<Vec<_>>()[..] {
        [pkg, kind, ty] => format!("{pkg}::{kind}::dds_::{ty}_"),
        _ => ros_type_name.to_string(),
    }
}

fn known_messages() -> Vec<(String, &'static str)> {
    MESSAGES
        .iter()
        .map(|i| (i.name.to_string(), i.text))
        .collect()
}

/// The descriptions of the upstream types ros2-client's own endpoints carry: every message
/// of [`MESSAGES`] and both halves of every service of [`SERVICES`].
pub fn builtin_descriptions() -> Result<Vec<TypeDescription>, DescriptionError> {
    let known = known_messages();
    let mut out = Vec::new();
    for m in MESSAGES {
        out.push(TypeDescription::from_texts(m.name, m.text, &known)?);
    }
    for s in SERVICES {
        let mut halves = s.text.splitn(2, "\n---\n");
        let request = halves.next().unwrap_or("");
        let response = halves.next().unwrap_or("");
        out.push(TypeDescription::from_texts(
            &format!("{}_Request", s.name),
            request,
            &known,
        )?);
        out.push(TypeDescription::from_texts(
            &format!("{}_Response", s.name),
            response,
            &known,
        )?);
    }
    Ok(out)
}

/// The definition of one of the upstream ROS 2 types above as rosbag2 stores it (`ros2msg`:
/// its text, then each type it uses after a line of `=` and `MSG: pkg/Type`).
pub fn builtin_definition(type_name: &str) -> Option<String> {
    let top = MESSAGES.iter().find(|m| m.name == type_name)?;
    let known = known_messages();
    let description = TypeDescription::from_texts(top.name, top.text, &known).ok()?;
    let mut text = top.text.trim_end().to_string();
    text.push('\n');
    for r in &description.referenced_type_descriptions {
        let dep = MESSAGES.iter().find(|m| m.name == r.type_name)?;
        text.push_str(&"=".repeat(80));
        text.push_str(&format!("\nMSG: {}\n", dep.name.replacen("/msg/", "/", 1)));
        text.push_str(dep.text.trim_end());
        text.push('\n');
    }
    Some(text)
}

fn announce(participant: &DomainParticipant, description: &TypeDescription) -> TypeHash {
    let hash = description.hash();
    participant.set_endpoint_user_data(
        &dds_type_name(&description.type_description.type_name),
        hash.user_data().into_bytes(),
    );
    hash
}

/// Announces the hashes of ros2-client's builtin endpoints' types; before the ros2-client
/// context is made, whose first endpoint is its `ros_discovery_info` writer.
pub(crate) fn announce_builtin_types(participant: &DomainParticipant) -> anyhow::Result<()> {
    for d in builtin_descriptions()? {
        announce(participant, &d);
    }
    Ok(())
}

/// Announces the hash of message `M`, before its first endpoint is made.
pub(crate) fn announce_message<M: MessageDefinition>(
    participant: &DomainParticipant,
) -> anyhow::Result<TypeHash> {
    Ok(announce(participant, &TypeDescription::of_message::<M>()?))
}

/// Announces the hashes of service `S`'s request and response, before its endpoints are made.
pub(crate) fn announce_service<S: ServiceDefinition>(
    participant: &DomainParticipant,
) -> anyhow::Result<()> {
    let (request, response) = TypeDescription::of_service::<S>()?;
    announce(participant, &request);
    announce(participant, &response);
    Ok(())
}

/// `type_description_interfaces/msg/FieldType` on the wire.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FieldTypeMsg {
    pub type_id: u8,
    pub capacity: u64,
    pub string_capacity: u64,
    pub nested_type_name: String,
}

/// `type_description_interfaces/msg/Field` on the wire.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FieldMsg {
    pub name: String,
    pub r#type: FieldTypeMsg,
    pub default_value: String,
}

/// `type_description_interfaces/msg/IndividualTypeDescription` on the wire.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IndividualTypeDescriptionMsg {
    pub type_name: String,
    pub fields: Vec<FieldMsg>,
}

/// `type_description_interfaces/msg/TypeDescription` on the wire.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TypeDescriptionMsg {
    pub type_description: IndividualTypeDescriptionMsg,
    pub referenced_type_descriptions: Vec<IndividualTypeDescriptionMsg>,
}

/// A field's type as a `.msg` file writes it (`float32[32]`, `string<=8`, `pkg/Type[]`).
pub fn msg_type_text(t: &FieldTypeMsg) -> String {
    use qt_therapy_msgs::type_description::field_type::*;
    let (value_id, suffix) = match t.type_id {
        id if id > UNBOUNDED_SEQUENCE => (id - UNBOUNDED_SEQUENCE, "[]".to_string()),
        id if id > BOUNDED_SEQUENCE => (id - BOUNDED_SEQUENCE, format!("[<={}]", t.capacity)),
        id if id > ARRAY => (id - ARRAY, format!("[{}]", t.capacity)),
        id => (id, String::new()),
    };
    let base = match value_id {
        NESTED_TYPE => t.nested_type_name.replacen("/msg/", "/", 1),
        INT8 => "int8".into(),
        UINT8 => "uint8".into(),
        INT16 => "int16".into(),
        UINT16 => "uint16".into(),
        INT32 => "int32".into(),
        UINT32 => "uint32".into(),
        INT64 => "int64".into(),
        UINT64 => "uint64".into(),
        FLOAT => "float32".into(),
        DOUBLE => "float64".into(),
        CHAR => "char".into(),
        BOOLEAN => "bool".into(),
        BYTE => "byte".into(),
        STRING => "string".into(),
        WSTRING => "wstring".into(),
        BOUNDED_STRING => format!("string<={}", t.string_capacity),
        BOUNDED_WSTRING => format!("wstring<={}", t.string_capacity),
        other => format!("unknown_type_{other}"),
    };
    format!("{base}{suffix}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_types_are_written_as_msg_files_write_them() {
        let t = |type_id, capacity, string_capacity, nested: &str| {
            msg_type_text(&FieldTypeMsg {
                type_id,
                capacity,
                string_capacity,
                nested_type_name: nested.into(),
            })
        };
        assert_eq!(t(58, 32, 0, ""), "float32[32]");
        assert_eq!(t(117, 3, 8, ""), "string<=8[<=3]");
        assert_eq!(t(145, 0, 0, "p/msg/T"), "p/T[]");
        assert_eq!(t(17, 0, 0, ""), "string");
    }

    #[test]
    fn dds_names_follow_ros2() {
        assert_eq!(
            dds_type_name("rcl_interfaces/msg/Log"),
            "rcl_interfaces::msg::dds_::Log_"
        );
        assert_eq!(
            dds_type_name("rcl_interfaces/srv/ListParameters_Request"),
            "rcl_interfaces::srv::dds_::ListParameters_Request_"
        );
    }

    // Jazzy's own hashes (share/<pkg>/msg/<Type>.json of the ros-jazzy-* wheels); the ROS 2
    // test (tests/ros2) compares every endpoint's with rosidl's.
    #[test]
    fn builtin_types_hash_as_jazzy_ships_them() {
        let all = builtin_descriptions().expect("describes");
        let hash = |name: &str| {
            all.iter()
                .find(|d| d.type_description.type_name == name)
                .map(|d| d.hash().to_string())
        };
        assert_eq!(
            hash("rcl_interfaces/msg/Log").as_deref(),
            Some("RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac")
        );
    }
}
