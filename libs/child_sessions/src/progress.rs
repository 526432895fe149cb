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
use qt_therapy_msgs::validate::Validate;
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

/// The belief about the child at one level, as a decision carried it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelBelief {
    /// The chance of a right answer without feedback, and its posterior standard deviation.
    pub success: f64,
    pub success_sd: f64,
    /// The engagement expected there (−1..1), and its posterior standard deviation.
    pub engagement: f64,
    pub engagement_sd: f64,
}

/// The belief one decision was planned on: levels 1..3 (index 0..2), after `observations`
/// sequences of the child's own.
#[derive(Debug, Clone, PartialEq)]
pub struct BeliefAt {
    pub observations: u32,
    pub levels: [LevelBelief; 3],
}

impl BeliefAt {
    /// The belief `d` was planned on; None when it was not planned on one, or carries one
    /// that is not valid (`Decision::validate`: three levels, each in range).
    fn of(d: &Decision) -> Option<BeliefAt> {
        if !d.planned_on_belief || d.validate().is_err() {
            return None;
        }
        let level = |k: usize| {
            Some(LevelBelief {
                success: *d.belief_success.get(k)?,
                success_sd: *d.belief_success_sd.get(k)?,
                engagement: *d.belief_engagement.get(k)?,
                engagement_sd: *d.belief_engagement_sd.get(k)?,
            })
        };
        Some(BeliefAt {
            observations: d.belief_observations,
            levels: [level(0)?, level(1)?, level(2)?],
        })
    }
}

/// What the robot believes about the child, from the last session whose decisions were
/// planned on a belief: where it stood then (its last such decision) and where it stood at
/// that session's start (its first), and how often that session the plan left the group's
/// table.
#[derive(Debug, Clone, PartialEq)]
pub struct CarriedBelief {
    /// The session, and its place among the child's sessions (1-based, oldest first).
    pub session_id: String,
    pub session_number: usize,
    pub now: BeliefAt,
    pub session_start: BeliefAt,
    /// That session's decisions planned on the belief, and those whose action differs from
    /// the one the cluster's Q-table would have taken (`baseline_action`).
    pub planned: usize,
    pub left_table: usize,
}

/// What the robot believes about the child now (per level P(success) and engagement with
/// their uncertainty), read from the policy's decisions (`msgs/msg/Decision.msg`) by
/// [`Belief::of`]; the report's "What the robot believes now" shows it.
#[derive(Debug, Clone, PartialEq)]
pub enum Belief {
    /// No decision of the policy was read for the child (no session, or no readable bag).
    NoDecisions,
    /// Decisions were read and none carries a belief: the policy decided from the group's
    /// (the cluster's) Q-table (its `child_belief` parameter off).
    NotCarried,
    /// Boxed: a belief is some 300 bytes, the other variants none.
    Carried(Box<CarriedBelief>),
}

impl Belief {
    /// The belief the child's decisions carry: `sessions` holds each session's id and
    /// decisions, oldest session first, each session's decisions in the order they were made.
    /// The last session with a decision planned on a (valid) belief is read.
    pub fn of(sessions: &[(String, Vec<Decision>)]) -> Belief {
        if sessions.iter().all(|(_, d)| d.is_empty()) {
            return Belief::NoDecisions;
        }
        let Some((number, (session_id, decisions))) = sessions
            .iter()
            .enumerate()
            .rev()
            .find(|(_, (_, d))| d.iter().any(|d| BeliefAt::of(d).is_some()))
        else {
            return Belief::NotCarried;
        };
        let planned: Vec<(&Decision, BeliefAt)> = decisions
            .iter()
            .filter_map(|d| Some((d, BeliefAt::of(d)?)))
            .collect();
        let (Some((_, session_start)), Some((_, now))) = (planned.first(), planned.last()) else {
            return Belief::NotCarried;
        };
        Belief::Carried(Box::new(CarriedBelief {
            session_id: session_id.clone(),
            session_number: number + 1,
            now: now.clone(),
            session_start: session_start.clone(),
            planned: planned.len(),
            left_table: planned
                .iter()
                .filter(|(d, _)| d.baseline_action != d.action)
                .count(),
        }))
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
        let mut counted: Vec<(SessionProgress, Vec<Decision>)> =
            gathered.into_iter().map(|(id, g)| counted(id, g)).collect();
        counted.sort_by(|(a, _), (b, _)| {
            a.started_ns
                .cmp(&b.started_ns)
                .then(a.session_id.cmp(&b.session_id))
        });
        let last_decision = counted.iter().rev().find_map(|(_, d)| d.last().cloned());
        // A belief that is not valid (a bag from a policy that wrote it wrong) is named and
        // not shown.
        for (s, decisions) in &counted {
            for d in decisions.iter().filter(|d| d.planned_on_belief) {
                if let Err(e) = d.validate() {
                    problems.push(format!(
                        "session {}, decision for sequence {}: {e}; its belief is not shown",
                        s.session_id, d.step
                    ));
                }
            }
        }
        let (sessions, decisions): (Vec<SessionProgress>, Vec<(String, Vec<Decision>)>) = counted
            .into_iter()
            .map(|(s, d)| {
                let id = s.session_id.clone();
                (s, (id, d))
            })
            .unzip();
        Ok(Progress {
            user: user.clone(),
            places: places.to_vec(),
            belief: Belief::of(&decisions),
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

/// The session counted, and its decisions in the order they were made (by sequence, then
/// stamp).
fn counted(session_id: String, mut g: Gathered) -> (SessionProgress, Vec<Decision>) {
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
    let mut decisions = g.decisions.clone().unwrap_or_default();
    decisions.sort_by_key(|d| (d.step, d.header.stamp.to_nanos()));
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
    (session, decisions)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A decision of sequence `step`, planned on a belief of `right` (P(right) per level) after
    /// `observations` sequences when given, the table's action `baseline`.
    fn decision(step: u8, action: u8, baseline: u8, belief: Option<([f64; 3], u32)>) -> Decision {
        let mut d = Decision {
            session_id: "s".into(),
            step,
            action,
            level: 1,
            q_values: vec![0.0; 5],
            probabilities: vec![0.2; 5],
            baseline_action: baseline,
            ..Default::default()
        };
        if let Some((right, observations)) = belief {
            d.planned_on_belief = true;
            d.belief_observations = observations;
            d.belief_success = right.to_vec();
            d.belief_success_sd = vec![0.06, 0.1, 0.15];
            d.belief_engagement = vec![0.4, 0.2, -0.1];
            d.belief_engagement_sd = vec![0.1, 0.12, 0.2];
        }
        d
    }

    fn session(id: &str, decisions: Vec<Decision>) -> (String, Vec<Decision>) {
        (id.into(), decisions)
    }

    #[test]
    fn decisions_without_a_belief_say_the_group_table_decided() {
        assert_eq!(Belief::of(&[]), Belief::NoDecisions);
        assert_eq!(Belief::of(&[session("a", Vec::new())]), Belief::NoDecisions);
        let table = |step| decision(step, 1, 1, None);
        assert_eq!(
            Belief::of(&[session("a", vec![table(1), table(2)]), session("b", vec![])]),
            Belief::NotCarried
        );
    }

    #[test]
    fn the_belief_now_and_at_the_start_of_the_last_session_planned_on_it() {
        let sessions = [
            // An older session planned on a belief: not the one read.
            session("a", vec![decision(1, 0, 0, Some(([0.5, 0.5, 0.5], 0)))]),
            session(
                "b",
                vec![
                    decision(1, 0, 0, Some(([0.8, 0.55, 0.3], 20))),
                    decision(2, 1, 0, Some(([0.82, 0.6, 0.3], 21))),
                    // One the table alone decided (the plan did not run): not counted.
                    decision(3, 2, 1, None),
                    decision(4, 1, 1, Some(([0.85, 0.68, 0.31], 23))),
                ],
            ),
            // The newest session has no decision (no bag): the belief stays b's.
            session("c", Vec::new()),
        ];
        let Belief::Carried(b) = Belief::of(&sessions) else {
            panic!("{:?}", Belief::of(&sessions));
        };
        assert_eq!((b.session_id.as_str(), b.session_number), ("b", 2));
        assert_eq!((b.planned, b.left_table), (3, 1));
        assert_eq!(b.now.observations, 23);
        assert_eq!(b.session_start.observations, 20);
        let right = |a: &BeliefAt| a.levels.map(|l| l.success);
        assert_eq!(right(&b.now), [0.85, 0.68, 0.31]);
        assert_eq!(right(&b.session_start), [0.8, 0.55, 0.3]);
        assert_eq!(b.now.levels[1].success_sd, 0.1);
        assert_eq!(b.now.levels[0].engagement, 0.4);
        assert_eq!(b.now.levels[2].engagement_sd, 0.2);
    }

    #[test]
    fn a_belief_that_is_not_valid_is_not_read() {
        let mut short = decision(2, 0, 0, Some(([0.8, 0.5, 0.3], 5)));
        short.belief_success.pop();
        let mut out_of_range = decision(3, 0, 0, Some(([0.8, 0.5, 0.3], 6)));
        out_of_range.belief_success[0] = 1.5;
        assert_eq!(
            Belief::of(&[session("a", vec![short.clone(), out_of_range.clone()])]),
            Belief::NotCarried
        );
        let good = decision(1, 0, 0, Some(([0.7, 0.5, 0.3], 4)));
        let Belief::Carried(b) = Belief::of(&[session("a", vec![good, short, out_of_range])])
        else {
            panic!("the good one is read");
        };
        assert_eq!((b.planned, b.now.observations), (1, 4));
    }
}
