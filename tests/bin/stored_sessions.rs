//! `stored_sessions`: a robot's stored sessions for tests, written by the suite's own writers
//! (the game manager's session files, `game_manager::session_file`, and the bag recorder's
//! MCAP writer, `bag_file`), as the installed service lays them out: one run directory per
//! start of the suite under the root, each with the session files of the sessions played in
//! it and one `session.mcap` of their results, decisions, proposals and game states.
//!   stored_sessions --root DIR --children 200                 # child-001 .. child-200, a session each
//!   stored_sessions --root DIR --child child-7:50 --damaged-bag 2 --missing-bag 4
//!   stored_sessions --root DIR --child child-7:12 --planned-on-belief child-7
//! A child's sessions are played ten to a run, one a day, from 2026-03-02 09:00 UTC (the
//! one-session children five a day); what
//! each sequence does (level, answer, engagement, feedback, a therapist's override, a pause,
//! proposals) is drawn from `--seed`, improving over the child's sessions. `--damaged-bag K`
//! cuts the K-th run's bag short (as a power cut leaves it), `--missing-bag K` leaves the
//! K-th run without one (K counts the runs written, from 1). `--planned-on-belief CODE` makes
//! that child's decisions carry a belief about the child, as the behaviour policy's with its
//! `child_belief` parameter on (`msgs/msg/Decision.msg`): per level the chance of a right
//! answer (the one the answers are drawn from, so it grows over the child's sequences) and the
//! engagement expected, each with a standard deviation that shrinks with the sequences
//! observed, and now and then an action other than the cluster's table would have taken.

use anyhow::{Context, bail};
use bag_file::{BagWriter, WriterOptions};
use clap::Parser;
use game_manager::session_file::{
    JournalCommand, JournalEntry, SequenceRecord, SessionEnd, SessionFiles, SessionSummary,
};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::topics::{ACTION_PROPOSAL, DECISION, GAME_STATE, SEQUENCE_RESULT};
use qt_therapy_msgs::{ActionProposal, BehaviourState, Decision, GameState, SequenceResult};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use session_tally::Tally;
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(about = "Writes a robot's stored sessions (session files and bags) for tests")]
struct Cli {
    /// The sessions root (a run directory per run is made in it).
    #[arg(long)]
    root: PathBuf,
    /// Children child-001 .. child-N, one session each.
    #[arg(long, default_value_t = 0)]
    children: usize,
    /// A child with this many sessions: CODE:COUNT (may be given more than once).
    #[arg(long = "child", value_name = "CODE:COUNT")]
    child: Vec<String>,
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Cut the K-th run's bag short.
    #[arg(long, value_name = "K")]
    damaged_bag: Option<usize>,
    /// Write no bag for the K-th run.
    #[arg(long, value_name = "K")]
    missing_bag: Option<usize>,
    /// This child's decisions are planned on a belief about the child (may be given more than
    /// once).
    #[arg(long = "planned-on-belief", value_name = "CODE")]
    planned_on_belief: Vec<String>,
}

const SEQUENCES: u8 = 10;
const SESSIONS_PER_RUN: usize = 10;
const DAY_NS: i64 = 86_400_000_000_000;
/// 2026-03-02 09:00 UTC.
const FIRST_DAY_NS: i64 = 1_772_442_000_000_000_000;
const EMOTIONS: [&str; 4] = ["happy", "disgusted", "sad", "angry"];

/// One session to write: whose, which of theirs, when.
#[derive(Clone)]
struct Planned {
    user: String,
    /// Its place among the child's sessions (0-based) and how many the child has.
    nth: usize,
    of: usize,
    start_ns: i64,
    /// Its decisions carry a belief about the child.
    belief: bool,
}

/// One run directory's bag, written as its sessions are.
struct RunBag {
    writer: bag_file::FileBagWriter,
    results: bag_file::Channel<SequenceResult>,
    decisions: bag_file::Channel<Decision>,
    proposals: bag_file::Channel<ActionProposal>,
    states: bag_file::Channel<GameState>,
}

fn stamp(ns: i64) -> Time {
    Time::from_nanos(ns)
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let mut plan: Vec<Vec<Planned>> = Vec::new();
    let believed = |user: &str| cli.planned_on_belief.iter().any(|b| b == user);
    let mut add_child = |user: String, count: usize, day0: i64| {
        let sessions: Vec<Planned> = (0..count)
            .map(|nth| Planned {
                user: user.clone(),
                nth,
                of: count,
                start_ns: FIRST_DAY_NS + (day0 + nth as i64) * DAY_NS,
                belief: believed(&user),
            })
            .collect();
        for chunk in sessions.chunks(SESSIONS_PER_RUN) {
            plan.push(chunk.to_vec());
        }
    };
    for spec in &cli.child {
        let Some((code, count)) = spec.rsplit_once(':') else {
            bail!("--child {spec:?} is not CODE:COUNT");
        };
        let count: usize = count.parse().with_context(|| format!("--child {spec:?}"))?;
        add_child(code.to_string(), count, 0);
    }
    // The one-session children share runs, ten to a run, a day apart.
    let singles: Vec<Planned> = (1..=cli.children)
        .map(|k| Planned {
            user: format!("child-{k:03}"),
            nth: 0,
            of: 1,
            start_ns: FIRST_DAY_NS + (k as i64) * DAY_NS / 5,
            belief: believed(&format!("child-{k:03}")),
        })
        .collect();
    for chunk in singles.chunks(SESSIONS_PER_RUN) {
        plan.push(chunk.to_vec());
    }
    std::fs::create_dir_all(&cli.root)
        .with_context(|| format!("creating {}", cli.root.display()))?;
    let mut written = 0;
    for (k, run) in plan.iter().enumerate() {
        let number = k + 1;
        let dir = cli.root.join(format!("run-{number:03}"));
        let bag = (cli.missing_bag != Some(number)).then_some(dir.join("session.mcap"));
        write_run(&dir, bag.as_deref(), run, cli.seed)?;
        if cli.damaged_bag == Some(number)
            && let Some(bag) = &bag
        {
            cut_short(bag)?;
        }
        written += run.len();
    }
    println!(
        "wrote {written} sessions in {} runs under {}",
        plan.len(),
        cli.root.display()
    );
    Ok(())
}

/// How far the child has come (0..1) in session `p`: later sessions go better.
fn progress_at(p: &Planned) -> f64 {
    if p.of > 1 {
        p.nth as f64 / (p.of - 1) as f64
    } else {
        0.5
    }
}

/// The chance of a right answer at `level` (the answers are drawn from it).
fn p_right(level: u8, progress: f64) -> f64 {
    let p = match level {
        1 => 0.85 + 0.1 * progress,
        2 => 0.6 + 0.3 * progress,
        _ => 0.35 + 0.45 * progress,
    };
    p.min(1.0)
}

/// Fills in the belief `decision` (of sequence `index` of session `p`) was planned on: near the
/// chance of a right answer the answers are drawn from and the engagement they go with, after
/// the child's sequences so far, with standard deviations of a Beta posterior of that many;
/// one decision in four left the table's action (the table would have taken the next one).
fn believe(decision: &mut Decision, p: &Planned, index: u8, rng: &mut ChaCha8Rng) {
    let observations = p.nth * usize::from(SEQUENCES) + usize::from(index) - 1;
    // What the belief has learnt by this sequence: it follows the child's progress a session
    // behind, and moves through the session.
    let progress = if p.of > 1 {
        (p.nth as f64 + f64::from(index) / f64::from(SEQUENCES)) / p.of as f64
    } else {
        0.5
    };
    let n = observations as f64 + 2.0;
    decision.planned_on_belief = true;
    decision.belief_observations = observations as u32;
    decision.belief_success = (1..=3).map(|l| p_right(l, progress)).collect();
    decision.belief_success_sd = decision
        .belief_success
        .iter()
        .map(|s| (s * (1.0 - s) / (n + 1.0)).sqrt())
        .collect();
    decision.belief_engagement = (1..=3)
        .map(|l| (0.6 * progress - 0.1 - 0.1 * f64::from(l - 1)).clamp(-1.0, 1.0))
        .collect();
    decision.belief_engagement_sd = vec![0.5 / n.sqrt(); 3];
    if rng.random_bool(0.25) {
        decision.baseline_action = (decision.action + 1) % 5;
    }
}

/// Keeps the first two thirds of `bag`: its summary and index are lost, and the chunks after
/// the cut, as when the power goes during a recording.
fn cut_short(bag: &Path) -> anyhow::Result<()> {
    let bytes = std::fs::read(bag).with_context(|| format!("reading {}", bag.display()))?;
    std::fs::write(bag, &bytes[..bytes.len() * 2 / 3])
        .with_context(|| format!("cutting {}", bag.display()))
}

fn write_run(dir: &Path, bag: Option<&Path>, run: &[Planned], seed: u64) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut files = SessionFiles::new(dir);
    let mut bag = match bag {
        Some(path) => {
            let options = WriterOptions {
                // Small chunks, so a bag cut short still holds its first sessions.
                chunk_size: 16 * 1024,
                ..WriterOptions::default()
            };
            let mut writer = BagWriter::create(path, &options)?;
            Some(RunBag {
                results: writer.add_topic(SEQUENCE_RESULT)?,
                decisions: writer.add_topic(DECISION)?,
                proposals: writer.add_topic(ACTION_PROPOSAL)?,
                states: writer.add_topic(GAME_STATE)?,
                writer,
            })
        }
        None => None,
    };
    for p in run {
        write_session(&mut files, bag.as_mut(), p, seed)?;
    }
    if let Some(b) = bag {
        b.writer.finish()?;
    }
    Ok(())
}

/// Plays one session by the seeded draws and writes it as the game manager and the recorder
/// would: each result to the session file and the bag, the journal's start and commands, the
/// policy's decisions and proposals to the bag, the summary at the end.
fn write_session(
    files: &mut SessionFiles,
    mut bag: Option<&mut RunBag>,
    p: &Planned,
    seed: u64,
) -> anyhow::Result<()> {
    let key = p
        .user
        .bytes()
        .fold(seed, |h, b| h.wrapping_mul(31).wrapping_add(u64::from(b)));
    let mut rng = ChaCha8Rng::seed_from_u64(key.wrapping_add(p.nth as u64));
    let session_id = format!("tablet-{}", p.start_ns / 1_000_000);
    // Later sessions go better: more right answers, more engagement.
    let progress = progress_at(p);
    let mut t = p.start_ns;
    files.append_journal(&JournalEntry::Started {
        session_id: session_id.clone(),
        user_id: p.user.clone(),
        user_model_cluster: -1,
        command_id: 1,
        at_ns: t,
    })?;
    // Every seventh session is stopped after six sequences; every fourth is paused once.
    let played: u8 = if p.nth % 7 == 3 { 6 } else { SEQUENCES };
    let paused_at = (p.nth % 4 == 1).then_some(3u8);
    let overridden_at = (p.nth % 5 == 2).then_some(5u8);
    let mut results: Vec<SequenceResult> = Vec::new();
    let (mut level, mut feedback, mut previous) = (1u8, 0u8, 0i8);
    let mut proposals = (0u32, 0u32, 0u32, 0u32);
    for index in 1..=played {
        let state = BehaviourState {
            level: if index == 1 { 0 } else { level },
            feedback,
            previous_score: previous,
        };
        // The policy's choice: up after a right answer, down after a wrong one, feedback now
        // and then (repeating the level).
        let (action, next_level, next_feedback) = if index > 1 && rng.random_bool(0.2) {
            let f = if rng.random_bool(0.5) { 1 } else { 2 };
            (2 + f, level, f)
        } else {
            let l = if index == 1 {
                1
            } else if previous > 0 {
                (level + 1).min(3)
            } else {
                level.saturating_sub(1).max(1)
            };
            (l - 1, l, 0)
        };
        let overridden = overridden_at == Some(index);
        let (level_played, feedback_played) = if overridden {
            (3, 0)
        } else {
            (next_level, next_feedback)
        };
        t += 2_000_000_000;
        let explored = rng.random_bool(0.15);
        let q: Vec<f64> = (0..5).map(|_| rng.random_range(-3.0..8.0)).collect();
        if let Some(b) = bag.as_deref_mut()
            && !overridden
        {
            let mut decision = Decision {
                header: Header::at(stamp(t)),
                session_id: session_id.clone(),
                step: index,
                state: state.clone(),
                action,
                level: next_level,
                feedback: next_feedback,
                probabilities: vec![0.2; 5],
                q_values: q,
                temperature: 0.5,
                explored,
                exploitation_only: false,
                model_used: "cluster 0 (q_tables/cluster_0.json)".into(),
                baseline_action: action,
                ..Default::default()
            };
            if p.belief {
                believe(&mut decision, p, index, &mut rng);
            }
            b.writer.write(b.decisions, t as u64, &decision)?;
            // Supervised autonomy in every third session: each decision proposed, most
            // accepted, the sixth left to run out.
            if p.nth.is_multiple_of(3) {
                let proposed = ActionProposal {
                    header: Header::at(stamp(t)),
                    session_id: session_id.clone(),
                    proposal_id: u64::from(index),
                    step: index,
                    state: state.clone(),
                    action,
                    level: next_level,
                    feedback: next_feedback,
                    temperature: 0.5,
                    success_std: -1.0,
                    reason: "test: every decision is proposed".into(),
                    countdown: 10.0,
                    deadline: stamp(t + 10_000_000_000),
                    status: ActionProposal::PROPOSED,
                    ..Default::default()
                };
                let status = if index == 6 {
                    ActionProposal::TIMED_OUT
                } else {
                    ActionProposal::ACCEPTED
                };
                proposals.0 += 1;
                if status == ActionProposal::ACCEPTED {
                    proposals.1 += 1;
                } else {
                    proposals.3 += 1;
                }
                let settled = ActionProposal {
                    status,
                    played_action: action,
                    played_level: next_level,
                    played_feedback: next_feedback,
                    response_time: 1.5,
                    command_id: u64::from(index) + 10,
                    ..proposed.clone()
                };
                b.writer.write(b.proposals, t as u64, &proposed)?;
                b.writer
                    .write(b.proposals, t as u64 + 1_500_000_000, &settled)?;
            }
        }
        if paused_at == Some(index) {
            for (command, id) in [(JournalCommand::Pause, 2), (JournalCommand::Resume, 3)] {
                files.append_journal(&JournalEntry::Command {
                    session_id: session_id.clone(),
                    command_id: id,
                    command,
                    level: None,
                    feedback: None,
                    sequence_index: Some(index),
                    at_ns: t,
                })?;
            }
        }
        let right = rng.random_bool(p_right(level_played, progress));
        let length = 2 * usize::from(level_played) + 1;
        let sequence: Vec<String> = (0..length)
            .map(|_| EMOTIONS[rng.random_range(0..4)].to_string())
            .collect();
        let mut answer = sequence.clone();
        if !right {
            answer[0] = EMOTIONS
                .iter()
                .find(|e| **e != sequence[0])
                .map_or("sad", |e| e)
                .into();
        }
        let engagement =
            (rng.random_range(-0.4..0.4) + 0.6 * progress - 0.1).clamp(-1.0, 1.0) as f32;
        let talk_start = t;
        t += 8_000_000_000 * i64::from(level_played);
        let result = SequenceResult {
            header: Header::at(stamp(t)),
            session_id: session_id.clone(),
            user_id: p.user.clone(),
            user_model_cluster: -1,
            sequence_index: index,
            state: state.clone(),
            action: if overridden { 2 } else { action },
            level: level_played,
            feedback: feedback_played,
            overridden,
            sequence,
            answer,
            outcome: if right { 1 } else { -1 },
            timed_out: false,
            activity_result: if right { 1.0 } else { 0.0 },
            engagement,
            engagement_per_second: vec![engagement; 4],
            engagement_period_start: stamp(talk_start),
            engagement_period_end: stamp(t),
            response_time: 4.0 + 2.0 * f32::from(level_played),
            sequences_planned: SEQUENCES,
        };
        files.append(&SequenceRecord {
            result: result.clone(),
            policy_fallback: false,
            decision_reason: if overridden {
                "therapist override".into()
            } else {
                "policy".into()
            },
            talk_start_ns: talk_start,
            task_sent_ns: t - 1_000_000_000,
            answered_ns: t,
            rejected_answers: 0,
        })?;
        if let Some(b) = bag.as_deref_mut() {
            b.writer.write(b.results, t as u64, &result)?;
        }
        level = level_played;
        feedback = feedback_played;
        previous = result.score() as i8;
        results.push(result);
    }
    let tally = Tally::of(&results);
    let end = if played < SEQUENCES {
        SessionEnd::Stopped
    } else {
        SessionEnd::Finished
    };
    if let Some(b) = bag {
        let state = GameState {
            header: Header::at(stamp(t)),
            session_id: session_id.clone(),
            user_id: p.user.clone(),
            phase: if end == SessionEnd::Finished {
                GameState::FINISHED
            } else {
                GameState::STOPPED
            },
            sequence_index: played,
            sequences_planned: SEQUENCES,
            ..Default::default()
        };
        b.writer.write(b.states, t as u64, &state)?;
    }
    files.write_summary(&SessionSummary {
        session_id,
        user_id: p.user.clone(),
        user_model_cluster: -1,
        end,
        reason: "test".into(),
        sequences_planned: SEQUENCES,
        sequences_played: played,
        interrupted_sequence: None,
        correct: tally.correct as u32,
        timeouts: 0,
        score: tally.score,
        max_score: tally.max_score,
        mean_engagement: tally.mean_engagement,
        overrides: results.iter().filter(|r| r.overridden).count() as u32,
        proposals: proposals.0,
        proposals_accepted: proposals.1,
        proposals_replaced: proposals.2,
        proposals_timed_out: proposals.3,
        policy_fallbacks: 0,
        rejected_commands: 0,
        rejected_answers: 0,
        seed: seed as i64,
        language: "en".into(),
        started_ns: p.start_ns,
        ended_ns: t,
    })?;
    Ok(())
}
