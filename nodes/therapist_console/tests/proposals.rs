//! The console's supervised-autonomy commands against a scripted game manager over DDS (inside
//! a loopback-only network namespace, tests/loopback-netns): `accept` with no proposal open is
//! refused with the game manager's reason; `encourage` and `challenge` send their codes and
//! wait for the answer; `run-session --accept-proposals` prints the proposal and its
//! settlement and accepts it, sending the accept again (same id) while it is unanswered.

use node_shell::{NoParameters, NodeShell, ShellOptions, header_now};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::topics::{ACTION_PROPOSAL, GAME_STATE, SEQUENCE_RESULT, THERAPIST_COMMAND};
use qt_therapy_msgs::{
    ActionProposal, BehaviourState, GameState, SequenceResult, TherapistCommand, Validate,
};
use std::time::Duration;

const NAME: &str = "proposals_and_feedback_commands_over_dds";
const MARKER: &str = "THERAPIST_PROPOSALS_TEST_INSIDE";

#[test]
fn proposals_and_feedback_commands_over_dds() {
    loopback_netns::test_inside_namespace(NAME, MARKER, Duration::from_secs(150), inside);
}

fn checked<M: Validate + std::fmt::Debug>(m: M) -> M {
    if let Err(e) = m.validate() {
        panic!("the scripted game manager would publish an invalid {m:?}: {e}");
    }
    m
}

fn state(phase: u8, session: &str, answered: Option<(&TherapistCommand, u8, &str)>) -> GameState {
    let (command_session_id, command_id, command_outcome, command_refusal) = match answered {
        Some((c, outcome, refusal)) => (
            c.session_id.clone(),
            c.command_id,
            outcome,
            refusal.to_string(),
        ),
        None => (String::new(), 0, GameState::COMMAND_NONE, String::new()),
    };
    checked(GameState {
        header: header_now(),
        phase,
        session_id: session.into(),
        sequences_planned: 2,
        command_session_id,
        command_id,
        command_outcome,
        command_refusal,
        ..Default::default()
    })
}

/// Sequence `i` of session "sim": 1 at level 1 from the start, 2 encouraged at level 1.
fn result(i: u8) -> SequenceResult {
    let said: Vec<String> = ["happy", "sad", "angry"].map(String::from).to_vec();
    checked(SequenceResult {
        header: header_now(),
        session_id: "sim".into(),
        user_id: "child-1".into(),
        sequence_index: i,
        sequences_planned: 2,
        state: if i == 1 {
            BehaviourState::default()
        } else {
            BehaviourState {
                level: 1,
                feedback: 0,
                previous_score: 1,
            }
        },
        action: if i == 1 { 0 } else { 3 },
        level: 1,
        feedback: u8::from(i == 2),
        sequence: said.clone(),
        answer: said,
        outcome: 1,
        activity_result: 1.0,
        engagement: 0.5,
        engagement_per_second: vec![0.5],
        response_time: 2.0,
        ..Default::default()
    })
}

fn proposal(status: u8, accept: Option<&TherapistCommand>) -> ActionProposal {
    checked(ActionProposal {
        header: header_now(),
        session_id: "sim".into(),
        proposal_id: 1_900_000_000_000_000_000,
        step: 2,
        state: result(2).state,
        action: 3,
        level: 1,
        feedback: 1,
        temperature: 235.0,
        success_std: 0.31,
        reason: "state seen twice".into(),
        countdown: 30.0,
        deadline: Time {
            sec: 2_000_000_000,
            nanosec: 0,
        },
        status,
        played_action: 3,
        played_level: 1,
        played_feedback: 1,
        command_id: accept.map_or(0, |c| c.command_id),
        response_time: if accept.is_some() { 2.5 } else { 0.0 },
    })
}

/// The game manager's side, scripted: answers each command; starts "sim" by sending
/// sequence 1's result and proposing sequence 2's action; leaves the first accept unanswered,
/// carries out its repeat, settles the proposal, sends sequence 2's result and finishes.
/// Returns every command received.
async fn scripted_game_manager(
    mut shell: NodeShell,
    done: tokio::sync::oneshot::Receiver<()>,
) -> Vec<TherapistCommand> {
    let states = shell.publisher(GAME_STATE).expect("publisher");
    let results = shell.publisher(SEQUENCE_RESULT).expect("publisher");
    let proposals = shell.publisher(ACTION_PROPOSAL).expect("publisher");
    let mut commands = shell
        .subscribe(THERAPIST_COMMAND, 64)
        .expect("subscription");
    states.send(state(GameState::IDLE, "", None));
    let mut received: Vec<TherapistCommand> = Vec::new();
    tokio::pin!(done);
    loop {
        let c = tokio::select! {
            _ = &mut done => break,
            Some(c) = commands.recv() => c,
        };
        let repeat = received.iter().any(|r| r.command_id == c.command_id);
        received.push(c.clone());
        let accepts = received
            .iter()
            .filter(|r| r.command == TherapistCommand::ACCEPT_PROPOSAL && r.session_id == "sim")
            .count();
        let answer = |phase: u8, session: &str, outcome: u8, refusal: &str| {
            state(phase, session, Some((&c, outcome, refusal)))
        };
        match (c.command, c.session_id.as_str()) {
            (_, "s0") if c.command == TherapistCommand::ACCEPT_PROPOSAL => {
                states.send(answer(
                    GameState::IDLE,
                    "",
                    GameState::COMMAND_REFUSED,
                    "no proposal is open",
                ));
            }
            (_, "s0") => {
                states.send(answer(
                    GameState::IDLE,
                    "",
                    GameState::COMMAND_CARRIED_OUT,
                    "",
                ));
            }
            (TherapistCommand::START, "sim") if repeat => {
                states.send(answer(
                    GameState::DECIDING,
                    "sim",
                    GameState::COMMAND_ALREADY_CARRIED_OUT,
                    "",
                ));
            }
            (TherapistCommand::START, "sim") => {
                states.send(answer(
                    GameState::DECIDING,
                    "sim",
                    GameState::COMMAND_CARRIED_OUT,
                    "",
                ));
                results.send(result(1));
                proposals.send(proposal(ActionProposal::PROPOSED, None));
            }
            // The first accept is "lost": the console must send it again.
            (TherapistCommand::ACCEPT_PROPOSAL, "sim") if accepts == 1 => {}
            (TherapistCommand::ACCEPT_PROPOSAL, "sim") if accepts == 2 => {
                states.send(answer(
                    GameState::SAYING_SEQUENCE,
                    "sim",
                    GameState::COMMAND_CARRIED_OUT,
                    "",
                ));
                proposals.send(proposal(ActionProposal::ACCEPTED, Some(&c)));
                results.send(result(2));
                tokio::time::sleep(Duration::from_millis(200)).await;
                let mut finished = state(GameState::FINISHED, "sim", None);
                finished.sequence_index = 2;
                states.send(finished);
            }
            _ => {
                states.send(answer(
                    GameState::IDLE,
                    "",
                    GameState::COMMAND_REFUSED,
                    "not in the script",
                ));
            }
        }
    }
    shell.stop().await;
    received
}

/// Runs the console with `args`; its exit code and stdout.
async fn therapist(args: &[&str]) -> (i32, String) {
    let out = tokio::time::timeout(
        Duration::from_secs(60),
        tokio::process::Command::new(env!("CARGO_BIN_EXE_therapist"))
            .args(["--params-file", "params/therapist_console.yaml"])
            .args(args)
            .env("RUST_BACKTRACE", "0")
            .output(),
    )
    .await
    .unwrap_or_else(|_| panic!("therapist {args:?} did not end within 60 s"))
    .expect("therapist runs");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("therapist {args:?}: {:?}\n{stdout}{stderr}", out.status);
    (out.status.code().unwrap_or(-1), stdout)
}

fn inside() {
    let dir = std::env::temp_dir().join(format!("therapist-proposals-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let params = dir.join("fake_game_manager.yaml");
    std::fs::write(&params, "fake_game_manager:\n  ros__parameters: {}\n").expect("writes");
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .expect("runtime");
    runtime.block_on(async {
        let options = ShellOptions {
            params_file: Some(params.clone()),
            namespace: "/".into(),
            service_mapping: "enhanced".into(),
            ..Default::default()
        };
        let (shell, NoParameters {}) =
            NodeShell::start("fake_game_manager", &options).expect("the scripted game manager");
        let (stop, done) = tokio::sync::oneshot::channel();
        let game_manager = tokio::spawn(scripted_game_manager(shell, done));

        let (code, stdout) = therapist(&["accept", "--session", "s0"]).await;
        assert_eq!(code, 4, "refused: {stdout}");
        assert!(
            stdout.contains("refused: no proposal is open"),
            "the reason: {stdout}"
        );
        assert_eq!(therapist(&["encourage", "--session", "s0"]).await.0, 0);
        assert_eq!(therapist(&["challenge", "--session", "s0"]).await.0, 0);

        let (code, stdout) = therapist(&[
            "run-session",
            "--user",
            "child-1",
            "--cluster",
            "0",
            "--session",
            "sim",
            "--accept-proposals",
            "--timeout",
            "40",
        ])
        .await;
        stop.send(()).expect("the game manager runs");
        let received = game_manager.await.expect("the game manager ends");
        assert_eq!(code, 0, "{stdout}");

        // What reached the game manager: the commands' codes, and the accept twice, one id.
        let s0: Vec<u8> = received
            .iter()
            .filter(|c| c.session_id == "s0")
            .map(|c| c.command)
            .collect();
        assert!(s0.contains(&TherapistCommand::ACCEPT_PROPOSAL), "{s0:?}");
        assert!(
            s0.contains(&TherapistCommand::OVERRIDE_ENCOURAGING),
            "{s0:?}"
        );
        assert!(
            s0.contains(&TherapistCommand::OVERRIDE_CHALLENGING),
            "{s0:?}"
        );
        let start = received
            .iter()
            .find(|c| c.command == TherapistCommand::START && c.session_id == "sim")
            .expect("the START");
        let accepts: Vec<&TherapistCommand> = received
            .iter()
            .filter(|c| c.command == TherapistCommand::ACCEPT_PROPOSAL && c.session_id == "sim")
            .collect();
        assert_eq!(accepts.len(), 2, "sent again once unanswered: {accepts:?}");
        assert_eq!(accepts[0].command_id, accepts[1].command_id, "one id");
        assert!(
            accepts[0].command_id > start.command_id,
            "ids only increase"
        );

        // What the therapist read, in order.
        let proposed = "  proposal for seq 2: L1 + encouraging (T 235, σ 0.31; state seen twice), \
                        30 s to answer";
        let accepted = format!(
            "  proposal for seq 2 accepted after 2.5 s (command {})",
            accepts[0].command_id
        );
        let lines: Vec<&str> = stdout.lines().collect();
        let at = |line: &str| {
            lines
                .iter()
                .position(|l| *l == line)
                .unwrap_or_else(|| panic!("no line {line:?} in:\n{stdout}"))
        };
        assert!(at(proposed) < at(&accepted), "{stdout}");
        assert!(lines.iter().any(|l| l.starts_with("seq  2/2  level 1")));
        assert_eq!(lines.last(), Some(&"session sim finished: 2 sequences"));
    });
    let _ = std::fs::remove_dir_all(&dir);
}
