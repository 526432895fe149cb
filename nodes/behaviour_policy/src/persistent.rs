//! A live policy bound to its Q-table file: every update is saved at once (temp file + rename),
//! so a crash mid-session loses nothing already learned. A file that is there but unreadable
//! is an error, never replaced. The file also remembers which sequences were learned from, so
//! results sent again to a respawned policy are learned exactly once.

use q_learning::learning::{Learning, Mode, QTable};
use q_learning::policy_core::{Decision, PolicyCore, PolicyError, Transition, Update};
use q_learning::q_table_file::{QTableError, QTableFile, QTableOwner};
use sequence_game::{Action, SEQUENCES_PER_SESSION, State};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum PersistentError {
    #[error(transparent)]
    Policy(#[from] PolicyError),
    #[error(transparent)]
    File(#[from] QTableError),
    #[error("{path} belongs to {found}, not {expected}")]
    Owner {
        path: PathBuf,
        found: QTableOwner,
        expected: QTableOwner,
    },
    #[error("{path}: learned, but saving failed ({source}); the update is kept in memory")]
    NotSaved { path: PathBuf, source: QTableError },
    #[error("{path}: no file, and no table to start from ({reason}); nothing written")]
    NoInitialTable { path: PathBuf, reason: String },
    #[error("sequence index {0} is outside 1..={SEQUENCES_PER_SESSION}; not learned")]
    SequenceIndex(u8),
    #[error(
        "sequence {sequence_index} starts from {state}: only sequence 1 starts from the start \
         state (0, 0, 0), and it always does; not learned"
    )]
    StartState { sequence_index: u8, state: State },
    #[error("sequence 1 took {0}: feedback is not allowed at the first sequence; not learned")]
    FeedbackAtFirstSequence(Action),
}

/// A `PolicyCore` and the file it lives in.
#[derive(Debug)]
pub struct PersistentPolicy {
    core: PolicyCore,
    owner: QTableOwner,
    provenance: String,
    learned: BTreeMap<String, u8>,
    path: PathBuf,
}

/// How `open` found the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Opened {
    Loaded,
    Created,
}

impl PersistentPolicy {
    /// Loads `dir/<owner file>`; when there is none, builds a table with `initial` (e.g.
    /// pretraining in simulation), saves it, and uses it. When `initial` fails nothing is
    /// written, so a later start does not mistake a placeholder for a trained table.
    pub fn open(
        dir: &Path,
        owner: QTableOwner,
        learning: Learning,
        mode: Mode,
        seed: u64,
        initial: impl FnOnce() -> Result<(QTable, String), String>,
    ) -> Result<(PersistentPolicy, Opened), PersistentError> {
        let path = dir.join(owner.file_name()?);
        let (file, opened) = if path.exists() {
            let file = QTableFile::load(&path)?;
            if file.owner != owner {
                return Err(PersistentError::Owner {
                    path,
                    found: file.owner,
                    expected: owner,
                });
            }
            (file, Opened::Loaded)
        } else {
            let (table, provenance) =
                initial().map_err(|reason| PersistentError::NoInitialTable {
                    path: path.clone(),
                    reason,
                })?;
            let file = QTableFile {
                owner: owner.clone(),
                provenance,
                updates: 0,
                learned: BTreeMap::new(),
                table,
            };
            file.save(&path)?;
            (file, Opened::Created)
        };
        Ok((
            PersistentPolicy {
                core: PolicyCore::new(file.table, learning, mode, seed, file.updates),
                owner,
                provenance: file.provenance,
                learned: file.learned,
                path,
            },
            opened,
        ))
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn owner(&self) -> &QTableOwner {
        &self.owner
    }

    pub fn core(&self) -> &PolicyCore {
        &self.core
    }

    pub fn decide(&mut self, state: State, step: u8) -> Result<Decision, PolicyError> {
        self.core.decide(state, step)
    }

    /// Learns from one sequence and saves the table before returning.
    pub fn learn(&mut self, t: &Transition) -> Result<Update, PersistentError> {
        let update = self.core.learn(t)?;
        self.save()?;
        Ok(update)
    }

    /// Learns from sequence `sequence_index` of `session_id` unless it already has (None):
    /// the results topic is replayed to a policy that restarts mid-session. Refuses a
    /// transition its place in the session rules out: sequence 1, and only it, starts from
    /// (0, 0, 0), with a1..a3 (the rule `decide` follows at step 1).
    pub fn learn_sequence(
        &mut self,
        session_id: &str,
        sequence_index: u8,
        t: &Transition,
    ) -> Result<Option<Update>, PersistentError> {
        check_place_in_session(sequence_index, t)?;
        if self
            .learned
            .get(session_id)
            .is_some_and(|last| sequence_index <= *last)
        {
            return Ok(None);
        }
        let update = self.core.learn(t)?;
        self.learned.insert(session_id.to_string(), sequence_index);
        self.save()?;
        Ok(Some(update))
    }

    /// The highest sequence index of `session_id` learned from, if any.
    pub fn last_learned(&self, session_id: &str) -> Option<u8> {
        self.learned.get(session_id).copied()
    }

    fn save(&self) -> Result<(), PersistentError> {
        let file = QTableFile {
            owner: self.owner.clone(),
            provenance: self.provenance.clone(),
            updates: self.core.updates(),
            learned: self.learned.clone(),
            table: self.core.q_table().clone(),
        };
        file.save(&self.path)
            .map_err(|source| PersistentError::NotSaved {
                path: self.path.clone(),
                source,
            })
    }
}

/// The session rules a transition's sequence index implies; `PolicyCore::learn` cannot check
/// them, as a `Transition` does not know where in the session it was.
fn check_place_in_session(sequence_index: u8, t: &Transition) -> Result<(), PersistentError> {
    if !(1..=SEQUENCES_PER_SESSION).contains(&usize::from(sequence_index)) {
        return Err(PersistentError::SequenceIndex(sequence_index));
    }
    if sequence_index == 1 && t.action.is_feedback() {
        return Err(PersistentError::FeedbackAtFirstSequence(t.action));
    }
    if (sequence_index == 1) != t.state.is_start() {
        return Err(PersistentError::StartState {
            sequence_index,
            state: t.state,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use sequence_game::{Action, Level};

    fn open(dir: &Path) -> Result<(PersistentPolicy, Opened), PersistentError> {
        PersistentPolicy::open(
            dir,
            QTableOwner::Cluster(0),
            Learning::default(),
            Mode::Exploit,
            1,
            || Ok((QTable::default(), "fresh".into())),
        )
    }

    /// A transition the game could report as sequence `step`: the first from (0, 0, 0), the
    /// others from (1, 0, +1).
    fn transition(step: u8) -> Transition {
        let level = Level::new(i64::from(step % 3) + 1).expect("level");
        Transition {
            state: if step == 1 {
                State::START
            } else {
                State::new(1, 0, 1).expect("state")
            },
            action: Action::SetLevel(level),
            activity_result: f64::from(level.get()),
            engagement: 0.25,
            next_state: State::new(level.get().into(), 0, 0).expect("state"),
            is_last: false,
        }
    }

    #[test]
    fn every_update_is_on_disk_before_learn_returns() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (mut p, how) = open(dir.path()).expect("creates");
        assert_eq!(how, Opened::Created);
        for step in 1..=10 {
            p.learn(&transition(step)).expect("learns");
            // A crash now would lose nothing: the file already holds this update.
            let on_disk = QTableFile::load(p.path()).expect("loads");
            assert_eq!(&on_disk.table, p.core().q_table());
            assert_eq!(on_disk.updates, u64::from(step));
        }
        drop(p);
        let (p, how) = open(dir.path()).expect("reopens");
        assert_eq!(how, Opened::Loaded);
        assert_eq!(p.core().updates(), 10);
    }

    #[test]
    fn a_sequence_sent_again_after_a_restart_is_learned_once() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (mut p, _) = open(dir.path()).expect("creates");
        for step in 1..=3 {
            assert!(
                p.learn_sequence("s1", step, &transition(step))
                    .expect("learns")
                    .is_some()
            );
        }
        let before = p.core().q_table().clone();
        drop(p);
        // Respawned: the results topic hands it sequences 1..5 of s1 again, and s2 is new.
        let (mut p, _) = open(dir.path()).expect("reopens");
        assert_eq!(p.last_learned("s1"), Some(3));
        for step in 1..=3 {
            assert!(
                p.learn_sequence("s1", step, &transition(step))
                    .expect("ok")
                    .is_none()
            );
        }
        assert_eq!(p.core().q_table(), &before);
        assert_eq!(p.core().updates(), 3);
        for step in 4..=5 {
            assert!(
                p.learn_sequence("s1", step, &transition(step))
                    .expect("learns")
                    .is_some()
            );
        }
        assert!(
            p.learn_sequence("s2", 1, &transition(1))
                .expect("learns")
                .is_some()
        );
        assert_eq!(p.core().updates(), 6);
        let on_disk = QTableFile::load(p.path()).expect("loads");
        assert_eq!(on_disk.learned.get("s1"), Some(&5));
        assert_eq!(on_disk.learned.get("s2"), Some(&1));
    }

    #[test]
    fn a_corrupt_or_foreign_file_is_refused_and_left_alone() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("cluster_0.json");
        std::fs::write(&path, "{\"format\": \"qt_therapy q_table\", \"vers").expect("write");
        let e = open(dir.path()).expect_err("corrupt");
        assert!(e.to_string().contains("cluster_0.json"), "{e}");
        assert_eq!(
            std::fs::read_to_string(&path).expect("read"),
            "{\"format\": \"qt_therapy q_table\", \"vers"
        );
        QTableFile {
            owner: QTableOwner::Cluster(3),
            provenance: "elsewhere".into(),
            updates: 0,
            learned: BTreeMap::new(),
            table: QTable::default(),
        }
        .save(&path)
        .expect("saves");
        let e = open(dir.path()).expect_err("foreign");
        assert!(e.to_string().contains("belongs to cluster 3"), "{e}");
    }

    #[test]
    fn a_refused_update_leaves_the_file_as_it_was() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (mut p, _) = open(dir.path()).expect("creates");
        p.learn(&transition(1)).expect("learns");
        let before = std::fs::read(p.path()).expect("read");
        let nan = Transition {
            engagement: f64::NAN,
            ..transition(2)
        };
        assert!(matches!(
            p.learn(&nan),
            Err(PersistentError::Policy(PolicyError::Engagement(_)))
        ));
        assert_eq!(std::fs::read(p.path()).expect("read"), before);
    }

    #[test]
    fn a_result_out_of_place_in_its_session_is_refused_and_nothing_written() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (mut p, _) = open(dir.path()).expect("creates");
        p.learn_sequence("s", 1, &transition(1)).expect("learns");
        let before = std::fs::read(p.path()).expect("read");
        let mid = State::new(2, 0, -2).expect("state");
        let refused = [
            // Sequence 1 from a state with a level: the game never starts there.
            (
                1,
                Transition {
                    state: mid,
                    next_state: State::new(2, 0, 2).expect("state"),
                    ..transition(1)
                },
                "sequence 1 starts from (L=2, F=0, PS=-2)",
            ),
            // Sequence 1 with feedback (allowed in that state, not at the first sequence).
            (
                1,
                Transition {
                    state: mid,
                    action: Action::Encourage,
                    next_state: State::new(2, 1, 2).expect("state"),
                    ..transition(1)
                },
                "sequence 1 took a4 encourage",
            ),
            // A later sequence from the start state.
            (
                4,
                Transition {
                    state: State::START,
                    ..transition(4)
                },
                "sequence 4 starts from (L=0, F=0, PS=+0)",
            ),
            (0, transition(2), "sequence index 0 is outside 1..=10"),
            (11, transition(2), "sequence index 11 is outside 1..=10"),
        ];
        for (index, t, says) in refused {
            let e = p.learn_sequence("t", index, &t).expect_err("out of place");
            assert!(e.to_string().contains(says), "{e} lacks {says:?}");
            assert_eq!(p.core().updates(), 1);
            assert_eq!(p.last_learned("t"), None);
            assert_eq!(std::fs::read(p.path()).expect("read"), before);
        }
        // The same session goes on normally.
        assert!(
            p.learn_sequence("t", 1, &transition(1))
                .expect("learns")
                .is_some()
        );
        assert!(
            p.learn_sequence("t", 2, &transition(2))
                .expect("learns")
                .is_some()
        );
        assert_eq!(p.core().updates(), 3);
    }

    #[test]
    fn no_initial_table_writes_no_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let e = PersistentPolicy::open(
            dir.path(),
            QTableOwner::Cluster(0),
            Learning::default(),
            Mode::Exploit,
            1,
            || Err("pretraining had no run".into()),
        )
        .expect_err("no table");
        assert!(
            e.to_string().contains("cluster_0.json") && e.to_string().contains("no run"),
            "{e}"
        );
        assert_eq!(std::fs::read_dir(dir.path()).expect("lists").count(), 0);
    }
}
