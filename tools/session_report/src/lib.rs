//! The session report: what happened in one session, for the therapist and the researcher.
//! It takes the messages a session produced (from a bag or live), and writes one
//! self-contained HTML page with plots: level and score per sequence, expected engagement over
//! time with the answers and stage ends (the paper's Fig. 2; one figure per camera / face),
//! and every decision with its Q-values and whether the robot explored.

use figures::engagement::{EngagementPlot, engagement_svg};
use plotters::prelude::*;
use qt_therapy_msgs::{Decision, ExpectedEngagement, GameState, SequenceResult, Tally};
use std::fmt::Write as _;

/// Why a report could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("the session has no sequence results: nothing to report")]
    Empty,
    #[error("drawing the {figure} figure: {reason}")]
    Draw {
        figure: &'static str,
        reason: String,
    },
}

/// The messages of one session, in the order they were logged.
#[derive(Debug, Clone, Default)]
pub struct SessionLog {
    pub results: Vec<SequenceResult>,
    pub engagement: Vec<ExpectedEngagement>,
    pub decisions: Vec<Decision>,
    pub states: Vec<GameState>,
}

/// Totals shown at the top of the report.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub session_id: String,
    pub user_id: String,
    pub cluster: i32,
    /// Sequences, right answers, timeouts, score L·O out of the best possible, engagement.
    pub tally: Tally,
    pub overrides: usize,
    pub policy_fallbacks: usize,
    pub explored: usize,
}

impl SessionLog {
    /// The session's messages from a bag (topics missing from the bag are empty). With
    /// `session` set, only that session; otherwise the last session in the bag.
    pub fn from_bag(
        reader: &bag_file::BagReader,
        session: Option<&str>,
    ) -> Result<SessionLog, bag_file::BagError> {
        use qt_therapy_msgs::topics::{DECISION, EXPECTED_ENGAGEMENT, GAME_STATE, SEQUENCE_RESULT};
        let results: Vec<SequenceResult> = reader.topic_messages(SEQUENCE_RESULT)?;
        let wanted = session
            .map(str::to_string)
            .or_else(|| results.last().map(|r| r.session_id.clone()))
            .unwrap_or_default();
        let mut log = SessionLog {
            results: results
                .into_iter()
                .filter(|r| r.session_id == wanted)
                .collect(),
            decisions: reader
                .topic_messages(DECISION)?
                .into_iter()
                .filter(|d| d.session_id == wanted)
                .collect(),
            states: reader
                .topic_messages(GAME_STATE)?
                .into_iter()
                .filter(|s| s.session_id == wanted)
                .collect(),
            engagement: reader.topic_messages(EXPECTED_ENGAGEMENT)?,
        };
        // Engagement carries no session id: keep the seconds of this session's time span.
        let start = log.states.first().map(|s| s.header.stamp.to_nanos());
        let end = log.states.last().map(|s| s.header.stamp.to_nanos());
        if let (Some(start), Some(end)) = (start, end) {
            log.engagement
                .retain(|e| e.window_end.to_nanos() >= start && e.window_start.to_nanos() <= end);
        }
        Ok(log)
    }

    pub fn summary(&self) -> Result<Summary, ReportError> {
        let first = self.results.first().ok_or(ReportError::Empty)?;
        Ok(Summary {
            session_id: first.session_id.clone(),
            user_id: first.user_id.clone(),
            cluster: first.user_model_cluster,
            tally: Tally::of(&self.results),
            overrides: self.results.iter().filter(|r| r.overridden).count(),
            policy_fallbacks: self
                .states
                .iter()
                .filter(|s| s.policy_fallback && s.phase == GameState::DECIDING)
                .map(|s| s.sequence_index)
                .collect::<std::collections::BTreeSet<_>>()
                .len(),
            explored: self.decisions.iter().filter(|d| d.explored).count(),
        })
    }
}

fn draw_err(figure: &'static str) -> impl Fn(String) -> ReportError {
    move |reason| ReportError::Draw { figure, reason }
}

/// Level (bars) and score L*O (markers) per sequence.
pub fn levels_svg(log: &SessionLog) -> Result<String, ReportError> {
    let err = draw_err("levels");
    let n = log.results.len();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1100, 320)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(format!("{e:?}")))?;
        let mut chart = ChartBuilder::on(&root)
            .caption("Level and score per sequence", ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(0.5..(n as f64 + 0.5), -3.5..3.5)
            .map_err(|e| err(format!("{e:?}")))?;
        chart
            .configure_mesh()
            .x_desc("sequence")
            .y_desc("level / score")
            .x_labels(n.max(1))
            .x_label_formatter(&|x| format!("{x:.0}"))
            .draw()
            .map_err(|e| err(format!("{e:?}")))?;
        let bars = log.results.iter().map(|r| {
            let x = f64::from(r.sequence_index);
            let colour = if r.feedback == 0 {
                RGBColor(170, 190, 220)
            } else {
                RGBColor(250, 200, 120)
            };
            Rectangle::new(
                [(x - 0.3, 0.0), (x + 0.3, f64::from(r.level))],
                colour.filled(),
            )
        });
        chart
            .draw_series(bars)
            .map_err(|e| err(format!("{e:?}")))?
            .label("level (orange: after feedback)")
            .legend(|(x, y)| {
                Rectangle::new(
                    [(x, y - 5), (x + 12, y + 5)],
                    RGBColor(170, 190, 220).filled(),
                )
            });
        let scores = log.results.iter().map(|r| {
            let x = f64::from(r.sequence_index);
            let s = f64::from(r.score());
            let colour = if r.is_right() {
                RGBColor(30, 140, 60)
            } else {
                RGBColor(200, 40, 40)
            };
            Circle::new((x, s), 6, colour.filled())
        });
        chart
            .draw_series(scores)
            .map_err(|e| err(format!("{e:?}")))?
            .label("score L·O (green right, red wrong)")
            .legend(|(x, y)| Circle::new((x + 6, y), 5, RGBColor(30, 140, 60).filled()));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| err(format!("{e:?}")))?;
        root.present().map_err(|e| err(format!("{e:?}")))?;
    }
    Ok(svg)
}

/// The paper's Fig. 2 for one source of faces (camera / face): its expected engagement per
/// second, with the session's answers and stage ends. Every source's figure shares one time
/// axis, so several cameras are compared second by second instead of mixed into one curve.
#[derive(Debug, Clone, PartialEq)]
pub struct EngagementFigure {
    /// `ExpectedEngagement.source`: "<camera frame_id>/<face_id>".
    pub source: String,
    /// Time zero of every figure of the session (ns since the epoch): the earliest of its first
    /// game state, its first result and any source's first second.
    pub start_ns: i64,
    /// Start of each of this source's seconds, ascending, in seconds since `start_ns`.
    pub seconds: Vec<f64>,
    /// Mean per second (NaN: no face that second).
    pub engagement: Vec<f64>,
    /// Smoothed mean per second (NaN: no face that second).
    pub smoothed: Vec<f64>,
    /// When each sequence's result came (the child answered, or the task timed out).
    pub answers: Vec<f64>,
    /// The last result of each stage (a run of sequences at one level) and its sequence length.
    pub stage_ends: Vec<(f64, u8)>,
}

impl EngagementFigure {
    /// Seconds in which this source saw a valid face.
    pub fn seconds_with_faces(&self) -> usize {
        self.engagement.iter().filter(|v| v.is_finite()).count()
    }
}

/// One figure per source, in the order the sources first appear in the log; none without
/// expected-engagement messages.
pub fn engagement_figures(log: &SessionLog) -> Vec<EngagementFigure> {
    let Some(start_ns) = log
        .engagement
        .iter()
        .map(|e| e.window_start.to_nanos())
        .min()
        .map(|first_second| {
            log.states
                .first()
                .map(|s| s.header.stamp.to_nanos())
                .into_iter()
                .chain(log.results.iter().map(|r| r.header.stamp.to_nanos()))
                .fold(first_second, i64::min)
        })
    else {
        return Vec::new();
    };
    // Differences of integer nanoseconds: no f64 rounding of epoch times.
    let since_start = |ns: i64| (ns - start_ns) as f64 / 1e9;
    let answers: Vec<f64> = log
        .results
        .iter()
        .map(|r| since_start(r.header.stamp.to_nanos()))
        .collect();
    // A stage ends where the next sequence has another level.
    let stage_ends: Vec<(f64, u8)> = log
        .results
        .windows(2)
        .filter(|w| w[0].level != w[1].level)
        .map(|w| &w[0])
        .chain(log.results.last())
        .map(|r| {
            let length =
                sequence_game::Level::new(r.level.into()).map_or(0, |l| l.sequence_length() as u8);
            (since_start(r.header.stamp.to_nanos()), length)
        })
        .collect();
    let mut sources: Vec<&str> = Vec::new();
    for e in &log.engagement {
        if !sources.contains(&e.source.as_str()) {
            sources.push(&e.source);
        }
    }
    sources
        .into_iter()
        .map(|source| {
            let mut seconds: Vec<&ExpectedEngagement> = log
                .engagement
                .iter()
                .filter(|e| e.source == source)
                .collect();
            seconds.sort_by_key(|e| e.window_start.to_nanos());
            let value = |e: &ExpectedEngagement, v: f32| {
                if e.has_faces { f64::from(v) } else { f64::NAN }
            };
            EngagementFigure {
                source: source.to_string(),
                start_ns,
                seconds: seconds
                    .iter()
                    .map(|e| since_start(e.window_start.to_nanos()))
                    .collect(),
                engagement: seconds.iter().map(|e| value(e, e.mean)).collect(),
                smoothed: seconds.iter().map(|e| value(e, e.smoothed)).collect(),
                answers: answers.clone(),
                stage_ends: stage_ends.clone(),
            }
        })
        .collect()
}

/// Draws one source's figure (the paper's Fig. 2) as SVG.
pub fn engagement_over_time_svg(
    figure: &EngagementFigure,
    title: &str,
) -> Result<String, ReportError> {
    let plot = EngagementPlot {
        title,
        seconds: &figure.seconds,
        engagement: &figure.engagement,
        smoothed: &figure.smoothed,
        answers: &figure.answers,
        stage_ends: &figure.stage_ends,
    };
    engagement_svg(&plot).map_err(|e| ReportError::Draw {
        figure: "engagement",
        reason: e.to_string(),
    })
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The newest `session.mcap` among the run directories under `sessions_root` (as the
/// installed service writes them: `<root>/<run>/session.mcap`), by modification time; None
/// when there is none.
pub fn last_bag(sessions_root: &std::path::Path) -> Option<std::path::PathBuf> {
    std::fs::read_dir(sessions_root)
        .ok()?
        .filter_map(Result::ok)
        .map(|run| run.path().join("session.mcap"))
        .filter_map(|bag| {
            let modified = bag.metadata().ok()?.modified().ok()?;
            Some((modified, bag))
        })
        .max()
        .map(|(_, bag)| bag)
}

/// The whole report as one HTML page (figures inline, no external resources).
pub fn report_html(log: &SessionLog) -> Result<String, ReportError> {
    let s = log.summary()?;
    let mut html = String::new();
    let title = format!(
        "Session {} — user {}",
        escape(&s.session_id),
        escape(&s.user_id)
    );
    let _ = write!(
        html,
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>{title}</title><style>\
         body{{font-family:sans-serif;margin:24px;max-width:1150px}} table{{border-collapse:collapse}}\
         td,th{{border:1px solid #bbb;padding:3px 7px;text-align:right}} th{{background:#eef}}\
         .ok{{color:#1a7f37}} .bad{{color:#c0392b}} .expl{{background:#fff3cd}}</style></head><body>\
         <h1>{title}</h1>"
    );
    let engagement = s
        .tally
        .mean_engagement
        .map(|e| format!("{e:+.2}"))
        .unwrap_or_else(|| "no face seen".into());
    let _ = write!(
        html,
        "<p>User-model cluster <b>{}</b>. {} sequences, {} right. Score <b>{}</b> of {} possible \
         (ratio {:.2}). Mean expected engagement <b>{engagement}</b>. Timeouts {}, therapist \
         overrides {}, policy fallbacks {}, exploratory decisions {}.</p>",
        s.cluster,
        s.tally.sequences,
        s.tally.correct,
        s.tally.score,
        s.tally.max_score,
        s.tally.ratio(),
        s.tally.timeouts,
        s.overrides,
        s.policy_fallbacks,
        s.explored
    );
    html.push_str(&levels_svg(log)?);
    let figures = engagement_figures(log);
    if figures.is_empty() {
        html.push_str("<p>No expected-engagement messages were recorded.</p>");
    }
    if figures.len() > 1 {
        let _ = write!(
            html,
            "<p>{} sources (camera / face) sent faces: one figure each, on one time axis.</p>",
            figures.len()
        );
    }
    for figure in &figures {
        let _ = write!(
            html,
            "<h2>Expected engagement of {}</h2><p>{} of {} seconds with a face.</p>",
            escape(&figure.source),
            figure.seconds_with_faces(),
            figure.seconds.len()
        );
        let title = format!("Expected engagement over the session: {}", figure.source);
        html.push_str(&engagement_over_time_svg(figure, &title)?);
    }
    html.push_str(
        "<h2>Sequences and decisions</h2><table><tr><th>#</th><th>state (L,F,PS)</th><th>action</th>\
         <th>how chosen</th><th>T</th><th>Q(L1)</th><th>Q(L2)</th><th>Q(L3)</th><th>Q(enc)</th>\
         <th>Q(chal)</th><th>sequence</th><th>answer</th><th>result</th><th>time s</th><th>E</th></tr>",
    );
    for r in &log.results {
        let d = log
            .decisions
            .iter()
            .find(|d| d.session_id == r.session_id && d.step == r.sequence_index);
        let action = sequence_game::Action::new(r.action.into())
            .map_or_else(|_| "?".into(), sequence_game::Action::label);
        let (how, t, qs, row_class) = match d {
            _ if r.overridden => (
                "therapist override".to_string(),
                String::new(),
                vec![String::new(); 5],
                "",
            ),
            Some(d) => (
                if d.explored {
                    "explored".to_string()
                } else {
                    "greedy".to_string()
                },
                format!("{:.1}", d.temperature),
                d.q_values.iter().map(|q| format!("{q:.2}")).collect(),
                if d.explored { " class=\"expl\"" } else { "" },
            ),
            None => (
                "fallback (no decision)".to_string(),
                String::new(),
                vec![String::new(); 5],
                "",
            ),
        };
        let result = if r.timed_out {
            "<span class=\"bad\">timeout</span>".to_string()
        } else if r.outcome == 1 {
            format!("<span class=\"ok\">+{}</span>", r.level)
        } else {
            format!("<span class=\"bad\">-{}</span>", r.level)
        };
        let _ = write!(
            html,
            "<tr{row_class}><td>{}</td><td>({},{},{:+})</td><td>{action}</td><td>{how}</td><td>{t}</td>",
            r.sequence_index, r.state.level, r.state.feedback, r.state.previous_score
        );
        for q in qs.iter().chain(std::iter::repeat(&String::new())).take(5) {
            let _ = write!(html, "<td>{q}</td>");
        }
        let _ = write!(
            html,
            "<td>{}</td><td>{}</td><td>{result}</td><td>{:.1}</td><td>{:+.2}</td></tr>",
            escape(&r.sequence.join(" ")),
            escape(&r.answer.join(" ")),
            r.response_time,
            r.engagement
        );
    }
    html.push_str("</table></body></html>\n");
    Ok(html)
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_last_bag_is_the_newest_runs() {
        let root = tempfile::tempdir().expect("temp dir");
        assert_eq!(super::last_bag(root.path()), None);
        assert_eq!(super::last_bag(&root.path().join("absent")), None);
        let at = |run: &str, secs: u64| {
            let dir = root.path().join(run);
            std::fs::create_dir_all(&dir).expect("run dir");
            let bag = dir.join("session.mcap");
            let file = std::fs::File::create(&bag).expect("bag");
            file.set_modified(std::time::UNIX_EPOCH + std::time::Duration::from_secs(secs))
                .expect("mtime");
            bag
        };
        at("20261201-090000", 1_000);
        let newest = at("20261203-100000", 3_000);
        at("20261202-110000", 2_000);
        // A run without a bag (started, refused) is passed over.
        std::fs::create_dir_all(root.path().join("20261204-120000")).expect("dir");
        assert_eq!(super::last_bag(root.path()), Some(newest));
    }

    use super::*;
    use qt_therapy_msgs::BehaviourState;
    use qt_therapy_msgs::builtin_interfaces::Time;
    use qt_therapy_msgs::std_msgs::Header;

    fn result(i: u8, level: u8, outcome: i8, t: i32) -> SequenceResult {
        SequenceResult {
            header: Header::at(Time { sec: t, nanosec: 0 }),
            session_id: "s1".into(),
            user_id: "child-7".into(),
            user_model_cluster: 1,
            sequence_index: i,
            state: BehaviourState {
                level: if i == 1 { 0 } else { level },
                feedback: 0,
                previous_score: 0,
            },
            action: level - 1,
            level,
            feedback: 0,
            sequence: vec!["happy".into(); usize::from(2 * level + 1)],
            answer: vec!["happy".into(); usize::from(2 * level + 1)],
            outcome,
            activity_result: if outcome == 1 { f32::from(level) } else { -1.0 },
            engagement: 0.5,
            engagement_per_second: vec![0.5],
            response_time: 5.0,
            ..Default::default()
        }
    }

    #[test]
    fn summary_counts_score_as_the_paper_does() {
        let log = SessionLog {
            results: vec![
                result(1, 1, 1, 10),
                result(2, 3, -1, 40),
                result(3, 2, 1, 70),
            ],
            ..Default::default()
        };
        let s = log.summary().expect("summary");
        assert_eq!(
            (
                s.tally.score,
                s.tally.max_score,
                s.tally.correct,
                s.tally.sequences
            ),
            (1 - 3 + 2, 6, 2, 3)
        );
        assert_eq!(s.tally.mean_engagement, Some(0.5));
        assert!(matches!(
            SessionLog::default().summary(),
            Err(ReportError::Empty)
        ));
    }

    fn second(source: &str, sec: i32, has_faces: bool, mean: f32) -> ExpectedEngagement {
        ExpectedEngagement {
            source: source.into(),
            window_start: Time { sec, nanosec: 0 },
            window_end: Time {
                sec: sec + 1,
                nanosec: 0,
            },
            has_faces,
            mean,
            smoothed: mean / 2.0,
            frame_count: if has_faces { 30 } else { 0 },
            missing_count: if has_faces { 0 } else { 30 },
            ..Default::default()
        }
    }

    #[test]
    fn each_source_gets_its_own_curve_on_one_time_axis() {
        // Two cameras interleaved as the classifier publishes them: "front/0" from 100 s,
        // engaged; "side/0" from 103 s, disengaged, no face in its second second, silent
        // from 106 s to 108 s.
        let mut engagement = Vec::new();
        for sec in 100..110 {
            engagement.push(second("front/0", sec, true, 0.6));
            if (103..106).contains(&sec) || sec >= 108 {
                engagement.push(second("side/0", sec, sec != 104, -0.4));
            }
        }
        let log = SessionLog {
            results: vec![
                result(1, 1, 1, 102),
                result(2, 1, 1, 105),
                result(3, 2, -1, 109),
            ],
            engagement,
            ..Default::default()
        };
        let figures = engagement_figures(&log);
        let sources: Vec<&str> = figures.iter().map(|f| f.source.as_str()).collect();
        assert_eq!(sources, ["front/0", "side/0"]);
        let (front, side) = (&figures[0], &figures[1]);
        assert_eq!(front.start_ns, 100_000_000_000);
        assert_eq!(side.start_ns, front.start_ns);
        assert_eq!(front.seconds, (0..10).map(f64::from).collect::<Vec<_>>());
        assert!(front.engagement.iter().all(|&v| v == f64::from(0.6f32)));
        assert!(front.smoothed.iter().all(|&v| v == f64::from(0.3f32)));
        assert_eq!(side.seconds, [3.0, 4.0, 5.0, 8.0, 9.0]);
        assert_eq!(side.seconds_with_faces(), 4);
        assert!(side.engagement[1].is_nan() && side.smoothed[1].is_nan());
        for (i, &v) in side.engagement.iter().enumerate().filter(|&(i, _)| i != 1) {
            assert_eq!(v, f64::from(-0.4f32), "second {i}");
        }
        // The session's answers and stage ends are the same on both time axes.
        for f in &figures {
            assert_eq!(f.answers, [2.0, 5.0, 9.0]);
            assert_eq!(f.stage_ends, [(5.0, 3), (9.0, 5)]);
        }
        let html = report_html(&log).expect("report");
        assert_eq!(html.matches("<svg").count(), 3, "levels + one per source");
        assert!(html.contains("Expected engagement of front/0</h2><p>10 of 10 seconds"));
        assert!(html.contains("Expected engagement of side/0</h2><p>4 of 5 seconds"));
        assert!(html.contains("2 sources (camera / face)"));
    }

    #[test]
    fn report_has_figures_and_a_row_per_sequence() {
        let engagement = (0..90)
            .map(|k| ExpectedEngagement {
                window_start: Time { sec: k, nanosec: 0 },
                window_end: Time {
                    sec: k + 1,
                    nanosec: 0,
                },
                has_faces: k % 17 != 0,
                mean: ((k as f32) / 10.0).sin(),
                smoothed: ((k as f32) / 10.0).sin() * 0.8,
                frame_count: 30,
                ..Default::default()
            })
            .collect();
        let log = SessionLog {
            results: vec![
                result(1, 1, 1, 10),
                result(2, 3, -1, 40),
                result(3, 2, 1, 70),
            ],
            engagement,
            ..Default::default()
        };
        let html = report_html(&log).expect("report");
        assert_eq!(html.matches("<svg").count(), 2);
        assert_eq!(html.matches("<tr").count(), 4);
        assert!(html.contains("Score <b>0</b> of 6"));
        assert!(html.contains("child-7"));
    }
}
