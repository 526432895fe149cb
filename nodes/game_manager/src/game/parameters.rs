//! The parameters a running game manager takes over the ROS 2 graph (`ros2 param set`): the
//! language of the robot's lines and supervised autonomy's settings, between sessions. A
//! session under way keeps what it started with (its lines and its proposals belong to it),
//! so a change then is refused with the reason. Every other key is read once at start-up.

use super::GameManager;
use crate::params::GameManagerParams;
use crate::utterances::Utterances;
use sequence_game::UserModelTable;

/// The keys [`GameManager::change_parameters`] takes; the rest are read-only.
pub const WRITABLE: [&str; 5] = [
    "language",
    "supervised_autonomy",
    "propose_above_temperature",
    "propose_above_success_std",
    "proposal_countdown_s",
];

impl GameManager {
    /// Takes `params`, which differ from the node's only in [`WRITABLE`] keys (`changed`
    /// names the keys set), between sessions: the next session speaks the new language and
    /// proposes by the new rule. Refused, with the reason, while a session runs, for a value
    /// the game cannot work with, or for a change of any other key.
    pub fn change_parameters(
        &mut self,
        params: GameManagerParams,
        changed: &[String],
    ) -> Result<(), String> {
        let keys = changed.join(", ");
        if let Some(session) = self.session.as_ref().filter(|_| self.session_running()) {
            return Err(format!(
                "{keys}: changes between sessions, and session {} is under way",
                session.id
            ));
        }
        let mut only_writable = self.params.clone();
        only_writable.lines.language = params.lines.language.clone();
        let s = &params.supervision;
        only_writable.supervision.supervised_autonomy = s.supervised_autonomy;
        only_writable.supervision.propose_above_temperature = s.propose_above_temperature;
        only_writable.supervision.propose_above_success_std = s.propose_above_success_std;
        only_writable.supervision.proposal_countdown_s = s.proposal_countdown_s;
        if only_writable != params {
            return Err(format!(
                "{keys}: only {} change while the game manager runs",
                WRITABLE.join(", ")
            ));
        }
        params.validate().map_err(|e| e.to_string())?;
        self.utterances = Utterances::from_params(&params.lines);
        self.proposals
            .set_params(&params.supervision, params.timing.time_scale);
        self.params = params;
        Ok(())
    }

    /// Whether the σ rule has the user models' tables (`with_user_models`, `set_user_models`).
    pub fn has_user_models(&self) -> bool {
        self.proposals.has_user_models()
    }

    /// The user models' tables for the σ rule, read by the shell when a change turns
    /// supervised autonomy on.
    pub fn set_user_models(&mut self, tables: Vec<UserModelTable>) {
        self.proposals.set_user_models(tables);
    }
}
