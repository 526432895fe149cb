//! The decision node's Q-tables, one per user-model cluster, sans-IO: a cluster whose file
//! cannot be used (corrupt, truncated, another owner's) is unavailable, its decisions refused
//! and its results not learned, naming the file, which is never written; the others serve.
//! Optionally (`per_user_q_tables`) each user also gets a table of their own, started from
//! their cluster's at their first decision (the paper's policy transfer, to one user), which
//! decides for them and learns from their sessions; the cluster's table still learns from all
//! of its users, so a new user starts from the group's experience.

use crate::child_beliefs::{BeliefServeError, ChildBeliefs, PlannedDecision};
use crate::persistent::{Opened, PersistentError, PersistentPolicy};
use q_learning::learning::{Learning, Mode, QTable};
use q_learning::messages::{ResultError, decision_message, transition};
use q_learning::policy_core::{PolicyError, Update};
use q_learning::q_table_file::QTableOwner;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{DecideActionRequest, SequenceResult};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Why a request or a result of the node was refused; no table or file was changed.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error("unknown user model cluster {cluster}: the policy holds {count}")]
    UnknownCluster { cluster: i64, count: usize },
    #[error(
        "cluster {cluster} is unavailable, its Q-table file is refused and left untouched: {reason}"
    )]
    Unavailable {
        cluster: usize,
        path: PathBuf,
        reason: String,
    },
    #[error("state: {0}")]
    State(String),
    #[error("user {user}'s Q-table is unavailable and left untouched: {reason}")]
    UserUnavailable {
        user: String,
        path: PathBuf,
        reason: String,
    },
    #[error(transparent)]
    Policy(#[from] PolicyError),
    #[error(transparent)]
    Result(#[from] ResultError),
    #[error(transparent)]
    Persistent(#[from] PersistentError),
    #[error("child belief: {0}")]
    Belief(#[from] BeliefServeError),
}

/// One owner's table (a cluster's or a user's): in use, or refused when it was opened.
#[derive(Debug)]
pub enum OwnedTable {
    // Boxed: a table is 3 kB, a refusal a few words.
    Ready(Box<PersistentPolicy>),
    /// `reason` names the file (`PersistentError` always does for a table's file).
    Unavailable {
        path: PathBuf,
        reason: String,
    },
}

impl OwnedTable {
    /// Opens `owner`'s table in `dir`, or makes it with `initial`; a table that cannot be
    /// opened is logged as an error with its file and the problem, and is unavailable.
    fn open(
        dir: &Path,
        owner: QTableOwner,
        learning: Learning,
        mode: Mode,
        seed: u64,
        initial: impl FnOnce() -> Result<(QTable, String), String>,
    ) -> OwnedTable {
        match PersistentPolicy::open(dir, owner.clone(), learning, mode, seed, initial) {
            Ok((p, how)) => {
                let how = match how {
                    Opened::Loaded => "loaded",
                    Opened::Created => "created",
                };
                tracing::info!(%owner, file = %p.path().display(), how,
                    updates = p.core().updates(), "Q-table ready");
                OwnedTable::Ready(Box::new(p))
            }
            Err(e) => {
                let path = owner
                    .file_name()
                    .map(|f| dir.join(f))
                    .unwrap_or_else(|_| dir.to_path_buf());
                tracing::error!(%owner, file = %path.display(),
                    "Q-table refused: {e}. Until the file is repaired or removed and the node \
                     restarted, {owner}'s decisions are refused and its results not learned in \
                     it; the file is left untouched");
                OwnedTable::Unavailable {
                    path,
                    reason: e.to_string(),
                }
            }
        }
    }
}

/// Every cluster's table, and the cluster used when a request names none (-1).
#[derive(Debug)]
pub struct ClusterPolicies {
    tables: Vec<OwnedTable>,
    default_cluster: i64,
    dir: PathBuf,
    learning: Learning,
    mode: Mode,
    seed: u64,
    /// Per-user tables, opened at each user's first decision or result; None: clusters only.
    users: Option<BTreeMap<String, OwnedTable>>,
    /// User ids that cannot name a file: served by their cluster's table (warned once each).
    unnamed_users: BTreeSet<String>,
    /// Per-child beliefs planned on (`child_belief`); None: the tables decide alone.
    beliefs: Option<ChildBeliefs>,
}

impl ClusterPolicies {
    /// Opens `dir/cluster_<k>.json` for clusters 0..clusters, building a missing one with
    /// `initial(k)`. A table that cannot be opened makes its cluster unavailable (logged as an
    /// error with the file and the problem); it does not stop the others.
    pub fn open(
        dir: &Path,
        clusters: usize,
        learning: Learning,
        mode: Mode,
        seed: u64,
        default_cluster: i64,
        mut initial: impl FnMut(usize) -> Result<(QTable, String), String>,
    ) -> ClusterPolicies {
        let tables = (0..clusters)
            .map(|k| {
                OwnedTable::open(
                    dir,
                    QTableOwner::Cluster(k),
                    learning,
                    mode,
                    seed ^ k as u64,
                    || initial(k),
                )
            })
            .collect();
        ClusterPolicies {
            tables,
            default_cluster,
            dir: dir.to_path_buf(),
            learning,
            mode,
            seed,
            users: None,
            unnamed_users: BTreeSet::new(),
            beliefs: None,
        }
    }

    /// Plans every named child's decisions on a belief about them, near the table that would
    /// decide for them, and teaches it their results (`child_beliefs`).
    pub fn with_child_beliefs(mut self, beliefs: Option<ChildBeliefs>) -> Self {
        self.beliefs = beliefs;
        self
    }

    /// Gives every user a table of their own (`dir/user_<id>.json`), started from their
    /// cluster's table at their first decision; false keeps one table per cluster.
    pub fn with_user_tables(mut self, on: bool) -> Self {
        self.users = on.then(BTreeMap::new);
        self
    }

    pub fn tables(&self) -> &[OwnedTable] {
        &self.tables
    }

    /// The per-user tables opened so far, by user id (empty without per-user tables).
    pub fn user_tables(&self) -> impl Iterator<Item = (&str, &OwnedTable)> {
        self.users
            .iter()
            .flat_map(|m| m.iter().map(|(id, t)| (id.as_str(), t)))
    }

    /// The cluster a message names; -1 (or any negative) means the default one.
    pub fn cluster(&self, requested: i32) -> Result<usize, ServeError> {
        let c = if requested < 0 {
            self.default_cluster
        } else {
            i64::from(requested)
        };
        usize::try_from(c)
            .ok()
            .filter(|k| *k < self.tables.len())
            .ok_or(ServeError::UnknownCluster {
                cluster: c,
                count: self.tables.len(),
            })
    }

    fn ready(&mut self, k: usize) -> Result<&mut PersistentPolicy, ServeError> {
        ready(&mut self.tables[k]).map_err(|(path, reason)| ServeError::Unavailable {
            cluster: k,
            path,
            reason,
        })
    }

    /// The table that decides for `user_id` in cluster `k`: the user's own with per-user
    /// tables (opened, or made from the cluster's table, on first use), else the cluster's.
    fn policy_for(&mut self, user_id: &str, k: usize) -> Result<&mut PersistentPolicy, ServeError> {
        let Some(file) = self.user_file(user_id) else {
            return self.ready(k);
        };
        // A user with no table yet whose cluster is unavailable has nothing to start from:
        // the cluster's refusal, and no entry, so a later request with a usable cluster
        // makes their table. (The file is looked for only until the table is open.)
        let unopened = self
            .users
            .as_ref()
            .is_some_and(|u| !u.contains_key(user_id));
        if unopened
            && matches!(self.tables[k], OwnedTable::Unavailable { .. })
            && !self.dir.join(file).exists()
        {
            return self.ready(k);
        }
        let users = match self.users {
            Some(ref mut users) => users,
            None => return self.ready(k),
        };
        let table = users.entry(user_id.to_string()).or_insert_with(|| {
            open_user_table(
                &self.dir,
                user_id,
                &self.tables[k],
                k,
                self.learning,
                self.mode,
                self.seed,
            )
        });
        ready(table).map_err(|(path, reason)| ServeError::UserUnavailable {
            user: user_id.to_string(),
            path,
            reason,
        })
    }

    /// The file of `user_id`'s own table, if they get one: per-user tables are on, and the
    /// id can name a file (a warning, once, for one that cannot: its cluster's table serves
    /// it).
    fn user_file(&mut self, user_id: &str) -> Option<String> {
        if self.users.is_none() || user_id.is_empty() {
            return None;
        }
        match QTableOwner::User(user_id.to_string()).file_name() {
            Ok(file) => Some(file),
            Err(e) => {
                if self.unnamed_users.insert(user_id.to_string()) {
                    tracing::warn!("{e}: the user's cluster's Q-table serves them");
                }
                None
            }
        }
    }

    /// The highest sequence of `request`'s session its cluster's table has learned from (kept
    /// in the table's file, so it survives a restart); `None` if none, or the cluster is not
    /// served.
    pub fn last_learned(&self, request: &DecideActionRequest) -> Option<u8> {
        let k = self.cluster(request.user_model_cluster).ok()?;
        match self.tables().get(k)? {
            OwnedTable::Ready(p) => p.last_learned(&request.session_id),
            OwnedTable::Unavailable { .. } => None,
        }
    }

    /// The Decision message answering `request`, stamped `header`.
    pub fn decide(
        &mut self,
        request: &DecideActionRequest,
        header: Header,
    ) -> Result<qt_therapy_msgs::Decision, ServeError> {
        let k = self.cluster(request.user_model_cluster)?;
        let policy = self.policy_for(&request.user_id, k)?;
        let state = request
            .state
            .to_state()
            .map_err(|e| ServeError::State(e.reason))?;
        let d = policy.decide(state, request.step)?;
        let table_used = model_used(policy);
        let table = policy.core().q_table().clone();
        let mut message = decision_message(&d, header, &request.session_id, table_used);
        let Some(beliefs) = self.beliefs.as_mut().filter(|b| b.serves(&request.user_id)) else {
            return Ok(message);
        };
        let planned = beliefs.decide(
            &request.user_id,
            &request.session_id,
            k,
            &table,
            state,
            request.step,
        )?;
        planned_message(&mut message, &planned, state)?;
        Ok(message)
    }

    /// Learns from one result and saves its cluster's table, and with per-user tables the
    /// user's too; None when that sequence was already learned (sent again after a restart).
    /// With per-user tables the user's update is the one returned; an error of either table is
    /// returned after both have tried.
    pub fn learn(&mut self, result: &SequenceResult) -> Result<Option<Update>, ServeError> {
        let k = self.cluster(result.user_model_cluster)?;
        let t = transition(result)?;
        let (session, index) = (&result.session_id, result.sequence_index);
        let per_user = self.user_file(&result.user_id).is_some();
        if per_user {
            // Opened, or made if this result is the user's first event, before the cluster
            // learns it, so the copy does not hold this result already. Its refusal, if any,
            // comes back from the second call below.
            let _ = self.policy_for(&result.user_id, k);
        }
        let cluster = self
            .ready(k)
            .and_then(|p| Ok(p.learn_sequence(session, index, &t)?));
        let tables = if per_user {
            let user = self
                .policy_for(&result.user_id, k)
                .and_then(|p| Ok(p.learn_sequence(session, index, &t)?));
            match (cluster, user) {
                (Err(e), _) => Err(e),
                (Ok(_), user) => user,
            }
        } else {
            cluster
        };
        // The child's belief learns whatever the tables made of it: it is theirs alone.
        let belief = match self.beliefs.as_mut() {
            Some(b) if b.serves(&result.user_id) => b.learn(result, k).map(|_| ()),
            _ => Ok(()),
        };
        match (tables, belief) {
            (Err(e), _) => Err(e),
            (Ok(_), Err(e)) => Err(e.into()),
            (Ok(u), Ok(())) => Ok(u),
        }
    }
}

/// The policy of a table in use, or where and why it was refused.
fn ready(table: &mut OwnedTable) -> Result<&mut PersistentPolicy, (PathBuf, String)> {
    match table {
        OwnedTable::Ready(p) => Ok(p),
        OwnedTable::Unavailable { path, reason } => Err((path.clone(), reason.clone())),
    }
}

/// Opens `dir/user_<id>.json`, or makes it from cluster `k`'s table as it stands now. A user's
/// file that cannot be used makes that user unavailable (logged with the file), not the node.
fn open_user_table(
    dir: &Path,
    user_id: &str,
    cluster: &OwnedTable,
    k: usize,
    learning: Learning,
    mode: Mode,
    seed: u64,
) -> OwnedTable {
    OwnedTable::open(
        dir,
        QTableOwner::User(user_id.to_string()),
        learning,
        mode,
        seed ^ sequence_game::stable_id_hash(user_id),
        || match cluster {
            OwnedTable::Ready(p) => Ok((
                p.core().q_table().clone(),
                format!(
                    "user {user_id}'s own table, started from cluster {k}'s ({}, {} updates)",
                    p.path().display(),
                    p.core().updates()
                ),
            )),
            OwnedTable::Unavailable { reason, .. } => Err(format!(
                "cluster {k}'s table, to start from, is refused: {reason}"
            )),
        },
    )
}

/// The Decision message of a decision planned on the child's belief: its action, level and
/// feedback, a probability of 1 on it (the plan is the belief's, drawn from nothing the
/// softmax sets), the belief per level, and the table's own choice beside it.
fn planned_message(
    message: &mut qt_therapy_msgs::Decision,
    planned: &PlannedDecision,
    state: sequence_game::State,
) -> Result<(), ServeError> {
    let d = &planned.decision;
    let (level, feedback) = d.action.apply(state).ok_or_else(|| {
        ServeError::State(format!("the plan's {} cannot follow {state}", d.action))
    })?;
    message.action = d.action.index() as u8;
    message.level = level.get();
    message.feedback = feedback as u8;
    message.probabilities = (0..sequence_game::ACTION_COUNT)
        .map(|a| if a == d.action.index() { 1.0 } else { 0.0 })
        .collect();
    message.explored = false;
    message.planned_on_belief = true;
    message.belief_observations = u32::try_from(planned.observations).unwrap_or(u32::MAX);
    message.belief_success = planned.levels.iter().map(|l| l.success).collect();
    message.belief_success_sd = planned.levels.iter().map(|l| l.success_sd).collect();
    message.belief_engagement = planned.levels.iter().map(|l| l.engagement).collect();
    message.belief_engagement_sd = planned.levels.iter().map(|l| l.engagement_sd).collect();
    message.baseline_action = d
        .baseline
        .map_or(message.baseline_action, |a| a.index() as u8);
    message.model_used = format!("{} near {}", planned.described, message.model_used);
    Ok(())
}

/// Which Q-table made a decision, for the Decision message (the replay reads it back).
fn model_used(p: &PersistentPolicy) -> String {
    format!(
        "{} ({}, {} updates)",
        p.owner(),
        p.path().display(),
        p.core().updates()
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use q_learning::q_table_file::QTableFile;
    use qt_therapy_msgs::BehaviourState;
    use sequence_game::State;

    const CORRUPT: &str = "{\"format\": \"qt_therapy q_table\", \"version\": 1, \"own";

    fn open(dir: &Path) -> ClusterPolicies {
        ClusterPolicies::open(dir, 3, Learning::default(), Mode::Exploit, 7, 0, |k| {
            Ok((QTable::default(), format!("fresh {k}")))
        })
    }

    fn request(cluster: i32) -> DecideActionRequest {
        DecideActionRequest {
            session_id: "s".into(),
            user_model_cluster: cluster,
            step: 1,
            state: BehaviourState::from_state(State::START),
            ..Default::default()
        }
    }

    fn result(cluster: i32) -> SequenceResult {
        SequenceResult {
            session_id: "s".into(),
            user_model_cluster: cluster,
            sequence_index: 1,
            state: BehaviourState::from_state(State::START),
            action: 1,
            level: 2,
            feedback: 0,
            outcome: 1,
            activity_result: 2.0,
            engagement: 0.5,
            engagement_per_second: vec![0.5],
            sequences_planned: 10,
            ..Default::default()
        }
    }

    #[test]
    fn a_corrupt_table_makes_only_its_cluster_unavailable_and_is_never_written() {
        let dir = tempfile::tempdir().expect("tempdir");
        let corrupt = dir.path().join("cluster_1.json");
        std::fs::write(&corrupt, CORRUPT).expect("write");
        let mut policies = open(dir.path());
        assert!(matches!(policies.tables()[0], OwnedTable::Ready(_)));
        assert!(
            matches!(&policies.tables()[1], OwnedTable::Unavailable { path, .. } if *path == corrupt)
        );
        assert!(matches!(policies.tables()[2], OwnedTable::Ready(_)));

        let e = policies
            .decide(&request(1), Header::default())
            .expect_err("unavailable");
        let text = e.to_string();
        assert!(
            text.starts_with("cluster 1 is unavailable")
                && text.contains(&corrupt.display().to_string())
                && text.contains("not JSON"),
            "{text}"
        );
        let e = policies.learn(&result(1)).expect_err("not learned");
        assert!(
            matches!(e, ServeError::Unavailable { cluster: 1, .. }),
            "{e}"
        );
        assert_eq!(std::fs::read_to_string(&corrupt).expect("read"), CORRUPT);

        // The others serve and learn; -1 is the default cluster 0.
        let d = policies
            .decide(&request(-1), Header::default())
            .expect("decides");
        assert!(d.model_used.starts_with("cluster 0 ("), "{}", d.model_used);
        assert!(policies.learn(&result(2)).expect("learns").is_some());
        let on_disk = QTableFile::load(&dir.path().join("cluster_2.json")).expect("loads");
        assert_eq!(on_disk.updates, 1);
        assert_eq!(std::fs::read_to_string(&corrupt).expect("read"), CORRUPT);
        // Only the three tables: no temporary or replacement file beside the corrupt one.
        assert_eq!(std::fs::read_dir(dir.path()).expect("lists").count(), 3);
    }

    #[test]
    fn what_the_therapist_chose_is_learned_as_played() {
        // Supervised autonomy: a proposal the therapist replaced (or any override) comes back
        // as the action that played, flagged overridden; the table learns that action.
        let dir = tempfile::tempdir().expect("tempdir");
        let mut policies = open(dir.path());
        let replaced = SequenceResult {
            action: 2,
            level: 3,
            overridden: true,
            outcome: 1,
            activity_result: 3.0,
            ..result(0)
        };
        policies.learn(&replaced).expect("learned");
        let row = *policies
            .ready(0)
            .expect("cluster 0")
            .core()
            .q_table()
            .row(State::START);
        assert!(row[2] > 0.0, "a3 (level 3) learned: {row:?}");
        assert_eq!(
            row[1], 0.0,
            "a2, the policy's own choice, untouched: {row:?}"
        );
    }

    #[test]
    fn unknown_clusters_and_bad_results_are_refused_by_name() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut policies = open(dir.path());
        let e = policies
            .decide(&request(5), Header::default())
            .expect_err("unknown");
        assert_eq!(
            e.to_string(),
            "unknown user model cluster 5: the policy holds 3"
        );
        assert!(matches!(
            policies.learn(&result(3)),
            Err(ServeError::UnknownCluster { cluster: 3, .. })
        ));
        let nan = SequenceResult {
            engagement_per_second: vec![f32::NAN],
            engagement: f32::NAN,
            ..result(0)
        };
        assert!(matches!(
            policies.learn(&nan),
            Err(ServeError::Persistent(PersistentError::Policy(
                PolicyError::Engagement(_)
            )))
        ));
        let late_start = SequenceResult {
            sequence_index: 2,
            ..result(0)
        };
        assert!(matches!(
            policies.learn(&late_start),
            Err(ServeError::Persistent(PersistentError::StartState { .. }))
        ));
        let on_disk = QTableFile::load(&dir.path().join("cluster_0.json")).expect("loads");
        assert_eq!(on_disk.updates, 0);
    }

    #[test]
    fn a_cluster_without_an_initial_table_is_unavailable_and_nothing_is_written() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut policies = ClusterPolicies::open(
            dir.path(),
            2,
            Learning::default(),
            Mode::Exploit,
            7,
            0,
            |k| {
                if k == 1 {
                    Err("pretraining failed".into())
                } else {
                    Ok((QTable::default(), String::new()))
                }
            },
        );
        let e = policies
            .decide(&request(1), Header::default())
            .expect_err("unavailable");
        assert!(e.to_string().contains("pretraining failed"), "{e}");
        assert!(!dir.path().join("cluster_1.json").exists());
        assert!(policies.decide(&request(0), Header::default()).is_ok());
    }

    fn for_user(user: &str, session: &str) -> (DecideActionRequest, SequenceResult) {
        (
            DecideActionRequest {
                user_id: user.into(),
                session_id: session.into(),
                ..request(0)
            },
            SequenceResult {
                user_id: user.into(),
                session_id: session.into(),
                ..result(0)
            },
        )
    }

    fn on_disk(dir: &Path, file: &str) -> QTableFile {
        QTableFile::load(&dir.join(file)).expect("loads")
    }

    #[test]
    fn per_user_tables_start_from_their_cluster_and_learn_only_their_users_sessions() {
        let dir = tempfile::tempdir().expect("tempdir");
        let d = dir.path();
        let mut policies = open(d).with_user_tables(true);
        let (ask_1, result_1) = for_user("u1", "s1");
        let decision = policies.decide(&ask_1, Header::default()).expect("decides");
        assert!(
            decision.model_used.starts_with("user u1 (")
                && decision.model_used.contains("user_u1.json"),
            "{}",
            decision.model_used
        );
        let u1 = on_disk(d, "user_u1.json");
        assert_eq!(u1.owner, QTableOwner::User("u1".into()));
        assert_eq!(
            u1.table,
            on_disk(d, "cluster_0.json").table,
            "a copy of its cluster's"
        );
        assert!(
            u1.provenance.contains("started from cluster 0's"),
            "{}",
            u1.provenance
        );

        assert!(policies.learn(&result_1).expect("learns").is_some());
        assert_eq!(on_disk(d, "user_u1.json").updates, 1);
        assert_eq!(
            on_disk(d, "cluster_0.json").updates,
            1,
            "the cluster learns from all"
        );

        // A second user starts from the cluster as it is now (after u1's sequence).
        let (ask_2, result_2) = for_user("u2", "s2");
        policies.decide(&ask_2, Header::default()).expect("decides");
        assert_eq!(
            on_disk(d, "user_u2.json").table,
            on_disk(d, "cluster_0.json").table
        );
        assert_ne!(on_disk(d, "user_u2.json").table, QTable::default());
        policies.learn(&result_2).expect("learns");
        assert_eq!(on_disk(d, "user_u2.json").updates, 1);
        assert_eq!(
            on_disk(d, "user_u1.json").updates,
            1,
            "only its user's sessions"
        );
        assert_eq!(on_disk(d, "cluster_0.json").updates, 2);
        let names: Vec<&str> = policies.user_tables().map(|(id, _)| id).collect();
        assert_eq!(names, ["u1", "u2"]);

        // A respawned node loads the user's table and learns a result sent again only once.
        let mut respawned = open(d).with_user_tables(true);
        assert_eq!(respawned.learn(&result_1).expect("no error"), None);
        assert_eq!(on_disk(d, "user_u1.json").updates, 1);
        assert_eq!(on_disk(d, "cluster_0.json").updates, 2);
        let again = respawned
            .decide(&ask_1, Header::default())
            .expect("decides");
        assert!(
            again.model_used.ends_with("user_u1.json, 1 updates)"),
            "{}",
            again.model_used
        );

        // A result as a user's first event (a session the node never decided for): the
        // user's table is made from the cluster's before the cluster learns it, so both
        // hold it once.
        let (_, result_4) = for_user("u4", "s4");
        respawned.learn(&result_4).expect("learns");
        let u4 = on_disk(d, "user_u4.json");
        assert_eq!(u4.updates, 1);
        assert_eq!(u4.table, on_disk(d, "cluster_0.json").table);

        // Off (the default), users share their cluster's table and no user file is made.
        let (ask_3, _) = for_user("u3", "s3");
        let shared = open(d).decide(&ask_3, Header::default()).expect("decides");
        assert!(
            shared.model_used.starts_with("cluster 0 ("),
            "{}",
            shared.model_used
        );
        assert!(!d.join("user_u3.json").exists());
    }

    #[test]
    fn a_user_id_that_cannot_name_a_file_is_served_by_its_cluster_and_a_corrupt_user_file_by_nobody()
     {
        let dir = tempfile::tempdir().expect("tempdir");
        let d = dir.path();
        let corrupt = d.join("user_u9.json");
        std::fs::write(&corrupt, CORRUPT).expect("write");
        std::fs::write(d.join("cluster_1.json"), CORRUPT).expect("write");
        let mut policies = open(d).with_user_tables(true);

        let (ask, result) = for_user("../a b", "s1");
        let decision = policies.decide(&ask, Header::default()).expect("decides");
        assert!(
            decision.model_used.starts_with("cluster 0 ("),
            "{}",
            decision.model_used
        );
        assert!(policies.learn(&result).expect("learns").is_some());
        assert_eq!(
            std::fs::read_dir(d).expect("lists").count(),
            4,
            "3 clusters, u9's"
        );

        // No table yet, and its cluster is refused: the cluster's refusal, nothing made, and
        // a later request with a usable cluster makes the user's table.
        let e = policies
            .decide(
                &DecideActionRequest {
                    user_model_cluster: 1,
                    ..for_user("u5", "s3").0
                },
                Header::default(),
            )
            .expect_err("unavailable");
        assert!(
            matches!(e, ServeError::Unavailable { cluster: 1, .. }),
            "{e}"
        );
        policies
            .decide(&for_user("u5", "s3").0, Header::default())
            .expect("decides");
        assert!(d.join("user_u5.json").exists());

        let (ask, result) = for_user("u9", "s2");
        let e = policies
            .decide(&ask, Header::default())
            .expect_err("refused");
        let text = e.to_string();
        assert!(
            text.starts_with("user u9's Q-table is unavailable")
                && text.contains(&corrupt.display().to_string()),
            "{text}"
        );
        assert!(matches!(
            policies.learn(&result),
            Err(ServeError::UserUnavailable { .. })
        ));
        assert_eq!(
            on_disk(d, "cluster_0.json").updates,
            2,
            "its cluster still learns"
        );
        assert_eq!(std::fs::read_to_string(&corrupt).expect("read"), CORRUPT);
    }
}
