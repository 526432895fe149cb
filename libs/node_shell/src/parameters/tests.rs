//! The parameter table against rclcpp's behaviour (jazzy: `node_parameters.cpp`,
//! `parameter_service.cpp`).

use super::*;
use serde::Deserialize;

/// A node's parameters as a node declares them.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, DescribedParameters)]
#[serde(deny_unknown_fields, default)]
struct Demo {
    /// Language of the robot's lines:
    /// "en" or "de".
    #[parameter(writable)]
    language: String,
    /// Seed of every draw.
    seed: i64,
    /// Confidence below which a frame is no face.
    #[parameter(writable)]
    min_confidence: f64,
    /// Nodes watched.
    watched: Vec<String>,
    /// Mean answer times.
    #[serde(rename = "answer.mean_s")]
    answer_mean_s: Vec<f64>,
    /// Repeat forever.
    #[serde(rename = "loop")]
    repeat: bool,
    /// At most this many.
    #[parameter(writable)]
    max_sources: u32,
    /// A secret.
    #[parameter(hidden)]
    pin: String,
}

impl Default for Demo {
    fn default() -> Self {
        Demo {
            language: "en".into(),
            seed: 7,
            min_confidence: 0.75,
            watched: vec![],
            answer_mean_s: vec![8.5, 13.3],
            repeat: false,
            max_sources: 8,
            pin: "8642".into(),
        }
    }
}

fn table() -> ParameterTable {
    ParameterTable::new(&Demo::default()).expect("describes")
}

fn names(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

fn param(name: &str, value: Value, kind: ParameterType) -> raw::Parameter {
    raw::Parameter {
        name: name.into(),
        value: to_ros(&value, kind).expect("a value"),
    }
}

#[test]
fn the_derive_names_describes_and_types_every_key() {
    let declared = Demo::declared();
    let by_name = |n: &str| declared.iter().find(|d| d.name == n).expect(n).clone();
    assert_eq!(declared.len(), 8);
    assert_eq!(
        by_name("language"),
        Declared {
            name: "language",
            description: "Language of the robot's lines: \"en\" or \"de\".",
            kind: ParameterType::String,
            writable: true,
            hidden: false,
        }
    );
    assert!(by_name("pin").hidden);
    assert_eq!(by_name("answer.mean_s").kind, ParameterType::DoubleArray);
    assert_eq!(by_name("loop").kind, ParameterType::Bool);
    assert_eq!(by_name("watched").kind, ParameterType::StringArray);
    assert_eq!(by_name("max_sources").kind, ParameterType::Integer);
    assert!(!by_name("seed").writable);
}

#[test]
fn lists_as_rclcpp_with_prefixes_and_depth() {
    let t = table();
    let all = t.list(&[], 0);
    assert_eq!(
        all.names,
        names(&[
            "answer.mean_s",
            "language",
            "loop",
            "max_sources",
            "min_confidence",
            "seed",
            "use_sim_time",
            "watched"
        ])
    );
    assert_eq!(all.prefixes, names(&["answer"]));
    // Depth 1: names without a separator only.
    assert!(!t.list(&[], 1).names.contains(&"answer.mean_s".to_string()));
    // A prefix: itself and what is under `prefix.`, not names that merely start with it.
    assert_eq!(
        t.list(&names(&["answer"]), 0).names,
        names(&["answer.mean_s"])
    );
    assert_eq!(
        t.list(&names(&["answer"]), 1).names,
        names(&["answer.mean_s"])
    );
    assert_eq!(t.list(&names(&["lang"]), 0).names, Vec::<String>::new());
    assert_eq!(t.list(&names(&["seed"]), 0).names, names(&["seed"]));
}

#[test]
fn get_types_and_describe_answer_nothing_for_a_name_not_declared() {
    let t = table();
    let values = t.get(&names(&["language", "seed", "answer.mean_s"]));
    assert_eq!(values.len(), 3);
    assert_eq!(values[0].ptype, 4);
    assert_eq!(values[0].string_value, "en");
    assert_eq!((values[1].ptype, values[1].int_value), (2, 7));
    assert_eq!(values[2].double_array, vec![8.5, 13.3]);
    // rclcpp's services catch ParameterNotDeclaredException and answer empty.
    assert!(t.get(&names(&["language", "nope"])).is_empty());
    assert!(t.types(&names(&["nope"])).is_empty());
    assert!(t.describe(&names(&["seed", "nope"])).is_empty());
    assert_eq!(t.types(&names(&["loop", "watched"])), vec![1, 9]);
    let d = t.describe(&names(&["language", "seed", "use_sim_time"]));
    assert_eq!(
        d[0].description,
        "Language of the robot's lines: \"en\" or \"de\"."
    );
    assert!(!d[0].read_only);
    assert!(d[1].read_only);
    assert!(d[2].read_only);
    assert!(!t.get(&names(&["use_sim_time"]))[0].boolean_value);
}

#[test]
fn a_set_is_refused_with_rclcpps_reasons() {
    let t = table();
    assert_eq!(
        t.check(&[param("nope", Value::from(1), ParameterType::Integer)]),
        Err(Refusal::NotDeclared("nope".into()))
    );
    assert_eq!(
        t.check(&[param("seed", Value::from(1), ParameterType::Integer)]),
        Err(Refusal::Reason(
            "parameter 'seed' cannot be set because it is read-only".into()
        ))
    );
    assert_eq!(
        t.check(&[param(
            "use_sim_time",
            Value::Bool(true),
            ParameterType::Bool
        )]),
        Err(Refusal::Reason(
            "parameter 'use_sim_time' cannot be set because it is read-only".into()
        ))
    );
    assert_eq!(
        t.check(&[param(
            "min_confidence",
            Value::from(1),
            ParameterType::Integer
        )]),
        Err(Refusal::Reason(
            "Wrong parameter type, parameter {min_confidence} is of type {double}, setting it \
             to {integer} is not allowed."
                .into()
        ))
    );
    let mut not_set = param("language", Value::from(""), ParameterType::String);
    not_set.value.ptype = 0;
    assert_eq!(
        t.check(&[not_set]),
        Err(Refusal::Reason(
            "cannot undeclare a statically typed parameter".into()
        ))
    );
    // All or nothing: one read-only name refuses the whole set.
    assert!(
        t.check(&[
            param("language", Value::from("de"), ParameterType::String),
            param("seed", Value::from(1), ParameterType::Integer),
        ])
        .is_err()
    );
}

#[test]
fn an_accepted_set_is_read_into_the_struct_and_stored() {
    let mut t = table();
    let set = [
        param("language", Value::from("de"), ParameterType::String),
        param("min_confidence", Value::from(0.5), ParameterType::Double),
    ];
    t.check(&set).expect("writable, declared, typed");
    let proposed: Demo = t.proposed(&set).expect("reads");
    assert_eq!(
        proposed,
        Demo {
            language: "de".into(),
            min_confidence: 0.5,
            ..Demo::default()
        }
    );
    // Not stored before the node took it.
    assert_eq!(t.get(&names(&["language"]))[0].string_value, "en");
    let changed = t.apply(&set);
    assert_eq!(changed.len(), 2);
    assert_eq!(t.get(&names(&["language"]))[0].string_value, "de");
    // A value the struct's type cannot hold is refused, naming the key.
    let negative = [param(
        "max_sources",
        Value::from(-1),
        ParameterType::Integer,
    )];
    t.check(&negative).expect("typed as an integer");
    let e = t.proposed::<Demo>(&negative).expect_err("u32");
    assert!(e.starts_with("parameter 'max_sources': "), "{e}");
}

#[test]
fn a_parameter_change_carries_the_nodes_answer() {
    let (change, mut answer) = ParameterChange::new(Demo::default(), names(&["language"]));
    assert_eq!(change.changed, names(&["language"]));
    change.respond(Err("a session is under way".into()));
    assert_eq!(answer.try_recv(), Ok(Err("a session is under way".into())));
}

#[test]
fn a_hidden_parameter_is_not_on_the_graph_but_kept() {
    let t = table();
    assert!(!t.list(&[], 0).names.contains(&"pin".to_string()));
    assert!(t.get(&names(&["pin"])).is_empty());
    assert!(t.describe(&names(&["pin"])).is_empty());
    assert_eq!(
        t.check(&[param("pin", Value::from("0000"), ParameterType::String)]),
        Err(Refusal::NotDeclared("pin".into()))
    );
    // A change of another key keeps the secret's value.
    let set = [param("language", Value::from("de"), ParameterType::String)];
    let proposed: Demo = t.proposed(&set).expect("reads");
    assert_eq!(proposed.pin, "8642");
}
