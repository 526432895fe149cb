//! TEST TOOL ONLY, for `tests/dds_session.rs`: a scripted DDS peer of the game manager. In one
//! process it plays a rule-based policy (DecideAction), the child tablet (answers each task
//! with the emotions the robot showed, or a wrong one, or nothing), a camera (one
//! ExpectedEngagement per second) and the therapist (start, a duplicated start, an override;
//! or, for a game manager that took over a session after a crash, the commands it had already
//! carried out delivered again and a resume; or, under supervised autonomy, the answers to
//! the game manager's proposals). It prints one JSON line per event. The real nodes live in
//! their own crates.

use clap::Parser;
use node_shell::{NoParameters, NodeShell, ShellOptions, header_now, now_nanos};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::topics::*;
use qt_therapy_msgs::*;
use std::time::Duration;

#[derive(Parser)]
struct Cli {
    #[arg(long)]
    session: String,
    /// Sequence indices answered wrongly.
    #[arg(long, value_delimiter = ',')]
    wrong: Vec<u8>,
    /// Sequence indices not answered (they time out).
    #[arg(long, value_delimiter = ',')]
    silent: Vec<u8>,
    /// While sequence 1 waits for its answer, set sequence 2 to this level.
    #[arg(long)]
    override_level: Option<u8>,
    #[arg(long, default_value_t = 300)]
    answer_delay_ms: u64,
    #[arg(long, default_value_t = 150)]
    timeout_s: u64,
    /// Do not start: wait for the game manager's recovered session, deliver its START (id 1)
    /// and override (id 2) again, then resume it with this id, twice.
    #[arg(long)]
    resume_recovered: Option<u64>,
    /// Resume the session whenever it pauses on its own (ids from 10 up), as a therapist
    /// would after the robot failed.
    #[arg(long)]
    resume_paused: bool,
    /// Press the emergency stop while the robot says this sequence (by index), as its second
    /// face shows (so mid-word); the run then ends at the emergency-stopped state rather than
    /// at the end of the session.
    #[arg(long)]
    emergency_stop_at: Option<u8>,
    /// Press the emergency stop `--emergency-stop-after-ms` after the robot starts saying a
    /// line containing this (as a stand-in robot's echo on /qt_robot/speech/say tells), so the
    /// press lands mid-sentence; the run then ends at the emergency-stopped state.
    #[arg(long)]
    emergency_stop_during: Option<String>,
    #[arg(long, default_value_t = 0)]
    emergency_stop_after_ms: u64,
    /// Steps whose decisions come from a hot state (temperature 250): the game manager, under
    /// supervised autonomy, proposes them to the therapist.
    #[arg(long, value_delimiter = ',')]
    unsure: Vec<u8>,
    /// The therapist's answer to the proposal of each listed step, in order: `accept`,
    /// `level1`..`level3`, `encourage`, `challenge`, or `wait` (let it run out).
    #[arg(long, value_delimiter = ',')]
    proposal_replies: Vec<String>,
    #[command(flatten)]
    shell: ShellOptions,
}

fn emit(v: serde_json::Value) {
    println!("{v}");
}

/// Level 1 first; up after a success; encourage after a failure without feedback; else same.
fn decide(r: &DecideActionRequest, unsure: &[u8]) -> DecideActionResponse {
    let s = &r.state;
    let (action, level, feedback) = if s.level == 0 {
        (0, 1, 0)
    } else if s.previous_score > 0 && s.level < 3 {
        (s.level, s.level + 1, 0)
    } else if s.previous_score < 0 && s.feedback == 0 {
        (3, s.level, 1)
    } else {
        (s.level - 1, s.level, 0)
    };
    DecideActionResponse {
        ok: true,
        error: String::new(),
        decision: Decision {
            header: header_now(),
            session_id: r.session_id.clone(),
            step: r.step,
            state: r.state.clone(),
            action,
            level,
            feedback,
            q_values: vec![0.1, 0.2, 0.3, 0.4, 0.5],
            probabilities: vec![0.2; 5],
            temperature: if unsure.contains(&r.step) { 250.0 } else { 1.0 },
            explored: r.step.is_multiple_of(2),
            exploitation_only: false,
            model_used: "test peer rule".into(),
            baseline_action: action,
            ..Default::default()
        },
    }
}

fn command(code: u8, session: &str, id: u64) -> TherapistCommand {
    TherapistCommand {
        header: header_now(),
        command: code,
        session_id: session.into(),
        command_id: id,
        user_id: "peer-child".into(),
        user_model_cluster: 0,
        level: 0,
    }
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let (mut shell, NoParameters {}) = NodeShell::start("game_manager_test_peer", &cli.shell)?;
    let code = run(&mut shell, &cli).await?;
    shell.stop().await;
    std::process::exit(code);
}

async fn run(shell: &mut NodeShell, cli: &Cli) -> anyhow::Result<i32> {
    let mut calls = shell.serve(DECIDE_ACTION, |e| DecideActionResponse {
        ok: false,
        error: e.to_string(),
        ..Default::default()
    })?;
    let mut states = shell.subscribe(GAME_STATE, 64)?;
    let mut emotions = shell.subscribe(ROBOT_EMOTION, 256)?;
    let mut speech = shell.subscribe(ROBOT_SPEECH, 256)?;
    let mut tasks = shell.subscribe(TABLET_TASK, 16)?;
    let mut results = shell.subscribe(SEQUENCE_RESULT, 16)?;
    let mut proposals = shell.subscribe(ACTION_PROPOSAL, 16)?;
    let commands = shell.publisher(THERAPIST_COMMAND)?;
    let answers = shell.publisher(TABLET_ANSWER)?;
    let engagement = shell.publisher(EXPECTED_ENGAGEMENT)?;

    // The game manager is up once its transient-local state arrives and it listens.
    let first = tokio::time::timeout(Duration::from_secs(30), states.recv()).await;
    if !matches!(first, Ok(Some(_))) {
        emit(serde_json::json!({"event": "error", "what": "no GameState within 30 s"}));
        return Ok(2);
    }
    for (name, ok) in [
        (
            "commands",
            commands
                .wait_for_subscribers(shell, Duration::from_secs(20))
                .await,
        ),
        (
            "answers",
            answers
                .wait_for_subscribers(shell, Duration::from_secs(20))
                .await,
        ),
        (
            "engagement",
            engagement
                .wait_for_subscribers(shell, Duration::from_secs(20))
                .await,
        ),
    ] {
        if !ok {
            emit(serde_json::json!({"event": "error", "what": format!("no {name} subscriber")}));
            return Ok(2);
        }
    }
    // Give the game manager's DecideAction client time to match this server.
    tokio::time::sleep(Duration::from_secs(1)).await;
    if let Some(resume_id) = cli.resume_recovered {
        let Ok(Some(first)) = first else {
            return Ok(2);
        };
        emit(serde_json::json!({"event": "state", "phase": first.phase,
            "index": first.sequence_index, "status": first.status}));
        // A session taken over from the files: paused, this session, and no command answered
        // yet by the new process.
        if first.phase != GameState::PAUSED
            || first.session_id != cli.session
            || first.command_outcome != GameState::COMMAND_NONE
        {
            emit(serde_json::json!({"event": "error", "what": "no recovered session"}));
            return Ok(2);
        }
        // What was carried out before the crash, delivered again, then the therapist's resume
        // (sent twice, as a console resends an unconfirmed command).
        let mut again = command(TherapistCommand::OVERRIDE_LEVEL, &cli.session, 2);
        again.level = cli.override_level.unwrap_or(3);
        for c in [
            command(TherapistCommand::START, &cli.session, 1),
            again,
            command(TherapistCommand::RESUME, &cli.session, resume_id),
            command(TherapistCommand::RESUME, &cli.session, resume_id),
        ] {
            commands.send(c);
        }
        emit(serde_json::json!({"event": "resumed"}));
    } else {
        commands.send(command(TherapistCommand::START, &cli.session, 1));
        commands.send(command(TherapistCommand::START, &cli.session, 1));
        emit(serde_json::json!({"event": "started"}));
    }

    let (answer_tx, mut due_answers) = tokio::sync::mpsc::channel::<TabletAnswer>(16);
    let mut shown: Vec<String> = Vec::new();
    let mut overridden = false;
    let mut emergency_sent = false;
    // Faces seen of the sequence the emergency stop is pressed in.
    let mut emergency_faces: Option<u8> = None;
    // The press timed from a line the robot started (--emergency-stop-during).
    let (press_tx, mut press) = tokio::sync::mpsc::channel::<()>(1);
    let mut next_command_id = 10;
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    let deadline = tokio::time::sleep(Duration::from_secs(cli.timeout_s));
    tokio::pin!(deadline);
    loop {
        tokio::select! {
            _ = &mut deadline => {
                emit(serde_json::json!({"event": "error", "what": "session did not finish in time"}));
                return Ok(3);
            }
            _ = tick.tick() => {
                // The second that just ended, engaged at 0.5.
                let sec = now_nanos() / 1_000_000_000 - 1;
                engagement.send(ExpectedEngagement {
                    header: header_now(),
                    source: "camera/0".into(),
                    window_start: Time::from_nanos(sec * 1_000_000_000),
                    window_end: Time::from_nanos((sec + 1) * 1_000_000_000),
                    has_faces: true,
                    mean: 0.5,
                    smoothed: 0.5,
                    frame_count: 30,
                    missing_count: 0,
                });
            }
            Some(call) = calls.recv() => {
                emit(serde_json::json!({"event": "decision", "step": call.request.step}));
                let response = decide(&call.request, &cli.unsure);
                call.respond(response);
            }
            Some(s) = states.recv() => {
                emit(serde_json::json!({"event": "state", "phase": s.phase, "index": s.sequence_index,
                    "status": s.status, "fallback": s.policy_fallback}));
                if let Some(level) = cli.override_level
                    && cli.resume_recovered.is_none()
                    && !overridden && s.sequence_index == 1 && s.phase == GameState::WAITING_FOR_ANSWER
                {
                    let mut c = command(TherapistCommand::OVERRIDE_LEVEL, &cli.session, 2);
                    c.level = level;
                    commands.send(c);
                    overridden = true;
                }
                if cli.resume_paused && s.phase == GameState::PAUSED && s.session_id == cli.session {
                    let c = command(TherapistCommand::RESUME, &cli.session, next_command_id);
                    next_command_id += 1;
                    emit(serde_json::json!({"event": "resuming", "status": s.status}));
                    commands.send(c);
                }
                if cli.emergency_stop_at == Some(s.sequence_index)
                    && s.phase == GameState::SAYING_SEQUENCE
                {
                    emergency_faces = Some(0);
                }
                let ended = s.phase == GameState::FINISHED
                    || (emergency_sent && s.phase == GameState::EMERGENCY_STOPPED);
                if ended {
                    let grace = tokio::time::sleep(session_tally::live_line::LAST_RESULT_GRACE);
                    tokio::pin!(grace);
                    loop {
                        tokio::select! {
                            _ = &mut grace => break,
                            Some(r) = results.recv() => emit(result_event(&r)),
                        }
                    }
                    emit(serde_json::json!({"event": "done", "phase": s.phase}));
                    return Ok(0);
                }
            }
            Some(e) = emotions.recv() => {
                shown.push(e.data.trim_start_matches("QT/").to_string());
                if let Some(faces) = emergency_faces.as_mut() && !emergency_sent {
                    *faces += 1;
                    if *faces == 2 {
                        emit(serde_json::json!({"event": "emergency_stop", "at_ns": now_nanos()}));
                        commands.send(command(TherapistCommand::EMERGENCY_STOP, &cli.session, next_command_id));
                        next_command_id += 1;
                        emergency_sent = true;
                    }
                }
            }
            Some(s) = speech.recv() => {
                emit(serde_json::json!({"event": "speech", "data": s.data, "at_ns": now_nanos()}));
                if let Some(during) = &cli.emergency_stop_during
                    && s.data.contains(during.as_str())
                    && !emergency_sent
                {
                    let tx = press_tx.clone();
                    let after = Duration::from_millis(cli.emergency_stop_after_ms);
                    tokio::spawn(async move {
                        tokio::time::sleep(after).await;
                        let _ = tx.send(()).await;
                    });
                }
            }
            Some(()) = press.recv(), if !emergency_sent => {
                emit(serde_json::json!({"event": "emergency_stop", "at_ns": now_nanos()}));
                commands.send(command(TherapistCommand::EMERGENCY_STOP, &cli.session, next_command_id));
                next_command_id += 1;
                emergency_sent = true;
            }
            Some(t) = tasks.recv() => {
                if t.session_id != cli.session || cli.silent.contains(&t.sequence_index) {
                    continue;
                }
                // The last `length` faces the robot showed are the words of the sequence.
                let n = usize::from(t.length);
                let mut words: Vec<String> = shown[shown.len().saturating_sub(n)..].to_vec();
                if cli.wrong.contains(&t.sequence_index)
                    && let Some(w) = words.first_mut()
                {
                    *w = if w == "happy" { "sad".into() } else { "happy".into() };
                }
                let answer = TabletAnswer {
                    header: header_now(),
                    session_id: t.session_id.clone(),
                    sequence_id: t.sequence_id,
                    answer: words,
                    response_time: cli.answer_delay_ms as f32 / 1000.0,
                };
                let tx = answer_tx.clone();
                let delay = Duration::from_millis(cli.answer_delay_ms);
                tokio::spawn(async move {
                    tokio::time::sleep(delay).await;
                    let _ = tx.send(answer).await;
                });
            }
            Some(a) = due_answers.recv() => {
                answers.send(a);
            }
            Some(r) = results.recv() => emit(result_event(&r)),
            Some(p) = proposals.recv() => {
                emit(serde_json::json!({"event": "proposal", "step": p.step, "status": p.status,
                    "level": p.level, "played_level": p.played_level,
                    "played_feedback": p.played_feedback, "command_id": p.command_id,
                    "success_std": p.success_std, "countdown": p.countdown, "reason": p.reason}));
                if p.status != ActionProposal::PROPOSED || p.session_id != cli.session {
                    continue;
                }
                let k = cli.unsure.iter().position(|s| *s == p.step);
                let reply = k.and_then(|k| cli.proposal_replies.get(k)).map(String::as_str);
                let code = match reply {
                    Some("accept") => Some((TherapistCommand::ACCEPT_PROPOSAL, 0)),
                    Some("level1") => Some((TherapistCommand::OVERRIDE_LEVEL, 1)),
                    Some("level2") => Some((TherapistCommand::OVERRIDE_LEVEL, 2)),
                    Some("level3") => Some((TherapistCommand::OVERRIDE_LEVEL, 3)),
                    Some("encourage") => Some((TherapistCommand::OVERRIDE_ENCOURAGING, 0)),
                    Some("challenge") => Some((TherapistCommand::OVERRIDE_CHALLENGING, 0)),
                    _ => None,
                };
                if let Some((code, level)) = code {
                    let mut c = command(code, &cli.session, next_command_id);
                    c.level = level;
                    next_command_id += 1;
                    emit(serde_json::json!({"event": "proposal_reply", "step": p.step,
                        "command": code, "command_id": c.command_id}));
                    commands.send(c);
                }
            }
        }
    }
}

fn result_event(r: &SequenceResult) -> serde_json::Value {
    serde_json::json!({
        "event": "result", "index": r.sequence_index, "level": r.level, "outcome": r.outcome,
        "timed_out": r.timed_out, "overridden": r.overridden, "engagement": r.engagement,
        "seconds": r.engagement_per_second.len(),
    })
}
