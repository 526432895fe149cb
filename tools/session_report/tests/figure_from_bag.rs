//! The report's expected-engagement figure (the paper's Fig. 2) made from bags: its answer
//! crosses, stage lines and curves are read back from the SVG through the figure's own axis
//! labels and compared with the messages in the bag.

use bag_file::{BagReader, BagWriter, WriterOptions};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::topics::{EXPECTED_ENGAGEMENT, GAME_STATE, SEQUENCE_RESULT, TABLET_ANSWER};
use qt_therapy_msgs::{
    BehaviourState, ExpectedEngagement, GameState, MessageDefinition, SequenceResult, TabletAnswer,
};
use session_report::{SessionLog, engagement_figures, engagement_over_time_svg};
use std::path::{Path, PathBuf};

/// What an engagement figure shows, in SVG pixels, as `engagement_classifier::plot` draws it.
mod drawn {
    /// The plot panel ends here; the legend (one sample of each mark) is right of it.
    const LEGEND_X: f64 = 1000.0;
    const SMOOTHED: &str = "#143C96";
    const STAGE_END: &str = "#FF0000";
    const CROSS: &str = "#000000";

    #[derive(Debug, Default)]
    pub struct Figure {
        pub title: String,
        /// (pixel, value) of each labelled tick.
        pub x_ticks: Vec<(f64, f64)>,
        pub y_ticks: Vec<(f64, f64)>,
        /// Centre of each answer cross.
        pub crosses: Vec<(f64, f64)>,
        pub stage_lines: Vec<f64>,
        pub stage_labels: Vec<String>,
        /// Points of the smoothed curve, one run per line drawn.
        pub smoothed: Vec<Vec<(f64, f64)>>,
    }

    fn attr<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
        let start = tag.find(&format!(" {name}=\""))? + name.len() + 3;
        let len = tag[start..].find('"')?;
        Some(&tag[start..start + len])
    }

    fn number(tag: &str, name: &str) -> f64 {
        attr(tag, name)
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no number {name} in {tag}"))
    }

    fn points(tag: &str) -> Vec<(f64, f64)> {
        attr(tag, "points")
            .unwrap_or_default()
            .split_whitespace()
            .map(|p| {
                let (x, y) = p.split_once(',').expect("x,y");
                (x.parse().expect("x"), y.parse().expect("y"))
            })
            .collect()
    }

    pub fn parse(svg: &str) -> Figure {
        let mut f = Figure::default();
        let mut cross_lines = Vec::new();
        for element in svg.split('<').skip(1) {
            let (tag, text) = element.split_once('>').unwrap_or((element, ""));
            let text = text.trim();
            if tag.starts_with("text ") {
                let (x, y) = (number(tag, "x"), number(tag, "y"));
                match (attr(tag, "text-anchor"), text.parse::<f64>()) {
                    (Some("middle"), Ok(v)) => f.x_ticks.push((x, v)),
                    (Some("end"), Ok(v)) => f.y_ticks.push((y, v)),
                    _ if text.starts_with("L = ") && x < LEGEND_X => {
                        f.stage_labels.push(text.to_string())
                    }
                    _ if f.title.is_empty() => f.title = text.to_string(),
                    _ => {}
                }
            } else if tag.starts_with("polyline ") {
                let p = points(tag);
                if p.iter().all(|&(x, _)| x >= LEGEND_X) {
                    continue;
                }
                match attr(tag, "stroke") {
                    Some(SMOOTHED) => f.smoothed.push(p),
                    Some(STAGE_END) => {
                        assert!(p.len() == 2 && p[0].0 == p[1].0, "vertical: {tag}");
                        f.stage_lines.push(p[0].0);
                    }
                    _ => {}
                }
            } else if tag.starts_with("line ")
                && attr(tag, "stroke") == Some(CROSS)
                && attr(tag, "stroke-width") == Some("2")
                && number(tag, "x1") < LEGEND_X
            {
                let (x1, y1, x2, y2) = (
                    number(tag, "x1"),
                    number(tag, "y1"),
                    number(tag, "x2"),
                    number(tag, "y2"),
                );
                cross_lines.push(((x1 + x2) / 2.0, (y1 + y2) / 2.0));
            }
        }
        // A cross is two strokes about one centre.
        assert_eq!(cross_lines.len() % 2, 0, "odd number of cross strokes");
        for pair in cross_lines.chunks(2) {
            assert_eq!(pair[0], pair[1], "the two strokes of a cross");
            f.crosses.push(pair[0]);
        }
        f
    }

    /// Pixel -> value along an axis, through its first and last labelled ticks; and how much
    /// value one pixel is.
    pub fn axis(ticks: &[(f64, f64)]) -> (impl Fn(f64) -> f64 + use<>, f64) {
        assert!(ticks.len() >= 2, "an axis has labelled ticks: {ticks:?}");
        let ((p0, v0), (p1, v1)) = (ticks[0], ticks[ticks.len() - 1]);
        let per_pixel = (v1 - v0) / (p1 - p0);
        (move |p: f64| v0 + (p - p0) * per_pixel, per_pixel.abs())
    }
}

/// Coordinates are whole pixels: a mark may sit half a pixel off, the ticks as well.
const PIXELS: f64 = 1.5;

fn stamp_ns(h: &Header) -> i64 {
    h.stamp.to_nanos()
}

fn read<M: MessageDefinition>(reader: &BagReader, topic: &str) -> Vec<M> {
    reader
        .messages::<M>(topic)
        .unwrap_or_else(|e| panic!("{topic}: {e}"))
        .into_iter()
        .map(|s| s.message)
        .collect()
}

/// The figure's marks against what they should show: one cross per result at (its time, the
/// smoothed value of the nearest second); one red line per stage at its last result, labelled
/// with its sequence length; the smoothed curve through every second with a face at its value,
/// broken where seconds had no face or were not reported.
fn check_figure(
    svg: &str,
    answers: &[(f64, f64)],
    stage_ends: &[(f64, u8)],
    smoothed: &[Vec<(f64, f64)>],
) -> drawn::Figure {
    let f = drawn::parse(svg);
    let (x_of, x_per_px) = drawn::axis(&f.x_ticks);
    let (y_of, y_per_px) = drawn::axis(&f.y_ticks);
    let (x_tol, y_tol) = (PIXELS * x_per_px, PIXELS * y_per_px);

    assert_eq!(f.crosses.len(), answers.len(), "one cross per answer");
    for (&(px, py), &(t, v)) in f.crosses.iter().zip(answers) {
        assert!(
            (x_of(px) - t).abs() <= x_tol && (y_of(py) - v).abs() <= y_tol,
            "cross at ({}, {}), answer at ({t}, {v})",
            x_of(px),
            y_of(py)
        );
    }

    assert_eq!(f.stage_lines.len(), stage_ends.len(), "one line per stage");
    for (&px, &(t, _)) in f.stage_lines.iter().zip(stage_ends) {
        assert!(
            (x_of(px) - t).abs() <= x_tol,
            "stage line at {} s, stage end at {t} s",
            x_of(px)
        );
    }
    let labels: Vec<String> = stage_ends.iter().map(|(_, n)| format!("L = {n}")).collect();
    assert_eq!(f.stage_labels, labels);

    let run_lengths = |runs: &[Vec<(f64, f64)>]| runs.iter().map(Vec::len).collect::<Vec<_>>();
    assert_eq!(
        run_lengths(&f.smoothed),
        run_lengths(smoothed),
        "one line per run of seconds with a face, one point per second"
    );
    for (&(px, py), &(t, v)) in f.smoothed.iter().flatten().zip(smoothed.iter().flatten()) {
        assert!(
            (x_of(px) - t).abs() <= x_tol && (y_of(py) - v).abs() <= y_tol,
            "curve point ({}, {}) for the second at {t} s, smoothed {v}",
            x_of(px),
            y_of(py)
        );
    }
    f
}

fn sample_bag(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../bags")
        .join(name)
}

/// A recorded session (bags/README.md: cluster 1, 10 sequences, level 2, then 3 from the
/// therapist's override and once more from the policy, with challenging feedback, then 2
/// again). Every mark of its figure is checked against the bag's
/// own messages, read here without `SessionLog`.
#[test]
fn the_figure_of_a_recorded_session_shows_its_answers_and_stages() {
    let reader = BagReader::open(&sample_bag("cluster1_seed11_pause_override.mcap"))
        .and_then(BagReader::strict)
        .expect("the sample bag reads");
    let results: Vec<SequenceResult> = read(&reader, SEQUENCE_RESULT.name);
    let answers: Vec<TabletAnswer> = read(&reader, TABLET_ANSWER.name);
    let seconds: Vec<ExpectedEngagement> = read(&reader, EXPECTED_ENGAGEMENT.name);
    assert_eq!(results.len(), 10);
    assert!(
        results
            .iter()
            .all(|r| r.session_id == results[0].session_id)
    );
    let levels: Vec<u8> = results.iter().map(|r| r.level).collect();
    assert_eq!(levels, [2, 2, 3, 3, 2, 2, 2, 2, 2, 2]);

    let log = SessionLog::from_bag(&reader, None).expect("decodes");
    let figures = engagement_figures(&log);
    assert_eq!(figures.len(), 1, "one camera in the simulated session");
    let figure = &figures[0];
    assert!(seconds.iter().all(|e| e.source == figure.source));
    let t = |ns: i64| (ns - figure.start_ns) as f64 / 1e9;

    // The answers: each result's time, just after the child's answer reached the game
    // manager (here within 11 ms), and before the next answer.
    let want_answers: Vec<f64> = results.iter().map(|r| t(stamp_ns(&r.header))).collect();
    assert_eq!(figure.answers, want_answers);
    assert_eq!(answers.len(), results.len());
    for (r, a) in results.iter().zip(&answers) {
        assert_eq!(a.sequence_id, u32::from(r.sequence_index));
        let after = (stamp_ns(&r.header) - stamp_ns(&a.header)) as f64 / 1e9;
        assert!(
            (0.0..0.5).contains(&after),
            "result {after} s after the answer"
        );
    }
    // The stages end with sequences 2 (level 2), 4 (level 3) and 10 (level 2).
    let end_of = |sequence: usize, length: u8| (want_answers[sequence - 1], length);
    let want_stages = [end_of(2, 5), end_of(4, 7), end_of(10, 5)];
    assert_eq!(figure.stage_ends, want_stages);
    // The curve: the bag's seconds in the session's span, those with a face at their value.
    let first = stamp_ns(&log.states[0].header);
    let last = stamp_ns(&results[9].header);
    let in_session: Vec<&ExpectedEngagement> = seconds
        .iter()
        .filter(|e| e.window_end.to_nanos() >= first && e.window_start.to_nanos() <= last)
        .collect();
    assert_eq!(figure.seconds.len(), in_session.len());
    assert!(in_session.len() >= 60, "{} seconds", in_session.len());
    let mut want_curve: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    let mut previous = None;
    for e in &in_session {
        let start = t(e.window_start.to_nanos());
        let silent = previous.is_some_and(|p: f64| start - p > 1.5);
        previous = Some(start);
        if (!e.has_faces || silent) && want_curve.last().is_some_and(|r| !r.is_empty()) {
            want_curve.push(Vec::new());
        }
        if e.has_faces {
            want_curve
                .last_mut()
                .expect("a run")
                .push((start, f64::from(e.smoothed)));
        }
    }
    want_curve.retain(|r| !r.is_empty());

    // A cross sits on the smoothed value of the second nearest its time (the later one on a
    // tie), on 0 when that second had no face.
    let on_curve = |at: f64| {
        let nearest = in_session
            .iter()
            .map(|e| (t(e.window_start.to_nanos()), e))
            .min_by(|(a, _), (b, _)| {
                (a - at)
                    .abs()
                    .total_cmp(&(b - at).abs())
                    .then(b.total_cmp(a))
            })
            .map(|(_, e)| e)
            .expect("seconds");
        if nearest.has_faces {
            f64::from(nearest.smoothed)
        } else {
            0.0
        }
    };
    let crosses: Vec<(f64, f64)> = want_answers.iter().map(|&a| (a, on_curve(a))).collect();

    let svg = engagement_over_time_svg(figure, "recorded session").expect("draws");
    let drawn = check_figure(&svg, &crosses, &want_stages, &want_curve);
    assert_eq!(drawn.title, "recorded session");
}

fn at(ns: i64) -> Header {
    Header::at(Time::from_nanos(ns))
}

const S: i64 = 1_000_000_000;

fn state(session: &str, ns: i64) -> GameState {
    GameState {
        header: at(ns),
        session_id: session.into(),
        user_id: "child-9".into(),
        ..Default::default()
    }
}

fn result(session: &str, index: u8, level: u8, ns: i64) -> SequenceResult {
    let emotions = vec!["happy".to_string(); usize::from(2 * level + 1)];
    SequenceResult {
        header: at(ns),
        session_id: session.into(),
        user_id: "child-9".into(),
        sequence_index: index,
        state: BehaviourState {
            level: if index == 1 { 0 } else { level },
            feedback: 0,
            previous_score: 0,
        },
        action: level - 1,
        level,
        sequence: emotions.clone(),
        answer: emotions,
        outcome: 1,
        activity_result: f32::from(level),
        response_time: 2.0,
        ..Default::default()
    }
}

fn second(source: &str, sec: i64, has_faces: bool, mean: f32) -> ExpectedEngagement {
    ExpectedEngagement {
        header: at((sec + 1) * S),
        source: source.into(),
        window_start: Time::from_nanos(sec * S),
        window_end: Time::from_nanos((sec + 1) * S),
        has_faces,
        mean,
        smoothed: mean / 2.0,
        frame_count: if has_faces { 30 } else { 0 },
        missing_count: if has_faces { 0 } else { 30 },
    }
}

/// A bag written here: an earlier session, then session s-2 seen by two cameras whose seconds
/// interleave ("front/0" engaged from the start; "side/0" disengaged from 4 s, without a face
/// at 7 s, silent at 10 s). `session_report` on it draws one figure per camera, each with only
/// its own seconds, and both with the session's answers and stage ends on one time axis.
#[test]
fn the_report_of_a_bag_with_two_cameras_draws_each_on_its_own() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("two_cameras.mcap");
    let t0 = 1_000 * S;
    let results = [
        result("s-2", 1, 1, t0 + 3_200_000_000),
        result("s-2", 2, 1, t0 + 6_700_000_000),
        result("s-2", 3, 2, t0 + 10_100_000_000),
        result("s-2", 4, 2, t0 + 12_500_000_000),
    ];
    {
        let mut w = BagWriter::create(&path, &WriterOptions::default()).expect("creates");
        let states = w.add_topic(GAME_STATE).expect("topic");
        let results_topic = w.add_topic(SEQUENCE_RESULT).expect("topic");
        let seconds = w.add_topic(EXPECTED_ENGAGEMENT).expect("topic");
        let log = |ns: i64| u64::try_from(ns).expect("after the epoch");
        // Session s-1: its seconds, strongly disengaged, must not reach s-2's figures.
        w.write(states, log(985 * S), &state("s-1", 985 * S))
            .expect("writes");
        for sec in 985..998 {
            w.write(
                seconds,
                log((sec + 1) * S),
                &second("front/0", sec, true, -0.9),
            )
            .expect("writes");
        }
        w.write(results_topic, log(990 * S), &result("s-1", 1, 3, 990 * S))
            .expect("writes");
        w.write(states, log(t0), &state("s-2", t0)).expect("writes");
        let mut next_result = results.iter().peekable();
        for sec in 1_000..1_013 {
            while let Some(r) = next_result.next_if(|r| stamp_ns(&r.header) < sec * S) {
                w.write(results_topic, log(stamp_ns(&r.header)), r)
                    .expect("writes");
            }
            w.write(
                seconds,
                log((sec + 1) * S),
                &second("front/0", sec, true, 0.6),
            )
            .expect("writes");
            if sec >= 1_004 && sec != 1_010 {
                w.write(
                    seconds,
                    log((sec + 1) * S),
                    &second("side/0", sec, sec != 1_007, -0.4),
                )
                .expect("writes");
            }
        }
        for r in next_result {
            w.write(results_topic, log(stamp_ns(&r.header)), r)
                .expect("writes");
        }
        let end = stamp_ns(&results[3].header);
        w.write(states, log(end), &state("s-2", end))
            .expect("writes");
        w.finish().expect("finishes");
    }

    let html_path = dir.path().join("report.html");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_session_report"))
        .arg(&path)
        .arg("--output")
        .arg(&html_path)
        .output()
        .expect("session_report runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("session s-2: 4 sequences"), "{stdout}");
    let html = std::fs::read_to_string(&html_path).expect("report written");
    let svgs: Vec<&str> = html
        .split("<svg")
        .skip(1)
        .map(|s| s.split("</svg>").next().unwrap_or_default())
        .collect();
    assert_eq!(svgs.len(), 3, "levels, then one figure per camera");

    // Time zero is s-2's first state; s-1's seconds end before it.
    let stage_ends = [(6.7, 3), (12.5, 5)];
    let front = vec![(0..13).map(|s| (f64::from(s), 0.3)).collect::<Vec<_>>()];
    let side_run = |seconds: &[i32]| seconds.iter().map(|&s| (f64::from(s), -0.2)).collect();
    let side: Vec<Vec<(f64, f64)>> =
        vec![side_run(&[4, 5, 6]), side_run(&[8, 9]), side_run(&[11, 12])];
    // Crosses on each camera's own curve: "side/0" at 3.2 s takes its first second (4 s), at
    // 6.7 s its second without a face (7 s), so 0, and at 10.1 s the reported second 11 s.
    let front_crosses = [(3.2, 0.3), (6.7, 0.3), (10.1, 0.3), (12.5, 0.3)];
    let side_crosses = [(3.2, -0.2), (6.7, 0.0), (10.1, -0.2), (12.5, -0.2)];
    for (svg, source, crosses, curve) in [
        (svgs[1], "front/0", &front_crosses, &front),
        (svgs[2], "side/0", &side_crosses, &side),
    ] {
        let drawn = check_figure(svg, crosses, &stage_ends, curve);
        assert!(drawn.title.ends_with(source), "{}", drawn.title);
    }
    let front_at = html
        .find("Expected engagement of front/0")
        .expect("front heading");
    let side_at = html
        .find("Expected engagement of side/0")
        .expect("side heading");
    assert!(front_at < side_at);
    assert!(html.contains("front/0</h2><p>13 of 13 seconds with a face"));
    assert!(html.contains("side/0</h2><p>7 of 8 seconds with a face"));
}
