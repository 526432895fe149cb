//! The decision node's Q-tables, one per user-model cluster, sans-IO: a cluster whose file
//! cannot be used (corrupt, truncated, another owner's) is unavailable, its decisions refused
//! and its results not learned, naming the file, which is never written; the others serve.

use crate::learning::{Learning, Mode, QTable};
use crate::messages::{ResultError, decision_message, transition};
use crate::persistent::{Opened, PersistentError, PersistentPolicy};
use crate::policy_core::{PolicyError, Update};
use crate::q_table_file::QTableOwner;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::{DecideActionRequest, SequenceResult};
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
    #[error(transparent)]
    Policy(#[from] PolicyError),
    #[error(transparent)]
    Result(#[from] ResultError),
    #[error(transparent)]
    Persistent(#[from] PersistentError),
}

/// One cluster's table: in use, or refused when the node started.
#[derive(Debug)]
pub enum ClusterTable {
    // Boxed: a table is 3 kB, a refusal a few words.
    Ready(Box<PersistentPolicy>),
    /// `reason` names the file (`PersistentError` always does for a cluster's table).
    Unavailable {
        path: PathBuf,
        reason: String,
    },
}

/// Every cluster's table, and the cluster used when a request names none (-1).
#[derive(Debug)]
pub struct ClusterPolicies {
    tables: Vec<ClusterTable>,
    default_cluster: i64,
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
                let owner = QTableOwner::Cluster(k);
                let opened = PersistentPolicy::open(
                    dir,
                    owner.clone(),
                    learning,
                    mode,
                    seed ^ k as u64,
                    || initial(k),
                );
                match opened {
                    Ok((p, how)) => {
                        let how = match how {
                            Opened::Loaded => "loaded",
                            Opened::Created => "created",
                        };
                        tracing::info!(cluster = k, file = %p.path().display(), how,
                            updates = p.core().updates(), "Q-table ready");
                        ClusterTable::Ready(Box::new(p))
                    }
                    Err(e) => {
                        let path = owner
                            .file_name()
                            .map(|f| dir.join(f))
                            .unwrap_or_else(|_| dir.to_path_buf());
                        tracing::error!(cluster = k, file = %path.display(),
                            "Q-table refused: {e}. Cluster {k} is unavailable (its decisions \
                             are refused and its results not learned) until the file is \
                             repaired or removed and the node restarted; the file is left \
                             untouched");
                        ClusterTable::Unavailable {
                            path,
                            reason: e.to_string(),
                        }
                    }
                }
            })
            .collect();
        ClusterPolicies {
            tables,
            default_cluster,
        }
    }

    pub fn tables(&self) -> &[ClusterTable] {
        &self.tables
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

    fn ready(&mut self, requested: i32) -> Result<&mut PersistentPolicy, ServeError> {
        let k = self.cluster(requested)?;
        match &mut self.tables[k] {
            ClusterTable::Ready(p) => Ok(p),
            ClusterTable::Unavailable { path, reason } => Err(ServeError::Unavailable {
                cluster: k,
                path: path.clone(),
                reason: reason.clone(),
            }),
        }
    }

    /// The Decision message answering `request`, stamped `header`.
    pub fn decide(
        &mut self,
        request: &DecideActionRequest,
        header: Header,
    ) -> Result<qt_therapy_msgs::Decision, ServeError> {
        let policy = self.ready(request.user_model_cluster)?;
        let state = request
            .state
            .to_state()
            .map_err(|e| ServeError::State(e.reason))?;
        let d = policy.decide(state, request.step)?;
        Ok(decision_message(
            &d,
            header,
            &request.session_id,
            model_used(policy),
        ))
    }

    /// Learns from one result and saves its cluster's table; None when that sequence was
    /// already learned (sent again after a restart).
    pub fn learn(&mut self, result: &SequenceResult) -> Result<Option<Update>, ServeError> {
        let policy = self.ready(result.user_model_cluster)?;
        let t = transition(result)?;
        Ok(policy.learn_sequence(&result.session_id, result.sequence_index, &t)?)
    }
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
    use crate::q_table_file::QTableFile;
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
            ..Default::default()
        }
    }

    #[test]
    fn a_corrupt_table_makes_only_its_cluster_unavailable_and_is_never_written() {
        let dir = tempfile::tempdir().expect("tempdir");
        let corrupt = dir.path().join("cluster_1.json");
        std::fs::write(&corrupt, CORRUPT).expect("write");
        let mut policies = open(dir.path());
        assert!(matches!(policies.tables()[0], ClusterTable::Ready(_)));
        assert!(
            matches!(&policies.tables()[1], ClusterTable::Unavailable { path, .. } if *path == corrupt)
        );
        assert!(matches!(policies.tables()[2], ClusterTable::Ready(_)));

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
}
