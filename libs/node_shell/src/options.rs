//! The command-line options every node accepts and where its parameter file is found: the
//! options' job ends with the node's typed parameters, before anything joins a graph.

use crate::params::{apply_overrides, parameters_from_map, read_parameter_map};
use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};

/// Command-line options every node accepts (flatten into the node's clap struct).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ShellOptions {
    /// ROS 2 parameter file [default: $QT_PARAMS_DIR/<node>.yaml, else params/<node>.yaml,
    /// else /etc/qt-therapy/<node>.yaml where the package installed it]
    #[arg(long)]
    pub params_file: Option<PathBuf>,
    /// Node name on the ROS graph; also the section read from the parameter file.
    #[arg(long)]
    pub node_name: Option<String>,
    /// Node namespace.
    #[arg(long, default_value = "/")]
    pub namespace: String,
    /// Service mapping: `enhanced` talks to rmw_fastrtps peers, `cyclone` to rmw_cyclonedds.
    #[arg(long, env = "QT_SERVICE_MAPPING", default_value = "enhanced")]
    pub service_mapping: String,
    /// Override one parameter of the file, as ROS 2's `-p`: `--param time_scale:=0.2`.
    #[arg(long = "param", value_name = "KEY:=VALUE")]
    pub param_overrides: Vec<String>,
    /// SROS2 enclave of this node, e.g. /qt_therapy/tablet_bridge (used when
    /// ROS_SECURITY_ENABLE=true; ROS_SECURITY_ENCLAVE_OVERRIDE wins over it, as in rcl).
    /// Always accepted, so launch files need no per-build variant; a build without the
    /// `security` feature refuses to start when security is enabled.
    #[arg(long)]
    pub enclave: Option<String>,
}

impl ShellOptions {
    /// The `--enclave` argument.
    pub fn enclave_arg(&self) -> Option<&str> {
        self.enclave.as_deref()
    }

    /// The parameter file this node reads.
    pub fn params_path(&self, node_name: &str) -> PathBuf {
        if let Some(p) = &self.params_file {
            return p.clone();
        }
        let dir = params_dir(
            std::env::var_os("QT_PARAMS_DIR").filter(|d| !d.is_empty()),
            |d| d.is_dir(),
        );
        dir.join(format!("{node_name}.yaml"))
    }

    /// The node's name: `--node-name`, else `default_name`.
    pub fn node_name_or(&self, default_name: &str) -> String {
        self.node_name
            .clone()
            .unwrap_or_else(|| default_name.to_string())
    }

    /// The node's parameters as `NodeShell::start` reads them (its file, then the `--param`
    /// overrides, into `P`), and the file's path: for a node that must check them before it
    /// joins the graph, and for a node run in process.
    pub fn parameters<P: DeserializeOwned>(
        &self,
        default_name: &str,
    ) -> anyhow::Result<(P, PathBuf)> {
        let name = self.node_name_or(default_name);
        let path = self.params_path(&name);
        let mut map = read_parameter_map(&path, &name)?;
        apply_overrides(&mut map, &self.param_overrides, &path, &name)?;
        let params = parameters_from_map(map, &path, &name)?;
        Ok((params, path))
    }
}

/// Where the qt-therapy package installs the parameter files (conffiles).
pub const INSTALLED_PARAMS_DIR: &str = "/etc/qt-therapy";

/// The directory the parameter files are read from: `QT_PARAMS_DIR`, else `params/` (in the
/// workspace), else the package's `/etc/qt-therapy` when it is there, so an installed program
/// started from anywhere finds its files; else `params/`, which the error then names.
fn params_dir(env: Option<std::ffi::OsString>, is_dir: impl Fn(&Path) -> bool) -> PathBuf {
    if let Some(dir) = env {
        return PathBuf::from(dir);
    }
    let workspace = Path::new("params");
    if !is_dir(workspace) && is_dir(Path::new(INSTALLED_PARAMS_DIR)) {
        return PathBuf::from(INSTALLED_PARAMS_DIR);
    }
    workspace.to_path_buf()
}

/// Parameters of a node that has none of its own.
#[derive(Debug, Clone, Default, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct NoParameters {}

impl crate::parameters::DescribedParameters for NoParameters {
    fn declared() -> Vec<crate::parameters::Declared> {
        vec![]
    }
}

#[cfg(test)]
mod tests {
    use super::{INSTALLED_PARAMS_DIR, params_dir};
    use std::path::{Path, PathBuf};

    #[test]
    fn parameter_files_come_from_the_env_then_the_workspace_then_the_package() {
        let only =
            |dirs: &'static [&'static str]| move |d: &Path| dirs.iter().any(|x| d == Path::new(x));
        let env = Some(std::ffi::OsString::from("/tmp/p"));
        assert_eq!(params_dir(env, only(&["params"])), PathBuf::from("/tmp/p"));
        assert_eq!(
            params_dir(None, only(&["params", INSTALLED_PARAMS_DIR])),
            PathBuf::from("params")
        );
        assert_eq!(
            params_dir(None, only(&[INSTALLED_PARAMS_DIR])),
            PathBuf::from(INSTALLED_PARAMS_DIR)
        );
        // Neither: the workspace's, so the error names the file a developer expects.
        assert_eq!(params_dir(None, only(&[])), PathBuf::from("params"));
    }
}
