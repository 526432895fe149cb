//! The launch description: a ROS 2 YAML launch file (`launch:` list of `arg`, `set_env` and
//! `executable` actions) with `$(var NAME)` and `$(env NAME [default])` substitutions, turned
//! into the list of processes to start. Pure: no processes here.

use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    #[error("launch file {path} is not a ROS 2 YAML launch file: {reason}")]
    Format { path: PathBuf, reason: String },
    #[error("launch file {path}: {reason}")]
    Invalid { path: PathBuf, reason: String },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LaunchFile {
    launch: Vec<Action>,
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
enum Action {
    Arg(ArgAction),
    SetEnv(EnvEntry),
    Executable(ExecutableAction),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ArgAction {
    name: String,
    default: Option<String>,
    #[serde(default)]
    description: Option<String>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct EnvEntry {
    name: String,
    value: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ExecutableAction {
    cmd: String,
    name: Option<String>,
    args: Option<String>,
    cwd: Option<String>,
    #[serde(default)]
    env: Vec<EnvEntry>,
    output: Option<String>,
    respawn: Option<String>,
    respawn_delay: Option<String>,
    /// `shutdown`: when this process ends, stop the whole launch (as XML's on_exit).
    on_exit: Option<String>,
    /// Start the process only if this is true (ROS 2's `if`: true, false, 1 or 0).
    #[serde(rename = "if")]
    if_true: Option<String>,
    /// Start the process only if this is false (ROS 2's `unless`).
    unless: Option<String>,
}

/// A launch condition's value as ROS 2 reads it.
fn condition(value: &str) -> Option<bool> {
    match value.trim().to_ascii_lowercase().as_str() {
        "true" | "1" => Some(true),
        "false" | "0" => Some(false),
        _ => None,
    }
}

/// Where a process's output lines go (`output:` of an executable, as in ROS 2 launch).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OutputTo {
    /// The launcher's terminal, prefixed by the process's name.
    #[default]
    Screen,
    /// The process's log file, `<log dir>/<name>.log`.
    Log,
    Both,
}

impl OutputTo {
    pub fn to_screen(self) -> bool {
        self != OutputTo::Log
    }
    pub fn to_log(self) -> bool {
        self != OutputTo::Screen
    }
}

/// One process to run.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcessSpec {
    pub name: String,
    pub program: String,
    pub args: Vec<String>,
    pub cwd: Option<PathBuf>,
    pub env: Vec<(String, String)>,
    pub respawn: bool,
    pub respawn_delay_secs: f64,
    pub shutdown_on_exit: bool,
    pub output: OutputTo,
}

/// Parses `text` (from `path`, used in errors and to resolve relative `cwd`) with the launch
/// arguments `overrides` (`name:=value` on the command line).
pub fn parse_launch(
    text: &str,
    path: &Path,
    overrides: &BTreeMap<String, String>,
) -> Result<Vec<ProcessSpec>, LaunchError> {
    let invalid = |reason: String| LaunchError::Invalid {
        path: path.to_path_buf(),
        reason,
    };
    let file: LaunchFile = serde_saphyr::from_str(text).map_err(|e| LaunchError::Format {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let mut vars: BTreeMap<String, String> = BTreeMap::new();
    let mut declared = Vec::new();
    let mut global_env: Vec<(String, String)> = Vec::new();
    let mut processes = Vec::new();
    for action in file.launch {
        match action {
            Action::Arg(arg) => {
                let _ = arg.description;
                let value = match (overrides.get(&arg.name), &arg.default) {
                    (Some(v), _) => v.clone(),
                    (None, Some(d)) => substitute(d, &vars).map_err(invalid)?,
                    (None, None) => {
                        return Err(invalid(format!(
                            "argument {:?} has no default: pass {}:=VALUE",
                            arg.name, arg.name
                        )));
                    }
                };
                declared.push(arg.name.clone());
                vars.insert(arg.name, value);
            }
            Action::SetEnv(e) => {
                global_env.push((e.name, substitute(&e.value, &vars).map_err(invalid)?));
            }
            Action::Executable(x) => {
                let mut wanted = true;
                for (key, value, start_if) in
                    [("if", &x.if_true, true), ("unless", &x.unless, false)]
                {
                    if let Some(v) = value {
                        let v = substitute(v, &vars).map_err(invalid)?;
                        let b = condition(&v).ok_or_else(|| {
                            invalid(format!(
                                "{}: {key} {v:?} is not true, false, 1 or 0",
                                x.name.as_deref().unwrap_or(&x.cmd)
                            ))
                        })?;
                        wanted &= b == start_if;
                    }
                }
                if !wanted {
                    continue;
                }
                let cmd = substitute(&x.cmd, &vars).map_err(invalid)?;
                let mut words = shlex::split(&cmd)
                    .ok_or_else(|| invalid(format!("cmd {cmd:?} has unbalanced quotes")))?;
                if let Some(args) = &x.args {
                    let args = substitute(args, &vars).map_err(invalid)?;
                    words.extend(
                        shlex::split(&args).ok_or_else(|| {
                            invalid(format!("args {args:?} have unbalanced quotes"))
                        })?,
                    );
                }
                // `cmd: "''"` splits into one empty word: no program either (found by fuzzing).
                if words.first().is_none_or(|w| w.trim().is_empty()) {
                    return Err(invalid(format!(
                        "an executable has no program in cmd {cmd:?}"
                    )));
                }
                let program = words.remove(0);
                let name = match &x.name {
                    Some(n) => substitute(n, &vars).map_err(invalid)?,
                    None => Path::new(&program)
                        .file_name()
                        .map(|f| f.to_string_lossy().to_string())
                        .unwrap_or_else(|| program.clone()),
                };
                if processes.iter().any(|p: &ProcessSpec| p.name == name) {
                    return Err(invalid(format!("two executables are named {name:?}")));
                }
                let output = match x.output.as_deref() {
                    None | Some("screen") => OutputTo::Screen,
                    Some("log") => OutputTo::Log,
                    Some("both") => OutputTo::Both,
                    Some(o) => {
                        return Err(invalid(format!(
                            "{name}: output {o:?} is not screen, log or both"
                        )));
                    }
                };
                let expand = |v: &Option<String>| -> Result<Option<String>, LaunchError> {
                    v.as_deref()
                        .map(|t| substitute(t, &vars).map_err(invalid))
                        .transpose()
                };
                let (respawn, respawn_delay, on_exit) = (
                    expand(&x.respawn)?,
                    expand(&x.respawn_delay)?,
                    expand(&x.on_exit)?,
                );
                let flag = |v: &Option<String>, what: &str| -> Result<bool, LaunchError> {
                    match v.as_deref().map(str::trim) {
                        None | Some("false") | Some("False") => Ok(false),
                        Some("true") | Some("True") => Ok(true),
                        Some(other) => Err(invalid(format!(
                            "{name}: {what} {other:?} is not true or false"
                        ))),
                    }
                };
                let respawn = flag(&respawn, "respawn")?;
                let respawn_delay_secs = match &respawn_delay {
                    None => 0.0,
                    Some(d) => d
                        .trim()
                        .parse::<f64>()
                        .ok()
                        .filter(|d| d.is_finite() && *d >= 0.0)
                        .ok_or_else(|| {
                            invalid(format!("{name}: respawn_delay {d:?} is not seconds"))
                        })?,
                };
                let shutdown_on_exit = match on_exit.as_deref() {
                    None => false,
                    Some("shutdown") => true,
                    Some(other) => {
                        return Err(invalid(format!(
                            "{name}: on_exit {other:?} is not shutdown"
                        )));
                    }
                };
                let mut env = global_env.clone();
                for e in &x.env {
                    env.push((
                        e.name.clone(),
                        substitute(&e.value, &vars).map_err(invalid)?,
                    ));
                }
                let cwd = match &x.cwd {
                    None => None,
                    Some(c) => Some(PathBuf::from(substitute(c, &vars).map_err(invalid)?)),
                };
                processes.push(ProcessSpec {
                    name,
                    program,
                    args: words,
                    cwd,
                    env,
                    respawn,
                    respawn_delay_secs,
                    shutdown_on_exit,
                    output,
                });
            }
        }
    }
    if let Some(unknown) = overrides.keys().find(|k| !declared.contains(k)) {
        return Err(invalid(format!(
            "{unknown}:= is not an argument of this launch file (it declares {declared:?})"
        )));
    }
    Ok(processes)
}

/// Expands `$(var NAME)` and `$(env NAME [default])`.
fn substitute(text: &str, vars: &BTreeMap<String, String>) -> Result<String, String> {
    let mut out = String::new();
    let mut rest = text;
    while let Some(start) = rest.find("$(") {
        out.push_str(&rest[..start]);
        let after = &rest[start + 2..];
        let end = after
            .find(')')
            .ok_or_else(|| format!("unclosed substitution in {text:?}"))?;
        let inner: Vec<&str> = after[..end].split_whitespace().collect();
        let value = match inner.as_slice() {
            ["var", name] => vars
                .get(*name)
                .cloned()
                .ok_or_else(|| format!("$(var {name}) names no argument declared before it"))?,
            ["env", name] => std::env::var(name).map_err(|_| {
                format!("$(env {name}) is not set (give a default: $(env {name} value))")
            })?,
            ["env", name, default @ ..] => {
                std::env::var(name).unwrap_or_else(|_| default.join(" "))
            }
            _ => return Err(format!("unknown substitution $({})", &after[..end])),
        };
        out.push_str(&value);
        rest = &after[end + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str, overrides: &[(&str, &str)]) -> Result<Vec<ProcessSpec>, LaunchError> {
        let o = overrides
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        parse_launch(text, Path::new("launch_scripts/demo.launch.yaml"), &o)
    }

    const DEMO: &str = r#"
launch:
- arg: {name: seed, default: "7"}
- arg: {name: bin, default: target/debug}
- set_env: {name: ROS_LOCALHOST_ONLY, value: "1"}
- executable:
    cmd: $(var bin)/policy run
    name: behaviour_policy
    args: "--seed $(var seed) --note 'two words'"
    env:
    - {name: RUST_LOG, value: debug}
    respawn: "true"
    respawn_delay: "0.5"
- executable:
    cmd: $(var bin)/game_manager
    on_exit: shutdown
"#;

    #[test]
    fn parses_actions_arguments_and_substitutions() {
        let p = parse(DEMO, &[("seed", "42")]).expect("parses");
        assert_eq!(p.len(), 2);
        assert_eq!(p[0].name, "behaviour_policy");
        assert_eq!(p[0].program, "target/debug/policy");
        assert_eq!(p[0].args, ["run", "--seed", "42", "--note", "two words"]);
        assert_eq!(
            p[0].env,
            [
                ("ROS_LOCALHOST_ONLY".into(), "1".into()),
                ("RUST_LOG".into(), "debug".into())
            ]
        );
        assert!(p[0].respawn && !p[0].shutdown_on_exit);
        assert_eq!(p[0].respawn_delay_secs, 0.5);
        assert_eq!(p[1].name, "game_manager");
        assert!(p[1].shutdown_on_exit && !p[1].respawn);
    }

    #[test]
    fn mistakes_are_named() {
        let e = parse(DEMO, &[("sed", "1")]).expect_err("unknown arg");
        assert!(e.to_string().contains("sed:= is not an argument"), "{e}");
        let e =
            parse("launch:\n- executable: {cmd: x, respawn: maybe}\n", &[]).expect_err("bad flag");
        assert!(e.to_string().contains("respawn \"maybe\""), "{e}");
        let e = parse("launch:\n- executable: {cmd: $(var nope)}\n", &[]).expect_err("undeclared");
        assert!(e.to_string().contains("$(var nope)"), "{e}");
        let e = parse("launch:\n- node: {pkg: x, exec: y}\n", &[]).expect_err("unsupported action");
        assert!(e.to_string().contains("demo.launch.yaml"), "{e}");
        let e = parse(
            "launch:\n- executable: {cmd: a}\n- executable: {cmd: a}\n",
            &[],
        )
        .expect_err("dup");
        assert!(e.to_string().contains("two executables"), "{e}");
        for cmd in ["\"\"", "\"''\"", "\"'  '\""] {
            let text = format!("launch:\n- executable: {{cmd: {cmd}}}\n");
            let e = parse(&text, &[]).expect_err("no program");
            assert!(e.to_string().contains("no program"), "{cmd}: {e}");
        }
        let e = parse("launch:\n- arg: {name: x}\n", &[]).expect_err("no default");
        assert!(e.to_string().contains("x:=VALUE"), "{e}");
        let e = parse(
            "launch:\n- executable: {cmd: a, name: cam, if: perhaps}\n",
            &[],
        )
        .expect_err("bad condition");
        assert!(
            e.to_string().contains("cam: if \"perhaps\" is not true"),
            "{e}"
        );
    }

    #[test]
    fn if_and_unless_start_a_process_or_leave_it_out() {
        let text = "launch:\n\
            - arg: {name: camera, default: \"false\"}\n\
            - executable: {cmd: bridge, if: $(var camera)}\n\
            - executable: {cmd: stand_in, unless: $(var camera)}\n\
            - executable: {cmd: always}\n";
        let names = |camera: &str| -> Vec<String> {
            parse(text, &[("camera", camera)])
                .expect("parses")
                .into_iter()
                .map(|p| p.name)
                .collect()
        };
        assert_eq!(names("false"), ["stand_in", "always"]);
        assert_eq!(names("True"), ["bridge", "always"]);
        assert_eq!(names("1"), ["bridge", "always"]);
    }
}
