//! A session a killed game manager left unfinished, taken over from its files: paused and
//! silent until the therapist's resume, then on as if never interrupted; damaged files used as
//! far as they are whole; no command carried out and no task id sent twice; a finished
//! session left alone.

use super::harness::*;
use crate::game::RECOVERED_STATUS;
use crate::params::GameManagerParams;
use crate::protocol::Output;
use crate::recovery::{RecoveredSession, choose, recover_session};
use crate::session_file::{JournalCommand, JournalEntry, SessionEnd, SessionFiles};
use qt_therapy_msgs::{GameState, SequenceResult, TherapistCommand as C};
use sequence_game::{Action, Level};

fn child() -> Box<dyn FnMut(&qt_therapy_msgs::TabletTask) -> ChildReply> {
    scripted_child(vec![(3, ChildReply::Wrong { after_s: 7.0 })])
}

/// Session "s" up to the crash: four sequences scored, the fifth's task on the tablet, an
/// override for sequence 6, a pause and a resume (command ids 1..4).
fn play_until_the_crash() -> Harness {
    let mut h = Harness::new(GameManagerParams::default(), rule_policy(), child());
    h.start("s");
    h.run_until_true(600.0, |h| h.records().len() == 4 && h.tasks().len() == 5);
    h.feed(override_to(1, "s", 2));
    h.feed(cmd(C::PAUSE, "s", 3));
    h.run_until(h.now + 2 * S);
    h.feed(cmd(C::RESUME, "s", 4));
    h.run_until(h.now + S);
    // The child answers 5 s after the task: sequence 5 is still open.
    assert_eq!(h.records().len(), 4);
    h
}

/// What a result says about the game (not its times).
fn played(r: &SequenceResult) -> String {
    format!(
        "{} L{} F{} state {:?} said {:?} tapped {:?} O{} overridden {}",
        r.sequence_index,
        r.level,
        r.feedback,
        r.state,
        r.sequence,
        r.answer,
        r.outcome,
        r.overridden
    )
}

fn recovered(h: &Harness) -> RecoveredSession {
    let (records, journal) = h.file_texts();
    recover_session("s", &records, &journal).expect("recoverable")
}

#[test]
fn a_killed_session_comes_back_paused_and_goes_on_as_if_never_interrupted() {
    // The same inputs without the crash: what the session should become.
    let mut whole = play_until_the_crash();
    whole.run(3600.0);
    let whole_results = whole.results();
    assert_eq!(whole_results.len(), 10);

    let crashed = play_until_the_crash();
    let said_before_the_crash = crashed.heard();
    let task5 = &crashed.tasks()[4].1;
    assert_eq!(
        said_before_the_crash.len(),
        usize::from(task5.length),
        "sequence 5 was said"
    );
    // Written before it was published: the journal entry of a task or command precedes it.
    let log: Vec<&Output> = crashed.outputs().collect();
    for (i, o) in log.iter().enumerate() {
        if let Output::Task(t) = o {
            assert!(log[..i].iter().any(|o| matches!(o, Output::Journal(e)
                if matches!(**e, JournalEntry::Task { task_id, .. } if task_id == t.sequence_id))));
        }
    }
    let r = recovered(&crashed);
    assert_eq!(
        (
            r.records.len(),
            r.next_index(),
            r.last_command_id,
            r.last_task_id,
            r.pending_override,
            r.started_ns,
        ),
        (4, 5, 4, 5, Some((6, Action::SetLevel(Level::ONE))), T0)
    );
    assert!(r.damage.is_empty(), "{:?}", r.damage);
    assert_eq!(r.user_id, "child-1");

    let restart = crashed.now + 30 * S;
    let mut h = Harness::recovering(
        GameManagerParams::default(),
        rule_policy(),
        child(),
        r,
        restart,
    );
    // Silence first, then the paused session with the reason.
    assert_eq!(h.log[0].1, Output::Silence);
    let s = h.last_state();
    assert_eq!(
        (
            s.phase,
            s.session_id.as_str(),
            s.sequence_index,
            s.user_id.as_str()
        ),
        (GameState::PAUSED, "s", 5, "child-1")
    );
    assert!(s.status.starts_with(RECOVERED_STATUS), "{}", s.status);
    assert!(
        h.outputs()
            .any(|o| matches!(o, Output::Alarm(l) if l.contains("4 of 10 sequences kept")))
    );
    // Nothing happens until the therapist resumes: no robot act, no task, no policy call.
    let quiet_from = h.log.len();
    h.run_until(h.now + 120 * S);
    assert!(h.robot_outputs_since(1).is_empty());
    assert!(h.tasks().is_empty());
    assert!(!h.outputs().any(|o| matches!(o, Output::Decide { .. })));
    assert_eq!(h.log.len(), quiet_from);

    // Commands carried out before the crash, delivered again: none is carried out twice.
    for (again, why) in [
        (
            cmd(C::START, "s", 1),
            "stale command id 1 (last accepted 4)",
        ),
        (override_to(1, "s", 2), "stale command id 2"),
        (cmd(C::PAUSE, "s", 3), "stale command id 3"),
        (cmd(C::RESUME, "s", 4), "duplicate command id 4"),
    ] {
        h.feed(again);
        let s = h.last_state();
        assert!(
            s.status.starts_with("rejected") && s.status.contains(why),
            "{}",
            s.status
        );
        assert_eq!(s.phase, GameState::PAUSED);
    }
    assert_eq!(h.journal().len(), 1, "only the recovery is journalled");
    assert!(h.tasks().is_empty() && h.robot_outputs_since(1).is_empty());

    h.feed(cmd(C::RESUME, "s", 5));
    assert!(h.last_state().status.contains("resumed (command 5)"));
    h.run(3600.0);
    let results = h.results();
    let indices: Vec<u8> = results.iter().map(|r| r.sequence_index).collect();
    assert_eq!(indices, vec![5, 6, 7, 8, 9, 10]);
    // The interrupted sequence is said again from its start, the same emotions.
    assert_eq!(results[0].sequence, said_before_the_crash);
    // The override set before the crash is used once, for sequence 6.
    assert!(results[1].overridden && results[1].level == 1);
    // Same state, same draws, same decisions: the rest is what the uninterrupted run played.
    let rest: Vec<String> = results.iter().map(played).collect();
    let expected: Vec<String> = whole_results[4..].iter().map(played).collect();
    assert_eq!(rest, expected);
    // Fresh task ids: the tablets ignore one they saw (task 5 went out before the crash).
    let ids: Vec<u32> = h.tasks().iter().map(|(_, t)| t.sequence_id).collect();
    assert_eq!(ids, vec![6, 7, 8, 9, 10, 11]);
    let summary = &h.summaries()[0];
    let whole_summary = &whole.summaries()[0];
    assert_eq!(summary.end, SessionEnd::Finished);
    assert_eq!(
        (
            summary.sequences_played,
            summary.score,
            summary.max_score,
            summary.overrides,
            summary.started_ns
        ),
        (10, whole_summary.score, whole_summary.max_score, 1, T0)
    );
}

#[test]
fn a_torn_last_line_and_damaged_lines_are_named_and_the_whole_ones_used() {
    let crashed = play_until_the_crash();
    let (records, journal) = crashed.file_texts();
    let lines: Vec<&str> = records.lines().collect();

    // A crash mid-write: half of a fifth line, no newline.
    let torn = format!("{records}{}", &lines[3][..lines[3].len() / 2]);
    let torn_journal = format!("{journal}{{\"entry\":\"comm");
    let r = recover_session("s", &torn, &torn_journal).expect("recoverable");
    assert_eq!(
        (r.records.len(), r.next_index(), r.last_command_id),
        (4, 5, 4)
    );
    assert_eq!(r.damage.len(), 2, "{:?}", r.damage);
    assert!(
        r.damage[0].starts_with("s.jsonl line 5: torn"),
        "{:?}",
        r.damage
    );
    assert!(r.damage[1].starts_with("s.journal line "), "{:?}", r.damage);
    let mut h = Harness::recovering(
        GameManagerParams::default(),
        rule_policy(),
        child(),
        r,
        crashed.now + S,
    );
    let warnings = h.warnings();
    assert!(
        warnings.iter().any(|w| w.contains("s.jsonl line 5: torn")),
        "{warnings:?}"
    );
    assert!(
        h.last_state()
            .status
            .contains("2 damaged or doubtful line(s)")
    );
    h.feed(cmd(C::RESUME, "s", 5));
    h.run(3600.0);
    assert_eq!(h.results().len(), 6);
    assert_eq!(h.summaries()[0].sequences_played, 10);

    // A damaged middle line, a line of another session and a repeated sequence: each named,
    // the rest used; the state comes from the last scored sequence.
    let mut other: serde_json::Value = serde_json::from_str(lines[2]).expect("json");
    other["result"]["session_id"] = "another".into();
    let damaged = format!(
        "{}\n{{\"result\": 17\n{}\n{}\n{}\n{}\n",
        lines[0], lines[2], other, lines[2], lines[3]
    );
    let r = recover_session("s", &damaged, &journal).expect("recoverable");
    let indices: Vec<u8> = r.records.iter().map(|x| x.result.sequence_index).collect();
    assert_eq!(indices, vec![1, 3, 4]);
    let named: Vec<&str> = r.damage.iter().map(String::as_str).collect();
    assert!(
        named[0].starts_with("s.jsonl line 2: not a valid line"),
        "{named:?}"
    );
    assert!(
        named[1].starts_with("s.jsonl line 4: for session \"another\""),
        "{named:?}"
    );
    assert!(
        named[2].starts_with("s.jsonl line 5: sequence 3 again"),
        "{named:?}"
    );
    assert!(named[3].contains("sequence 2 is missing"), "{named:?}");
    assert_eq!(r.next_index(), 5);
    let h = Harness::recovering(
        GameManagerParams::default(),
        rule_policy(),
        child(),
        r,
        crashed.now + S,
    );
    let s = h.last_state();
    let fourth = &crashed.results()[3];
    assert_eq!(
        (s.phase, s.sequence_index, s.level, s.last_score),
        (
            GameState::PAUSED,
            5,
            fourth.level,
            (fourth.level as i8) * fourth.outcome
        )
    );
    assert!(
        h.warnings()
            .iter()
            .any(|w| w.contains("sequences from here on are drawn afresh"))
    );

    // A file of garbage after the good lines: named, but not line by line without end.
    let garbage = format!("{records}{}", "not json\n".repeat(500));
    let r = recover_session("s", &garbage, &journal).expect("recoverable");
    assert_eq!((r.records.len(), r.damage.len()), (4, 50));
    assert_eq!(r.damage[49], "... and 451 more damaged or doubtful lines");

    // Files without a session in them are not recovered, and say why.
    let none = recover_session("x", "garbage\n", "{\"entry\":\"task\"").expect_err("nothing");
    assert!(none.contains("names a session"), "{none}");
}

#[test]
fn the_files_are_only_appended_to_and_the_same_session_goes_on_in_them() {
    let dir = tempfile::tempdir().expect("temp dir");
    let crashed = play_until_the_crash();
    let mut files = SessionFiles::new(dir.path());
    for o in crashed.outputs() {
        match o {
            Output::Record(r) => {
                files.append(r).expect("append");
            }
            Output::Journal(e) => {
                files.append_journal(e).expect("journal");
            }
            _ => {}
        }
    }
    // The crash tears the last line.
    let jsonl = dir.path().join("s.jsonl");
    let mut text = std::fs::read_to_string(&jsonl).expect("read");
    text.push_str("{\"result\":{\"session_id\":\"s\",\"seq");
    std::fs::write(&jsonl, &text).expect("write");

    let scan = SessionFiles::new(dir.path()).scan();
    assert!(scan.finished_ids.is_empty() && scan.problems.is_empty());
    assert_eq!(scan.unfinished.len(), 1);
    let u = &scan.unfinished[0];
    let r = recover_session(&u.stem, &u.records, &u.journal).expect("recoverable");
    assert_eq!((r.stem.as_str(), r.records.len()), ("s", 4));

    let mut files = SessionFiles::new(dir.path());
    files.adopt(&r.session_id, &r.stem);
    let mut h = Harness::recovering(
        GameManagerParams::default(),
        rule_policy(),
        child(),
        r,
        crashed.now + S,
    );
    h.feed(cmd(C::RESUME, "s", 5));
    h.run(3600.0);
    for o in h.outputs() {
        match o {
            Output::Record(r) => {
                files.append(r).expect("append");
            }
            Output::Journal(e) => {
                files.append_journal(e).expect("journal");
            }
            Output::Summary(s) => {
                files.write_summary(s).expect("summary");
            }
            _ => {}
        }
    }
    // Appended: what was there is still there, byte for byte; the torn line is ended so
    // the next record is a line of its own.
    let after = std::fs::read_to_string(&jsonl).expect("read");
    assert!(after.starts_with(&text));
    let r = recover_session("s", &after, "").expect("readable");
    let indices: Vec<u8> = r.records.iter().map(|x| x.result.sequence_index).collect();
    assert_eq!(indices, (1..=10).collect::<Vec<u8>>());
    assert_eq!(r.damage.len(), 2, "{:?}", r.damage);
    assert!(r.damage[0].starts_with("s.jsonl line 5: not a valid line"));
    // One session, one set of files, now finished: a later start-up leaves it alone.
    let mut names: Vec<String> = std::fs::read_dir(dir.path())
        .expect("dir")
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().to_string())
        .collect();
    names.sort();
    assert_eq!(names, vec!["s.journal", "s.jsonl", "s.summary.json"]);
    let scan = SessionFiles::new(dir.path()).scan();
    assert_eq!(scan.finished_ids, vec!["s".to_string()]);
    assert!(scan.unfinished.is_empty());
    let journal = std::fs::read_to_string(dir.path().join("s.journal")).expect("journal");
    assert!(journal.contains("\"entry\":\"recovered\""));
}

#[test]
fn a_finished_session_is_not_recovered_and_its_id_is_not_started_again() {
    let mut whole = play_until_the_crash();
    whole.run(3600.0);
    // Killed after the last record, before the summary: the restart writes the summary.
    let (records, journal) = whole.file_texts();
    let r = recover_session("s", &records, &journal).expect("recoverable");
    assert_eq!(r.next_index(), 11);
    let mut h = Harness::recovering(
        GameManagerParams::default(),
        rule_policy(),
        child(),
        r,
        whole.now + S,
    );
    assert_eq!(h.last_state().phase, GameState::FINISHED);
    let summary = &h.summaries()[0];
    assert_eq!(
        (summary.end, summary.sequences_played, summary.score),
        (SessionEnd::Finished, 10, whole.summaries()[0].score)
    );
    assert!(h.journal().is_empty());
    h.feed(cmd(C::START, "s", 9));
    assert!(
        h.last_state()
            .status
            .contains("this session id was already used")
    );

    // With its summary the session is finished: a scan leaves it out of the unfinished ones,
    // and its id (like any found there) cannot be started again.
    let dir = tempfile::tempdir().expect("temp dir");
    let mut files = SessionFiles::new(dir.path());
    for o in whole.outputs() {
        match o {
            Output::Record(r) => drop(files.append(r).expect("append")),
            Output::Journal(e) => drop(files.append_journal(e).expect("journal")),
            Output::Summary(s) => drop(files.write_summary(s).expect("summary")),
            _ => {}
        }
    }
    std::fs::write(dir.path().join("junk.summary.json"), "{").expect("write");
    let scan = files.scan();
    assert_eq!(scan.finished_ids, vec!["s".to_string()]);
    assert!(scan.unfinished.is_empty());
    assert_eq!(scan.problems.len(), 1, "{:?}", scan.problems);
    let mut fresh = Harness::new(GameManagerParams::default(), rule_policy(), child());
    fresh.gm.remember_sessions(scan.finished_ids);
    fresh.start("s");
    assert!(
        fresh
            .last_state()
            .status
            .contains("this session id was already used")
    );
}

#[test]
fn a_session_killed_before_its_first_result_comes_back_from_its_journal() {
    let mut h = Harness::new(GameManagerParams::default(), rule_policy(), child());
    h.start("s");
    h.run_until(T0 + 3 * S); // still introducing itself
    let (records, journal) = h.file_texts();
    assert!(records.is_empty());
    let r = recover_session("s", &records, &journal).expect("the start entry is enough");
    assert_eq!(
        (r.next_index(), r.last_command_id, r.user_id.as_str()),
        (1, 1, "child-1")
    );
    let mut h = Harness::recovering(
        GameManagerParams::default(),
        rule_policy(),
        child(),
        r,
        h.now + S,
    );
    assert_eq!(h.last_state().phase, GameState::PAUSED);
    h.feed(cmd(C::RESUME, "s", 2));
    h.run(3600.0);
    assert_eq!(h.results().len(), 10);
    assert_eq!(h.summaries()[0].started_ns, T0);
}

#[test]
fn the_newest_recent_unfinished_session_is_taken_over_and_the_others_left() {
    let crashed = play_until_the_crash();
    let base = recovered(&crashed);
    let at = |id: &str, activity: i64| RecoveredSession {
        session_id: id.into(),
        stem: id.into(),
        last_activity_ns: activity,
        ..base.clone()
    };
    let now = 10_000 * S;
    let (chosen, left) = choose(
        vec![
            at("old", now - 7200 * S),
            at("new", now - 5 * S),
            at("mid", now - 60 * S),
        ],
        now,
        3600.0,
    );
    assert_eq!(chosen.map(|c| c.session_id), Some("new".to_string()));
    assert_eq!(left.len(), 2);
    assert!(left[0].contains("\"mid\"") && left[0].contains("a newer unfinished session"));
    assert!(left[1].contains("\"old\"") && left[1].contains("7200 s ago"));
    let (chosen, left) = choose(vec![at("new", now - 5 * S)], now, 0.0);
    assert!(chosen.is_none() && left.len() == 1);
    // A therapist's resume is journalled with its id, before it takes effect.
    let resume = crashed.journal().into_iter().find(|e| {
        matches!(
            e,
            JournalEntry::Command {
                command: JournalCommand::Resume,
                ..
            }
        )
    });
    assert!(matches!(
        resume,
        Some(JournalEntry::Command { command_id: 4, .. })
    ));
}

#[test]
fn a_feedback_override_set_before_the_crash_survives_it() {
    let mut h = Harness::new(
        GameManagerParams::default(),
        rule_policy(),
        scripted_child(vec![]),
    );
    h.start("s");
    h.run_until(T0 + 15 * S); // sequence 1 waits for its answer
    h.feed(cmd(C::OVERRIDE_CHALLENGING, "s", 2));
    let r = recovered(&h);
    assert_eq!(r.pending_override, Some((2, Action::Challenge)));
    assert_eq!(r.last_command_id, 2);
    // Taken over: sequence 2 gets the challenge once the therapist resumes.
    h.run(3600.0);
    let whole = h.results();
    let mut again = Harness::recovering(
        GameManagerParams::default(),
        rule_policy(),
        scripted_child(vec![]),
        recovered_after_first(&whole),
        T0 + 100 * S,
    );
    again.feed(cmd(C::RESUME, "s", 3));
    again.run(3600.0);
    let r2 = &again.results()[0];
    assert_eq!(
        (r2.sequence_index, r2.action, r2.feedback, r2.overridden),
        (2, 4, 2, true)
    );
}

/// The files of a session killed right after its first sequence was scored, with the
/// challenge for sequence 2 journalled.
fn recovered_after_first(whole: &[SequenceResult]) -> RecoveredSession {
    let mut h = Harness::new(
        GameManagerParams::default(),
        rule_policy(),
        scripted_child(vec![]),
    );
    h.start("s");
    h.run_until(T0 + 15 * S);
    h.feed(cmd(C::OVERRIDE_CHALLENGING, "s", 2));
    h.run_until_true(60.0, |h| !h.results().is_empty());
    assert_eq!(h.results()[0], whole[0]);
    recovered(&h)
}
