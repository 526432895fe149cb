//! The game manager node's run loop, on any bus (`node_shell::Bus`: DDS on the robot, in
//! process in the cross-node tests). Moves messages between the bus and the sans-IO core
//! (`GameManager`): therapist commands, tablet answers, engagement and heartbeats in; robot
//! speech, faces, gestures (QTrobot's topics or services, `robot`), tablet tasks, game states
//! and results out; DecideAction calls with a deadline; the core's timers on the bus's clock;
//! session files; the operator's lines in the log. At start-up, a session a killed
//! predecessor left unfinished in the sessions directory is taken over.

pub mod robot;

use crate::recovery::{self, RecoveredSession};
use crate::session_file::SessionFiles;
use crate::{GameManager, GameManagerParams, Input, LogLevel, Now, Output};
use anyhow::Context as _;
use node_shell::{Bus, Clock, Outbox};
use qt_therapy_msgs::topics::{
    ACTION_PROPOSAL, DECIDE_ACTION, EXPECTED_ENGAGEMENT, GAME_STATE, HEARTBEAT, SEQUENCE_RESULT,
    TABLET_ANSWER, TABLET_TASK, THERAPIST_COMMAND,
};
use qt_therapy_msgs::{ActionProposal, DecideAction, GameState, SequenceResult, TabletTask};
use robot::{Act, Robot};
use std::collections::BTreeSet;
use std::time::Duration;
use tokio::sync::mpsc;

/// The node's name on the graph (and its parameter file's).
pub const NODE: &str = "game_manager";

/// The node's publishers.
struct Outboxes {
    task: Outbox<TabletTask>,
    state: Outbox<GameState>,
    result: Outbox<SequenceResult>,
    proposal: Outbox<ActionProposal>,
}

/// Runs the game with `params` (read from `params_file`, named in errors) until the node is
/// asked to stop; a session under way is then saved as stopped. The caller holds the lock on
/// `params.sessions_dir` (`node_shell::instance_lock`).
pub async fn run(
    bus: &mut impl Bus,
    params: GameManagerParams,
    params_file: &std::path::Path,
) -> anyhow::Result<()> {
    let mut core = GameManager::new(params.clone())
        .with_context(|| format!("parameter file {}", params_file.display()))?;
    if let Some(tables) = sigma_rule_models(&params, params_file)? {
        core = core.with_user_models(tables);
    }
    let mut files = SessionFiles::new(&params.files.sessions_dir);
    let out = Outboxes {
        task: bus.publisher(TABLET_TASK)?,
        state: bus.publisher(GAME_STATE)?,
        result: bus.publisher(SEQUENCE_RESULT)?,
        proposal: bus.publisher(ACTION_PROPOSAL)?,
    };
    let mut commands = bus.subscribe(THERAPIST_COMMAND, 64)?;
    let mut answers = bus.subscribe(TABLET_ANSWER, 64)?;
    let mut engagement = bus.subscribe(EXPECTED_ENGAGEMENT, 256)?;
    // Every node's 10 Hz heartbeat; the core watches those named in watched_nodes.
    let mut heartbeats = bus.subscribe(HEARTBEAT, 256)?;
    // `ros2 param set` of the language and supervised autonomy's settings, between sessions.
    let mut changes = bus.parameter_changes::<GameManagerParams>();
    let policy = bus.client(DECIDE_ACTION)?;
    let clock = bus.clock();
    // Inputs from tasks of ours: the policy's answers and the robot's steps.
    let (decided_tx, mut decided) = mpsc::channel::<Input>(16);
    let mut robot = Robot::new(bus, &params, decided_tx.clone())?;
    robot.check(bus, Duration::from_secs(5)).await;
    let unheard = tokio::select! {
        biased;
        _ = bus.shutdown_signal() => return Ok(()),
        unheard = robot.wait_for_listener(
            bus,
            &params.robot.robot_speech_node,
            Duration::from_secs_f64(params.robot.robot_call_timeout_s),
        ) => unheard,
    };
    if let Some(reason) = &unheard {
        tracing::warn!("{reason}");
    }
    // (due time on the steady clock, timer id) of the timers the core asked for.
    let mut timers: BTreeSet<(i64, u64)> = BTreeSet::new();
    if params.timing.policy_startup_wait_s > 0.0 {
        let wait = Duration::from_secs_f64(params.timing.policy_startup_wait_s);
        tokio::select! {
            biased;
            _ = bus.shutdown_signal() => return Ok(()),
            found = bus.wait_for_service(&policy, wait) => {
                if found {
                    tracing::info!("behaviour policy reachable on {}", DECIDE_ACTION.name);
                } else {
                    tracing::warn!(
                        "no {} server within {wait:?}: starting anyway; sequences use the safe \
                         fallback until it answers",
                        DECIDE_ACTION.name
                    );
                }
            }
        }
    }
    tracing::info!(sessions_dir = %params.files.sessions_dir, language = %params.lines.language,
        time_scale = params.timing.time_scale, "game manager ready");

    let disk = DiskLook::new(&params);
    disk.keep_within_budget();
    let now = Now::of(&clock);
    let initial = match recovered_session(&mut core, &files, &params, now.steady_ns) {
        Some(r) => {
            tracing::warn!(session = %r.session_id, stem = %r.stem, sequences = r.records.len(),
                "taking over a session left unfinished");
            files.adopt(&r.session_id, &r.stem);
            core.recover(r, now)
        }
        None => core.initial_outputs(now),
    };
    let mut ctx = Dispatch {
        out: &out,
        files: &mut files,
        timers: &mut timers,
        policy: &policy,
        decided: &decided_tx,
        robot: &mut robot,
        clock,
    };
    ctx.apply(initial);
    if let Some(reason) = unheard {
        ctx.apply(core.handle(Input::RobotUnheard { reason }, Now::of(&clock)));
    }
    let outputs = core.handle(disk.space(), Now::of(&clock));
    ctx.apply(outputs);
    let mut disk_tick =
        tokio::time::interval(Duration::from_secs_f64(params.disk.disk_check_interval_s));
    disk_tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let stop = bus.shutdown_signal();
    tokio::pin!(stop);
    loop {
        let next_timer = ctx.timers.first().map(|(at, _)| *at);
        // Biased: a message already here is handled before a due timer it may make moot (a
        // heartbeat queued while the loop was busy must not let the watchdog see a loss).
        let input = tokio::select! {
            biased;
            _ = &mut stop => {
                let outputs = core.handle(Input::Shutdown { reason: "node shut down (signal)".into() }, Now::of(&clock));
                ctx.apply(outputs);
                break;
            }
            Some(c) = commands.recv() => {
                // A start is judged on the disk as it is now, old bags deleted first if over.
                if c.command == qt_therapy_msgs::TherapistCommand::START {
                    disk.keep_within_budget();
                }
                let outputs = core.handle(disk.space(), Now::of(&clock));
                ctx.apply(outputs);
                Input::Command(c)
            }
            Some(a) = answers.recv() => Input::Answer(a),
            Some(e) = engagement.recv() => Input::Engagement(e),
            Some(h) = heartbeats.recv() => Input::Heartbeat(h),
            Some(d) = decided.recv() => d,
            Some(change) = changes.recv() => {
                let result = change_parameters(&mut core, &change, params_file);
                change.respond(result);
                continue;
            }
            _ = disk_tick.tick() => {
                disk.keep_within_budget();
                if ctx.files.unsaved() > 0 {
                    let outputs = core.handle(ctx.retry_unsaved(), Now::of(&clock));
                    ctx.apply(outputs);
                }
                disk.space()
            }
            _ = clock.sleep_until(next_timer.unwrap_or_default()), if next_timer.is_some() => {
                match ctx.timers.pop_first() {
                    Some((_, id)) => Input::TimerFired { id },
                    None => continue,
                }
            }
        };
        let span = tracing::info_span!(
            "session",
            id = core.session_id().unwrap_or("-"),
            sequence = core.sequence_index()
        );
        let _entered = span.enter();
        let outputs = core.handle(input, Now::of(&clock));
        ctx.apply(outputs);
    }
    Ok(())
}

/// The user models supervised autonomy's σ rule reads (`user_model_file`), when supervised
/// autonomy is on and the file is named; a file it cannot use is named in the error.
fn sigma_rule_models(
    params: &GameManagerParams,
    params_file: &std::path::Path,
) -> anyhow::Result<Option<Vec<sequence_game::UserModelTable>>> {
    let supervision = &params.supervision;
    if !supervision.supervised_autonomy {
        return Ok(None);
    }
    if supervision.user_model_file.is_empty() {
        tracing::info!(
            "supervised autonomy: proposing decisions above temperature {} (no user_model_file: \
             no σ rule)",
            supervision.propose_above_temperature
        );
        return Ok(None);
    }
    // The σ rule reads the same models as the policy.
    let path = std::path::Path::new(&supervision.user_model_file);
    let models = user_models::UserModelSet::load(path).with_context(|| {
        format!(
            "user_model_file (supervised autonomy's σ rule) in {}",
            params_file.display()
        )
    })?;
    tracing::info!(file = %path.display(), clusters = models.cluster_count(),
        "supervised autonomy: proposing decisions above temperature {} or σ {}",
        supervision.propose_above_temperature, supervision.propose_above_success_std);
    Ok(Some(models.tables()))
}

/// A change of parameters asked for over the graph, handed to the core; a change that turns
/// supervised autonomy on first reads the σ rule's user models, and one whose file cannot be
/// read is refused with the reason.
fn change_parameters(
    core: &mut GameManager,
    change: &node_shell::parameters::ParameterChange<GameManagerParams>,
    params_file: &std::path::Path,
) -> Result<(), String> {
    let new = &change.parameters;
    let models = if core.has_user_models() || core.session_running() {
        None
    } else {
        sigma_rule_models(new, params_file).map_err(|e| format!("{e:#}"))?
    };
    core.change_parameters(new.clone(), &change.changed)?;
    if let Some(tables) = models {
        core.set_user_models(tables);
    }
    tracing::info!(keys = ?change.changed, language = %new.lines.language,
        supervised_autonomy = new.supervision.supervised_autonomy, "parameters changed");
    Ok(())
}

/// Reads the sessions directory: every session id found there is used (a START with it is
/// refused); the newest unfinished session, if recent enough, is returned to be taken over.
/// Whatever cannot be read or recovered is named in the log and left on disk as it is.
fn recovered_session(
    core: &mut GameManager,
    files: &SessionFiles,
    params: &GameManagerParams,
    now: i64,
) -> Option<RecoveredSession> {
    let scan = files.scan();
    for p in &scan.problems {
        tracing::warn!("sessions directory: {p}");
    }
    core.remember_sessions(scan.finished_ids);
    let mut candidates = Vec::new();
    for u in scan.unfinished {
        match recovery::recover_session(&u.stem, &u.records, &u.journal) {
            Ok(r) => {
                core.remember_sessions([r.session_id.clone()]);
                candidates.push(r);
            }
            Err(why) => tracing::warn!(
                "session files {}/{}.*: not recoverable ({why}); left as they are",
                files.dir().display(),
                u.stem
            ),
        }
    }
    let (chosen, left) = recovery::choose(candidates, now, params.reliability.recovery_max_age_s);
    for l in left {
        tracing::warn!("{l}");
    }
    chosen
}

/// Carries out the core's outputs, in order.
struct Dispatch<'a> {
    out: &'a Outboxes,
    files: &'a mut SessionFiles,
    timers: &'a mut BTreeSet<(i64, u64)>,
    policy: &'a node_shell::ServiceClient<DecideAction>,
    decided: &'a mpsc::Sender<Input>,
    robot: &'a mut Robot,
    clock: Clock,
}

impl Dispatch<'_> {
    fn apply(&mut self, outputs: Vec<Output>) {
        for o in outputs {
            match o {
                Output::Say(s) => self.robot.act(Act::Say(s)),
                Output::Silence => self.robot.act(Act::Silence),
                Output::ShowEmotion(s) => self.robot.act(Act::Emotion(s)),
                Output::PlayGesture(s) => self.robot.act(Act::Gesture(s)),
                Output::AwaitRobot { step } => self.robot.await_step(step),
                Output::Task(t) => {
                    self.out.task.send(t);
                }
                Output::State(s) => {
                    self.out.state.send(s);
                }
                Output::Result(r) => {
                    self.out.result.send(r);
                }
                Output::Proposal(p) => {
                    self.out.proposal.send(p);
                }
                Output::Decide {
                    request_id,
                    request,
                    deadline_ns,
                } => {
                    let client = self.policy.clone();
                    let tx = self.decided.clone();
                    // The core falls back at the deadline itself; this only bounds the call.
                    let left = deadline_ns.saturating_sub(self.clock.steady_nanos());
                    let timeout = Duration::from_nanos(u64::try_from(left).unwrap_or(0))
                        + Duration::from_millis(500);
                    tokio::spawn(async move {
                        let input = match client.call(request, timeout).await {
                            Ok(response) => Input::Decision {
                                request_id,
                                response,
                            },
                            Err(e) => Input::DecisionFailed {
                                request_id,
                                reason: e.to_string(),
                            },
                        };
                        let _ = tx.send(input).await;
                    });
                }
                Output::SetTimer { id, at_ns } => {
                    self.timers.insert((at_ns, id));
                }
                Output::Record(r) => match self.files.append(&r) {
                    Ok(path) => tracing::debug!(path = %path.display(), "sequence recorded"),
                    // Kept in memory to be written later; in the log too.
                    Err(e) => self.unsaved(
                        e,
                        format!("record: {}", serde_json::to_string(&r).unwrap_or_default()),
                    ),
                },
                Output::Journal(e) => match self.files.append_journal(&e) {
                    Ok(path) => tracing::debug!(path = %path.display(), "journal entry written"),
                    Err(e2) => self.unsaved(
                        e2,
                        format!(
                            "journal entry: {}",
                            serde_json::to_string(&e).unwrap_or_default()
                        ),
                    ),
                },
                Output::Summary(s) => match self.files.write_summary(&s) {
                    Ok(path) => tracing::info!(path = %path.display(), "session summary written"),
                    Err(e) => self.unsaved(
                        e,
                        format!("summary: {}", serde_json::to_string(&s).unwrap_or_default()),
                    ),
                },
                // The operator's line, once: a log record (terminal, log file, journal, /rosout).
                Output::LiveLine(line) => node_shell::logging::log_at(LogLevel::INFO, &line),
                Output::Alarm(line) => node_shell::logging::log_at(LogLevel::WARN, &line),
                Output::Log { level, message } => node_shell::logging::log_at(level, &message),
            }
        }
        self.robot.detach();
    }

    /// A session-file write failed: logged with what it held; the core is told how many
    /// writes wait (it warns the therapist), through the channel of inputs from our tasks.
    fn unsaved(&mut self, e: crate::session_file::SessionFileError, what: String) {
        tracing::error!("{e}; kept in memory to write when there is room; {what}");
        let _ = self.decided.try_send(Input::FilesUnsaved {
            unsaved: self.files.unsaved(),
            reason: e.to_string(),
        });
    }

    /// Writes what the disk had no room for before; what the core should know of it.
    fn retry_unsaved(&mut self) -> Input {
        let reason = match self.files.retry_unsaved() {
            Ok(()) => String::new(),
            Err(e) => e.to_string(),
        };
        Input::FilesUnsaved {
            unsaved: self.files.unsaved(),
            reason,
        }
    }
}

/// The node's looks at the disk of its sessions directory: the free space, and retention
/// (`crate::retention`) when `retention_dir` is set.
struct DiskLook {
    sessions_dir: std::path::PathBuf,
    retention_dir: Option<std::path::PathBuf>,
    removes: Vec<crate::retention::Removable>,
    budget: u64,
    want_free: u64,
}

impl DiskLook {
    fn new(params: &GameManagerParams) -> DiskLook {
        let d = &params.disk;
        DiskLook {
            sessions_dir: params.files.sessions_dir.clone().into(),
            retention_dir: (!d.retention_dir.is_empty()).then(|| d.retention_dir.clone().into()),
            removes: d
                .retention_removes
                .iter()
                .filter_map(|k| crate::retention::Removable::parse(k))
                .collect(),
            budget: (d.retention_budget_mb * 1e6) as u64,
            want_free: (d.disk_warning_free_mb * 1e6) as u64,
        }
    }

    /// The free space where the session files go (the nearest directory that exists).
    fn space(&self) -> Input {
        let mut dir = self.sessions_dir.as_path();
        while !dir.is_dir() {
            match dir.parent() {
                Some(p) if !p.as_os_str().is_empty() => dir = p,
                _ => {
                    dir = std::path::Path::new(".");
                    break;
                }
            }
        }
        match atomic_file::disk_space(dir) {
            Ok(s) => Input::DiskSpace { free: s.free },
            Err(e) => {
                tracing::warn!("cannot measure the free space of {}: {e}", dir.display());
                Input::DiskSpace { free: u64::MAX }
            }
        }
    }

    /// Deletes what retention allows when the runs are over their budget or the disk is low.
    fn keep_within_budget(&self) {
        let Some(root) = &self.retention_dir else {
            return;
        };
        for line in crate::retention::apply(
            root,
            &self.sessions_dir,
            &self.removes,
            self.budget,
            self.want_free,
        ) {
            tracing::warn!("{line}");
        }
    }
}
