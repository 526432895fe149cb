//! Everything the places searched hold of one user: which files, what part of each, what
//! erase would do with it, what it cannot do, and what would make it refuse. `list` prints
//! it, `export` archives it, `erase` carries it out; the last two read each file again when
//! they use it, so they act on the file as it is then.

use crate::bags::{self, Ownership};
use crate::error::ChildDataError;
use crate::find::{FileKind, Found, Walk, walk};
use crate::live::{self, LiveBy, Processes};
use crate::rows::{self, CsvRows};
use crate::sessions::{SessionFiles, read_sessions};
use crate::user::{UserId, names_token};
use bag_file::BagReader;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Largest text file (JSON, HTML, a file of no known kind) searched for the id.
const MAX_TEXT_BYTES: u64 = 64 << 20;

/// What a file is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum ItemKind {
    SessionFile,
    UserQTable,
    /// The behaviour policy's belief about this child (`belief_<id>.json`, `child_belief`).
    UserBelief,
    Bag,
    InteractionCsv,
    Report,
    Log,
    UserModel,
    /// A file of no kind the suite writes, that names the user.
    Unknown,
}

impl ItemKind {
    pub fn label(self) -> &'static str {
        match self {
            ItemKind::SessionFile => "session file",
            ItemKind::UserQTable => "Q-table",
            ItemKind::UserBelief => "belief about the child",
            ItemKind::Bag => "bag",
            ItemKind::InteractionCsv => "interaction CSV",
            ItemKind::Report => "session report",
            ItemKind::Log => "log",
            ItemKind::UserModel => "fitted user models",
            ItemKind::Unknown => "file of unknown kind",
        }
    }
}

/// A bag's part that is the user's.
#[derive(Debug, Clone, PartialEq)]
pub struct BagPart {
    pub user_messages: usize,
    pub total: usize,
    /// Per topic: (the user's, all).
    pub topics: BTreeMap<String, (usize, usize)>,
    /// The user's sessions in the bag.
    pub sessions: Vec<String>,
    /// The other users whose messages stay.
    pub others: Vec<String>,
    /// The first bad record, if the bag is damaged: nothing after it could be read.
    pub damage: Option<String>,
    /// Bytes from the bad record to the end of the file.
    pub unreadable_bytes: u64,
    /// Why the unreadable rest probably holds this user's messages too.
    pub tail_is_users: Option<String>,
    /// The bag was not closed (a recording killed, or still going).
    pub complete: bool,
}

/// What a file holds of the user.
#[derive(Debug, Clone, PartialEq)]
pub enum Content {
    /// All of it: exported as it is, deleted by erase.
    Whole,
    /// Some of a bag's messages: exported as a bag of their own; erase rewrites the bag
    /// without them (deletes it when nothing else is left).
    Bag(BagPart),
    /// Some rows of a CSV, or lines of a log: exported alone; erase rewrites the file without
    /// them (deletes it when nothing else is left).
    Rows { total: usize, users: usize },
    /// Cannot be told apart from other users' data: erase leaves it; `todo` says what to do.
    Inseparable { todo: String },
}

/// One file holding something of the user.
#[derive(Debug, Clone, PartialEq)]
pub struct Item {
    pub path: PathBuf,
    /// Which place searched it was found under, and its path below it.
    pub place: usize,
    pub rel: PathBuf,
    pub kind: ItemKind,
    /// What it holds of the user, in words.
    pub what: String,
    pub content: Content,
}

/// What erase does with a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EraseAction {
    Delete,
    Rewrite,
    Leave,
}

impl Item {
    pub fn erase_action(&self) -> EraseAction {
        match &self.content {
            Content::Whole => EraseAction::Delete,
            Content::Bag(b) if b.user_messages == b.total => EraseAction::Delete,
            Content::Rows { total, users } if total == users => EraseAction::Delete,
            Content::Bag(_) | Content::Rows { .. } => EraseAction::Rewrite,
            Content::Inseparable { .. } => EraseAction::Leave,
        }
    }

    /// What erase would do, in words.
    pub fn erase_plan(&self) -> String {
        match (&self.content, self.erase_action()) {
            (Content::Inseparable { todo }, _) => format!("erase leaves it: {todo}"),
            (_, EraseAction::Delete) => "erase deletes the file".into(),
            (Content::Bag(b), _) => format!(
                "erase rewrites the bag without them ({} messages stay)",
                b.total - b.user_messages
            ),
            (Content::Rows { total, users }, _) => {
                format!(
                    "erase rewrites the file without them ({} stay)",
                    total - users
                )
            }
            _ => "erase rewrites the file".into(),
        }
    }
}

/// Why erase would refuse, changing nothing.
#[derive(Debug, Clone, PartialEq)]
pub enum Blocker {
    /// A session of this user has no summary and its run is alive.
    RunningSession {
        session: String,
        dir: PathBuf,
        by: Vec<LiveBy>,
    },
    /// Files to change are in a run directory still in use (a bag being recorded, a log
    /// being written).
    Live {
        dir: PathBuf,
        files: Vec<PathBuf>,
        by: Vec<LiveBy>,
    },
    /// A damaged bag holds (or probably held, past the damage) this user's messages.
    Damaged { path: PathBuf, why: String },
}

impl std::fmt::Display for Blocker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let by = |by: &[LiveBy]| {
            by.iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join("; ")
        };
        match self {
            Blocker::RunningSession {
                session,
                dir,
                by: b,
            } => write!(
                f,
                "session {session:?} of this user is running in {} ({}): wait until the \
                 therapist ends it, then stop the service when no session runs \
                 (sudo systemctl stop qt-therapy) and erase again",
                dir.display(),
                by(b)
            ),
            Blocker::Live { dir, files, by: b } => {
                let names: Vec<String> = files
                    .iter()
                    .map(|p| p.strip_prefix(dir).unwrap_or(p).display().to_string())
                    .collect();
                write!(
                    f,
                    "{} ({}) belong to a run still going ({}): they are still being written. \
                     Stop the service when no session runs (sudo systemctl stop qt-therapy), \
                     erase again, then start it",
                    dir.display(),
                    names.join(", "),
                    by(b)
                )
            }
            Blocker::Damaged { path, why } => write!(
                f,
                "{} is damaged: {why}. It cannot be rewritten whole: `erase --rewrite-damaged` \
                 keeps what reads before the damage without this user's messages and drops \
                 the unreadable rest (other users' messages in it too); or move the bag off \
                 the robot to repair it and erase again",
                path.display()
            ),
        }
    }
}

/// Everything found for one user.
#[derive(Debug)]
pub struct Inventory {
    pub user: UserId,
    /// The places searched, made absolute.
    pub places: Vec<PathBuf>,
    pub items: Vec<Item>,
    pub blockers: Vec<Blocker>,
    /// What is worth knowing but is not an item (cluster tables, damaged bags that hold
    /// nothing of the user, sessions cut off by a crash).
    pub notes: Vec<String>,
    /// Directories and files that could not be read: they may hold data of the user.
    pub unreadable: Vec<(PathBuf, String)>,
    /// The user's session ids per run directory (for matching log lines).
    pub sessions: BTreeMap<PathBuf, BTreeSet<String>>,
}

impl Inventory {
    /// Searches `places` for everything of `user`.
    pub fn build(user: &UserId, places: &[PathBuf]) -> Result<Inventory, ChildDataError> {
        let Walk {
            places,
            files,
            unreadable,
        } = walk(places)?;
        let mut inv = Inventory {
            user: user.clone(),
            places,
            items: Vec::new(),
            blockers: Vec::new(),
            notes: Vec::new(),
            unreadable,
            sessions: BTreeMap::new(),
        };
        let processes = Processes::scan();
        let of = |kind: FileKind| files.iter().filter(move |f| f.kind == kind);

        // Session files first: they say which sessions are the user's, and where.
        let paths: Vec<&Path> = of(FileKind::SessionFile)
            .map(|f| f.path.as_path())
            .collect();
        let sessions = read_sessions(&paths);
        let mut covered = BTreeSet::new();
        let mut user_sessions: Vec<&SessionFiles> = Vec::new();
        for s in &sessions {
            // A session whose user no file names is searched as text below.
            if s.user_id.is_some() {
                covered.extend(s.files.iter().cloned());
            }
            if s.user_id.as_deref() == Some(user.as_str()) {
                user_sessions.push(s);
            }
        }
        for s in &user_sessions {
            let id = s.session_id.clone().unwrap_or_else(|| s.stem.clone());
            inv.sessions
                .entry(s.dir.clone())
                .or_default()
                .insert(id.clone());
            if s.unfinished() {
                let by = live::live_by(&s.dir, &processes);
                if by.is_empty() {
                    inv.notes.push(format!(
                        "session {id:?} in {} has no summary and nothing runs it: it was cut \
                         off (a crash, a power cut); its files are this user's like the others",
                        s.dir.display()
                    ));
                } else {
                    inv.blockers.push(Blocker::RunningSession {
                        session: id.clone(),
                        dir: s.dir.clone(),
                        by,
                    });
                }
            }
            for path in &s.files {
                let found = files.iter().find(|f| &f.path == path);
                let what = match path.file_name().map(|n| n.to_string_lossy().into_owned()) {
                    Some(n) if n.ends_with(".summary.json") => "its summary",
                    Some(n) if n.ends_with(".journal") => "its journal (start, commands, tasks)",
                    _ => "one line per sequence (results, answers, engagement)",
                };
                let state = if s.finished { "" } else { ", unfinished" };
                inv.push(
                    found,
                    ItemKind::SessionFile,
                    format!("session {id}{state}: {what}"),
                    Content::Whole,
                );
            }
            for p in &s.problems {
                inv.notes
                    .push(format!("part of a session file could not be read: {p}"));
            }
        }

        // Bags: their sessions complete the list of the user's sessions.
        for f in of(FileKind::Bag) {
            inv.bag(f, &user_sessions);
        }

        // JSON files: Q-tables and fitted user models, by their `format`.
        let mut unknown: Vec<&Found> = of(FileKind::Other)
            .chain(of(FileKind::SessionFile).filter(|f| !covered.contains(&f.path)))
            .collect();
        for f in of(FileKind::Json) {
            if !inv.json(f) {
                unknown.push(f);
            }
        }
        for f in of(FileKind::Csv) {
            if !inv.csv(f) {
                unknown.push(f);
            }
        }
        for f in of(FileKind::Html) {
            inv.report(f);
        }
        for f in of(FileKind::Log) {
            inv.log(f);
        }
        for f in unknown {
            inv.unknown(f);
        }
        inv.live_checks(&processes);
        inv.items
            .sort_by(|a, b| a.kind.cmp(&b.kind).then(a.path.cmp(&b.path)));
        Ok(inv)
    }

    fn push(&mut self, found: Option<&Found>, kind: ItemKind, what: String, content: Content) {
        let Some(f) = found else { return };
        self.items.push(Item {
            path: f.path.clone(),
            place: f.place,
            rel: f.rel.clone(),
            kind,
            what,
            content,
        });
    }

    /// The user's session ids known in the run `file` belongs to.
    pub fn sessions_of_run(&self, file: &Path) -> BTreeSet<String> {
        self.sessions
            .get(&run_dir(file))
            .cloned()
            .unwrap_or_default()
    }

    fn bag(&mut self, f: &Found, user_sessions: &[&SessionFiles]) {
        let reader = match BagReader::open(&f.path) {
            Ok(r) => r,
            Err(e) => {
                self.unreadable.push((f.path.clone(), e.to_string()));
                return;
            }
        };
        let Some(part) = bag_part(&reader, &self.user, user_sessions) else {
            if let Some(d) = reader.damage() {
                self.notes.push(format!(
                    "{} is damaged ({d}); what reads before the damage holds nothing of this \
                     user, and the rest cannot be read to tell",
                    f.path.display()
                ));
            }
            return;
        };
        let dir = f.path.parent().unwrap_or(Path::new("/")).to_path_buf();
        self.sessions
            .entry(dir)
            .or_default()
            .extend(part.sessions.iter().cloned());
        if let Some(d) = &part.damage {
            let mut why = format!(
                "{d}; {} bytes after it cannot be read",
                part.unreadable_bytes
            );
            if let Some(t) = &part.tail_is_users {
                let _ = write!(why, ", and {t}");
            }
            self.blockers.push(Blocker::Damaged {
                path: f.path.clone(),
                why,
            });
        }
        let what = describe_bag(&part);
        self.push(Some(f), ItemKind::Bag, what, Content::Bag(part));
    }

    /// A Q-table or a fitted model file; false when the JSON is neither (searched as text).
    fn json(&mut self, f: &Found) -> bool {
        let Some(value) = read_capped(&f.path)
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        else {
            return false;
        };
        let user = self.user.as_str();
        match value.get("format").and_then(|v| v.as_str()) {
            Some("qt_therapy q_table") => {
                let owner = value.get("owner");
                if owner.and_then(|o| o.get("user")).and_then(|u| u.as_str()) == Some(user) {
                    self.push(
                        Some(f),
                        ItemKind::UserQTable,
                        "this user's own Q-table (Q-values and visits learned from their \
                         sessions, and the session ids)"
                            .into(),
                        Content::Whole,
                    );
                } else if let Some(k) = owner.and_then(|o| o.get("cluster")) {
                    let learned: Vec<&str> = value
                        .get("learned")
                        .and_then(|l| l.as_object())
                        .map(|l| l.keys().map(String::as_str).collect())
                        .unwrap_or_default();
                    let mine: BTreeSet<&str> = self
                        .sessions
                        .values()
                        .flatten()
                        .map(String::as_str)
                        .filter(|s| learned.contains(s))
                        .collect();
                    if !mine.is_empty() {
                        self.notes.push(format!(
                            "{}: cluster {k}'s Q-table learned from this user's sessions ({}) \
                             together with its other users': the Q-values are aggregated and \
                             hold no user id (its `learned` list names session ids only); \
                             neither exported nor erased",
                            f.path.display(),
                            mine.into_iter().collect::<Vec<_>>().join(", ")
                        ));
                    }
                }
                true
            }
            Some("qt_therapy child_belief") => {
                if value.get("user_id").and_then(|u| u.as_str()) == Some(user) {
                    self.push(
                        Some(f),
                        ItemKind::UserBelief,
                        "the behaviour policy's belief about this user (every sequence of theirs \
                         it learned from: level, feedback, score, answer right or wrong, \
                         engagement, and the session ids)"
                            .into(),
                        Content::Whole,
                    );
                }
                true
            }
            Some("qt_therapy user models") => {
                let points = value.get("users").and_then(|u| u.as_array());
                let point = points.and_then(|p| {
                    p.iter()
                        .find(|x| x.get("user").and_then(|u| u.as_str()) == Some(user))
                });
                let clusters = value.get("clusters").and_then(|c| c.as_array());
                let cluster = clusters.and_then(|cs| {
                    cs.iter().find(|c| {
                        c.get("users")
                            .and_then(|u| u.as_array())
                            .is_some_and(|u| u.iter().any(|x| x.as_str() == Some(user)))
                    })
                });
                if point.is_none() && cluster.is_none() {
                    return true;
                }
                let of_cluster = cluster.map_or_else(String::new, |c| {
                    format!(
                        " of cluster {} ({} users)",
                        c.get("cluster").unwrap_or(&serde_json::Value::Null),
                        c.get("users")
                            .and_then(|u| u.as_array())
                            .map_or(0, Vec::len)
                    )
                });
                self.push(
                    Some(f),
                    ItemKind::UserModel,
                    format!(
                        "fitted from this user's data: one of the users{of_cluster}, with their \
                         user vector and projection; their sequences are in the cluster's \
                         Gaussian processes, unnamed"
                    ),
                    Content::Inseparable {
                        todo: format!(
                            "the fit used this child's data, which removing a name cannot \
                             undo: fit the models again from data without the child \
                             (qt-therapy-user-model fit --data ... --output {}), then delete \
                             this file",
                            f.path.display()
                        ),
                    },
                );
                true
            }
            _ => false,
        }
    }

    /// An interaction CSV; false when it has no user column (searched as text).
    fn csv(&mut self, f: &Found) -> bool {
        let bytes = match std::fs::read(&f.path) {
            Ok(b) => b,
            Err(e) => {
                self.unreadable.push((f.path.clone(), e.to_string()));
                return true;
            }
        };
        match rows::csv_rows(&bytes, self.user.as_str()) {
            Ok(Some(r)) => {
                if r.users_rows() > 0 {
                    let what = format!(
                        "{} of {} rows (column {})",
                        r.users_rows(),
                        r.rows.len(),
                        r.column
                    );
                    let content = Content::Rows {
                        total: r.rows.len(),
                        users: r.users_rows(),
                    };
                    self.push(Some(f), ItemKind::InteractionCsv, what, content);
                }
                true
            }
            Ok(None) => false,
            Err(e) => {
                self.unreadable.push((f.path.clone(), e));
                true
            }
        }
    }

    fn report(&mut self, f: &Found) {
        let Ok(html) = read_capped(&f.path) else {
            return self.unknown(f);
        };
        // A child's progress report (`qt-therapy-report --user`) is about that child alone.
        if child_sessions::progress_report_of(&html).as_deref() == Some(self.user.as_str()) {
            return self.push(
                Some(f),
                ItemKind::Report,
                "the progress report of this user across sessions".into(),
                Content::Whole,
            );
        }
        match rows::report_title(&html) {
            Some((session, user)) if user == self.user.as_str() => self.push(
                Some(f),
                ItemKind::Report,
                format!("the report of this user's session {session}"),
                Content::Whole,
            ),
            title if self.user.named_in(&html) => {
                let of = title.map_or_else(
                    || "an HTML file".to_string(),
                    |(s, u)| format!("the report of session {s} (user {u})"),
                );
                self.push(
                    Some(f),
                    ItemKind::Report,
                    format!("{of} that also names this user"),
                    Content::Inseparable {
                        todo: "it is about someone else too: make it again with \
                               qt-therapy-report from the erased bag, or delete it"
                            .into(),
                    },
                );
            }
            _ => {}
        }
    }

    fn log(&mut self, f: &Found) {
        let Some(part) = log_lines(self, &f.path) else {
            return;
        };
        let (total, users) = (part.len(), part.iter().filter(|(_, p)| *p).count());
        if users > 0 {
            let what = format!("{users} of {total} lines name this user or their sessions");
            self.push(Some(f), ItemKind::Log, what, Content::Rows { total, users });
        }
    }

    fn unknown(&mut self, f: &Found) {
        let Ok(meta) = std::fs::metadata(&f.path) else {
            return;
        };
        if meta.len() > MAX_TEXT_BYTES {
            return;
        }
        let Ok(bytes) = std::fs::read(&f.path) else {
            self.unreadable
                .push((f.path.clone(), "cannot be read".into()));
            return;
        };
        if self.user.named_in(&String::from_utf8_lossy(&bytes)) {
            self.push(
                Some(f),
                ItemKind::Unknown,
                "names this user; not a file the suite writes, so not told apart".into(),
                Content::Inseparable {
                    todo: "look at it and delete or edit it by hand".into(),
                },
            );
        }
    }

    /// Files erase would change in a run that is still going block it. The Q-table directory
    /// is always held by the running behaviour policy, which opens a user's table and belief
    /// only when that user plays; with every run holding the user's data ended, it has not
    /// opened them.
    fn live_checks(&mut self, processes: &Processes) {
        let mut runs: BTreeMap<PathBuf, (Vec<LiveBy>, Vec<PathBuf>)> = BTreeMap::new();
        for item in &self.items {
            if item.erase_action() == EraseAction::Leave
                || matches!(item.kind, ItemKind::UserQTable | ItemKind::UserBelief)
            {
                continue;
            }
            let run = run_dir(&item.path);
            let entry = runs
                .entry(run.clone())
                .or_insert_with(|| (live::live_by(&run, processes), Vec::new()));
            entry.1.push(item.path.clone());
        }
        for (dir, (by, files)) in runs {
            if by.is_empty() {
                continue;
            }
            // A bag still being recorded ends in a chunk being written: not damage to report
            // on top of the run going on.
            self.blockers
                .retain(|b| !matches!(b, Blocker::Damaged { path, .. } if files.contains(path)));
            self.blockers.push(Blocker::Live { dir, files, by });
        }
    }

    /// The blockers that make erase refuse (a damaged bag only without `--rewrite-damaged`).
    pub fn refusals(&self, rewrite_damaged: bool) -> Vec<&Blocker> {
        self.blockers
            .iter()
            .filter(|b| !(rewrite_damaged && matches!(b, Blocker::Damaged { .. })))
            .collect()
    }

    /// What `list` prints: every item with what erase would do, then the notes.
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        let user = self.user.as_str();
        let places: Vec<String> = self
            .places
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        let _ = writeln!(out, "user {user:?}, searched: {}", places.join(", "));
        if self.items.is_empty() {
            let _ = writeln!(
                out,
                "nothing of this user found (ids are matched exactly, case and all)"
            );
        }
        for item in &self.items {
            let _ = writeln!(
                out,
                "  {} [{}]\n      {}; {}",
                item.path.display(),
                item.kind.label(),
                item.what,
                item.erase_plan()
            );
        }
        for b in &self.blockers {
            let _ = writeln!(out, "erase would refuse: {b}");
        }
        for n in &self.notes {
            let _ = writeln!(out, "note: {n}");
        }
        for (p, why) in &self.unreadable {
            let _ = writeln!(
                out,
                "not searched (it may hold data of this user): {}: {why}",
                p.display()
            );
        }
        out
    }
}

/// The run directory a file belongs to: its directory, or for a log in `logs/`, the run's.
pub fn run_dir(path: &Path) -> PathBuf {
    let dir = path.parent().unwrap_or(Path::new("/"));
    if dir.file_name().is_some_and(|n| n == "logs") {
        dir.parent().unwrap_or(dir).to_path_buf()
    } else {
        dir.to_path_buf()
    }
}

/// Reads a text file of at most [`MAX_TEXT_BYTES`].
fn read_capped(path: &Path) -> Result<String, String> {
    let len = std::fs::metadata(path).map_err(|e| e.to_string())?.len();
    if len > MAX_TEXT_BYTES {
        return Err(format!("{len} bytes: too large to search"));
    }
    std::fs::read(path)
        .map(|b| String::from_utf8_lossy(&b).into_owned())
        .map_err(|e| e.to_string())
}

/// The lines of a log, those naming the user or one of the user's sessions of its run marked.
pub fn log_lines(inv: &Inventory, path: &Path) -> Option<Vec<(Range<usize>, bool)>> {
    let bytes = std::fs::read(path).ok()?;
    let text = String::from_utf8_lossy(&bytes);
    if text.len() != bytes.len() {
        // Not UTF-8 throughout: byte ranges of the lossy text would not be the file's.
        return None;
    }
    let sessions = inv.sessions_of_run(path);
    let pick =
        |line: &str| inv.user.named_in(line) || sessions.iter().any(|s| names_token(line, s));
    Some(rows::lines(&text, &pick))
}

/// The user's part of a read bag; None when it holds nothing of the user.
pub fn bag_part(
    reader: &BagReader,
    user: &UserId,
    user_sessions: &[&SessionFiles],
) -> Option<BagPart> {
    bag_part_of(reader, &Ownership::of(reader), user, user_sessions)
}

/// [`bag_part`] with the bag's ownership already worked out.
pub fn bag_part_of(
    reader: &BagReader,
    ownership: &Ownership,
    user: &UserId,
    user_sessions: &[&SessionFiles],
) -> Option<BagPart> {
    let count = ownership.count(user.as_str());
    let last = reader.time_range().map(|(_, l)| l);
    let tail_is_users = reader.damage().and_then(|_| {
        let dir = Path::new(reader.name()).parent()?;
        if ownership.sessions.last().and_then(|s| s.user.as_deref()) == Some(user.as_str()) {
            return Some("the session the readable part ends in is this user's".to_string());
        }
        user_sessions
            .iter()
            .filter(|s| s.dir == dir)
            .find(|s| {
                s.last_ns
                    .is_some_and(|l| last.is_none_or(|last| l > 0 && l as u64 > last))
            })
            .map(|s| {
                format!(
                    "this user's session {} went on after the last readable message (its \
                     session files say so)",
                    s.session_id.as_deref().unwrap_or(&s.stem)
                )
            })
    });
    if count == 0 && tail_is_users.is_none() {
        return None;
    }
    let k = ownership.user_index(user.as_str());
    let mut sessions: Vec<String> = Vec::new();
    for s in &ownership.sessions {
        if s.user.as_deref() == Some(user.as_str()) && !sessions.contains(&s.session_id) {
            sessions.push(s.session_id.clone());
        }
    }
    let mut others: BTreeSet<String> = BTreeSet::new();
    for o in ownership.owners.iter().flatten() {
        if Some(*o) != k {
            others.insert(ownership.users[*o].clone());
        }
    }
    let damage = reader.damage().map(ToString::to_string);
    let unreadable_bytes = reader
        .damage()
        .and_then(|d| d.record())
        .map_or(0, |at| reader.size_bytes().saturating_sub(at.offset));
    Some(BagPart {
        user_messages: count,
        total: reader.raw_messages().len(),
        topics: bags::per_topic(reader, ownership, user.as_str()),
        sessions,
        others: others.into_iter().collect(),
        damage,
        unreadable_bytes,
        tail_is_users,
        complete: reader.is_complete(),
    })
}

fn describe_bag(b: &BagPart) -> String {
    let topics = b.topics.values().filter(|(u, _)| *u > 0).count();
    let mut s = if b.user_messages == b.total {
        format!(
            "all {} messages are this user's (sessions {}; {topics} topics)",
            b.total,
            b.sessions.join(", ")
        )
    } else {
        format!(
            "{} of {} messages are this user's (sessions {}; {topics} topics); the rest is {}",
            b.user_messages,
            b.total,
            b.sessions.join(", "),
            if b.others.is_empty() {
                "of no known user".to_string()
            } else {
                format!("users {}", b.others.join(", "))
            }
        )
    };
    if let Some(d) = &b.damage {
        let _ = write!(
            s,
            "; DAMAGED: {d} ({} bytes unreadable)",
            b.unreadable_bytes
        );
        if let Some(t) = &b.tail_is_users {
            let _ = write!(s, ", and {t}");
        }
    } else if !b.complete {
        s.push_str("; not closed (a recording killed or still going)");
    }
    s
}

/// A CSV's rows as they are now (for export and erase).
pub fn csv_now(path: &Path, user: &UserId) -> Result<(Vec<u8>, Option<CsvRows>), ChildDataError> {
    let bytes = std::fs::read(path).map_err(ChildDataError::io(path))?;
    let rows = rows::csv_rows(&bytes, user.as_str()).map_err(|reason| ChildDataError::Csv {
        path: path.to_path_buf(),
        reason,
    })?;
    Ok((bytes, rows))
}
