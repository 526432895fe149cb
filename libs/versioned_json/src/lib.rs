//! The suite's versioned JSON files (user models, Q-tables): beside its content a file holds a
//! `format` that says what it is and the `version` of its layout. Reading checks both before
//! anything else, so a file of another kind or version is refused as such, not as a missing
//! field; then the content is read into its type, and an error names the file and the field at
//! fault. Writing is pretty JSON with a final newline, whole or not at all (`atomic_file`).
//! What each file's content must satisfy beyond its type is its owner's to check.

use serde::Serialize;
use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};

/// One kind of versioned file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Kind {
    /// Its `format` field, e.g. `qt_therapy q_table`.
    pub format: &'static str,
    /// The one `version` this program reads and writes.
    pub version: u32,
    /// What such a file is called in errors, e.g. `Q-table`.
    pub name: &'static str,
}

/// Why a versioned file cannot be read or written, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    #[error("{path}: {reason}")]
    File { path: PathBuf, reason: String },
    #[error("{path}, field {field}: {reason}")]
    Field {
        path: PathBuf,
        field: String,
        reason: String,
    },
    #[error(
        "{path} is a {name} file of format version {found}; this program reads version \
         {expected}"
    )]
    Version {
        path: PathBuf,
        name: &'static str,
        found: u64,
        expected: u32,
    },
}

impl FileError {
    /// The file as a whole is at fault.
    pub fn file(path: &Path, reason: impl ToString) -> FileError {
        FileError::File {
            path: path.into(),
            reason: reason.to_string(),
        }
    }

    /// `field` (a path into the JSON, e.g. `states[3].q`) is at fault.
    pub fn field(path: &Path, field: impl ToString, reason: impl ToString) -> FileError {
        FileError::Field {
            path: path.into(),
            field: field.to_string(),
            reason: reason.to_string(),
        }
    }
}

impl Kind {
    /// Reads and checks the file at `path` (see [`Kind::from_json_str`]).
    pub fn load<T: DeserializeOwned>(&self, path: &Path) -> Result<T, FileError> {
        let text = std::fs::read_to_string(path).map_err(|e| FileError::file(path, e))?;
        self.from_json_str(&text, path)
    }

    /// The file's content from its text (`path` only names it in errors): JSON, this kind's
    /// `format`, this program's `version`, then `T` (which holds `format` and `version` too).
    pub fn from_json_str<T: DeserializeOwned>(
        &self,
        text: &str,
        path: &Path,
    ) -> Result<T, FileError> {
        let value: serde_json::Value = serde_json::from_str(text)
            .map_err(|e| FileError::file(path, format!("not JSON (truncated?): {e}")))?;
        if value.get("format").and_then(|f| f.as_str()) != Some(self.format) {
            return Err(FileError::field(
                path,
                "format",
                format!("is not {:?}: not a {} file", self.format, self.name),
            ));
        }
        match value.get("version").and_then(serde_json::Value::as_u64) {
            Some(v) if v == u64::from(self.version) => {}
            Some(found) => {
                return Err(FileError::Version {
                    path: path.into(),
                    name: self.name,
                    found,
                    expected: self.version,
                });
            }
            None => return Err(FileError::field(path, "version", "is missing")),
        }
        serde_path_to_error::deserialize(value)
            .map_err(|e| FileError::field(path, e.path(), e.inner()))
    }

    /// Writes `content` (which holds this kind's `format` and `version`) to `path`: pretty
    /// JSON and a final newline, replacing the old file only once the new one is whole and
    /// synced.
    pub fn save<T: Serialize>(&self, path: &Path, content: &T) -> Result<(), FileError> {
        let text = serde_json::to_string_pretty(content).map_err(|e| FileError::file(path, e))?;
        atomic_file::write(path, format!("{text}\n").as_bytes())
            .map_err(|e| FileError::file(path, e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const KIND: Kind = Kind {
        format: "qt_therapy example",
        version: 2,
        name: "sample",
    };

    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Example {
        format: String,
        version: u32,
        rows: Vec<Row>,
    }

    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Row {
        q: f64,
    }

    fn example() -> Example {
        Example {
            format: KIND.format.into(),
            version: KIND.version,
            rows: vec![Row { q: 1.5 }, Row { q: -0.25 }],
        }
    }

    #[test]
    fn a_saved_file_reads_back_and_ends_with_a_newline() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("example.json");
        KIND.save(&path, &example()).expect("saves");
        assert_eq!(KIND.load::<Example>(&path).expect("loads"), example());
        let text = std::fs::read_to_string(&path).expect("reads");
        assert!(
            text.starts_with("{\n  \"format\"") && text.ends_with("}\n"),
            "{text}"
        );
    }

    #[test]
    fn kind_and_version_are_checked_before_the_content_and_the_culprit_named() {
        let path = Path::new("dir/example.json");
        let good = serde_json::to_string_pretty(&example()).expect("JSON");
        for (text, words) in [
            (
                good[..good.len() / 2].to_string(),
                "dir/example.json: not JSON (truncated?)",
            ),
            (
                good.replace(KIND.format, "qt_therapy other"),
                "dir/example.json, field format: is not \"qt_therapy example\": not a sample file",
            ),
            // Another version is refused as such, whatever else is wrong with it.
            (
                good.replace("\"version\": 2", "\"version\": 3")
                    .replace("\"rows\"", "\"lines\""),
                "dir/example.json is a sample file of format version 3; this program reads \
                 version 2",
            ),
            (
                good.replace("\"version\": 2,", ""),
                "dir/example.json, field version: is missing",
            ),
            (
                good.replacen("1.5", "\"x\"", 1),
                "dir/example.json, field rows[0].q: invalid type: string \"x\", expected f64",
            ),
        ] {
            let e = KIND
                .from_json_str::<Example>(&text, path)
                .expect_err(words)
                .to_string();
            assert!(e.starts_with(words), "{e}\nlacks {words}");
        }
        let missing = KIND
            .load::<Example>(Path::new("/nonexistent/example.json"))
            .expect_err("no file");
        assert!(
            matches!(missing, FileError::File { .. })
                && missing.to_string().contains("/nonexistent"),
            "{missing}"
        );
    }
}
