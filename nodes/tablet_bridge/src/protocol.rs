//! The JSON the tablet pages and the bridge exchange over the WebSocket. Incoming messages are
//! parsed strictly (unknown types and fields, wrong types and missing fields are rejected with
//! serde's reason); outgoing ones are views of the DDS messages the pages need.

use qt_therapy_msgs::{
    ActionProposal, Decision, ExpectedEngagement, GameState, ProposalStatus, SequenceResult,
    TabletTask,
};
use sequence_game::{ACTION_COUNT, Action, Feedback};
use serde::{Deserialize, Serialize};
use session_tally::Tally;
use session_tally::live_line::proposal_status_name;

/// A feedback code's name, `unknown` outside 0..=2.
fn feedback_name(feedback: u8) -> &'static str {
    Feedback::new(feedback.into()).map_or("unknown", Feedback::name)
}

/// An action code's key (`level_1` .. `challenge`), `unknown` outside 0..=4.
fn action_key(action: u8) -> &'static str {
    Action::new(action.into()).map_or("unknown", Action::key)
}

/// Which page a connection belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    Child,
    Therapist,
}

/// A message from a page.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ClientMessage {
    /// Child page: the tapped sequence for the task `sequence_id`.
    Answer {
        sequence_id: u32,
        answer: Vec<String>,
        /// Seconds from the task appearing to the submit tap, measured on the tablet.
        response_time: f64,
    },
    /// Therapist page: unlocks the live view.
    Login { pin: String },
    /// Therapist page: one command; every command carries the PIN.
    Command {
        pin: String,
        command: CommandKind,
        #[serde(default)]
        user_id: Option<String>,
        #[serde(default)]
        cluster: Option<i32>,
        #[serde(default)]
        level: Option<u8>,
        /// The step of the proposal this command answers (the proposal card sends it): the
        /// bridge refuses the command once that proposal is no longer open.
        #[serde(default)]
        proposal: Option<u8>,
    },
    /// Therapist page: the children the robot knows (read from the stored sessions).
    Children { pin: String },
    /// Therapist page: a code typed for a child the robot does not know yet, to be checked
    /// by the rules of a user id (nothing is stored: the child is stored once a session of
    /// it starts).
    NewChild { pin: String, user_id: String },
    /// Therapist page: one child's progress across sessions.
    Progress { pin: String, user_id: String },
}

/// The therapist's commands, as `TherapistCommand` defines them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandKind {
    Start,
    Pause,
    Resume,
    Stop,
    OverrideLevel,
    EmergencyStop,
    /// The next sequence repeats the level with encouraging feedback.
    OverrideEncouraging,
    /// The next sequence repeats the level with challenging feedback.
    OverrideChallenging,
    /// Carry out the action the game manager proposes now.
    AcceptProposal,
}

impl CommandKind {
    pub fn code(self) -> u8 {
        match self {
            CommandKind::Start => qt_therapy_msgs::TherapistCommand::START,
            CommandKind::Pause => qt_therapy_msgs::TherapistCommand::PAUSE,
            CommandKind::Resume => qt_therapy_msgs::TherapistCommand::RESUME,
            CommandKind::Stop => qt_therapy_msgs::TherapistCommand::STOP,
            CommandKind::OverrideLevel => qt_therapy_msgs::TherapistCommand::OVERRIDE_LEVEL,
            CommandKind::EmergencyStop => qt_therapy_msgs::TherapistCommand::EMERGENCY_STOP,
            CommandKind::OverrideEncouraging => {
                qt_therapy_msgs::TherapistCommand::OVERRIDE_ENCOURAGING
            }
            CommandKind::OverrideChallenging => {
                qt_therapy_msgs::TherapistCommand::OVERRIDE_CHALLENGING
            }
            CommandKind::AcceptProposal => qt_therapy_msgs::TherapistCommand::ACCEPT_PROPOSAL,
        }
    }

    /// The command's name in the page protocol (`override_level`, ...).
    pub fn name(self) -> &'static str {
        match self {
            CommandKind::Start => "start",
            CommandKind::Pause => "pause",
            CommandKind::Resume => "resume",
            CommandKind::Stop => "stop",
            CommandKind::OverrideLevel => "override_level",
            CommandKind::EmergencyStop => "emergency_stop",
            CommandKind::OverrideEncouraging => "override_encouraging",
            CommandKind::OverrideChallenging => "override_challenging",
            CommandKind::AcceptProposal => "accept_proposal",
        }
    }

    /// Whether the command can answer a proposal (accept it, or replace it by its action).
    pub fn answers_proposal(self) -> bool {
        matches!(
            self,
            CommandKind::OverrideLevel
                | CommandKind::OverrideEncouraging
                | CommandKind::OverrideChallenging
                | CommandKind::AcceptProposal
        )
    }
}

/// Parses one page message; the error is the reason sent back to the page.
pub fn parse_client_message(text: &str) -> Result<ClientMessage, String> {
    serde_json::from_str(text).map_err(|e| {
        let shown: String = e.to_string().chars().take(200).collect();
        format!("not a valid message: {shown}")
    })
}

/// A message to a page.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMessage {
    /// Therapist page: send a `login` with the PIN first.
    LoginRequired,
    LoggedIn,
    /// Where the game is (the child page gets the same view).
    Game(GameView),
    /// Child page: collect this sequence.
    Task(TaskView),
    /// Child page: nothing to answer now.
    NoTask {
        reason: String,
    },
    /// What the page sent was done.
    Accepted {
        what: String,
    },
    /// What the page sent was refused, and why.
    Rejected {
        reason: String,
    },
    /// Therapist page: a command went to the game manager.
    CommandSent {
        command: CommandKind,
        session_id: String,
        command_id: u64,
    },
    Engagement(EngagementPoint),
    EngagementHistory {
        points: Vec<EngagementPoint>,
    },
    Decision(DecisionView),
    Result(ResultView),
    /// Therapist page only: the action the game manager proposes, or what became of it.
    Proposal(ProposalView),
    /// Therapist page: the children the robot knows, the most recent first.
    Children {
        children: Vec<ChildView>,
        /// The sessions root, when it does not exist (yet): no session stored there.
        missing: Option<String>,
        /// What could not be read (a child may be missing from the list).
        problems: Vec<String>,
    },
    /// Therapist page: a new code passed the rules of a user id.
    ChildChecked {
        user_id: String,
    },
    /// Therapist page: a child's progress, as the report's HTML body (`child_sessions`).
    Progress {
        user_id: String,
        sessions: usize,
        html: String,
    },
}

/// A child on the therapist page's list.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChildView {
    /// The child's code (never a name).
    pub user_id: String,
    pub sessions: usize,
    /// The last time any of its session files names, ms since the epoch (the page shows the
    /// tablet's local date); null when none does.
    pub last_ms: Option<i64>,
}

impl ChildView {
    pub fn of(c: &child_sessions::Child) -> Self {
        ChildView {
            user_id: c.user_id.clone(),
            sessions: c.sessions,
            last_ms: c.last_ns.map(|ns| ns / 1_000_000),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GameView {
    pub phase: &'static str,
    pub session_id: String,
    pub user_id: String,
    pub cluster: i32,
    pub sequence_index: u8,
    pub level: u8,
    pub feedback: u8,
    /// The feedback's name (`none`, `encouraging`, `challenging`), which the page translates.
    pub feedback_name: &'static str,
    pub last_score: i8,
    pub policy_fallback: bool,
    pub status: String,
    /// The disk warning that `status` starts with (`GameState::disk_warning`), empty when the
    /// disk is fine: the therapist page shows it in its own element.
    pub disk_warning: String,
    /// A sequence is under way (the page enables pause, stop and override on it).
    pub running: bool,
    /// Sequences this session plays.
    pub sequences_planned: u8,
}

impl GameView {
    pub fn of(g: &GameState) -> Self {
        GameView {
            phase: GameState::phase_name(g.phase),
            session_id: g.session_id.clone(),
            user_id: g.user_id.clone(),
            cluster: g.user_model_cluster,
            sequence_index: g.sequence_index,
            level: g.level,
            feedback: g.feedback,
            feedback_name: feedback_name(g.feedback),
            last_score: g.last_score,
            policy_fallback: g.policy_fallback,
            status: g.status.clone(),
            disk_warning: GameState::disk_warning(&g.status)
                .unwrap_or_default()
                .to_string(),
            running: GameState::is_running(g.phase),
            sequences_planned: g.sequences_planned,
        }
    }

    /// What the child page may see: no user id, cluster or status text.
    pub fn for_child(g: &GameState) -> Self {
        GameView {
            user_id: String::new(),
            cluster: -1,
            status: String::new(),
            disk_warning: String::new(),
            ..GameView::of(g)
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TaskView {
    pub sequence_id: u32,
    pub sequence_index: u8,
    pub length: u8,
    pub choices: Vec<String>,
    pub timeout: f32,
}

impl TaskView {
    pub fn of(t: &TabletTask) -> Self {
        TaskView {
            sequence_id: t.sequence_id,
            sequence_index: t.sequence_index,
            length: t.length,
            choices: t.choices.clone(),
            timeout: t.timeout,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EngagementPoint {
    /// End of the one-second window, seconds since the epoch.
    pub t: f64,
    pub source: String,
    pub has_faces: bool,
    pub mean: f32,
    pub smoothed: f32,
}

impl EngagementPoint {
    pub fn of(e: &ExpectedEngagement) -> Self {
        EngagementPoint {
            t: e.window_end.as_secs_f64(),
            source: e.source.clone(),
            has_faces: e.has_faces,
            mean: e.mean,
            smoothed: e.smoothed,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DecisionView {
    pub session_id: String,
    pub step: u8,
    /// (L, F, PS) before the action.
    pub state: [i16; 3],
    pub action: u8,
    pub level: u8,
    pub feedback: u8,
    pub q_values: Vec<f64>,
    pub probabilities: Vec<f64>,
    pub temperature: f64,
    pub explored: bool,
    pub exploitation_only: bool,
    pub model_used: String,
    /// The actions' keys in index order (`level_1` .. `challenge`), which the page translates.
    pub action_names: [&'static str; ACTION_COUNT],
    pub feedback_name: &'static str,
}

impl DecisionView {
    pub fn of(d: &Decision) -> Self {
        // JSON has no NaN or infinity: a non-finite number is shown as null by serde_json,
        // which the page renders as "–".
        DecisionView {
            session_id: d.session_id.clone(),
            step: d.step,
            state: [
                d.state.level.into(),
                d.state.feedback.into(),
                d.state.previous_score.into(),
            ],
            action: d.action,
            level: d.level,
            feedback: d.feedback,
            q_values: d.q_values.clone(),
            probabilities: d.probabilities.clone(),
            temperature: d.temperature,
            explored: d.explored,
            exploitation_only: d.exploitation_only,
            model_used: d.model_used.clone(),
            action_names: Action::ALL.map(Action::key),
            feedback_name: feedback_name(d.feedback),
        }
    }
}

/// The actions the therapist may choose in `p`'s state, as keys in index order: no
/// feedback in the start state (sequence 1 has no level to repeat).
pub fn proposal_choices(p: &ActionProposal) -> Vec<&'static str> {
    let allowed = p
        .state
        .to_state()
        .map_or(&Action::ALL[..3], |s| s.allowed_actions());
    allowed.iter().map(|a| a.key()).collect()
}

/// A proposal as the therapist page shows it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProposalView {
    pub session_id: String,
    /// The sequence the proposed action sets up.
    pub step: u8,
    /// (L, F, PS) before the action.
    pub state: [i16; 3],
    pub action: u8,
    /// The proposed action's key (`level_1` .. `challenge`), which the page translates.
    pub action_name: &'static str,
    pub level: u8,
    pub feedback: u8,
    pub feedback_name: &'static str,
    pub temperature: f64,
    /// The user model's sigma of P(success) after the action; null without a user model.
    pub success_std: Option<f64>,
    /// Why it is proposed, in the game manager's words.
    pub reason: String,
    /// Seconds the therapist was given.
    pub countdown: f32,
    /// Seconds left when the bridge sent this view (the page counts down from its arrival).
    pub remaining: f64,
    /// `proposed` while open; then `accepted`, `replaced`, `timed_out` or `withdrawn`.
    pub status: &'static str,
    /// Still waiting for the therapist.
    pub open: bool,
    /// The actions (keys) the therapist may choose instead, in index order.
    pub choices: Vec<&'static str>,
    /// Settled and played (accepted, replaced, timed out): what plays; null otherwise.
    pub played_action_name: Option<&'static str>,
    pub played_level: u8,
    pub played_feedback: u8,
    pub played_feedback_name: &'static str,
    /// The therapist command that settled it (0 when it ran out or was withdrawn).
    pub command_id: u64,
    /// Seconds from the proposal to the therapist's answer.
    pub response_time: f32,
}

impl ProposalView {
    /// `p` with `remaining` seconds left on its countdown (as the bridge counts it).
    pub fn of(p: &ActionProposal, remaining: f64) -> Self {
        let status = ProposalStatus::try_from(p.status);
        let played = matches!(
            status,
            Ok(ProposalStatus::Accepted | ProposalStatus::Replaced | ProposalStatus::TimedOut)
        );
        let open = status == Ok(ProposalStatus::Proposed);
        ProposalView {
            session_id: p.session_id.clone(),
            step: p.step,
            state: [
                p.state.level.into(),
                p.state.feedback.into(),
                p.state.previous_score.into(),
            ],
            action: p.action,
            action_name: action_key(p.action),
            level: p.level,
            feedback: p.feedback,
            feedback_name: feedback_name(p.feedback),
            temperature: p.temperature,
            success_std: (p.success_std >= 0.0).then_some(p.success_std),
            reason: p.reason.clone(),
            countdown: p.countdown,
            remaining: if open {
                remaining.clamp(0.0, f64::from(p.countdown))
            } else {
                0.0
            },
            status: proposal_status_name(p.status),
            open,
            choices: proposal_choices(p),
            played_action_name: played.then(|| action_key(p.played_action)),
            played_level: p.played_level,
            played_feedback: p.played_feedback,
            played_feedback_name: feedback_name(p.played_feedback),
            command_id: p.command_id,
            response_time: p.response_time,
        }
    }
}

/// A sequence's result as the therapist page's results table shows it: some of the
/// message's fields under their own names, then the scores. The page's JSON is a contract of
/// its own, so a view keeps it; the message's serde is its DDS (CDR) encoding and cannot take
/// the page's attributes. The view holds the message, and the fields the page gets are named
/// once, where it is serialised.
#[derive(Debug, Clone, PartialEq)]
pub struct ResultView {
    result: SequenceResult,
    /// The session's score so far and the best it could be with its levels.
    session_score: i32,
    session_max_score: i32,
}

impl ResultView {
    /// `r` with the tally of its session so far (`r` included).
    pub fn of(r: SequenceResult, session: &Tally) -> Self {
        ResultView {
            result: r,
            session_score: session.score,
            session_max_score: session.max_score,
        }
    }

    pub fn session_id(&self) -> &String {
        &self.result.session_id
    }
}

impl Serialize for ResultView {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct as _;
        let r = &self.result;
        let mut row = s.serialize_struct("ResultView", 14)?;
        row.serialize_field("session_id", &r.session_id)?;
        row.serialize_field("sequence_index", &r.sequence_index)?;
        row.serialize_field("level", &r.level)?;
        row.serialize_field("feedback", &r.feedback)?;
        row.serialize_field("overridden", &r.overridden)?;
        row.serialize_field("sequence", &r.sequence)?;
        row.serialize_field("answer", &r.answer)?;
        row.serialize_field("outcome", &r.outcome)?;
        row.serialize_field("timed_out", &r.timed_out)?;
        row.serialize_field("engagement", &r.engagement)?;
        row.serialize_field("response_time", &r.response_time)?;
        // The paper's score of the sequence, L·O.
        row.serialize_field("score", &r.score())?;
        row.serialize_field("session_score", &self.session_score)?;
        row.serialize_field("session_max_score", &self.session_max_score)?;
        row.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn valid_messages_parse() {
        assert_eq!(
            parse_client_message(
                r#"{"type":"answer","sequence_id":3,"answer":["sad"],"response_time":1.5}"#
            ),
            Ok(ClientMessage::Answer {
                sequence_id: 3,
                answer: vec!["sad".into()],
                response_time: 1.5
            })
        );
        assert_eq!(
            parse_client_message(
                r#"{"type":"command","pin":"1234","command":"override_level","level":2}"#
            ),
            Ok(ClientMessage::Command {
                pin: "1234".into(),
                command: CommandKind::OverrideLevel,
                user_id: None,
                cluster: None,
                level: Some(2),
                proposal: None,
            })
        );
        assert_eq!(
            parse_client_message(
                r#"{"type":"command","pin":"1","command":"accept_proposal","proposal":4}"#
            ),
            Ok(ClientMessage::Command {
                pin: "1".into(),
                command: CommandKind::AcceptProposal,
                user_id: None,
                cluster: None,
                level: None,
                proposal: Some(4),
            })
        );
    }

    #[test]
    fn every_command_has_its_code_and_its_protocol_name() {
        use qt_therapy_msgs::TherapistCommand as C;
        let all = [
            (CommandKind::Start, C::START),
            (CommandKind::Pause, C::PAUSE),
            (CommandKind::Resume, C::RESUME),
            (CommandKind::Stop, C::STOP),
            (CommandKind::OverrideLevel, C::OVERRIDE_LEVEL),
            (CommandKind::EmergencyStop, C::EMERGENCY_STOP),
            (CommandKind::OverrideEncouraging, C::OVERRIDE_ENCOURAGING),
            (CommandKind::OverrideChallenging, C::OVERRIDE_CHALLENGING),
            (CommandKind::AcceptProposal, C::ACCEPT_PROPOSAL),
        ];
        for (kind, code) in all {
            assert_eq!(kind.code(), code, "{kind:?}");
            let json = serde_json::to_value(kind).expect("serialises");
            assert_eq!(json, kind.name(), "{kind:?}");
            let text = format!(
                r#"{{"type":"command","pin":"1","command":"{}"}}"#,
                kind.name()
            );
            assert!(
                matches!(parse_client_message(&text), Ok(ClientMessage::Command { command, .. }) if command == kind)
            );
        }
        let codes: Vec<u8> = all.iter().map(|(k, _)| k.code()).collect();
        assert_eq!(codes, (0..=8).collect::<Vec<u8>>(), "every code once");
        let answering: Vec<&str> = all
            .iter()
            .filter(|(k, _)| k.answers_proposal())
            .map(|(k, _)| k.name())
            .collect();
        assert_eq!(
            answering,
            [
                "override_level",
                "override_encouraging",
                "override_challenging",
                "accept_proposal"
            ]
        );
    }

    #[test]
    fn a_proposal_view_names_what_is_proposed_and_what_became_of_it() {
        use qt_therapy_msgs::{ActionProposal, BehaviourState};
        let open = ActionProposal {
            session_id: "s".into(),
            step: 4,
            state: BehaviourState {
                level: 2,
                feedback: 1,
                previous_score: -2,
            },
            action: 4,
            level: 2,
            feedback: 2,
            temperature: 235.0,
            success_std: 0.31,
            reason: "unsure".into(),
            countdown: 10.0,
            status: ActionProposal::PROPOSED,
            ..Default::default()
        };
        let v = ProposalView::of(&open, 12.5);
        assert_eq!(v.remaining, 10.0, "never more than the countdown");
        assert_eq!(ProposalView::of(&open, -3.0).remaining, 0.0);
        assert_eq!(
            (v.action_name, v.feedback_name, v.status, v.open),
            ("challenge", "challenging", "proposed", true)
        );
        assert_eq!(v.state, [2, 1, -2]);
        assert_eq!(v.played_action_name, None, "nothing plays yet");
        let json = serde_json::to_value(ServerMessage::Proposal(v)).expect("serialises");
        assert_eq!(json["type"], "proposal");
        assert_eq!(json["success_std"], 0.31);
        assert_eq!(json["choices"].as_array().map(Vec::len), Some(5));

        let replaced = ActionProposal {
            status: ActionProposal::REPLACED,
            played_action: 0,
            played_level: 1,
            played_feedback: 0,
            success_std: -1.0,
            command_id: 77,
            response_time: 2.5,
            ..open.clone()
        };
        let v = ProposalView::of(&replaced, 5.0);
        assert_eq!((v.status, v.open, v.remaining), ("replaced", false, 0.0));
        assert_eq!(
            (v.played_action_name, v.played_level, v.played_feedback_name),
            (Some("level_1"), 1, "none")
        );
        assert_eq!((v.command_id, v.response_time), (77, 2.5));
        let json = serde_json::to_value(&v).expect("serialises");
        assert!(json["success_std"].is_null(), "-1: no user model");
        for (status, name, plays) in [
            (ActionProposal::ACCEPTED, "accepted", true),
            (ActionProposal::TIMED_OUT, "timed_out", true),
            (ActionProposal::WITHDRAWN, "withdrawn", false),
        ] {
            let p = ActionProposal {
                status,
                ..replaced.clone()
            };
            let v = ProposalView::of(&p, 0.0);
            assert_eq!((v.status, v.played_action_name.is_some()), (name, plays));
        }
        assert_eq!(proposal_status_name(9), "unknown");
    }

    #[test]
    fn schema_violations_come_back_with_a_reason() {
        let cases = [
            ("not json", "expected"),
            ("[1,2]", "invalid type"),
            (r#"{"type":"dance"}"#, "unknown variant `dance`"),
            (r#"{"sequence_id":1}"#, "missing field `type`"),
            (
                r#"{"type":"answer","sequence_id":1,"answer":[]}"#,
                "missing field `response_time`",
            ),
            (
                r#"{"type":"answer","sequence_id":-1,"answer":[],"response_time":1}"#,
                "invalid value",
            ),
            (
                r#"{"type":"answer","sequence_id":1,"answer":"sad","response_time":1}"#,
                "invalid type",
            ),
            (
                r#"{"type":"login","pin":"1","admin":true}"#,
                "unknown field `admin`",
            ),
            (
                r#"{"type":"command","pin":"1","command":"reboot"}"#,
                "unknown variant `reboot`",
            ),
            (
                r#"{"type":"command","pin":"1","command":"start","cluster":1e99}"#,
                "invalid type",
            ),
        ];
        for (text, reason) in cases {
            let e = parse_client_message(text).expect_err(text);
            assert!(e.starts_with("not a valid message: "), "{e}");
            assert!(e.contains(reason), "{text}: {e}");
        }
    }

    #[test]
    fn server_messages_serialise_with_their_type() {
        let m = ServerMessage::CommandSent {
            command: CommandKind::EmergencyStop,
            session_id: "s".into(),
            command_id: 7,
        };
        let v: serde_json::Value = serde_json::to_value(&m).expect("serialises");
        assert_eq!(v["type"], "command_sent");
        assert_eq!(v["command"], "emergency_stop");
        let g = GameState {
            phase: GameState::WAITING_FOR_ANSWER,
            user_id: "child-7".into(),
            status: "waiting".into(),
            ..Default::default()
        };
        let v = serde_json::to_value(ServerMessage::Game(GameView::for_child(&g))).expect("ok");
        assert_eq!(v["type"], "game");
        assert_eq!(v["phase"], "waiting_for_answer");
        assert_eq!(v["user_id"], "");
        assert_eq!(GameState::phase_name(200), "unknown");
    }

    #[test]
    fn the_disk_warning_goes_to_the_therapist_page_only() {
        let g = GameState {
            status: "disk: 4.0 MB free in /s, below 500 MB: delete old bags or reports; \
                     node lost: bag_recorder; paused"
                .into(),
            ..Default::default()
        };
        let therapist = GameView::of(&g);
        assert_eq!(
            therapist.disk_warning,
            "4.0 MB free in /s, below 500 MB: delete old bags or reports"
        );
        assert_eq!(GameView::for_child(&g).disk_warning, "");
        let fine = GameState {
            status: "waiting".into(),
            ..Default::default()
        };
        assert_eq!(GameView::of(&fine).disk_warning, "");
    }

    /// The result row the therapist page reads, byte for byte: which of the message's fields
    /// it gets, in which order, and the scores added to them.
    #[test]
    fn a_result_view_is_the_pages_json_of_the_message() {
        let r = SequenceResult {
            session_id: "s1".into(),
            user_id: "child-7".into(),
            user_model_cluster: 2,
            sequence_index: 3,
            action: 2,
            level: 3,
            feedback: 1,
            overridden: true,
            sequence: vec!["happy".into(), "sad".into(), "angry".into()],
            answer: vec!["happy".into(), "sad".into(), "sad".into()],
            outcome: -1,
            activity_result: 0.5,
            engagement: 0.1,
            engagement_per_second: vec![0.25, -1.0],
            response_time: 12.7,
            sequences_planned: 10,
            ..Default::default()
        };
        let earlier = SequenceResult {
            sequence_index: 2,
            level: 2,
            outcome: 1,
            ..r.clone()
        };
        let tally = Tally::of(&[earlier, r.clone()]);
        let json = serde_json::to_string(&ServerMessage::Result(ResultView::of(r, &tally)))
            .expect("serialises");
        assert_eq!(
            json,
            r#"{"type":"result","session_id":"s1","sequence_index":3,"level":3,"feedback":1,"#
                .to_owned()
                + r#""overridden":true,"sequence":["happy","sad","angry"],"#
                + r#""answer":["happy","sad","sad"],"outcome":-1,"timed_out":false,"#
                + r#""engagement":0.1,"response_time":12.7,"score":-3,"session_score":-1,"#
                + r#""session_max_score":5}"#
        );
    }
}
