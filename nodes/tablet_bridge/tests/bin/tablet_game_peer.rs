//! TEST TOOL, not part of the suite: a DDS peer that plays the game manager's side of the
//! tablet topics for the browser test, until the test runs against the real game manager.
//! It publishes GameState, TabletTask, Decision, SequenceResult and ExpectedEngagement over
//! real DDS (through the node shell), obeys TherapistCommands the simplest way, and prints one
//! JSON line per command, answer and task on stdout so the test can check what crossed.
//! Its two sequences are fixed: it scores answers against them, it does not learn anything.

use clap::Parser;
use node_shell::{NoParameters, NodeShell, ShellOptions, header_now};
use qt_therapy_msgs::topics::{
    DECISION, EXPECTED_ENGAGEMENT, GAME_STATE, SEQUENCE_RESULT, TABLET_ANSWER, TABLET_TASK,
    THERAPIST_COMMAND,
};
use qt_therapy_msgs::{
    BehaviourState, Decision, ExpectedEngagement, GameState, SequenceResult, TabletAnswer,
    TabletTask, TherapistCommand,
};
use std::time::Duration;

#[derive(Parser)]
#[command(
    about = "Test tool: the game side of the tablet topics, for the tablet bridge's browser test"
)]
struct Cli {
    #[command(flatten)]
    shell: ShellOptions,
}

/// The fixed sequences the "robot" says, one per step (levels 1 and 2).
const SEQUENCES: [&[&str]; 2] = [
    &["happy", "sad", "angry"],
    &["angry", "happy", "disgusted", "sad", "happy"],
];
const CHOICES: [&str; 4] = ["happy", "disgusted", "sad", "angry"];

fn emit(event: serde_json::Value) {
    println!("{event}");
}

#[derive(Default)]
struct Game {
    state: GameState,
    step: usize,
    answered: bool,
    last_command_id: u64,
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let (mut shell, NoParameters {}) = NodeShell::start("tablet_game_peer", &cli.shell)?;
    {
        let states = shell.publisher(GAME_STATE)?;
        let tasks = shell.publisher(TABLET_TASK)?;
        let decisions = shell.publisher(DECISION)?;
        let results = shell.publisher(SEQUENCE_RESULT)?;
        let engagement = shell.publisher(EXPECTED_ENGAGEMENT)?;
        let mut commands = shell.subscribe(THERAPIST_COMMAND, 64)?;
        let mut answers = shell.subscribe(TABLET_ANSWER, 64)?;
        let mut game = Game::default();
        game.state.status = "ready".into();
        states.send(game.state.clone());
        emit(serde_json::json!({"event": "ready"}));
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        let mut second = 0u32;
        let stop = shell.shutdown_signal();
        tokio::pin!(stop);
        loop {
            tokio::select! {
                _ = &mut stop => break,
                _ = tick.tick() => {
                    second += 1;
                    let mean = (f64::from(second) / 4.0).sin() as f32 * 0.6;
                    let mut e = ExpectedEngagement {
                        header: header_now(),
                        source: "peer/0".into(),
                        has_faces: !second.is_multiple_of(15),
                        mean,
                        smoothed: mean * 0.8,
                        frame_count: 30,
                        ..Default::default()
                    };
                    e.window_end = e.header.stamp.clone();
                    e.window_start = qt_therapy_msgs::builtin_interfaces::Time::from_nanos(e.header.stamp.to_nanos() - 1_000_000_000);
                    engagement.send(e);
                }
                Some(c) = commands.recv() => {
                    emit(serde_json::json!({
                        "event": "command", "command": c.command, "session_id": c.session_id,
                        "command_id": c.command_id, "user_id": c.user_id,
                        "cluster": c.user_model_cluster, "level": c.level,
                    }));
                    if c.command_id <= game.last_command_id && c.session_id == game.state.session_id {
                        emit(serde_json::json!({"event": "stale_command", "command_id": c.command_id}));
                        continue;
                    }
                    game.last_command_id = c.command_id;
                    command(&mut game, &c, &states, &tasks, &decisions);
                }
                Some(a) = answers.recv() => {
                    emit(serde_json::json!({
                        "event": "answer", "session_id": a.session_id,
                        "sequence_id": a.sequence_id, "answer": a.answer,
                    }));
                    answer(&mut game, &a, &states, &tasks, &decisions, &results);
                }
            }
        }
    }
    shell.stop().await;
    Ok(())
}

type Out<M> = node_shell::Outbox<M>;

fn command(
    game: &mut Game,
    c: &TherapistCommand,
    states: &Out<GameState>,
    tasks: &Out<TabletTask>,
    decisions: &Out<Decision>,
) {
    let g = &mut game.state;
    match c.command {
        TherapistCommand::START => {
            *g = GameState {
                session_id: c.session_id.clone(),
                user_id: c.user_id.clone(),
                user_model_cluster: c.user_model_cluster,
                ..Default::default()
            };
            game.step = 0;
            next_sequence(game, states, tasks, decisions);
            return;
        }
        _ if c.session_id != g.session_id => {
            g.status = format!("command for unknown session {}", c.session_id);
        }
        TherapistCommand::PAUSE => g.phase = GameState::PAUSED,
        TherapistCommand::RESUME => g.phase = GameState::WAITING_FOR_ANSWER,
        TherapistCommand::STOP => g.phase = GameState::STOPPED,
        TherapistCommand::EMERGENCY_STOP => g.phase = GameState::EMERGENCY_STOPPED,
        TherapistCommand::OVERRIDE_LEVEL => {
            g.status = format!("next level overridden to {}", c.level)
        }
        _ => {}
    }
    g.header = header_now();
    states.send(g.clone());
}

/// Decides (fixed Q-values), then asks the child tablet for the next fixed sequence.
fn next_sequence(
    game: &mut Game,
    states: &Out<GameState>,
    tasks: &Out<TabletTask>,
    decisions: &Out<Decision>,
) {
    let Some(sequence) = SEQUENCES.get(game.step) else {
        game.state.phase = GameState::FINISHED;
        game.state.header = header_now();
        states.send(game.state.clone());
        return;
    };
    game.step += 1;
    game.answered = false;
    let level = (sequence.len() as u8 - 1) / 2;
    let g = &mut game.state;
    let before = BehaviourState {
        level: g.level,
        feedback: g.feedback,
        previous_score: g.last_score,
    };
    g.phase = GameState::DECIDING;
    g.header = header_now();
    states.send(g.clone());
    decisions.send(Decision {
        header: header_now(),
        session_id: g.session_id.clone(),
        step: game.step as u8,
        state: before,
        action: level - 1,
        level,
        feedback: 0,
        q_values: vec![0.42, 0.61, -0.2, 0.1, 0.05],
        probabilities: vec![0.2, 0.45, 0.05, 0.15, 0.15],
        temperature: 1.5,
        explored: game.step == 2,
        exploitation_only: false,
        model_used: "test peer: fixed values".into(),
    });
    g.sequence_index = game.step as u8;
    g.level = level;
    g.phase = GameState::WAITING_FOR_ANSWER;
    g.status = "waiting for the child".into();
    g.header = header_now();
    states.send(g.clone());
    emit(serde_json::json!({"event": "task", "sequence_id": game.step, "sequence": sequence}));
    tasks.send(TabletTask {
        header: header_now(),
        session_id: g.session_id.clone(),
        sequence_id: game.step as u32,
        sequence_index: game.step as u8,
        length: sequence.len() as u8,
        choices: CHOICES.map(String::from).to_vec(),
        timeout: 120.0,
    });
}

fn answer(
    game: &mut Game,
    a: &TabletAnswer,
    states: &Out<GameState>,
    tasks: &Out<TabletTask>,
    decisions: &Out<Decision>,
    results: &Out<SequenceResult>,
) {
    let current = game.step as u32;
    if a.session_id != game.state.session_id || a.sequence_id != current || game.answered {
        emit(serde_json::json!({"event": "unexpected_answer", "sequence_id": a.sequence_id}));
        return;
    }
    game.answered = true;
    let sequence: Vec<String> = SEQUENCES[game.step - 1]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let outcome: i8 = if a.answer == sequence { 1 } else { -1 };
    let g = &mut game.state;
    results.send(SequenceResult {
        header: header_now(),
        session_id: g.session_id.clone(),
        user_id: g.user_id.clone(),
        user_model_cluster: g.user_model_cluster,
        sequence_index: g.sequence_index,
        state: BehaviourState {
            level: 0,
            feedback: 0,
            previous_score: 0,
        },
        action: g.level - 1,
        level: g.level,
        feedback: 0,
        overridden: false,
        sequence,
        answer: a.answer.clone(),
        outcome,
        timed_out: false,
        activity_result: if outcome == 1 {
            f32::from(g.level)
        } else {
            -1.0
        },
        engagement: 0.25,
        engagement_per_second: vec![0.2, 0.3],
        response_time: a.response_time,
    });
    g.last_score = if outcome == 1 {
        g.level as i8
    } else {
        -(g.level as i8)
    };
    g.phase = GameState::GIVING_FEEDBACK;
    g.header = header_now();
    states.send(g.clone());
    next_sequence(game, states, tasks, decisions);
}
