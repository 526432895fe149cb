//! ROS 2 type descriptions and their RIHS01 type hashes (REP-2011), computed from the `.msg`
//! and `.srv` text exactly as Jazzy's `rosidl_generator_type_description` computes them
//! (`rosidl_generator_type_description/__init__.py`: `serialize_individual_type_description`,
//! `extract_full_type_description`, `calculate_type_hash`). A ROS 2 endpoint carries its type's
//! hash in its USER_DATA (`typehash=RIHS01_<hex>;`), and `~/get_type_description` answers with
//! the description. `tests/ros2/rosidl_hashes.py` runs rosidl's own code on the same files, the
//! independent check of [`TypeDescription::hash`].

use crate::definition::{Dependency, MessageDefinition};
use crate::services::ServiceDefinition;
use std::fmt;

/// The type ids of `type_description_interfaces/msg/FieldType.msg`.
pub mod field_type {
    pub const NESTED_TYPE: u8 = 1;
    pub const INT8: u8 = 2;
    pub const UINT8: u8 = 3;
    pub const INT16: u8 = 4;
    pub const UINT16: u8 = 5;
    pub const INT32: u8 = 6;
    pub const UINT32: u8 = 7;
    pub const INT64: u8 = 8;
    pub const UINT64: u8 = 9;
    pub const FLOAT: u8 = 10;
    pub const DOUBLE: u8 = 11;
    pub const CHAR: u8 = 13;
    pub const BOOLEAN: u8 = 15;
    pub const BYTE: u8 = 16;
    pub const STRING: u8 = 17;
    pub const WSTRING: u8 = 18;
    pub const BOUNDED_STRING: u8 = 21;
    pub const BOUNDED_WSTRING: u8 = 22;
    /// Added to a value type's id for a fixed-size array (`T[N]`).
    pub const ARRAY: u8 = 48;
    /// Added for a bounded sequence (`T[<=N]`).
    pub const BOUNDED_SEQUENCE: u8 = 96;
    /// Added for an unbounded sequence (`T[]`).
    pub const UNBOUNDED_SEQUENCE: u8 = 144;
}

/// `type_description_interfaces/msg/FieldType`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldType {
    pub type_id: u8,
    /// The array's size or the sequence's bound; 0 otherwise.
    pub capacity: u64,
    /// A bounded string's bound; 0 otherwise.
    pub string_capacity: u64,
    /// `pkg/msg/Type` of a nested type; empty otherwise.
    pub nested_type_name: String,
}

/// `type_description_interfaces/msg/Field`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldDescription {
    pub name: String,
    pub field_type: FieldType,
    /// The default as the `.msg` writes it (not part of the hash).
    pub default_value: String,
}

/// `type_description_interfaces/msg/IndividualTypeDescription`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IndividualTypeDescription {
    /// `pkg/msg/Type` or `pkg/srv/Type_Request`.
    pub type_name: String,
    pub fields: Vec<FieldDescription>,
}

/// `type_description_interfaces/msg/TypeDescription`: a type and every type it refers to,
/// sorted by name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TypeDescription {
    pub type_description: IndividualTypeDescription,
    pub referenced_type_descriptions: Vec<IndividualTypeDescription>,
}

/// A RIHS01 type hash: SHA-256 of the description's canonical JSON.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TypeHash(pub [u8; 32]);

impl TypeHash {
    /// RIHS version 1, as `rosidl_type_hash_t.version` has it.
    pub const VERSION: u8 = 1;

    /// `typehash=RIHS01_<hex>;`, the USER_DATA of a ROS 2 endpoint
    /// (`rmw_dds_common::encode_type_hash_for_user_data_qos`).
    pub fn user_data(&self) -> String {
        format!("typehash={self};")
    }

    /// Parses `RIHS01_<64 hex digits>`.
    pub fn parse(text: &str) -> Option<TypeHash> {
        let hex = text.strip_prefix("RIHS01_")?;
        if hex.len() != 64 {
            return None;
        }
        let mut out = [0u8; 32];
        for (i, byte) in out.iter_mut().enumerate() {
            *byte = u8::from_str_radix(hex.get(2 * i..2 * i + 2)?, 16).ok()?;
        }
        Some(TypeHash(out))
    }
}

impl fmt::Display for TypeHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("RIHS01_")?;
        for b in self.0 {
            write!(f, "{b:02x}")?;
        }
        Ok(())
    }
}

/// Why a definition could not be described.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DescriptionError {
    #[error("{type_name}: line {line:?} is not `TYPE NAME [DEFAULT]` or `TYPE NAME=VALUE`")]
    Line { type_name: String, line: String },
    #[error("{type_name}: field {field}: unknown type {ros_type:?}")]
    Type {
        type_name: String,
        field: String,
        ros_type: String,
    },
    #[error("{type_name} refers to {missing}, whose definition is not known")]
    Missing { type_name: String, missing: String },
}

/// The `.msg` primitive types, as rosidl_adapter maps them to IDL and the generator to ids
/// (`char` is IDL `uint8`, `byte` is `octet`).
fn primitive_id(ros_type: &str) -> Option<u8> {
    use field_type::*;
    Some(match ros_type {
        "bool" => BOOLEAN,
        "byte" => BYTE,
        "char" => UINT8,
        "int8" => INT8,
        "uint8" => UINT8,
        "int16" => INT16,
        "uint16" => UINT16,
        "int32" => INT32,
        "uint32" => UINT32,
        "int64" => INT64,
        "uint64" => UINT64,
        "float32" => FLOAT,
        "float64" => DOUBLE,
        "string" => STRING,
        "wstring" => WSTRING,
        _ => return None,
    })
}

/// `pkg/Type` (or `Type`, in `package`) as `pkg/msg/Type`.
fn nested_name(ros_type: &str, package: &str) -> Option<String> {
    let valid = |s: &str| !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    match ros_type.split_once('/') {
        Some((pkg, ty)) if valid(pkg) && valid(ty) => Some(format!("{pkg}/msg/{ty}")),
        None if ros_type == "Header" => Some("std_msgs/msg/Header".to_string()),
        None if valid(ros_type) => Some(format!("{package}/msg/{ros_type}")),
        _ => None,
    }
}

/// A field's `.msg` type as a `FieldType`, names of nested types resolved in `package`.
fn field_type(ros_type: &str, package: &str) -> Option<FieldType> {
    use field_type::*;
    let (base, suffix, capacity) = match ros_type.find('[') {
        None => (ros_type, 0, 0),
        Some(i) => {
            let inner = ros_type[i..].strip_prefix('[')?.strip_suffix(']')?;
            let base = &ros_type[..i];
            if inner.is_empty() {
                (base, UNBOUNDED_SEQUENCE, 0)
            } else if let Some(bound) = inner.strip_prefix("<=") {
                (base, BOUNDED_SEQUENCE, bound.parse().ok()?)
            } else {
                (base, ARRAY, inner.parse().ok()?)
            }
        }
    };
    let (value_id, string_capacity, nested_type_name) =
        if let Some(bound) = base.strip_prefix("string<=") {
            (BOUNDED_STRING, bound.parse().ok()?, String::new())
        } else if let Some(bound) = base.strip_prefix("wstring<=") {
            (BOUNDED_WSTRING, bound.parse().ok()?, String::new())
        } else if let Some(id) = primitive_id(base) {
            (id, 0, String::new())
        } else {
            (NESTED_TYPE, 0, nested_name(base, package)?)
        };
    Some(FieldType {
        type_id: value_id + suffix,
        capacity,
        string_capacity,
        nested_type_name,
    })
}

/// The fields of one `.msg` text (or half a `.srv`) named `type_name` (`pkg/msg/Type`);
/// constants are not fields, and a definition without fields gets rosidl's
/// `uint8 structure_needs_at_least_one_member`.
pub fn individual_description(
    type_name: &str,
    text: &str,
) -> Result<IndividualTypeDescription, DescriptionError> {
    let package = type_name.split('/').next().unwrap_or("");
    let mut fields = Vec::new();
    for raw in text.lines() {
        let line = strip_comment(raw).trim();
        if line.is_empty() {
            continue;
        }
        let bad_line = || DescriptionError::Line {
            type_name: type_name.to_string(),
            line: raw.to_string(),
        };
        let (ros_type, rest) = line.split_once(char::is_whitespace).ok_or_else(bad_line)?;
        let rest = rest.trim();
        // `TYPE NAME=VALUE` (or `TYPE NAME = VALUE`) is a constant.
        let name_end = rest
            .find(|c: char| c.is_whitespace() || c == '=')
            .unwrap_or(rest.len());
        let (name, after) = rest.split_at(name_end);
        if name.is_empty() {
            return Err(bad_line());
        }
        if after.trim_start().starts_with('=') {
            continue;
        }
        let field_type = field_type(ros_type, package).ok_or_else(|| DescriptionError::Type {
            type_name: type_name.to_string(),
            field: name.to_string(),
            ros_type: ros_type.to_string(),
        })?;
        fields.push(FieldDescription {
            name: name.to_string(),
            field_type,
            default_value: default_text(after.trim()),
        });
    }
    if fields.is_empty() {
        fields.push(FieldDescription {
            name: "structure_needs_at_least_one_member".to_string(),
            field_type: FieldType {
                type_id: field_type::UINT8,
                capacity: 0,
                string_capacity: 0,
                nested_type_name: String::new(),
            },
            default_value: String::new(),
        });
    }
    Ok(IndividualTypeDescription {
        type_name: type_name.to_string(),
        fields,
    })
}

/// A line without its comment; a `#` inside a quoted default or constant value stays.
fn strip_comment(line: &str) -> &str {
    let mut quote = None;
    for (i, c) in line.char_indices() {
        match (quote, c) {
            (None, '#') => return &line[..i],
            (None, '"' | '\'') => quote = Some(c),
            (Some(q), c) if c == q => quote = None,
            _ => {}
        }
    }
    line
}

/// A default as rosidl's description keeps it: a string's content without its quotes.
fn default_text(raw: &str) -> String {
    let unquoted = raw
        .strip_prefix('"')
        .and_then(|r| r.strip_suffix('"'))
        .or_else(|| raw.strip_prefix('\'').and_then(|r| r.strip_suffix('\'')));
    unquoted.unwrap_or(raw).to_string()
}

impl TypeDescription {
    /// `type_name`'s description from its text and the texts of the types it refers to
    /// (`known`: `pkg/msg/Type` and its text); only those reached from `type_name` are kept,
    /// sorted by name (`extract_full_type_description`).
    pub fn from_texts(
        type_name: &str,
        text: &str,
        known: &[(String, &str)],
    ) -> Result<TypeDescription, DescriptionError> {
        let top = individual_description(type_name, text)?;
        let mut referenced: Vec<IndividualTypeDescription> = Vec::new();
        let mut queue: Vec<String> = nested_names(&top);
        while let Some(name) = queue.pop() {
            if referenced.iter().any(|d| d.type_name == name) {
                continue;
            }
            let (_, text) = known.iter().find(|(n, _)| *n == name).ok_or_else(|| {
                DescriptionError::Missing {
                    type_name: type_name.to_string(),
                    missing: name.clone(),
                }
            })?;
            let description = individual_description(&name, text)?;
            queue.extend(nested_names(&description));
            referenced.push(description);
        }
        referenced.sort_by(|a, b| a.type_name.cmp(&b.type_name));
        Ok(TypeDescription {
            type_description: top,
            referenced_type_descriptions: referenced,
        })
    }

    /// The description of message `M`, from its `.msg` text and its dependencies'.
    pub fn of_message<M: MessageDefinition>() -> Result<TypeDescription, DescriptionError> {
        let type_name = format!("{}/msg/{}", M::PACKAGE, M::NAME);
        Self::with_dependencies::<M>(&type_name)
    }

    /// The descriptions of service `S`'s request and response (`pkg/srv/S_Request`, ...),
    /// the types a ROS 2 service's request and reply endpoints carry the hashes of.
    pub fn of_service<S: ServiceDefinition>()
    -> Result<(TypeDescription, TypeDescription), DescriptionError> {
        let request = format!("{}/srv/{}_Request", S::PACKAGE, S::NAME);
        let response = format!("{}/srv/{}_Response", S::PACKAGE, S::NAME);
        Ok((
            Self::with_dependencies::<S::Request>(&request)?,
            Self::with_dependencies::<S::Response>(&response)?,
        ))
    }

    fn with_dependencies<M: MessageDefinition>(
        type_name: &str,
    ) -> Result<TypeDescription, DescriptionError> {
        let mut deps: Vec<Dependency> = Vec::new();
        for collect in M::field_dependency_collectors() {
            collect(&mut deps);
        }
        let known: Vec<(String, &str)> = deps
            .iter()
            .map(|d| {
                let full = match d.name.split_once('/') {
                    Some((pkg, ty)) => format!("{pkg}/msg/{ty}"),
                    None => d.name.clone(),
                };
                (full, d.text)
            })
            .collect();
        Self::from_texts(type_name, M::definition_text(), &known)
    }

    /// The canonical JSON that is hashed: Python's `json.dumps(..., separators=(', ', ': '))`
    /// of the description without default values, keys in rosidl's order.
    pub fn hash_input(&self) -> String {
        let mut out = String::from("{\"type_description\": ");
        individual_json(&self.type_description, &mut out);
        out.push_str(", \"referenced_type_descriptions\": [");
        for (i, d) in self.referenced_type_descriptions.iter().enumerate() {
            if i > 0 {
                out.push_str(", ");
            }
            individual_json(d, &mut out);
        }
        out.push_str("]}");
        out
    }

    /// The RIHS01 hash.
    pub fn hash(&self) -> TypeHash {
        use sha2::Digest as _;
        TypeHash(sha2::Sha256::digest(self.hash_input().as_bytes()).into())
    }
}

fn nested_names(d: &IndividualTypeDescription) -> Vec<String> {
    d.fields
        .iter()
        .map(|f| f.field_type.nested_type_name.clone())
        .filter(|n| !n.is_empty())
        .collect()
}

fn individual_json(d: &IndividualTypeDescription, out: &mut String) {
    out.push_str("{\"type_name\": ");
    json_string(&d.type_name, out);
    out.push_str(", \"fields\": [");
    for (i, f) in d.fields.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        out.push_str("{\"name\": ");
        json_string(&f.name, out);
        let t = &f.field_type;
        out.push_str(&format!(
            ", \"type\": {{\"type_id\": {}, \"capacity\": {}, \"string_capacity\": {}, \"nested_type_name\": ",
            t.type_id, t.capacity, t.string_capacity
        ));
        json_string(&t.nested_type_name, out);
        out.push_str("}}");
    }
    out.push_str("]}");
}

/// A JSON string as Python's `json.dumps(ensure_ascii=True)` writes it.
fn json_string(s: &str, out: &mut String) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 || (c as u32) > 0x7e => {
                let mut buf = [0u16; 2];
                for unit in c.encode_utf16(&mut buf) {
                    out.push_str(&format!("\\u{unit:04x}"));
                }
            }
            c => out.push(c),
        }
    }
    out.push('"');
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::std_msgs::{Header, StringMsg};

    // The hashes Jazzy's std_msgs and builtin_interfaces ship (share/<pkg>/msg/<Type>.json
    // of the ros-jazzy-* wheels); tests/ros2/rosidl_hashes.py checks every type of the suite.
    #[test]
    fn standard_types_hash_as_jazzy_ships_them() {
        assert_eq!(
            TypeDescription::of_message::<StringMsg>()
                .expect("describes")
                .hash()
                .to_string(),
            "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
        );
        assert_eq!(
            TypeDescription::of_message::<Header>()
                .expect("describes")
                .hash()
                .to_string(),
            "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01"
        );
    }

    #[test]
    fn field_types_follow_rosidl() {
        let d = individual_description(
            "p/msg/T",
            "# c\nuint8 A = 1\nstring NAME=\"x#y\"\nfloat32[32] f # c\nstring<=8[<=3] s\nT2[] n\nHeader h\nchar c\nbyte b\nfloat32 speed 0.0\nstring e \"\"\n",
        )
        .expect("parses");
        let ids: Vec<(&str, u8, u64, u64, &str)> = d
            .fields
            .iter()
            .map(|f| {
                let t = &f.field_type;
                (
                    f.name.as_str(),
                    t.type_id,
                    t.capacity,
                    t.string_capacity,
                    t.nested_type_name.as_str(),
                )
            })
            .collect();
        assert_eq!(
            ids,
            vec![
                ("f", 58, 32, 0, ""),
                ("s", 117, 3, 8, ""),
                ("n", 145, 0, 0, "p/msg/T2"),
                ("h", 1, 0, 0, "std_msgs/msg/Header"),
                ("c", 3, 0, 0, ""),
                ("b", 16, 0, 0, ""),
                ("speed", 10, 0, 0, ""),
                ("e", 17, 0, 0, ""),
            ]
        );
        assert_eq!(d.fields[6].default_value, "0.0");
        let empty = individual_description("p/srv/S_Request", "# nothing\n").expect("parses");
        assert_eq!(empty.fields[0].name, "structure_needs_at_least_one_member");
    }

    #[test]
    fn a_missing_dependency_or_bad_line_is_named() {
        let e = TypeDescription::from_texts("p/msg/T", "Other o\n", &[]).expect_err("missing");
        assert!(e.to_string().contains("p/msg/Other"), "{e}");
        let e = individual_description("p/msg/T", "float32\n").expect_err("bad line");
        assert!(e.to_string().contains("float32"), "{e}");
        assert!(TypeHash::parse("RIHS01_00").is_none());
        let h = TypeDescription::of_message::<StringMsg>()
            .expect("describes")
            .hash();
        assert_eq!(TypeHash::parse(&h.to_string()), Some(h));
    }
}
