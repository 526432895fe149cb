//! Reads a node's parameters from a ROS 2 parameter file (`params/<node>.yaml`), the same file
//! `ros2 run ... --ros-args --params-file` accepts, into the node's typed parameter struct.
//! Unknown keys and wrong types are startup errors that name the file and the key.

use serde::de::DeserializeOwned;
use serde_json::{Map, Value};
use std::path::{Path, PathBuf};

/// Why a parameter file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ParamsError {
    #[error("reading parameter file {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("parameter file {path} is not valid YAML: {reason}")]
    Yaml { path: PathBuf, reason: String },
    #[error(
        "parameter file {path} has no section for node {node:?} (expected a top-level key `{node}`, `/{node}`, `/**/{node}` or `/**` holding `ros__parameters:`)"
    )]
    NoSection { path: PathBuf, node: String },
    #[error("parameter file {path}: `{section}` must hold a `ros__parameters:` map")]
    Shape { path: PathBuf, section: String },
    #[error("parameter file {path}: {node}.ros__parameters.{key}: {reason}")]
    Key {
        path: PathBuf,
        node: String,
        key: String,
        reason: String,
    },
}

/// The flat `ros__parameters` map of `node` in `path` (nested maps flattened to `a.b`, as
/// ROS 2 does). Sections `/**` apply to every node; the node's own section wins.
pub fn read_parameter_map(path: &Path, node: &str) -> Result<Map<String, Value>, ParamsError> {
    let text = std::fs::read_to_string(path).map_err(|source| ParamsError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    parameter_map_from_str(&text, path, node)
}

/// As [`read_parameter_map`], from text (`path` only names the file in errors).
pub fn parameter_map_from_str(
    text: &str,
    path: &Path,
    node: &str,
) -> Result<Map<String, Value>, ParamsError> {
    let doc: Value = serde_saphyr::from_str(text).map_err(|e| ParamsError::Yaml {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let Value::Object(top) = doc else {
        return Err(ParamsError::NoSection {
            path: path.to_path_buf(),
            node: node.to_string(),
        });
    };
    let base = node.trim_start_matches('/');
    let base_name = base.rsplit('/').next().unwrap_or(base);
    // Least specific first, so later sections override earlier ones.
    let candidates = [
        "/**".to_string(),
        format!("/**/{base_name}"),
        base_name.to_string(),
        format!("/{base_name}"),
        format!("/{base}"),
    ];
    let mut flat = Map::new();
    let mut found = false;
    for key in candidates.iter() {
        let Some(section) = top.get(key) else {
            continue;
        };
        let params = section
            .get("ros__parameters")
            .and_then(Value::as_object)
            .ok_or_else(|| ParamsError::Shape {
                path: path.to_path_buf(),
                section: key.clone(),
            })?;
        flatten("", params, &mut flat);
        found = true;
    }
    if !found {
        return Err(ParamsError::NoSection {
            path: path.to_path_buf(),
            node: base_name.to_string(),
        });
    }
    Ok(flat)
}

fn flatten(prefix: &str, map: &Map<String, Value>, out: &mut Map<String, Value>) {
    for (k, v) in map {
        let key = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            Value::Object(inner) => flatten(&key, inner, out),
            other => {
                out.insert(key, other.clone());
            }
        }
    }
}

/// Applies command-line overrides `key:=value` (ROS 2's `-p key:=value`); the value is read
/// as YAML, so `0.2`, `true`, `[1, 2]` and `text` have their natural types.
pub fn apply_overrides(
    map: &mut Map<String, Value>,
    overrides: &[String],
    path: &Path,
    node: &str,
) -> Result<(), ParamsError> {
    for o in overrides {
        let (key, raw) = o.split_once(":=").ok_or_else(|| ParamsError::Key {
            path: path.to_path_buf(),
            node: node.to_string(),
            key: o.clone(),
            reason: "a parameter override must be KEY:=VALUE".into(),
        })?;
        let value: Value = serde_saphyr::from_str(raw).map_err(|e| ParamsError::Key {
            path: path.to_path_buf(),
            node: node.to_string(),
            key: key.to_string(),
            reason: format!("override value {raw:?} is not YAML: {e}"),
        })?;
        map.insert(key.trim().to_string(), value);
    }
    Ok(())
}

/// Deserialises a flat parameter map into `P` (which should use `deny_unknown_fields`).
/// `use_sim_time`, which rclcpp declares on every node and `ros2 param dump` writes, may be
/// `false`, as ours always is (`parameters::USE_SIM_TIME`); `true` is refused.
pub fn parameters_from_map<P: DeserializeOwned>(
    mut map: Map<String, Value>,
    path: &Path,
    node: &str,
) -> Result<P, ParamsError> {
    if let Some(sim) = map.remove(crate::parameters::USE_SIM_TIME)
        && sim != Value::Bool(false)
    {
        return Err(ParamsError::Key {
            path: path.to_path_buf(),
            node: node.to_string(),
            key: crate::parameters::USE_SIM_TIME.to_string(),
            reason: format!("{sim}: the suite's nodes keep the wall clock; only false is accepted"),
        });
    }
    let deserializer = Value::Object(map);
    serde_path_to_error::deserialize(deserializer).map_err(|e| {
        let key = e.path().to_string();
        let inner = e.into_inner().to_string();
        // serde names an unknown field in its message; lift it into the key.
        let key = match (key.as_str(), inner.strip_prefix("unknown field `")) {
            ("." | "", Some(rest)) => rest.split('`').next().unwrap_or("?").to_string(),
            _ => key,
        };
        ParamsError::Key {
            path: path.to_path_buf(),
            node: node.to_string(),
            key,
            reason: inner,
        }
    })
}

/// Reads `node`'s section of `path` into `P`.
pub fn load_parameters<P: DeserializeOwned>(path: &Path, node: &str) -> Result<P, ParamsError> {
    let map = read_parameter_map(path, node)?;
    parameters_from_map(map, path, node)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(deny_unknown_fields)]
    struct Demo {
        model_file: String,
        min_confidence: f64,
        #[serde(default)]
        cameras: Vec<String>,
        #[serde(rename = "qos.depth", default)]
        qos_depth: i64,
    }

    fn load(text: &str) -> Result<Demo, ParamsError> {
        let path = Path::new("params/demo.yaml");
        parameters_from_map(parameter_map_from_str(text, path, "demo")?, path, "demo")
    }

    #[test]
    fn reads_ros2_form_with_wildcards_and_nesting() {
        let d = load(
            "/**:\n  ros__parameters:\n    min_confidence: 0.2\n    model_file: a\ndemo:\n  ros__parameters:\n    model_file: m.json\n    cameras: [front, top]\n    qos:\n      depth: 5\n",
        )
        .expect("loads");
        assert_eq!(
            d,
            Demo {
                model_file: "m.json".into(),
                min_confidence: 0.2,
                cameras: vec!["front".into(), "top".into()],
                qos_depth: 5
            }
        );
    }

    #[test]
    fn overrides_replace_values_with_their_yaml_types() {
        let path = Path::new("params/demo.yaml");
        let mut map = parameter_map_from_str(
            "demo:\n  ros__parameters:\n    model_file: m\n    min_confidence: 0.5\n",
            path,
            "demo",
        )
        .expect("map");
        apply_overrides(
            &mut map,
            &["min_confidence:=0.9".into(), "cameras:=[a, b]".into()],
            path,
            "demo",
        )
        .expect("applies");
        let d: Demo = parameters_from_map(map.clone(), path, "demo").expect("typed");
        assert_eq!(
            (d.min_confidence, d.cameras),
            (0.9, vec!["a".to_string(), "b".to_string()])
        );
        assert!(apply_overrides(&mut map, &["nonsense".into()], path, "demo").is_err());
        apply_overrides(&mut map, &["min_confidense:=1".into()], path, "demo").expect("applies");
        assert!(
            parameters_from_map::<Demo>(map, path, "demo").is_err(),
            "unknown overridden key is refused"
        );
    }

    #[test]
    fn unknown_key_names_file_and_key() {
        let e = load("demo:\n  ros__parameters:\n    model_file: m\n    min_confidence: 1\n    min_confidnce: 2\n")
            .expect_err("unknown key");
        let msg = e.to_string();
        assert!(
            msg.contains("params/demo.yaml") && msg.contains("min_confidnce"),
            "{msg}"
        );
    }

    #[test]
    fn wrong_type_names_file_and_key() {
        let e = load("demo:\n  ros__parameters:\n    model_file: m\n    min_confidence: high\n")
            .expect_err("wrong type");
        let msg = e.to_string();
        assert!(
            msg.contains("params/demo.yaml") && msg.contains("min_confidence"),
            "{msg}"
        );
    }

    #[test]
    fn use_sim_time_false_is_accepted_and_true_refused() {
        let d = load("demo:\n  ros__parameters:\n    model_file: m\n    min_confidence: 1.0\n    use_sim_time: false\n")
            .expect("use_sim_time: false, as ros2 param dump writes it");
        assert_eq!(d.model_file, "m");
        let e = load("demo:\n  ros__parameters:\n    model_file: m\n    min_confidence: 1.0\n    use_sim_time: true\n")
            .expect_err("use_sim_time: true");
        assert!(e.to_string().contains("use_sim_time"), "{e}");
        assert!(e.to_string().contains("wall clock"), "{e}");
    }

    #[test]
    fn missing_section_and_bad_yaml_are_named() {
        let e = load("other:\n  ros__parameters:\n    x: 1\n").expect_err("no section");
        assert!(
            e.to_string().contains("no section for node \"demo\""),
            "{e}"
        );
        let e = load("demo: [unclosed\n").expect_err("bad yaml");
        assert!(e.to_string().contains("not valid YAML"), "{e}");
        let e = load("demo:\n  params: {}\n").expect_err("no ros__parameters");
        assert!(e.to_string().contains("ros__parameters"), "{e}");
    }
}
