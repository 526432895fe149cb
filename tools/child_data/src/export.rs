//! `export`: one `.tar.gz` with everything of the user an [`Inventory`] found, under
//! `child-data-<id>/` in the layout of the places searched, and a `MANIFEST.txt` first that
//! lists each file of the archive (where it came from, what it is), what was found but is
//! not in it and why, and what the tool cannot reach. Whole files go in as they are; a bag's
//! part as a bag of its own (same channels, QoS and stamps); CSV rows with their header and
//! log lines as they were written; of a fitted model file, the user's own entry. The archive
//! is written beside its final name and renamed when complete, readable by its owner only
//! (0600): it is the child's health data.

use crate::bags::{Ownership, write_subset};
use crate::error::ChildDataError;
use crate::find::STAGING_PREFIX;
use crate::inventory::{Content, Inventory, Item, ItemKind, bag_part_of, csv_now, log_lines};
use crate::rows::gather;
use bag_file::BagReader;
use std::fmt::Write as _;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};
use time::OffsetDateTime;

/// One file of the archive.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Entry {
    /// Its path in the archive.
    pub name: String,
    pub source: PathBuf,
    pub what: String,
}

/// What an export wrote.
#[derive(Debug)]
pub struct Exported {
    pub archive: PathBuf,
    pub entries: Vec<Entry>,
    /// Found but not in the archive, with why.
    pub left_out: Vec<(PathBuf, String)>,
    pub manifest: String,
}

/// The archive's top directory, `child-data-<id as a file name>`.
pub fn top_dir(inv: &Inventory) -> String {
    let stem = inv.user.file_stem();
    format!(
        "child-data-{}",
        if stem.is_empty() { "user" } else { &stem }
    )
}

/// The default archive name, in the working directory.
pub fn default_output(inv: &Inventory) -> PathBuf {
    PathBuf::from(format!("{}.tar.gz", top_dir(inv)))
}

/// `item`'s path in the archive (`suffix` replaces its extension for an extract).
fn entry_name(inv: &Inventory, item: &Item, suffix: Option<&str>) -> String {
    let mut p = PathBuf::from(top_dir(inv));
    if inv.places.len() > 1 {
        let label = inv.places[item.place]
            .file_name()
            .map_or_else(|| "root".to_string(), |n| n.to_string_lossy().into_owned());
        p.push(format!("{}-{label}", item.place + 1));
    }
    let mut rel = item.rel.clone();
    if let Some(suffix) = suffix {
        let name = rel
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let stem = name.strip_suffix(".json").unwrap_or(&name).to_string();
        rel.set_file_name(format!("{stem}{suffix}"));
    }
    p.push(rel);
    p.to_string_lossy().into_owned()
}

/// Writes the archive of `inv` to `output`, which must not exist yet.
pub fn export(inv: &Inventory, output: &Path) -> Result<Exported, ChildDataError> {
    if output.exists() {
        return Err(ChildDataError::OutputExists {
            path: output.to_path_buf(),
        });
    }
    let dir = match output.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    // Parts made here are staged beside the archive (the same file system, private).
    let staging = tempfile::Builder::new()
        .prefix(STAGING_PREFIX)
        .tempdir_in(&dir)
        .map_err(ChildDataError::io(&dir))?;
    let mut entries: Vec<(Entry, PathBuf)> = Vec::new();
    let mut left_out = Vec::new();
    for (k, item) in inv.items.iter().enumerate() {
        let stage = staging.path().join(k.to_string());
        std::fs::create_dir_all(&stage).map_err(ChildDataError::io(&stage))?;
        let file_name = item.path.file_name().unwrap_or_default();
        let staged = stage.join(file_name);
        let what = format!("{}: {}", item.kind.label(), item.what);
        let name = |suffix| entry_name(inv, item, suffix);
        match (&item.content, item.kind) {
            (Content::Whole, _) => {
                std::fs::copy(&item.path, &staged).map_err(ChildDataError::io(&item.path))?;
                entries.push((entry(name(None), item, what), staged));
            }
            (Content::Bag(_), _) => {
                let reader = BagReader::open(&item.path)?;
                let ownership = Ownership::of(&reader);
                let Some(part) = bag_part_of(&reader, &ownership, &inv.user, &[]) else {
                    left_out.push((item.path.clone(), "no message of this user left".into()));
                    continue;
                };
                if part.user_messages == 0 {
                    left_out.push((
                        item.path.clone(),
                        format!("damaged; no readable message is this user's: {}", item.what),
                    ));
                    continue;
                }
                let k = ownership.user_index(inv.user.as_str());
                write_subset(&reader, &|i| ownership.is(i, k), &staged)?;
                let mut what = format!(
                    "bag: this user's {} messages of the {} in the bag, on {} topics (sessions \
                     {}), with the bag's channels, QoS and stamps",
                    part.user_messages,
                    part.total,
                    part.topics.values().filter(|(u, _)| *u > 0).count(),
                    part.sessions.join(", ")
                );
                if let Some(d) = &part.damage {
                    let _ = write!(
                        what,
                        "; the bag is damaged ({d}): what could not be read is not here"
                    );
                }
                entries.push((entry(name(None), item, what), staged));
            }
            (Content::Rows { .. }, ItemKind::InteractionCsv) => {
                let (bytes, rows) = csv_now(&item.path, &inv.user)?;
                let Some(rows) = rows else { continue };
                let mut out = bytes[rows.header.clone()].to_vec();
                out.extend(gather(&bytes, &rows.rows, true));
                write_staged(&staged, &out)?;
                let what = format!(
                    "interaction CSV: the header and this user's {} of {} rows",
                    rows.users_rows(),
                    rows.rows.len()
                );
                entries.push((entry(name(None), item, what), staged));
            }
            (Content::Rows { .. }, _) => {
                let Some(lines) = log_lines(inv, &item.path) else {
                    continue;
                };
                let bytes = std::fs::read(&item.path).map_err(ChildDataError::io(&item.path))?;
                let picked = lines.iter().filter(|(_, p)| *p).count();
                write_staged(&staged, &gather(&bytes, &lines, true))?;
                let what = format!(
                    "log: the {picked} of {} lines naming this user or their sessions",
                    lines.len()
                );
                entries.push((entry(name(None), item, what), staged));
            }
            (Content::Inseparable { .. }, ItemKind::UserModel) => {
                let extract = model_entry(item, inv.user.as_str())?;
                write_staged(&staged, extract.as_bytes())?;
                let what = format!(
                    "this user's entry in the fitted user models {} (the whole file holds \
                     other users' data)",
                    item.path.display()
                );
                entries.push((entry(name(Some(".this-user.json")), item, what), staged));
            }
            (Content::Inseparable { .. }, _) => left_out.push((
                item.path.clone(),
                format!("{what}: it holds someone else's data too"),
            )),
        }
    }
    let manifest = manifest(inv, &entries, &left_out);
    // Written beside the output and renamed into place only once complete and synced
    // (atomic_file), never over an existing file; 0600 on the way.
    let mut tmp = atomic_file::NewFile::with_prefix(output, STAGING_PREFIX, 0o600)
        .map_err(ChildDataError::io(&dir))?;
    write_archive(tmp.file(), &manifest, inv, &entries).map_err(|e| ChildDataError::Archive {
        path: output.to_path_buf(),
        reason: e.to_string(),
    })?;
    tmp.commit_new().map_err(|e| {
        if e.kind() == std::io::ErrorKind::AlreadyExists {
            ChildDataError::OutputExists {
                path: output.to_path_buf(),
            }
        } else {
            ChildDataError::io(output)(e)
        }
    })?;
    Ok(Exported {
        archive: output.to_path_buf(),
        entries: entries.into_iter().map(|(e, _)| e).collect(),
        left_out,
        manifest,
    })
}

fn entry(name: String, item: &Item, what: String) -> Entry {
    Entry {
        name,
        source: item.path.clone(),
        what,
    }
}

fn write_staged(path: &Path, bytes: &[u8]) -> Result<(), ChildDataError> {
    std::fs::write(path, bytes).map_err(ChildDataError::io(path))
}

/// The user's entry of a fitted model file: their point (vector, projection, cluster) and
/// the cluster they are in.
fn model_entry(item: &Item, user: &str) -> Result<String, ChildDataError> {
    let text = std::fs::read_to_string(&item.path).map_err(ChildDataError::io(&item.path))?;
    let value: serde_json::Value = serde_json::from_str(&text).map_err(|e| ChildDataError::Io {
        path: item.path.clone(),
        source: std::io::Error::other(e),
    })?;
    let point = value
        .get("users")
        .and_then(|u| u.as_array())
        .and_then(|p| {
            p.iter()
                .find(|x| x.get("user").and_then(|u| u.as_str()) == Some(user))
        })
        .cloned();
    let cluster = value
        .get("clusters")
        .and_then(|c| c.as_array())
        .and_then(|cs| {
            cs.iter().find(|c| {
                c.get("users")
                    .and_then(|u| u.as_array())
                    .is_some_and(|u| u.iter().any(|x| x.as_str() == Some(user)))
            })
        });
    let out = serde_json::json!({
        "model_file": item.path.display().to_string(),
        "format": value.get("format"),
        "provenance": value.get("provenance"),
        "user": point,
        "cluster": cluster.and_then(|c| c.get("cluster")),
        "cluster_users": cluster.and_then(|c| c.get("users")).and_then(|u| u.as_array()).map(Vec::len),
        "note": "The models of the user's cluster were fitted from the sequences of all of its \
                 users together; the file keeps them unnamed, so they cannot be picked out.",
    });
    serde_json::to_string_pretty(&out).map_err(|e| ChildDataError::Io {
        path: item.path.clone(),
        source: std::io::Error::other(e),
    })
}

/// The archive's `MANIFEST.txt`.
fn manifest(
    inv: &Inventory,
    entries: &[(Entry, PathBuf)],
    left_out: &[(PathBuf, String)],
) -> String {
    let mut m = String::new();
    let places: Vec<String> = inv.places.iter().map(|p| p.display().to_string()).collect();
    let _ = writeln!(
        m,
        "Everything the QTrobot therapy suite holds of user {:?} in the places searched.\n\
         made:     {} by child_data {}\nsearched: {}\n",
        inv.user.as_str(),
        utc_now(),
        env!("CARGO_PKG_VERSION"),
        places.join(", ")
    );
    if entries.is_empty() {
        let _ = writeln!(
            m,
            "Nothing of this user was found there (user ids are matched exactly).\n"
        );
    } else {
        let _ = writeln!(
            m,
            "In this archive ({} files; path, where it came from, what it is):\n",
            entries.len()
        );
    }
    for (e, _) in entries {
        let _ = writeln!(
            m,
            "{}\n    from {}\n    {}\n",
            e.name,
            e.source.display(),
            e.what
        );
    }
    if !left_out.is_empty() {
        let _ = writeln!(m, "Found, but not in this archive:\n");
        for (p, why) in left_out {
            let _ = writeln!(m, "{}\n    {why}\n", p.display());
        }
    }
    let _ = writeln!(m, "Notes:\n");
    for n in &inv.notes {
        let _ = writeln!(m, "- {n}");
    }
    for (p, why) in &inv.unreadable {
        let _ = writeln!(
            m,
            "- {} could not be read ({why}): it may hold data of this user",
            p.display()
        );
    }
    for n in outside_notes(inv) {
        let _ = writeln!(m, "- {n}");
    }
    m
}

/// What no command of the suite reaches, said in every listing, manifest and erase.
pub fn outside_notes(inv: &Inventory) -> Vec<String> {
    // journalctl's --grep takes a regular expression: the id's own characters, escaped, and
    // quoted for the shell.
    let pattern: String = inv
        .user
        .as_str()
        .chars()
        .flat_map(|c| {
            let escape = "\\^$.|?*+()[]{}".contains(c);
            escape.then_some('\\').into_iter().chain([c])
        })
        .collect();
    let quoted = format!("'{}'", pattern.replace('\'', "'\\''"));
    vec![
        format!(
            "The systemd journal (journalctl -u qt-therapy) holds the service's log lines, \
             which name the user when a session starts; it cannot be edited line by line. \
             Show them with: journalctl -u qt-therapy --case-sensitive --grep {quoted}. \
             Deleting them deletes the whole journal, every service's: sudo journalctl \
             --rotate && sudo journalctl --vacuum-time=1s"
        ),
        "Copies outside the places searched are not reached: backups, archives made by \
         export, reports written elsewhere (qt-therapy-report writes report-<run>.html into \
         the directory it ran in when it cannot write beside the bag), files copied off the \
         robot. Give their paths as arguments too, or delete them by hand."
            .to_string(),
        "OpenFace writes the camera's features to its own CSV (QT_OPENFACE_CSV), with no user \
         id: delete it by hand after the sessions it recorded."
            .to_string(),
    ]
}

fn write_archive(
    file: &mut File,
    manifest: &str,
    inv: &Inventory,
    entries: &[(Entry, PathBuf)],
) -> std::io::Result<()> {
    let now = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let gz = flate2::write::GzEncoder::new(file, flate2::Compression::default());
    let mut tar = tar::Builder::new(gz);
    let header = |size: u64| {
        let mut h = tar::Header::new_gnu();
        h.set_size(size);
        h.set_mode(0o600);
        h.set_mtime(now);
        h.set_entry_type(tar::EntryType::Regular);
        h
    };
    let name = format!("{}/MANIFEST.txt", top_dir(inv));
    tar.append_data(
        &mut header(manifest.len() as u64),
        name,
        manifest.as_bytes(),
    )?;
    for (e, staged) in entries {
        let f = File::open(staged)?;
        let len = f.metadata()?.len();
        tar.append_data(&mut header(len), &e.name, f)?;
    }
    tar.into_inner()?.finish()?;
    Ok(())
}

/// Now as `YYYY-MM-DD HH:MM:SS UTC`.
pub fn utc_now() -> String {
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    utc(secs)
}

/// Seconds since the epoch as `YYYY-MM-DD HH:MM:SS UTC`.
pub fn utc(secs: u64) -> String {
    let date = i64::try_from(secs)
        .ok()
        .and_then(|s| OffsetDateTime::from_unix_timestamp(s).ok());
    match date {
        Some(t) => format!(
            "{:04}-{:02}-{:02} {:02}:{:02}:{:02} UTC",
            t.year(),
            u8::from(t.month()),
            t.day(),
            t.hour(),
            t.minute(),
            t.second()
        ),
        // Past the year 9999, which `time` does not hold.
        None => format!("{secs} s after the epoch"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_dates() {
        assert_eq!(utc(0), "1970-01-01 00:00:00 UTC");
        assert_eq!(utc(1_700_000_000), "2023-11-14 22:13:20 UTC");
        assert_eq!(utc(951_782_400), "2000-02-29 00:00:00 UTC");
    }
}
