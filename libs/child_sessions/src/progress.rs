//! One child's progress across sessions, read from what the robot stores: the game manager's
//! session files (one line per sequence, the journal of the start and the therapist's
//! commands, the summary) and the bags of the runs those files are in. A session is the
//! child's when its session files say so (`sessions`, as `child_data` decides whose a file
//! is); the bags of the same run directories add what the files do not hold (the policy's
//! decisions, the proposals of a session cut off before its summary) and any result a torn
//! line lost. Every result, decision and proposal passes the suite's one rule for what
//! arrived twice (`session_log::Once`): a result in both the session file and the bag is
//! taken once; two that differ are named and the first kept. A bag that is damaged, cut off,
//! unreadable or missing is named, and what the rest holds is still shown.

use crate::error::StoredError;
use crate::find::{FileKind, walk};
use crate::sessions::read_sessions;
use crate::user::UserId;
use bag_file::BagReader;
use qt_therapy_msgs::{ActionProposal, Decision, ProposalStatus, SequenceResult};
use serde::Deserialize;
use session_log::{Arrival, Messages, Once};
use session_tally::Tally;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// How a session ended, as its summary says; `Unfinished` without a summary (running, or cut
/// off by a crash or a power cut).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    Finished,
    Stopped,
    EmergencyStopped,
    NodeShutdown,
    Unfinished,
}

impl Ended {
    fn of(end: &str) -> Ended {
        match end {
            "finished" => Ended::Finished,
            "stopped" => Ended::Stopped,
            "emergency_stopped" => Ended::EmergencyStopped,
            "node_shutdown" => Ended::NodeShutdown,
            _ => Ended::Unfinished,
        }
    }

    /// The key the report's words are looked up by.
    pub fn key(self) -> &'static str {
        match self {
            Ended::Finished => "end_finished",
            Ended::Stopped => "end_stopped",
            Ended::EmergencyStopped => "end_emergency_stopped",
            Ended::NodeShutdown => "end_node_shutdown",
            Ended::Unfinished => "end_unfinished",
        }
    }
}

/// What the therapist was asked over a session (supervised autonomy) and answered.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ProposalCounts {
    pub proposed: u32,
    pub accepted: u32,
    pub replaced: u32,
    /// Nobody answered within the countdown: carried out.
    pub timed_out: u32,
}

/// One session of the child.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionProgress {
    pub session_id: String,
    /// The run directory its files are in.
    pub dir: PathBuf,
    /// When it started (ns since the epoch): the journal's start, the summary's, or the first
    /// result's stamp.
    pub started_ns: Option<i64>,
    pub ended: Ended,
    /// The user-model cluster it was played with (-1: the policy's default).
    pub cluster: Option<i32>,
    pub sequences_planned: Option<u8>,
    /// Its results, one per sequence played, in order.
    pub results: Vec<SequenceResult>,
    /// Score of the maximum, right answers, timeouts, mean engagement (`session_tally`).
    pub tally: Tally,
    /// Sequences after encouraging and after challenging feedback.
    pub encouraging: usize,
    pub challenging: usize,
    /// Sequences whose action the therapist set (an override, or a proposal replaced).
    pub overrides: usize,
    pub pauses: usize,
    /// The policy answered too late (same level, no feedback), per the session file.
    pub policy_fallbacks: usize,
    /// From the summary, or counted from the bag's proposals when there is no summary; None
    /// when neither says.
    pub proposals: Option<ProposalCounts>,
    /// The policy's decisions the bags hold for it, and how many explored; None without a
    /// readable bag.
    pub decisions: Option<usize>,
    pub explored: Option<usize>,
    /// A restarted game manager took it over this many times (journal).
    pub recovered: usize,
}

impl SessionProgress {
    /// The level of each sequence played, in order.
    pub fn levels(&self) -> Vec<u8> {
        self.results.iter().map(|r| r.level).collect()
    }

    /// Each sequence's expected engagement E where a face was seen.
    pub fn engagement(&self) -> Vec<f64> {
        self.results
            .iter()
            .filter_map(SequenceResult::seen_engagement)
            .collect()
    }
}

/// What the robot believes about the child now: per level P(success) and engagement with
/// their uncertainty, or weights over known models. The policy's decisions
/// (`msgs/msg/Decision.msg`) do not carry a belief yet, so it is [`Belief::NotCarried`];
/// once they do, [`Belief::of`] reads it from the child's last decision and the report's
/// "What the robot believes now" shows it.
#[derive(Debug, Clone, PartialEq)]
pub enum Belief {
    /// Decisions carry no belief about the child: not available.
    NotCarried,
}

impl Belief {
    /// The belief the child's last decision carries.
    pub fn of(_last_decision: Option<&Decision>) -> Belief {
        Belief::NotCarried
    }
}

/// One child's sessions, oldest first, and what could not be read.
#[derive(Debug, Clone)]
pub struct Progress {
    pub user: UserId,
    /// The places searched, as given.
    pub places: Vec<PathBuf>,
    pub sessions: Vec<SessionProgress>,
    /// Damaged, cut-off, unreadable or missing bags, unreadable lines, messages that arrived
    /// twice and differ: each named; what the rest holds is shown.
    pub problems: Vec<String>,
    /// The policy's last decision for the child, from the bags.
    pub last_decision: Option<Decision>,
    pub belief: Belief,
}

#[derive(Debug, Deserialize)]
struct RecordLine {
    result: SequenceResult,
    #[serde(default)]
    policy_fallback: bool,
}

#[derive(Debug, Deserialize)]
struct JournalLine {
    entry: String,
    #[serde(default)]
    user_model_cluster: Option<i32>,
    #[serde(default)]
    command: Option<String>,
    #[serde(default)]
    at_ns: i64,
}

#[derive(Debug, Deserialize)]
struct SummaryFile {
    #[serde(default)]
    user_model_cluster: Option<i32>,
    #[serde(default)]
    end: String,
    #[serde(default)]
    sequences_planned: Option<u8>,
    #[serde(default)]
    proposals: u32,
    #[serde(default)]
    proposals_accepted: u32,
    #[serde(default)]
    proposals_replaced: u32,
    #[serde(default)]
    proposals_timed_out: u32,
    #[serde(default)]
    started_ns: i64,
}

/// A session as its files and bags tell it, before it is counted.
#[derive(Debug, Default)]
struct Gathered {
    dir: PathBuf,
    started_ns: Option<i64>,
    ended: Option<Ended>,
    cluster: Option<i32>,
    sequences_planned: Option<u8>,
    results: Vec<SequenceResult>,
    policy_fallbacks: usize,
    pauses: usize,
    recovered: usize,
    summary_proposals: Option<ProposalCounts>,
    bag_proposals: Vec<ActionProposal>,
    decisions: Option<Vec<Decision>>,
}

/// The rule for what arrived twice, over every file and bag read for the child.
#[derive(Default)]
struct Rule {
    results: Once<SequenceResult>,
    decisions: Once<Decision>,
    proposals: Once<ActionProposal>,
}

/// Takes `m` from `origin` through `once`: true when it is new; a conflict is named in
/// `problems` (the first stays).
fn taken<M: session_log::Identified>(
    once: &mut Once<M>,
    m: &M,
    origin: &str,
    problems: &mut Vec<String>,
) -> bool {
    match once.arrive(m, origin) {
        Ok(Arrival::New) => true,
        Ok(Arrival::Repeat) => false,
        Err(conflict) => {
            problems.push(conflict.to_string());
            false
        }
    }
}

/// Largest session file read (the game manager writes a few kB per session).
const MAX_SESSION_FILE_BYTES: u64 = 16 << 20;

fn read_lines(path: &Path, problems: &mut Vec<String>) -> Vec<(usize, String)> {
    let text = match std::fs::metadata(path) {
        Ok(m) if m.len() > MAX_SESSION_FILE_BYTES => {
            problems.push(format!(
                "{}: {} bytes is too large for a session file; not read",
                path.display(),
                m.len()
            ));
            return Vec::new();
        }
        _ => match std::fs::read(path) {
            Ok(b) => String::from_utf8_lossy(&b).into_owned(),
            Err(e) => {
                problems.push(format!("{}: {e}", path.display()));
                return Vec::new();
            }
        },
    };
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(n, l)| (n + 1, l.to_string()))
        .collect()
}

fn ends_with(path: &Path, suffix: &str) -> bool {
    path.file_name()
        .is_some_and(|n| n.to_string_lossy().ends_with(suffix))
}

impl Progress {
    /// Reads every session of `user` under `places` (the sessions root: every run's
    /// directory below it), and the bags of their run directories.
    pub fn build(user: &UserId, places: &[PathBuf]) -> Result<Progress, StoredError> {
        let found = walk(places)?;
        let mut problems: Vec<String> = found
            .unreadable
            .iter()
            .map(|(p, why)| format!("{} could not be read: {why}", p.display()))
            .collect();
        let session_paths: Vec<&Path> = found
            .files
            .iter()
            .filter(|f| f.kind == FileKind::SessionFile)
            .map(|f| f.path.as_path())
            .collect();
        let mut rule = Rule::default();
        let mut gathered: BTreeMap<String, Gathered> = BTreeMap::new();
        for s in read_sessions(&session_paths) {
            if s.user_id.as_deref() != Some(user.as_str()) {
                continue;
            }
            let id = s.session_id.clone().unwrap_or_else(|| s.stem.clone());
            let g = gathered.entry(id).or_default();
            g.dir = s.dir.clone();
            g.started_ns = s.started_ns;
            g.ended = Some(Ended::Unfinished);
            problems.extend(s.problems.iter().cloned());
            for path in &s.files {
                read_session_file(path, g, &mut rule, &mut problems);
            }
        }
        // The bags of the runs the child's sessions are in.
        let dirs: BTreeSet<PathBuf> = gathered.values().map(|g| g.dir.clone()).collect();
        for dir in &dirs {
            let bags: Vec<&Path> = found
                .files
                .iter()
                .filter(|f| f.kind == FileKind::Bag && f.path.parent() == Some(dir.as_path()))
                .map(|f| f.path.as_path())
                .collect();
            let in_dir: Vec<String> = gathered
                .iter()
                .filter(|(_, g)| &g.dir == dir)
                .map(|(id, _)| id.clone())
                .collect();
            if bags.is_empty() {
                problems.push(format!(
                    "no bag in {}: sessions {} show what their session files hold, without the \
                     policy's decisions",
                    dir.display(),
                    in_dir.join(", ")
                ));
                continue;
            }
            for bag in bags {
                read_bag(bag, dir, user, &mut gathered, &mut rule, &mut problems);
            }
        }
        let mut counted: Vec<(SessionProgress, Option<Decision>)> =
            gathered.into_iter().map(|(id, g)| counted(id, g)).collect();
        counted.sort_by(|(a, _), (b, _)| {
            a.started_ns
                .cmp(&b.started_ns)
                .then(a.session_id.cmp(&b.session_id))
        });
        let last_decision = counted.iter().rev().find_map(|(_, d)| d.clone());
        let sessions = counted.into_iter().map(|(s, _)| s).collect();
        Ok(Progress {
            user: user.clone(),
            places: places.to_vec(),
            belief: Belief::of(last_decision.as_ref()),
            sessions,
            problems,
            last_decision,
        })
    }

    /// The first and the last session's start (ns since the epoch).
    pub fn span_ns(&self) -> Option<(i64, i64)> {
        let starts: Vec<i64> = self.sessions.iter().filter_map(|s| s.started_ns).collect();
        Some((*starts.iter().min()?, *starts.iter().max()?))
    }
}

/// Reads one of a session's files (`.jsonl`, `.journal`, `.summary.json`) into `g`.
fn read_session_file(path: &Path, g: &mut Gathered, rule: &mut Rule, problems: &mut Vec<String>) {
    if ends_with(path, ".summary.json") {
        let text = read_lines(path, problems)
            .into_iter()
            .map(|(_, l)| l)
            .collect::<Vec<_>>()
            .join("\n");
        match serde_json::from_str::<SummaryFile>(&text) {
            Ok(s) => {
                g.ended = Some(Ended::of(&s.end));
                g.cluster = g.cluster.or(s.user_model_cluster);
                g.sequences_planned = s.sequences_planned;
                if s.started_ns > 0 {
                    g.started_ns = Some(s.started_ns);
                }
                g.summary_proposals = Some(ProposalCounts {
                    proposed: s.proposals,
                    accepted: s.proposals_accepted,
                    replaced: s.proposals_replaced,
                    timed_out: s.proposals_timed_out,
                });
            }
            Err(e) => problems.push(format!("{}: {e}", path.display())),
        }
    } else if ends_with(path, ".journal") {
        for (n, line) in read_lines(path, problems) {
            match serde_json::from_str::<JournalLine>(&line) {
                Ok(j) => match j.entry.as_str() {
                    "started" => {
                        g.cluster = j.user_model_cluster.or(g.cluster);
                        if j.at_ns > 0 {
                            g.started_ns = Some(j.at_ns);
                        }
                    }
                    "command" if j.command.as_deref() == Some("pause") => g.pauses += 1,
                    "recovered" => g.recovered += 1,
                    _ => {}
                },
                // A torn line (a crash mid-write) is named; the rest is read.
                Err(e) => problems.push(format!("{}, line {n}: {e}", path.display())),
            }
        }
    } else {
        let origin = path.display().to_string();
        for (n, line) in read_lines(path, problems) {
            match serde_json::from_str::<RecordLine>(&line) {
                Ok(r) => {
                    let at = format!("{origin}, line {n}");
                    if taken(&mut rule.results, &r.result, &at, problems) {
                        g.policy_fallbacks += usize::from(r.policy_fallback);
                        g.results.push(r.result);
                    }
                }
                Err(e) => problems.push(format!("{}, line {n}: {e}", path.display())),
            }
        }
    }
}

/// Reads one bag of run `dir`: the child's results the session files lacked, and the
/// decisions and proposals of the child's sessions.
fn read_bag(
    path: &Path,
    dir: &Path,
    user: &UserId,
    gathered: &mut BTreeMap<String, Gathered>,
    rule: &mut Rule,
    problems: &mut Vec<String>,
) {
    let reader = match BagReader::open(path) {
        Ok(r) => r,
        Err(e) => {
            problems.push(format!(
                "the bag {} cannot be read ({e}): the sessions in {} show what their session \
                 files hold",
                path.display(),
                dir.display()
            ));
            return;
        }
    };
    if let Some(d) = reader.damage() {
        problems.push(format!(
            "the bag {} is damaged ({d}): what reads before the damage is used",
            path.display()
        ));
    } else if !reader.is_complete() {
        problems.push(format!(
            "the bag {} was not closed (a recording killed, or still going): read to its last \
             whole record",
            path.display()
        ));
    }
    let (messages, _missing) = match Messages::from_bag(&reader) {
        Ok(m) => m,
        Err(e) => {
            problems.push(format!("the bag {}: {e}", path.display()));
            return;
        }
    };
    let name = path.display().to_string();
    let mine = |session: &str, g: &BTreeMap<String, Gathered>| {
        g.get(session).is_some_and(|s| s.dir == dir)
    };
    for (k, r) in messages.results.iter().enumerate() {
        let r = &r.message;
        if r.user_id != user.as_str() {
            continue;
        }
        let origin = format!("{name}, SequenceResult #{}", k + 1);
        if taken(&mut rule.results, r, &origin, problems) {
            // A session the bag holds and no session file names (its files removed): the
            // bag's results stand for it.
            let g = gathered
                .entry(r.session_id.clone())
                .or_insert_with(|| Gathered {
                    dir: dir.to_path_buf(),
                    ..Default::default()
                });
            g.results.push(r.clone());
        }
    }
    for (k, d) in messages.decisions.iter().enumerate() {
        let d = &d.message;
        if !mine(&d.session_id, gathered) {
            continue;
        }
        let origin = format!("{name}, Decision #{}", k + 1);
        if taken(&mut rule.decisions, d, &origin, problems)
            && let Some(g) = gathered.get_mut(&d.session_id)
        {
            g.decisions.get_or_insert_with(Vec::new).push(d.clone());
        }
    }
    if reader.damage().is_none() {
        for g in gathered.values_mut().filter(|g| g.dir == dir) {
            // A whole bag was read for the run: a session without decisions in it had none.
            g.decisions.get_or_insert_with(Vec::new);
        }
    }
    for (k, p) in messages.proposals.iter().enumerate() {
        let p = &p.message;
        if !mine(&p.session_id, gathered) {
            continue;
        }
        let origin = format!("{name}, ActionProposal #{}", k + 1);
        if taken(&mut rule.proposals, p, &origin, problems)
            && let Some(g) = gathered.get_mut(&p.session_id)
        {
            g.bag_proposals.push(p.clone());
        }
    }
}

/// Proposals counted from their messages: each (session, step) proposed once, however often
/// it was shown again, and how it was settled.
fn counted_proposals(messages: &[ActionProposal]) -> ProposalCounts {
    let mut steps: BTreeMap<u8, Option<u8>> = BTreeMap::new();
    for p in messages {
        let entry = steps.entry(p.step).or_insert(None);
        if p.status != ActionProposal::PROPOSED {
            *entry = Some(p.status);
        }
    }
    let mut c = ProposalCounts {
        proposed: steps.len() as u32,
        ..Default::default()
    };
    for status in steps.values().flatten() {
        match ProposalStatus::try_from(*status) {
            Ok(ProposalStatus::Accepted) => c.accepted += 1,
            Ok(ProposalStatus::Replaced) => c.replaced += 1,
            Ok(ProposalStatus::TimedOut) => c.timed_out += 1,
            _ => {}
        }
    }
    c
}

/// The session counted, and its last decision (the newest stamp).
fn counted(session_id: String, mut g: Gathered) -> (SessionProgress, Option<Decision>) {
    g.results.sort_by_key(|r| r.sequence_index);
    let started_ns = g.started_ns.or_else(|| {
        g.results
            .first()
            .map(|r| r.engagement_period_start.to_nanos())
            .filter(|ns| *ns > 0)
    });
    let proposals = g
        .summary_proposals
        .or_else(|| (!g.bag_proposals.is_empty()).then(|| counted_proposals(&g.bag_proposals)));
    let explored = g
        .decisions
        .as_ref()
        .map(|d| d.iter().filter(|d| d.explored).count());
    let last_decision = g
        .decisions
        .iter()
        .flatten()
        .max_by_key(|d| (d.step, d.header.stamp.to_nanos()))
        .cloned();
    let session = SessionProgress {
        tally: Tally::of(&g.results),
        encouraging: g.results.iter().filter(|r| r.feedback == 1).count(),
        challenging: g.results.iter().filter(|r| r.feedback == 2).count(),
        overrides: g.results.iter().filter(|r| r.overridden).count(),
        cluster: g
            .cluster
            .or_else(|| g.results.first().map(|r| r.user_model_cluster)),
        sequences_planned: g
            .sequences_planned
            .or_else(|| g.results.first().map(|r| r.sequences_planned)),
        session_id,
        dir: g.dir,
        started_ns,
        ended: g.ended.unwrap_or(Ended::Unfinished),
        pauses: g.pauses,
        policy_fallbacks: g.policy_fallbacks,
        proposals,
        decisions: g.decisions.as_ref().map(Vec::len),
        explored,
        recovered: g.recovered,
        results: g.results,
    };
    (session, last_decision)
}
