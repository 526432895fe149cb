//! The recorded write log and what a power cut after any of its operations leaves on disk.
//!
//! The model is the weakest one POSIX and Linux promise, not ext4's kinder habits: a file's
//! data is on disk only once the file was fsync'd (or fdatasync'd) after it was written, and a
//! name created, renamed or removed in a directory only once that directory was fsync'd. What
//! a cut leaves is one of several states; each cut point is checked in three:
//!
//! - [`Model::Forget`]: nothing unsynced reached the disk (names and data alike).
//! - [`Model::NamesKept`]: every name change reached the disk (a journal commit), but no
//!   unsynced data: a file renamed into place before its data was synced is empty, as ext4
//!   with delayed allocation can leave it.
//! - [`Model::TornTail`]: all unsynced data reached the disk except the last write, cut in
//!   half (a torn append or chunk), and no unsynced name change.
//!
//! Not modelled: writes reordered within a file beyond a torn last one, and blocks of stale
//! or zeroed data (ext4 `data=writeback`); a kinder file system leaves a subset of these states.

use std::collections::{BTreeMap, HashMap};
use std::ffi::OsString;
use std::path::Path;

/// An inode number of the recording file system (1 is its root).
pub type Ino = u64;

/// The root directory's inode.
pub const ROOT: Ino = 1;

/// One operation that changes what is on disk, or makes it durable, in the order the file
/// system carried them out.
#[derive(Debug, Clone, PartialEq)]
pub enum Op {
    /// A new file or directory `name` in `parent`.
    Create {
        parent: Ino,
        name: OsString,
        ino: Ino,
        dir: bool,
    },
    Write {
        ino: Ino,
        offset: u64,
        data: Vec<u8>,
    },
    /// A truncation or extension (ftruncate, O_TRUNC).
    SetLen { ino: Ino, len: u64 },
    /// `name` in `parent` becomes `new_name` in `new_parent`, replacing what was there.
    Rename {
        parent: Ino,
        name: OsString,
        new_parent: Ino,
        new_name: OsString,
    },
    /// `name` removed from `parent` (unlink or rmdir).
    Remove { parent: Ino, name: OsString },
    /// fsync or fdatasync of a file (its data and size), or fsync of a directory (its names).
    Sync { ino: Ino },
}

/// A file's bytes or a directory's names.
#[derive(Debug, Clone, PartialEq)]
pub enum Node {
    File(Vec<u8>),
    Dir(BTreeMap<OsString, Ino>),
}

/// A whole tree: every inode there is or was.
#[derive(Debug, Clone, Default)]
pub struct Tree {
    pub nodes: HashMap<Ino, Node>,
}

impl Tree {
    /// An empty root directory.
    pub fn new() -> Tree {
        let mut nodes = HashMap::new();
        nodes.insert(ROOT, Node::Dir(BTreeMap::new()));
        Tree { nodes }
    }

    /// The names of directory `ino` (empty for a file or an unknown inode).
    pub fn entries(&self, ino: Ino) -> Option<&BTreeMap<OsString, Ino>> {
        match self.nodes.get(&ino) {
            Some(Node::Dir(e)) => Some(e),
            _ => None,
        }
    }

    fn entries_mut(&mut self, ino: Ino) -> Option<&mut BTreeMap<OsString, Ino>> {
        match self.nodes.get_mut(&ino) {
            Some(Node::Dir(e)) => Some(e),
            _ => None,
        }
    }

    fn data_mut(&mut self, ino: Ino) -> Option<&mut Vec<u8>> {
        match self.nodes.get_mut(&ino) {
            Some(Node::File(d)) => Some(d),
            _ => None,
        }
    }

    /// Carries out `op` (the live view: everything in the page cache).
    pub fn apply(&mut self, op: &Op) {
        match op {
            Op::Create {
                parent,
                name,
                ino,
                dir,
            } => {
                let node = if *dir {
                    Node::Dir(BTreeMap::new())
                } else {
                    Node::File(Vec::new())
                };
                self.nodes.insert(*ino, node);
                if let Some(e) = self.entries_mut(*parent) {
                    e.insert(name.clone(), *ino);
                }
            }
            Op::Write { ino, offset, data } => {
                if let Some(d) = self.data_mut(*ino) {
                    write_at(d, *offset, data);
                }
            }
            Op::SetLen { ino, len } => {
                if let Some(d) = self.data_mut(*ino) {
                    d.resize(*len as usize, 0);
                }
            }
            Op::Rename {
                parent,
                name,
                new_parent,
                new_name,
            } => {
                let moved = self.entries_mut(*parent).and_then(|e| e.remove(name));
                if let (Some(ino), Some(e)) = (moved, self.entries_mut(*new_parent)) {
                    e.insert(new_name.clone(), ino);
                }
            }
            Op::Remove { parent, name } => {
                if let Some(e) = self.entries_mut(*parent) {
                    e.remove(name);
                }
            }
            Op::Sync { .. } => {}
        }
    }

    /// Writes the tree under `ino` into `dir` on a real disk (files and directories).
    pub fn materialize(&self, ino: Ino, dir: &Path) -> std::io::Result<()> {
        std::fs::create_dir_all(dir)?;
        let Some(entries) = self.entries(ino) else {
            return Ok(());
        };
        for (name, child) in entries {
            let path = dir.join(name);
            match self.nodes.get(child) {
                Some(Node::File(d)) => std::fs::write(&path, d)?,
                Some(Node::Dir(_)) => self.materialize(*child, &path)?,
                None => {}
            }
        }
        Ok(())
    }

    /// The bytes of the file at `path` (relative to the root), if there is one.
    pub fn file(&self, path: &Path) -> Option<&[u8]> {
        let mut ino = ROOT;
        for part in path.iter() {
            ino = *self.entries(ino)?.get(part)?;
        }
        match self.nodes.get(&ino) {
            Some(Node::File(d)) => Some(d),
            _ => None,
        }
    }
}

fn write_at(d: &mut Vec<u8>, offset: u64, data: &[u8]) {
    let start = offset as usize;
    let end = start + data.len();
    if d.len() < end {
        d.resize(end, 0);
    }
    d[start..end].copy_from_slice(data);
}

/// Which of the states a cut may leave (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Model {
    Forget,
    NamesKept,
    TornTail,
}

impl Model {
    pub const ALL: [Model; 3] = [Model::Forget, Model::NamesKept, Model::TornTail];
}

/// Replays a log one operation at a time, keeping the live tree and what is durable.
#[derive(Debug, Clone)]
pub struct Replay {
    /// Everything written (what a killed process leaves).
    pub live: Tree,
    /// Each inode as of its last sync (files: data; directories: names).
    durable: HashMap<Ino, Node>,
    /// The last write not yet synced: its file's bytes before it, and the write.
    last_write: Option<(Ino, Vec<u8>, u64, Vec<u8>)>,
}

impl Replay {
    /// Starts from `baseline`, all of it durable (as after `sync`).
    pub fn new(baseline: Tree) -> Replay {
        Replay {
            durable: baseline.nodes.clone(),
            live: baseline,
            last_write: None,
        }
    }

    /// Carries out the next operation.
    pub fn step(&mut self, op: &Op) {
        match op {
            Op::Create { ino, dir, .. } => {
                // A new inode holds nothing durable until it is synced.
                let empty = if *dir {
                    Node::Dir(BTreeMap::new())
                } else {
                    Node::File(Vec::new())
                };
                self.durable.insert(*ino, empty);
            }
            Op::Write { ino, offset, data } => {
                let before = match self.live.nodes.get(ino) {
                    Some(Node::File(d)) => d.clone(),
                    _ => Vec::new(),
                };
                self.last_write = Some((*ino, before, *offset, data.clone()));
            }
            Op::Sync { ino } => {
                if let Some(n) = self.live.nodes.get(ino) {
                    self.durable.insert(*ino, n.clone());
                }
                if self.last_write.as_ref().is_some_and(|w| w.0 == *ino) {
                    self.last_write = None;
                }
            }
            _ => {}
        }
        self.live.apply(op);
    }

    /// What the disk holds if the power is cut now, under `model`.
    pub fn after_cut(&self, model: Model) -> Tree {
        let mut nodes = HashMap::new();
        for (ino, live) in &self.live.nodes {
            let durable = self.durable.get(ino);
            let node = match (live, model) {
                (Node::Dir(_), Model::NamesKept) => live.clone(),
                (Node::Dir(_), _) => durable.cloned().unwrap_or(Node::Dir(BTreeMap::new())),
                (Node::File(_), Model::TornTail) => live.clone(),
                (Node::File(_), _) => durable.cloned().unwrap_or(Node::File(Vec::new())),
            };
            nodes.insert(*ino, node);
        }
        if model == Model::TornTail
            && let Some((ino, before, offset, data)) = &self.last_write
        {
            let mut torn = before.clone();
            write_at(&mut torn, *offset, &data[..data.len() / 2]);
            nodes.insert(*ino, Node::File(torn));
        }
        Tree { nodes }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn name(s: &str) -> OsString {
        s.into()
    }

    /// The replace-whole-file dance, each step in turn, and what each model keeps.
    #[test]
    fn a_file_replaced_whole_is_old_or_new_only_with_both_syncs() {
        let mut base = Tree::new();
        base.apply(&Op::Create {
            parent: ROOT,
            name: name("q.json"),
            ino: 2,
            dir: false,
        });
        base.apply(&Op::Write {
            ino: 2,
            offset: 0,
            data: b"old".to_vec(),
        });
        let ops = [
            Op::Create {
                parent: ROOT,
                name: name(".q.tmp"),
                ino: 3,
                dir: false,
            },
            Op::Write {
                ino: 3,
                offset: 0,
                data: b"new!".to_vec(),
            },
            Op::Sync { ino: 3 },
            Op::Rename {
                parent: ROOT,
                name: name(".q.tmp"),
                new_parent: ROOT,
                new_name: name("q.json"),
            },
            Op::Sync { ino: ROOT },
        ];
        let mut r = Replay::new(base);
        let q = Path::new("q.json");
        for (i, op) in ops.iter().enumerate() {
            r.step(op);
            for m in Model::ALL {
                let t = r.after_cut(m);
                let got = t.file(q).expect("q.json is always there");
                assert!(
                    got == b"old" || got == b"new!",
                    "{m:?} after op {i}: {got:?}"
                );
            }
        }
        assert_eq!(r.after_cut(Model::Forget).file(q), Some(&b"new!"[..]));
        // Without the file's sync, NamesKept finds the new name empty.
        let mut r = Replay::new(Tree::new());
        r.step(&ops[0]);
        r.step(&ops[1]);
        r.step(&Op::Sync { ino: ROOT });
        assert_eq!(
            r.after_cut(Model::NamesKept).file(Path::new(".q.tmp")),
            Some(&b""[..])
        );
        // An unsynced append is torn in half.
        r.step(&Op::Sync { ino: 3 });
        r.step(&Op::Write {
            ino: 3,
            offset: 4,
            data: b"abcd".to_vec(),
        });
        assert_eq!(
            r.after_cut(Model::TornTail).file(Path::new(".q.tmp")),
            Some(&b"new!ab"[..])
        );
        assert_eq!(
            r.after_cut(Model::Forget).file(Path::new(".q.tmp")),
            Some(&b"new!"[..])
        );
    }
}
