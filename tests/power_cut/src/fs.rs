//! The recording file system: an in-memory tree served over FUSE (`fuser`, mounted directly
//! as root, no libfuse or fusermount), which logs every operation that changes the disk or
//! makes it durable ([`crate::cut::Op`]) in the order it carries them out. Every write of
//! every process under the mount point goes through it, whatever library made it. One thread
//! serves the kernel's requests, so the log's order is the order they were carried out.
//! The kernel's write-back cache stays off (fuser's default): a write(2) reaches it at once.

use crate::cut::{Ino, Node, Op, ROOT, Tree};
use fuser::{
    Errno, FileAttr, FileHandle, FileType, Filesystem, FopenFlags, Generation, INodeNo, LockOwner,
    OpenFlags, RenameFlags, ReplyAttr, ReplyCreate, ReplyData, ReplyDirectory, ReplyEmpty,
    ReplyEntry, ReplyOpen, ReplyStatfs, ReplyWrite, Request, TimeOrNow, WriteFlags,
};
use std::ffi::OsStr;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

const TTL: Duration = Duration::from_secs(1);

/// What the file system holds and has logged, shared with the test.
#[derive(Debug)]
pub struct State {
    pub tree: Tree,
    pub log: Vec<Op>,
    next_ino: Ino,
}

impl State {
    fn new() -> State {
        State {
            tree: Tree::new(),
            log: Vec::new(),
            next_ino: ROOT + 1,
        }
    }

    fn record(&mut self, op: Op) {
        self.tree.apply(&op);
        self.log.push(op);
    }

    fn attr(&self, ino: Ino) -> Option<FileAttr> {
        let (kind, size, perm, nlink) = match self.tree.nodes.get(&ino)? {
            Node::File(d) => (FileType::RegularFile, d.len() as u64, 0o644, 1),
            Node::Dir(_) => (FileType::Directory, 0, 0o755, 2),
        };
        Some(FileAttr {
            ino: INodeNo(ino),
            size,
            blocks: size.div_ceil(512),
            atime: UNIX_EPOCH,
            mtime: UNIX_EPOCH,
            ctime: UNIX_EPOCH,
            crtime: UNIX_EPOCH,
            kind,
            perm,
            nlink,
            uid: 0,
            gid: 0,
            rdev: 0,
            flags: 0,
            blksize: 4096,
        })
    }

    fn child(&self, parent: Ino, name: &OsStr) -> Option<Ino> {
        self.tree.entries(parent)?.get(name).copied()
    }

    fn is_dir(&self, ino: Ino) -> bool {
        self.tree.entries(ino).is_some()
    }

    fn create(&mut self, parent: Ino, name: &OsStr, dir: bool) -> Result<Ino, Errno> {
        if !self.is_dir(parent) {
            return Err(Errno::ENOTDIR);
        }
        if self.child(parent, name).is_some() {
            return Err(Errno::EEXIST);
        }
        let ino = self.next_ino;
        self.next_ino += 1;
        self.record(Op::Create {
            parent,
            name: name.to_os_string(),
            ino,
            dir,
        });
        Ok(ino)
    }
}

/// The file system served to the kernel.
pub struct RecordingFs {
    state: Arc<Mutex<State>>,
}

impl RecordingFs {
    /// An empty file system and the handle the test keeps on its state.
    pub fn new() -> (RecordingFs, Arc<Mutex<State>>) {
        let state = Arc::new(Mutex::new(State::new()));
        (
            RecordingFs {
                state: state.clone(),
            },
            state,
        )
    }

    fn state(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Filesystem for RecordingFs {
    fn lookup(&self, _req: &Request, parent: INodeNo, name: &OsStr, reply: ReplyEntry) {
        let s = self.state();
        match s.child(parent.0, name).and_then(|i| s.attr(i)) {
            Some(a) => reply.entry(&TTL, &a, Generation(0)),
            None => reply.error(Errno::ENOENT),
        }
    }

    fn getattr(&self, _req: &Request, ino: INodeNo, _fh: Option<FileHandle>, reply: ReplyAttr) {
        match self.state().attr(ino.0) {
            Some(a) => reply.attr(&TTL, &a),
            None => reply.error(Errno::ENOENT),
        }
    }

    fn setattr(
        &self,
        _req: &Request,
        ino: INodeNo,
        _mode: Option<u32>,
        _uid: Option<u32>,
        _gid: Option<u32>,
        size: Option<u64>,
        _atime: Option<TimeOrNow>,
        _mtime: Option<TimeOrNow>,
        _ctime: Option<SystemTime>,
        _fh: Option<FileHandle>,
        _crtime: Option<SystemTime>,
        _chgtime: Option<SystemTime>,
        _bkuptime: Option<SystemTime>,
        _flags: Option<fuser::BsdFileFlags>,
        reply: ReplyAttr,
    ) {
        let mut s = self.state();
        if let Some(len) = size {
            if s.is_dir(ino.0) {
                return reply.error(Errno::EISDIR);
            }
            s.record(Op::SetLen { ino: ino.0, len });
        }
        // Modes, owners and times are not the power cut's concern: accepted, not kept.
        match s.attr(ino.0) {
            Some(a) => reply.attr(&TTL, &a),
            None => reply.error(Errno::ENOENT),
        }
    }

    fn mkdir(
        &self,
        _req: &Request,
        parent: INodeNo,
        name: &OsStr,
        _mode: u32,
        _umask: u32,
        reply: ReplyEntry,
    ) {
        let mut s = self.state();
        match s.create(parent.0, name, true) {
            Ok(ino) => reply.entry(&TTL, &s.attr(ino).expect("just made"), Generation(0)),
            Err(e) => reply.error(e),
        }
    }

    fn mknod(
        &self,
        _req: &Request,
        parent: INodeNo,
        name: &OsStr,
        _mode: u32,
        _umask: u32,
        _rdev: u32,
        reply: ReplyEntry,
    ) {
        let mut s = self.state();
        match s.create(parent.0, name, false) {
            Ok(ino) => reply.entry(&TTL, &s.attr(ino).expect("just made"), Generation(0)),
            Err(e) => reply.error(e),
        }
    }

    fn create(
        &self,
        _req: &Request,
        parent: INodeNo,
        name: &OsStr,
        _mode: u32,
        _umask: u32,
        flags: i32,
        reply: ReplyCreate,
    ) {
        let mut s = self.state();
        let ino = match s.child(parent.0, name) {
            Some(_) if flags & libc::O_EXCL != 0 => return reply.error(Errno::EEXIST),
            Some(ino) => {
                if flags & libc::O_TRUNC != 0 {
                    s.record(Op::SetLen { ino, len: 0 });
                }
                ino
            }
            None => match s.create(parent.0, name, false) {
                Ok(ino) => ino,
                Err(e) => return reply.error(e),
            },
        };
        let attr = s.attr(ino).expect("there");
        reply.created(
            &TTL,
            &attr,
            Generation(0),
            FileHandle(0),
            FopenFlags::empty(),
        );
    }

    fn open(&self, _req: &Request, ino: INodeNo, flags: OpenFlags, reply: ReplyOpen) {
        let mut s = self.state();
        if s.attr(ino.0).is_none() {
            return reply.error(Errno::ENOENT);
        }
        if flags.0 & libc::O_TRUNC != 0 && !s.is_dir(ino.0) {
            s.record(Op::SetLen { ino: ino.0, len: 0 });
        }
        reply.opened(FileHandle(0), FopenFlags::empty());
    }

    fn read(
        &self,
        _req: &Request,
        ino: INodeNo,
        _fh: FileHandle,
        offset: u64,
        size: u32,
        _flags: OpenFlags,
        _lock_owner: Option<LockOwner>,
        reply: ReplyData,
    ) {
        let s = self.state();
        match s.tree.nodes.get(&ino.0) {
            Some(Node::File(d)) => {
                let start = (offset as usize).min(d.len());
                let end = (start + size as usize).min(d.len());
                reply.data(&d[start..end]);
            }
            Some(Node::Dir(_)) => reply.error(Errno::EISDIR),
            None => reply.error(Errno::ENOENT),
        }
    }

    fn write(
        &self,
        _req: &Request,
        ino: INodeNo,
        _fh: FileHandle,
        offset: u64,
        data: &[u8],
        _write_flags: WriteFlags,
        _flags: OpenFlags,
        _lock_owner: Option<LockOwner>,
        reply: ReplyWrite,
    ) {
        let mut s = self.state();
        if s.is_dir(ino.0) {
            return reply.error(Errno::EISDIR);
        }
        s.record(Op::Write {
            ino: ino.0,
            offset,
            data: data.to_vec(),
        });
        reply.written(data.len() as u32);
    }

    fn flush(
        &self,
        _req: &Request,
        _ino: INodeNo,
        _fh: FileHandle,
        _lock_owner: LockOwner,
        reply: ReplyEmpty,
    ) {
        // close(2): nothing becomes durable.
        reply.ok();
    }

    fn fsync(
        &self,
        _req: &Request,
        ino: INodeNo,
        _fh: FileHandle,
        _datasync: bool,
        reply: ReplyEmpty,
    ) {
        self.state().record(Op::Sync { ino: ino.0 });
        reply.ok();
    }

    fn fsyncdir(
        &self,
        _req: &Request,
        ino: INodeNo,
        _fh: FileHandle,
        _datasync: bool,
        reply: ReplyEmpty,
    ) {
        self.state().record(Op::Sync { ino: ino.0 });
        reply.ok();
    }

    fn unlink(&self, _req: &Request, parent: INodeNo, name: &OsStr, reply: ReplyEmpty) {
        let mut s = self.state();
        match s.child(parent.0, name) {
            Some(ino) if s.is_dir(ino) => reply.error(Errno::EISDIR),
            Some(_) => {
                s.record(Op::Remove {
                    parent: parent.0,
                    name: name.to_os_string(),
                });
                reply.ok();
            }
            None => reply.error(Errno::ENOENT),
        }
    }

    fn rmdir(&self, _req: &Request, parent: INodeNo, name: &OsStr, reply: ReplyEmpty) {
        let mut s = self.state();
        match s.child(parent.0, name) {
            Some(ino) if !s.is_dir(ino) => reply.error(Errno::ENOTDIR),
            Some(ino) if s.tree.entries(ino).is_some_and(|e| !e.is_empty()) => {
                reply.error(Errno::ENOTEMPTY)
            }
            Some(_) => {
                s.record(Op::Remove {
                    parent: parent.0,
                    name: name.to_os_string(),
                });
                reply.ok();
            }
            None => reply.error(Errno::ENOENT),
        }
    }

    fn rename(
        &self,
        _req: &Request,
        parent: INodeNo,
        name: &OsStr,
        newparent: INodeNo,
        newname: &OsStr,
        flags: RenameFlags,
        reply: ReplyEmpty,
    ) {
        let mut s = self.state();
        let Some(ino) = s.child(parent.0, name) else {
            return reply.error(Errno::ENOENT);
        };
        if flags.contains(RenameFlags::RENAME_EXCHANGE) {
            return reply.error(Errno::EINVAL);
        }
        if let Some(target) = s.child(newparent.0, newname) {
            if flags.contains(RenameFlags::RENAME_NOREPLACE) {
                return reply.error(Errno::EEXIST);
            }
            match (s.is_dir(ino), s.is_dir(target)) {
                (false, true) => return reply.error(Errno::EISDIR),
                (true, false) => return reply.error(Errno::ENOTDIR),
                (true, true) if s.tree.entries(target).is_some_and(|e| !e.is_empty()) => {
                    return reply.error(Errno::ENOTEMPTY);
                }
                _ => {}
            }
        }
        s.record(Op::Rename {
            parent: parent.0,
            name: name.to_os_string(),
            new_parent: newparent.0,
            new_name: newname.to_os_string(),
        });
        reply.ok();
    }

    fn readdir(
        &self,
        _req: &Request,
        ino: INodeNo,
        _fh: FileHandle,
        offset: u64,
        mut reply: ReplyDirectory,
    ) {
        let s = self.state();
        let Some(entries) = s.tree.entries(ino.0) else {
            return reply.error(Errno::ENOTDIR);
        };
        let mut all = vec![
            (ino.0, FileType::Directory, OsStr::new(".").to_os_string()),
            (ROOT, FileType::Directory, OsStr::new("..").to_os_string()),
        ];
        for (name, child) in entries {
            let kind = if s.is_dir(*child) {
                FileType::Directory
            } else {
                FileType::RegularFile
            };
            all.push((*child, kind, name.clone()));
        }
        for (i, (child, kind, name)) in all.into_iter().enumerate().skip(offset as usize) {
            if reply.add(INodeNo(child), (i + 1) as u64, kind, &name) {
                break;
            }
        }
        reply.ok();
    }

    fn statfs(&self, _req: &Request, _ino: INodeNo, reply: ReplyStatfs) {
        // Room enough for anything a session writes (the disk is not what this tests).
        let blocks = 4 << 20;
        reply.statfs(
            blocks,
            blocks / 2,
            blocks / 2,
            1 << 20,
            1 << 19,
            4096,
            255,
            4096,
        );
    }

    fn access(&self, _req: &Request, _ino: INodeNo, _mask: fuser::AccessFlags, reply: ReplyEmpty) {
        reply.ok();
    }
}
