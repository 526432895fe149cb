//! The core on CSV text: rows become messages stamped from OpenFace's clock, lost faces and low
//! confidence are skipped and counted, every bad-row kind is named once with its line number,
//! a rewritten file is not published twice, and a new run starts a new clock.

use super::*;
use crate::test_csv::{header, row};
use qt_therapy_msgs::Validate;

const S: i64 = 1_000_000_000;
const WALL: i64 = 1_800_000_000 * S;

fn params(stamp: StampSource) -> OpenFaceBridgeParams {
    OpenFaceBridgeParams {
        csv_path: "-".into(),
        frame_id: "cam_front".into(),
        stamp: match stamp {
            StampSource::OpenFace => "openface".into(),
            StampSource::Receipt => "receipt".into(),
        },
        ..Default::default()
    }
}

fn bridge(stamp: StampSource, min_confidence: f64) -> Bridge {
    let p = OpenFaceBridgeParams {
        min_confidence,
        ..params(stamp)
    };
    Bridge::new(&p, stamp)
}

/// What one read gave: the log lines, and the messages with the time each was due.
#[derive(Default)]
struct Fed {
    logs: Vec<String>,
    sent: Vec<(i64, OpenFaceFeatures)>,
}

impl Fed {
    fn messages(&self) -> Vec<&OpenFaceFeatures> {
        self.sent.iter().map(|(_, m)| m).collect()
    }

    fn stamps(&self) -> Vec<i64> {
        self.sent
            .iter()
            .map(|(_, m)| m.header.stamp.to_nanos())
            .collect()
    }

    fn logged(&self, text: &str) -> bool {
        self.logs.iter().any(|l| l.contains(text))
    }
}

/// Publishes what is queued, each at the time it is due.
fn drain(b: &mut Bridge, fed: &mut Fed) {
    while let Some(due) = b.next_due_ns() {
        for m in b.due(due) {
            fed.sent.push((due, m));
        }
    }
}

fn keep_logs(fed: &mut Fed, logs: Vec<LogLine>) {
    fed.logs.extend(logs.into_iter().map(|LogLine(_, l)| l));
}

/// Feeds `lines` from line 1, each its own read `lag` after the previous; publishes all.
fn feed(b: &mut Bridge, lines: &[String], from_ns: i64, lag: i64) -> Fed {
    let mut fed = Fed::default();
    for (i, l) in lines.iter().enumerate() {
        let now = from_ns + i as i64 * lag;
        let logs = b.line(l, i as u64 + 1, now).expect("the header maps");
        keep_logs(&mut fed, logs);
        let logs = b.end_of_read(now);
        keep_logs(&mut fed, logs);
    }
    drain(b, &mut fed);
    fed
}

/// Feeds `lines` as one read at `now`.
fn feed_at_once(b: &mut Bridge, lines: &[String], first_line: u64, now: i64) -> Fed {
    let mut fed = Fed::default();
    for (i, l) in lines.iter().enumerate() {
        let logs = b
            .line(l, first_line + i as u64, now)
            .expect("the header maps");
        keep_logs(&mut fed, logs);
    }
    let logs = b.end_of_read(now);
    keep_logs(&mut fed, logs);
    drain(b, &mut fed);
    fed
}

/// A run's header and rows 1..=n at 30 fps from OpenFace time 0.
fn run_of(n: u32) -> Vec<String> {
    std::iter::once(header())
        .chain((1..=n).map(|f| row(f, f64::from(f - 1) / 30.0, 0.9, true)))
        .collect()
}

#[test]
fn rows_become_messages_stamped_from_openfaces_clock() {
    let mut b = bridge(StampSource::OpenFace, 0.0);
    let lines = vec![
        header(),
        row(1, 0.000, 0.98, true),
        row(2, 0.033, 0.97, true),
        row(3, 0.067, 0.96, true),
    ];
    // The bridge reads the rows late and unevenly: the stamps keep OpenFace's spacing.
    let fed = feed(&mut b, &lines, WALL, S / 2);
    let m = fed.messages();
    assert_eq!(m.len(), 3);
    assert_eq!(
        fed.stamps(),
        [
            WALL + S / 2,
            WALL + S / 2 + 33_000_000,
            WALL + S / 2 + 67_000_000
        ]
    );
    assert!(
        m.iter()
            .all(|m| m.header.frame_id == "cam_front" && m.face_id == "0")
    );
    assert!((m[1].confidence - 0.97).abs() < 1e-6);
    // Features in the message's order: pose first (frame / 1000), AU flags 1.
    assert_eq!(m[1].features.len(), 32);
    assert!((m[1].features[0] - 0.002).abs() < 1e-6);
    assert_eq!(m[1].features[6], 1.0, "AU01_c");
    assert!(m.iter().all(|m| m.validate().is_ok()));
    assert_eq!(b.counts().published, 3);

    let mut r = bridge(StampSource::Receipt, 0.0);
    let fed = feed(&mut r, &lines, WALL, S / 2);
    assert_eq!(fed.stamps(), [WALL + S / 2, WALL + S, WALL + 3 * S / 2]);
}

#[test]
fn no_stamp_is_ahead_of_the_clock_when_rows_come_in_late_chunks() {
    // OpenFace's rows reach the file in 8 KiB chunks (RecorderCSV writes "\n", not
    // std::endl, through std::ofstream's buffer): six rows a chunk here, each chunk found a
    // varying while after its last row was written. The offset falls to the smallest lag; no
    // stamp passes the time its row was read; stamps never go back.
    let mut b = bridge(StampSource::OpenFace, 0.0);
    let mut fed = Fed::default();
    keep_logs(&mut fed, b.line(&header(), 1, WALL).expect("header"));
    let delays_ms = [120, 10, 50, 2, 20];
    let mut read_at = Vec::new();
    for (k, delay) in delays_ms.iter().enumerate() {
        let frames = (6 * k as u32 + 1)..=(6 * k as u32 + 6);
        let newest = f64::from(6 * k as u32 + 5) / 30.0;
        let now = WALL + ((newest * 1e3).round() as i64 + delay) * 1_000_000;
        for f in frames {
            let line = row(f, f64::from(f - 1) / 30.0, 0.9, true);
            keep_logs(&mut fed, b.line(&line, u64::from(f) + 1, now).expect("row"));
            read_at.push(now);
        }
        keep_logs(&mut fed, b.end_of_read(now));
    }
    drain(&mut b, &mut fed);
    let stamps = fed.stamps();
    assert_eq!(stamps.len(), 30);
    for (stamp, read) in stamps.iter().zip(&read_at) {
        assert!(stamp <= read, "{stamp} after its read {read}");
    }
    assert!(stamps.windows(2).all(|w| w[0] <= w[1]), "{stamps:?}");
    // From the chunk found 2 ms late on, each stamp is OpenFace's time plus those 2 ms.
    for (k, stamp) in stamps.iter().enumerate().skip(18) {
        let t = (f64::from(k as u32) / 30.0 * 1e3).round() as i64;
        assert_eq!(*stamp, WALL + (t + 2) * 1_000_000, "frame {}", k + 1);
    }
}

#[test]
fn a_backlog_read_at_a_restart_lands_in_the_past_and_only_its_newest_seconds_go_out() {
    // The bridge was restarted 16 s into a run: the file holds 480 rows, read at once. Before,
    // its rows were anchored at the first one and stamped up to 16 s ahead of the clock.
    let p = OpenFaceBridgeParams {
        csv_path: "/tmp/webcam.csv".into(),
        max_backlog_s: 2.0,
        ..params(StampSource::OpenFace)
    };
    let mut b = Bridge::new(&p, StampSource::OpenFace);
    let now = WALL + 100 * S;
    let lines = run_of(480);
    let mut fed = Fed::default();
    for (i, l) in lines.iter().enumerate() {
        keep_logs(&mut fed, b.line(l, i as u64 + 1, now).expect("maps"));
    }
    keep_logs(&mut fed, b.caught_up());
    keep_logs(&mut fed, b.end_of_read(now));
    drain(&mut b, &mut fed);
    let stamps = fed.stamps();
    // 2 s at 30 fps: frames 420..=480 (OpenFace 13.967 s to 15.967 s).
    assert_eq!(stamps.len(), 61, "{:?}", fed.logs);
    assert_eq!(b.counts().backlog_skipped, 419);
    assert_eq!(*stamps.last().expect("one"), now, "the newest row is now");
    assert!(stamps.iter().all(|s| *s <= now));
    assert_eq!(stamps[1] - stamps[0], 33_000_000, "OpenFace's spacing kept");
    assert!(fed.logged("61 rows) published, 419 older rows skipped"));
    // Live rows after it: on the same clock, read promptly.
    let next = row(481, 16.0, 0.9, true);
    let fed = feed_at_once(&mut b, &[next], 482, now + 40_000_000);
    assert_eq!(fed.stamps(), [now + 33_000_000]);
}

#[test]
fn a_burst_is_paced_at_max_publish_hz() {
    let p = OpenFaceBridgeParams {
        max_publish_hz: 250.0,
        ..params(StampSource::OpenFace)
    };
    let mut b = Bridge::new(&p, StampSource::OpenFace);
    // OpenFace stalled, then wrote 100 rows at once.
    let fed = feed_at_once(&mut b, &run_of(100), 1, WALL);
    let due: Vec<i64> = fed.sent.iter().map(|(d, _)| *d).collect();
    assert_eq!(due.len(), 100);
    assert_eq!(due[0], WALL);
    assert!(
        due.windows(2).all(|w| w[1] - w[0] == 4_000_000),
        "4 ms apart"
    );
    // Stamps keep OpenFace's clock, whenever they are published.
    assert_eq!(fed.stamps()[99] - fed.stamps()[0], 3_300_000_000);
    // A queue held back (no reader had matched yet) goes out paced when released, not at
    // once.
    feed_at_once(&mut b, &[header()], 1, WALL + 5 * S);
    let mut held = Bridge::new(&p, StampSource::OpenFace);
    for (i, l) in run_of(10).iter().enumerate() {
        held.line(l, i as u64 + 1, WALL).expect("maps");
    }
    held.end_of_read(WALL);
    let later = WALL + 3 * S;
    assert_eq!(held.due(later).len(), 1, "one now");
    assert_eq!(held.next_due_ns(), Some(later + 4_000_000));
}

#[test]
fn a_replay_is_published_on_openfaces_clock_times_the_rate() {
    let p = OpenFaceBridgeParams {
        csv_path: "/data/session.csv".into(),
        replay_rate: 2.0,
        ..params(StampSource::OpenFace)
    };
    let mut b = Bridge::new(&p, StampSource::OpenFace);
    let mut lines = run_of(4);
    // A lost face is not published but keeps its place on the clock.
    lines[2] = row(2, 1.0 / 30.0, 0.0, false);
    let fed = feed_at_once(&mut b, &lines, 1, WALL);
    let due: Vec<i64> = fed.sent.iter().map(|(d, _)| *d).collect();
    assert_eq!(
        due,
        [WALL, WALL + 33_500_000, WALL + 50_000_000],
        "frames 1, 3, 4 at half OpenFace's time"
    );
    assert_eq!(fed.stamps(), due, "stamped when due");
    assert_eq!(b.counts().backlog_skipped, 0, "a replay has no backlog");
}

#[test]
fn lost_faces_and_low_confidence_are_skipped_and_counted() {
    let mut b = bridge(StampSource::OpenFace, 0.8);
    let lines = vec![
        header(),
        row(1, 0.0, 0.9, true),
        row(2, 0.033, 0.2, false),
        row(3, 0.067, 0.5, true),
        row(4, 0.1, 0.85, true),
    ];
    let fed = feed(&mut b, &lines, WALL, 0);
    assert_eq!(fed.sent.len(), 2);
    let c = b.counts();
    assert_eq!(
        (c.rows, c.published, c.lost_face, c.low_confidence, c.bad),
        (4, 2, 1, 1, 0)
    );
    assert!(
        b.report()
            .starts_with("4 rows: 2 published, 1 without a face, 1 below")
    );
}

#[test]
fn every_bad_row_kind_is_named_once_with_its_line_and_counted() {
    let mut b = bridge(StampSource::OpenFace, 0.0);
    let good = row(1, 0.0, 0.9, true);
    let out = b.line(&good, 1, WALL).expect("not a header");
    assert_eq!(
        texts(&out),
        [
            "skipped a bad OpenFace CSV row at line 1: a row before any header (rows like it are skipped and counted without another word)"
        ]
    );
    feed(&mut b, &[header()], WALL, 0);
    let short: String = good.split(", ").take(40).collect::<Vec<_>>().join(", ");
    let with = |column: usize, value: &str| {
        let mut f: Vec<String> = good.split(", ").map(String::from).collect();
        f[column] = value.to_string();
        f.join(", ")
    };
    let pose_tx = 5 + 8 + 5 * 56;
    let cases = [
        (short.clone(), "40 fields, the header has"),
        (with(pose_tx, "abc"), "pose_Tx = \"abc\" is not a number"),
        (with(pose_tx, "nan"), "pose_Tx = NaN is not finite"),
        (with(4, "0.5"), "success = 0.5 is not 0 or 1"),
        (with(3, "1.7"), "confidence = 1.7 is not in [0, 1]"),
        (with(1, ""), "face_id is empty"),
        ("x".repeat(70_000), "longer than 65536 bytes"),
    ];
    for (k, (line, says)) in cases.iter().enumerate() {
        let line_no = 10 + k as u64;
        let out = b.line(line, line_no, WALL).expect("not a header");
        let told = texts(&out);
        assert_eq!(told.len(), 1, "{says}: {told:?}");
        assert!(
            told[0].contains(&format!("line {line_no}: {says}")),
            "{}",
            told[0]
        );
        // The same kind again: counted, not told again.
        let again = b.line(line, line_no + 100, WALL).expect("not a header");
        assert!(again.is_empty(), "{says}: {again:?}");
    }
    // Another value that is not finite is the same kind: counted without a word.
    assert!(b.line(&with(2, "inf"), 50, WALL).expect("row").is_empty());
    assert_eq!(b.counts().bad, 1 + 2 * cases.len() as u64 + 1);
    assert_eq!(b.queued(), 0, "none of them published");
    // Good rows still flow.
    assert_eq!(feed_at_once(&mut b, &[good], 99, WALL).sent.len(), 1);
}

fn texts(out: &[LogLine]) -> Vec<&str> {
    out.iter().map(|LogLine(_, l)| l.as_str()).collect()
}

#[test]
fn a_header_without_a_needed_column_is_refused_by_name() {
    let mut b = bridge(StampSource::OpenFace, 0.0);
    let no_pose = header().replace("pose_Rz, ", "");
    assert_eq!(
        b.line(&no_pose, 1, WALL),
        Err(HeaderError::Missing("pose_Rz".into()))
    );
}

#[test]
fn a_rewritten_file_is_not_published_twice_and_a_new_run_gets_a_new_clock() {
    let mut b = bridge(StampSource::OpenFace, 0.0);
    let run = run_of(8);
    assert_eq!(feed(&mut b, &run, WALL, S / 30).sent.len(), 8);
    // OpenFace ends and rewrites the file (post-processed AUs), all of it at once: the same
    // frames and timestamps, and two more it had not flushed.
    b.restarted("rewritten in place");
    let mut rewritten = run.clone();
    rewritten.extend((9..=10).map(|f| row(f, f64::from(f - 1) / 30.0, 0.9, true)));
    let fed = feed_at_once(&mut b, &rewritten, 1, WALL + 10 * S);
    assert_eq!(fed.sent.len(), 2, "only frames 9 and 10 are new");
    // Stamped on the first run's clock: each row was read 1/30 s after the one before; the
    // smallest lag between OpenFace's (3-decimal) time and the read was 33.0 ms (frame 3,
    // 0.067 s, read at 0.1 s), and frame 9 is OpenFace's 0.267 s.
    let want = WALL + 33_000_000 + 267_000_000;
    assert!((fed.stamps()[0] - want).abs() < 1_000, "{:?}", fed.stamps());
    assert_eq!(b.counts().already_read, 8);
    assert!(fed.logged("OpenFace rewrote its run"));

    // OpenFace started again on the same video: the same timestamps, but at the camera's
    // pace, so a new run with a new clock.
    b.restarted("truncated");
    let fed = feed(&mut b, &run_of(6), WALL + 60 * S, S / 30);
    let m = fed.stamps();
    assert_eq!(m.len(), 6, "held until five rows decided, then all of them");
    // On a clock of its own: the smallest lag of the new run's rows (33.0 ms, as above).
    assert!((m[0] - (WALL + 60 * S + 33_000_000)).abs() < 1_000, "{m:?}");
    assert_eq!(m[1] - m[0], 33_000_000);

    // A webcam run: other timestamps from its first row on: decided at once.
    b.restarted("truncated");
    let fed = feed(
        &mut b,
        &[header(), row(1, 0.041, 0.95, true)],
        WALL + 90 * S,
        0,
    );
    assert_eq!(fed.sent.len(), 1);
    assert_eq!(b.counts().runs, 4);
    assert_eq!(b.counts().already_read, 8);
}

#[test]
fn a_rewrite_publishes_the_faces_of_a_frame_not_read_before() {
    // Two faces per frame; the bridge had read face 0 of frame 3 but not yet face 1 when
    // OpenFace ended and rewrote its file: face 1 of frame 3 is new, nothing else is.
    let mut b = bridge(StampSource::OpenFace, 0.0);
    let face = |frame: u32, face: u32| {
        row(frame, f64::from(frame - 1) / 30.0, 0.9, true).replacen(
            ", 0, ",
            &format!(", {face}, "),
            1,
        )
    };
    let mut lines = vec![header()];
    for f in 1..=3 {
        lines.push(face(f, 0));
        lines.push(face(f, 1));
    }
    let read = &lines[..6];
    assert_eq!(feed(&mut b, read, WALL, S / 60).sent.len(), 5);
    b.restarted("rewritten in place");
    let fed = feed_at_once(&mut b, &lines, 1, WALL + 5 * S);
    let new: Vec<(String, f32)> = fed
        .messages()
        .iter()
        .map(|m| (m.face_id.clone(), m.features[0]))
        .collect();
    assert_eq!(new, [("1".to_string(), 0.003)]);
    assert_eq!(b.counts().already_read, 5);
}
