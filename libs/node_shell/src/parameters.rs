//! A node's parameters as ROS 2 tools see them (`ros2 param list/get/describe/set/dump`,
//! rqt_reconfigure): each key of its parameter file a declared parameter with its value, its
//! type, its description (the key's doc comment) and whether it may change while the node
//! runs. [`ParameterTable`] answers the standard `rcl_interfaces` parameter services as rclcpp's
//! `ParameterService` and `NodeParameters` (jazzy) do: the same lists, the same empty answer
//! for a name not declared, the same refusals with the same reasons. The services over DDS are
//! `parameter_services`; a change the table accepts goes to the node's run loop as a
//! [`ParameterChange`], and only the node's core says whether it takes it.
//!
//! A node's parameter struct describes its keys with `#[derive(DescribedParameters)]` (doc
//! comment per field; `#[parameter(writable)]` on a key the core applies while it runs); every
//! other key is read-only.

use ros2_client::parameters::raw;
use ros2_client::rcl_interfaces::ListParametersResult;
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::{Map, Value};
use std::collections::BTreeMap;
use std::path::Path;
use tokio::sync::oneshot;

pub use node_parameters_derive::DescribedParameters;

/// A ROS 2 parameter type (rcl_interfaces/msg/ParameterType), by its code.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParameterType {
    Bool = 1,
    Integer = 2,
    Double = 3,
    String = 4,
    ByteArray = 5,
    BoolArray = 6,
    IntegerArray = 7,
    DoubleArray = 8,
    StringArray = 9,
}

/// rclcpp's `to_string(ParameterType)`, which its refusals quote.
fn type_name(code: u8) -> &'static str {
    match code {
        0 => "not set",
        1 => "bool",
        2 => "integer",
        3 => "double",
        4 => "string",
        5 => "byte_array",
        6 => "bool_array",
        7 => "integer_array",
        8 => "double_array",
        9 => "string_array",
        _ => "unknown type",
    }
}

/// The ROS 2 type of a parameter of Rust type `Self`.
pub trait ParameterKind {
    const KIND: ParameterType;
}

macro_rules! kinds {
    ($($t:ty => $k:ident),* $(,)?) => {
        $( impl ParameterKind for $t { const KIND: ParameterType = ParameterType::$k; } )*
    };
}

kinds! {
    bool => Bool,
    i8 => Integer, i16 => Integer, i32 => Integer, i64 => Integer,
    u8 => Integer, u16 => Integer, u32 => Integer, u64 => Integer, usize => Integer,
    f32 => Double, f64 => Double,
    String => String,
    Vec<bool> => BoolArray,
    Vec<i32> => IntegerArray, Vec<i64> => IntegerArray, Vec<u32> => IntegerArray,
    Vec<u64> => IntegerArray, Vec<usize> => IntegerArray,
    Vec<f32> => DoubleArray, Vec<f64> => DoubleArray,
    Vec<String> => StringArray,
}

/// One declared parameter: its key, description, type, whether it may change while the
/// node runs, and whether it is kept off the graph (a secret).
#[derive(Debug, Clone, PartialEq)]
pub struct Declared {
    pub name: &'static str,
    pub description: &'static str,
    pub kind: ParameterType,
    pub writable: bool,
    pub hidden: bool,
}

/// A parameter struct that describes its keys (`#[derive(DescribedParameters)]`).
pub trait DescribedParameters {
    /// Every key, in the struct's order.
    fn declared() -> Vec<Declared>;
}

/// What the node shell needs of a node's parameters: read from the file, written back as
/// values, described.
pub trait NodeParameters:
    DescribedParameters + DeserializeOwned + Serialize + Send + Sync + 'static
{
}

impl<P> NodeParameters for P where
    P: DescribedParameters + DeserializeOwned + Serialize + Send + Sync + 'static
{
}

/// rclcpp declares `use_sim_time` on every node; ours keep the wall clock, so it is always
/// false and read-only. A parameter file may say `use_sim_time: false` (`ros2 param dump`
/// writes it); true is refused at start-up (`params::parameters_from_map`).
pub const USE_SIM_TIME: &str = "use_sim_time";
const USE_SIM_TIME_DESCRIPTION: &str = "Always false: the suite's nodes keep the wall clock \
     (a parameter file may say false; true is refused at start-up).";

/// A change of writable parameters asked for over the graph (`ros2 param set`), which the
/// node shell has checked (declared, writable, of the declared type, read into the node's
/// parameter struct). The node's run loop hands it to its core and answers with what the core
/// said: `Ok` takes the change (the shell then stores it and publishes `/parameter_events`),
/// `Err(reason)` refuses it and the caller reads the reason.
#[derive(Debug)]
pub struct ParameterChange<P> {
    /// Every parameter of the node as it would be with the change.
    pub parameters: P,
    /// The keys the change sets, in the order asked.
    pub changed: Vec<String>,
    responder: oneshot::Sender<Result<(), String>>,
}

impl<P> ParameterChange<P> {
    /// A change and the receiver of the node's answer (the shell's side, and tests').
    pub fn new(
        parameters: P,
        changed: Vec<String>,
    ) -> (Self, oneshot::Receiver<Result<(), String>>) {
        let (responder, answer) = oneshot::channel();
        (
            ParameterChange {
                parameters,
                changed,
                responder,
            },
            answer,
        )
    }

    /// The node's answer: `Ok` takes the change, `Err(reason)` refuses it.
    pub fn respond(self, result: Result<(), String>) {
        // The caller may have given up waiting; nothing to do then.
        let _ = self.responder.send(result);
    }
}

/// Why a node's parameters could not be described.
#[derive(Debug, thiserror::Error)]
pub enum DescribeError {
    #[error("the parameters do not serialise to a map of keys: {0}")]
    NotAMap(String),
    #[error("parameter {key}: {reason}")]
    Key { key: String, reason: String },
}

struct Entry {
    value: raw::ParameterValue,
    declared: Declared,
}

/// A node's declared parameters and their values, answering as rclcpp does.
pub struct ParameterTable {
    // Sorted by name, as rclcpp's std::map: lists come out in this order.
    entries: BTreeMap<String, Entry>,
}

impl ParameterTable {
    /// The table of `params`: every key `P` declares, with its value in `params`, and
    /// `use_sim_time`.
    pub fn new<P: NodeParameters>(params: &P) -> Result<ParameterTable, DescribeError> {
        let values = flat_values(params)?;
        let mut entries = BTreeMap::new();
        for declared in P::declared() {
            let json = values
                .get(declared.name)
                .ok_or_else(|| DescribeError::Key {
                    key: declared.name.to_string(),
                    reason: "declared but not among the serialised values".into(),
                })?;
            let value = to_ros(json, declared.kind).map_err(|reason| DescribeError::Key {
                key: declared.name.to_string(),
                reason,
            })?;
            entries.insert(declared.name.to_string(), Entry { value, declared });
        }
        if let Some(extra) = values.keys().find(|k| !entries.contains_key(k.as_str())) {
            return Err(DescribeError::Key {
                key: extra.clone(),
                reason: "a serialised value without a declaration".into(),
            });
        }
        entries.insert(
            USE_SIM_TIME.to_string(),
            Entry {
                value: to_ros(&Value::Bool(false), ParameterType::Bool).expect("a bool"),
                declared: Declared {
                    name: USE_SIM_TIME,
                    description: USE_SIM_TIME_DESCRIPTION,
                    kind: ParameterType::Bool,
                    writable: false,
                    hidden: false,
                },
            },
        );
        Ok(ParameterTable { entries })
    }

    /// A parameter shown on the graph (not hidden).
    fn shown(&self, name: &str) -> Option<&Entry> {
        self.entries.get(name).filter(|e| !e.declared.hidden)
    }

    /// ListParameters, as rclcpp's `NodeParameters::list_parameters`: with no prefixes, the
    /// names with fewer than `depth` separators (0: all); else the names equal to a prefix or
    /// under `prefix.` within `depth` more levels; `prefixes` are the listed names'
    /// namespaces.
    pub fn list(&self, prefixes: &[String], depth: u64) -> ListParametersResult {
        let fewer_than_depth = |s: &str| (s.matches('.').count() as u64) < depth;
        let recursive = prefixes.is_empty() && depth == 0;
        let mut result = ListParametersResult {
            names: vec![],
            prefixes: vec![],
        };
        for (name, entry) in &self.entries {
            if entry.declared.hidden {
                continue;
            }
            if !recursive {
                let get_all = prefixes.is_empty() && fewer_than_depth(name);
                let prefix_matches = prefixes.iter().any(|prefix| {
                    if name == prefix {
                        return true;
                    }
                    match name.strip_prefix(&format!("{prefix}.")) {
                        Some(rest) => depth == 0 || fewer_than_depth(rest),
                        None => false,
                    }
                });
                if !get_all && !prefix_matches {
                    continue;
                }
            }
            result.names.push(name.clone());
            if let Some((prefix, _)) = name.rsplit_once('.')
                && !result.prefixes.iter().any(|p| p == prefix)
            {
                result.prefixes.push(prefix.to_string());
            }
        }
        result
    }

    /// GetParameters: the values in the order asked, or none at all when a name is not
    /// declared (rclcpp's service catches ParameterNotDeclaredException and answers empty).
    pub fn get(&self, names: &[String]) -> Vec<raw::ParameterValue> {
        names
            .iter()
            .map(|n| self.shown(n).map(|e| e.value.clone()))
            .collect::<Option<Vec<_>>>()
            .unwrap_or_default()
    }

    /// GetParameterTypes: as [`ParameterTable::get`], the types' codes.
    pub fn types(&self, names: &[String]) -> Vec<u8> {
        names
            .iter()
            .map(|n| self.shown(n).map(|e| e.declared.kind as u8))
            .collect::<Option<Vec<_>>>()
            .unwrap_or_default()
    }

    /// DescribeParameters: as [`ParameterTable::get`], each one's descriptor.
    pub fn describe(&self, names: &[String]) -> Vec<raw::ParameterDescriptor> {
        names
            .iter()
            .map(|n| {
                self.shown(n).map(|e| raw::ParameterDescriptor {
                    name: n.clone(),
                    r#type: e.declared.kind as u8,
                    description: e.declared.description.to_string(),
                    additional_constraints: if e.declared.writable {
                        String::new()
                    } else {
                        "set in the parameter file; read once at start-up".to_string()
                    },
                    read_only: !e.declared.writable,
                    dynamic_typing: false,
                    floating_point_range: vec![],
                    integer_range: vec![],
                })
            })
            .collect::<Option<Vec<_>>>()
            .unwrap_or_default()
    }

    /// The checks rclcpp's `set_parameters_atomically` makes before the node's callbacks, in
    /// its order: every name declared, none read-only, none undeclared by NOT_SET, every
    /// value of its parameter's type. `Err(Refusal::NotDeclared)` is rclcpp's
    /// ParameterNotDeclaredException, which each service words in its own way.
    pub fn check(&self, parameters: &[raw::Parameter]) -> Result<(), Refusal> {
        for p in parameters {
            let Some(entry) = self.shown(&p.name) else {
                return Err(Refusal::NotDeclared(p.name.clone()));
            };
            if !entry.declared.writable {
                return Err(Refusal::Reason(format!(
                    "parameter '{}' cannot be set because it is read-only",
                    p.name
                )));
            }
        }
        if parameters.iter().any(|p| p.value.ptype == 0) {
            return Err(Refusal::Reason(
                "cannot undeclare a statically typed parameter".into(),
            ));
        }
        for p in parameters {
            let declared = self.entries[&p.name].declared.kind as u8;
            if p.value.ptype != declared {
                return Err(Refusal::Reason(format!(
                    "Wrong parameter type, parameter {{{}}} is of type {{{}}}, setting it to \
                     {{{}}} is not allowed.",
                    p.name,
                    type_name(declared),
                    type_name(p.value.ptype)
                )));
            }
        }
        Ok(())
    }

    /// The node's parameters as they would be with `parameters` set (already
    /// [`ParameterTable::check`]ed), read into `P` as the parameter file is; a value `P`
    /// refuses (an integer out of its type's range) is refused with serde's reason.
    pub fn proposed<P: NodeParameters>(&self, parameters: &[raw::Parameter]) -> Result<P, String> {
        let mut map = Map::new();
        for (name, entry) in &self.entries {
            if name != USE_SIM_TIME {
                map.insert(name.clone(), to_json(&entry.value));
            }
        }
        for p in parameters {
            map.insert(p.name.clone(), to_json(&p.value));
        }
        let file = Path::new("(the parameter services)");
        crate::params::parameters_from_map::<P>(map, file, "node").map_err(|e| match e {
            crate::params::ParamsError::Key { key, reason, .. } => {
                format!("parameter '{key}': {reason}")
            }
            other => other.to_string(),
        })
    }

    /// Stores `parameters` (checked, and taken by the node): the changed parameters of the
    /// `/parameter_events` message that announces them.
    pub fn apply(&mut self, parameters: &[raw::Parameter]) -> Vec<raw::Parameter> {
        for p in parameters {
            if let Some(entry) = self.entries.get_mut(&p.name) {
                entry.value = p.value.clone();
            }
        }
        parameters.to_vec()
    }
}

/// Why a set was refused before the node was asked.
#[derive(Debug, Clone, PartialEq)]
pub enum Refusal {
    /// rclcpp's ParameterNotDeclaredException: the name.
    NotDeclared(String),
    /// A SetParametersResult's reason.
    Reason(String),
}

/// `params` as a flat map of keys (the parameter file's form).
fn flat_values<P: Serialize>(params: &P) -> Result<Map<String, Value>, DescribeError> {
    match serde_json::to_value(params) {
        Ok(Value::Object(map)) => Ok(map),
        Ok(other) => Err(DescribeError::NotAMap(format!("{other}"))),
        Err(e) => Err(DescribeError::NotAMap(e.to_string())),
    }
}

fn empty_value(ptype: ParameterType) -> raw::ParameterValue {
    raw::ParameterValue {
        ptype: ptype as u8,
        boolean_value: false,
        int_value: 0,
        double_value: 0.0,
        string_value: String::new(),
        byte_array: vec![],
        bool_array: vec![],
        int_array: vec![],
        double_array: vec![],
        string_array: vec![],
    }
}

/// A parameter file's value as the ROS 2 value of type `kind`.
fn to_ros(json: &Value, kind: ParameterType) -> Result<raw::ParameterValue, String> {
    let mut v = empty_value(kind);
    let items = || match json {
        Value::Array(items) => Ok(items),
        other => Err(format!("{other} is not a list")),
    };
    let integer = |x: &Value| {
        x.as_i64()
            .ok_or_else(|| format!("{x} is not a 64-bit integer"))
    };
    let double = |x: &Value| x.as_f64().ok_or_else(|| format!("{x} is not a number"));
    let string = |x: &Value| {
        x.as_str()
            .map(String::from)
            .ok_or_else(|| format!("{x} is not a string"))
    };
    let boolean = |x: &Value| x.as_bool().ok_or_else(|| format!("{x} is not a bool"));
    match kind {
        ParameterType::Bool => v.boolean_value = boolean(json)?,
        ParameterType::Integer => v.int_value = integer(json)?,
        ParameterType::Double => v.double_value = double(json)?,
        ParameterType::String => v.string_value = string(json)?,
        ParameterType::ByteArray => {
            v.byte_array = items()?
                .iter()
                .map(|x| {
                    integer(x)
                        .and_then(|i| u8::try_from(i).map_err(|_| format!("{i} is not a byte")))
                })
                .collect::<Result<_, _>>()?
        }
        ParameterType::BoolArray => {
            v.bool_array = items()?.iter().map(boolean).collect::<Result<_, _>>()?
        }
        ParameterType::IntegerArray => {
            v.int_array = items()?.iter().map(integer).collect::<Result<_, _>>()?
        }
        ParameterType::DoubleArray => {
            v.double_array = items()?.iter().map(double).collect::<Result<_, _>>()?
        }
        ParameterType::StringArray => {
            v.string_array = items()?.iter().map(string).collect::<Result<_, _>>()?
        }
    }
    Ok(v)
}

/// A ROS 2 value as the parameter file's value (its type's field; NOT_SET is null).
fn to_json(v: &raw::ParameterValue) -> Value {
    let number = |x: f64| {
        serde_json::Number::from_f64(x)
            .map(Value::Number)
            .unwrap_or(Value::Null)
    };
    match v.ptype {
        1 => Value::Bool(v.boolean_value),
        2 => Value::from(v.int_value),
        3 => number(v.double_value),
        4 => Value::String(v.string_value.clone()),
        5 => Value::from(v.byte_array.clone()),
        6 => Value::from(v.bool_array.clone()),
        7 => Value::from(v.int_array.clone()),
        8 => Value::Array(v.double_array.iter().map(|x| number(*x)).collect()),
        9 => Value::from(v.string_array.clone()),
        _ => Value::Null,
    }
}

#[cfg(test)]
mod tests;
