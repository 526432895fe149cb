//! The session report: what happened in one session, for the therapist and the researcher.
//! It takes the messages a session produced (from a bag or live), and writes one
//! self-contained HTML page with plots: level and score per sequence, expected engagement over
//! time with the answers and stage ends (the paper's Fig. 2; one figure per camera / face),
//! every decision with its Q-values and whether the robot explored, and what the therapist was
//! asked when the game manager proposed an action (supervised autonomy) and how they answered.

use figures::engagement::{EngagementPlot, engagement_svg};
use plotters::prelude::*;
use qt_therapy_msgs::{
    ActionProposal, Decision, ExpectedEngagement, GameState, ProposalStatus, SequenceResult,
};
use session_tally::Tally;
use session_tally::live_line::{proposal_answer, proposal_asked};
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
    /// Actions proposed to the therapist and their settlement (none in a bag recorded
    /// before supervised autonomy, or with it off).
    pub proposals: Vec<ActionProposal>,
    /// Messages of the bag delivered again and taken once (every session's).
    pub repeats: usize,
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
    pub proposals: ProposalTally,
}

/// What the therapist was asked (supervised autonomy) over a session, and how it ended.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ProposalTally {
    /// Sequences whose action was proposed (a proposal made again after a pause counts once).
    pub proposed: usize,
    pub accepted: usize,
    pub replaced: usize,
    /// Nobody answered within the countdown: the proposal was carried out.
    pub timed_out: usize,
    /// The session ended first.
    pub withdrawn: usize,
    /// Proposed, but the bag holds no settlement (it ends, or is damaged, before it).
    pub unsettled: usize,
    /// Mean seconds from proposal to the therapist's answer (accepted or replaced).
    pub mean_response_time: Option<f64>,
}

/// One sequence's proposal: the messages of one (session, step).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Proposal<'a> {
    /// The last PROPOSED message (a pause proposes again with a fresh countdown).
    pub proposed: &'a ActionProposal,
    /// How many times it was proposed.
    pub times_proposed: usize,
    /// The message that settled it, if the log holds one.
    pub settled: Option<&'a ActionProposal>,
}

impl Proposal<'_> {
    pub fn session_id(&self) -> &str {
        &self.settled.unwrap_or(self.proposed).session_id
    }

    pub fn step(&self) -> u8 {
        self.settled.unwrap_or(self.proposed).step
    }

    /// What the therapist was asked and answered, in words: `proposed L2 + encouraging
    /// (T 235, σ 0.31): accepted after 2.1 s`.
    pub fn describe(&self) -> String {
        let again = if self.times_proposed > 1 {
            format!(", {} times", self.times_proposed)
        } else {
            String::new()
        };
        let answer = self
            .settled
            .map_or_else(|| "no answer recorded".to_string(), proposal_answer);
        format!(
            "proposed {}{again}: {answer}",
            proposal_asked(self.proposed)
        )
    }
}

impl SessionLog {
    /// The session's messages from a bag (topics missing from the bag are empty), each
    /// message delivered again taken once by the suite's rule (`session_log`,
    /// docs/session_log.md); a message that contradicts an earlier one of the same identity
    /// is an error naming both. With `session` set, only that session; otherwise the last
    /// session in the bag. Where the recorder saw the wall clock stepped, the stamps the
    /// report places on its timeline (states, results, seconds of engagement) are moved onto
    /// the recorder's unstepped clock, each on its side of the step, so the session is one
    /// timeline.
    pub fn from_bag(
        reader: &bag_file::BagReader,
        session: Option<&str>,
    ) -> Result<SessionLog, session_log::SessionLogError> {
        let taken = session_log::SessionLog::read(reader)?;
        let mut m = taken.messages;
        let steps = clock_steps::ClockSteps::from_steps(reader.clock_steps());
        // A stamp of the wall clock that reached the recorder at `log_time`, on its clock.
        let unstepped = |t: &mut qt_therapy_msgs::builtin_interfaces::Time, log_time: u64| {
            let log_time = i64::try_from(log_time).unwrap_or(i64::MAX);
            *t = qt_therapy_msgs::builtin_interfaces::Time::from_nanos(
                steps.steady_of(t.to_nanos(), log_time),
            );
        };
        for s in &mut m.states {
            unstepped(&mut s.message.header.stamp, s.log_time);
        }
        for r in &mut m.results {
            unstepped(&mut r.message.header.stamp, r.log_time);
        }
        for e in &mut m.engagement {
            // The second moves whole, by where its middle falls.
            let (start, end) = (
                e.message.window_start.to_nanos(),
                e.message.window_end.to_nanos(),
            );
            let mut middle =
                qt_therapy_msgs::builtin_interfaces::Time::from_nanos(start + (end - start) / 2);
            unstepped(&mut middle, e.log_time);
            let shift = middle.to_nanos() - (start + (end - start) / 2);
            e.message.window_start =
                qt_therapy_msgs::builtin_interfaces::Time::from_nanos(start + shift);
            e.message.window_end =
                qt_therapy_msgs::builtin_interfaces::Time::from_nanos(end + shift);
            unstepped(&mut e.message.header.stamp, e.log_time);
        }
        let wanted = session
            .map(str::to_string)
            .or_else(|| m.last_session().map(str::to_string))
            .unwrap_or_default();
        fn of<M>(v: Vec<bag_file::Stamped<M>>, keep: impl Fn(&M) -> bool) -> Vec<M> {
            v.into_iter()
                .map(|s| s.message)
                .filter(|m| keep(m))
                .collect()
        }
        let mut log = SessionLog {
            results: of(m.results, |r| r.session_id == wanted),
            decisions: of(m.decisions, |d| d.session_id == wanted),
            states: of(m.states, |s| s.session_id == wanted),
            // Absent from bags recorded before supervised autonomy: none then.
            proposals: of(m.proposals, |p| p.session_id == wanted),
            engagement: of(m.engagement, |_| true),
            repeats: taken.repeats.len(),
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
            proposals: self.proposal_tally(),
        })
    }

    /// Each (session, step) proposed to the therapist, in the order first proposed. A
    /// settlement without its PROPOSED message (the bag began after it) stands for both. The
    /// log's proposals are taken once each (as [`SessionLog::from_bag`] takes them).
    pub fn proposals(&self) -> Vec<Proposal<'_>> {
        let mut out: Vec<Proposal<'_>> = Vec::new();
        for p in &self.proposals {
            let at = out
                .iter()
                .position(|o| o.session_id() == p.session_id && o.step() == p.step);
            let entry = match at {
                Some(i) => &mut out[i],
                None => {
                    out.push(Proposal {
                        proposed: p,
                        times_proposed: 0,
                        settled: None,
                    });
                    out.last_mut().expect("just pushed")
                }
            };
            // Each PROPOSED message is a showing of its own: the log holds a message
            // delivered again once (session_log).
            if p.status == ActionProposal::PROPOSED {
                entry.proposed = p;
                entry.times_proposed += 1;
            } else {
                entry.settled = Some(p);
            }
        }
        out
    }

    /// The proposal of one sequence, if its action was proposed.
    pub fn proposal_for(&self, session_id: &str, step: u8) -> Option<Proposal<'_>> {
        self.proposals()
            .into_iter()
            .find(|p| p.session_id() == session_id && p.step() == step)
    }

    fn proposal_tally(&self) -> ProposalTally {
        let mut t = ProposalTally::default();
        let mut answered = Vec::new();
        for p in self.proposals() {
            t.proposed += 1;
            match p.settled.map(|s| ProposalStatus::try_from(s.status)) {
                Some(Ok(ProposalStatus::Accepted)) => t.accepted += 1,
                Some(Ok(ProposalStatus::Replaced)) => t.replaced += 1,
                Some(Ok(ProposalStatus::TimedOut)) => t.timed_out += 1,
                Some(Ok(ProposalStatus::Withdrawn)) => t.withdrawn += 1,
                Some(Ok(ProposalStatus::Proposed) | Err(_)) | None => t.unsettled += 1,
            }
            if let Some(s) = p.settled.filter(|s| {
                matches!(
                    ProposalStatus::try_from(s.status),
                    Ok(ProposalStatus::Accepted | ProposalStatus::Replaced)
                )
            }) {
                answered.push(f64::from(s.response_time));
            }
        }
        t.mean_response_time =
            (!answered.is_empty()).then(|| answered.iter().sum::<f64>() / answered.len() as f64);
        t
    }
}

impl ProposalTally {
    /// The summary's sentence: `Proposals to the therapist 4: accepted 2, replaced 1, ran
    /// out 1; mean answer 1.6 s.`
    pub fn sentence(&self) -> String {
        if self.proposed == 0 {
            return "No action was proposed to the therapist.".to_string();
        }
        let mut s = format!(
            "Proposals to the therapist {}: accepted {}, replaced {}, ran out {}",
            self.proposed, self.accepted, self.replaced, self.timed_out
        );
        if self.withdrawn > 0 {
            let _ = write!(s, ", withdrawn {}", self.withdrawn);
        }
        if self.unsettled > 0 {
            let _ = write!(s, ", no answer recorded {}", self.unsettled);
        }
        if let Some(m) = self.mean_response_time {
            let _ = write!(s, "; mean answer {m:.1} s");
        }
        s.push('.');
        s
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
         .asked{{text-align:left}} .ok{{color:#1a7f37}} .bad{{color:#c0392b}} .expl{{background:#fff3cd}}</style></head><body>\
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
         overrides {}, policy fallbacks {}, exploratory decisions {}. {}</p>",
        s.cluster,
        s.tally.sequences,
        s.tally.correct,
        s.tally.score,
        s.tally.max_score,
        s.tally.ratio(),
        s.tally.timeouts,
        s.overrides,
        s.policy_fallbacks,
        s.explored,
        escape(&s.proposals.sentence())
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
         <th>how chosen</th><th>therapist asked</th><th>T</th><th>Q(L1)</th><th>Q(L2)</th><th>Q(L3)</th><th>Q(enc)</th>\
         <th>Q(chal)</th><th>sequence</th><th>answer</th><th>result</th><th>time s</th><th>E</th></tr>",
    );
    // Each sequence's proposal, gathered once for the table and the list below it.
    let proposals = log.proposals();
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
        let asked = proposals
            .iter()
            .find(|p| p.session_id() == r.session_id && p.step() == r.sequence_index)
            .map(|p| {
                format!(
                    "{}<br><small>{}</small>",
                    escape(&p.describe()),
                    escape(&p.proposed.reason)
                )
            })
            .unwrap_or_default();
        let result = if r.timed_out {
            "<span class=\"bad\">timeout</span>".to_string()
        } else if r.outcome == 1 {
            format!("<span class=\"ok\">+{}</span>", r.level)
        } else {
            format!("<span class=\"bad\">-{}</span>", r.level)
        };
        let _ = write!(
            html,
            "<tr{row_class}><td>{}</td><td>({},{},{:+})</td><td>{action}</td><td>{how}</td><td class=\"asked\">{asked}</td><td>{t}</td>",
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
    html.push_str("</table>");
    // Proposals of sequences that never played (withdrawn when the session ended).
    let unplayed: Vec<&Proposal<'_>> = proposals
        .iter()
        .filter(|p| {
            !log.results
                .iter()
                .any(|r| r.session_id == p.session_id() && r.sequence_index == p.step())
        })
        .collect();
    if !unplayed.is_empty() {
        html.push_str("<h2>Proposals of sequences not played</h2><ul>");
        for p in unplayed {
            let _ = write!(
                html,
                "<li>sequence {}: {}</li>",
                p.step(),
                escape(&p.describe())
            );
        }
        html.push_str("</ul>");
    }
    html.push_str("</body></html>\n");
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

    /// A proposal message of session s1 for `step`: L2 + encouraging (a4) at T 235, σ 0.31.
    fn proposal(step: u8, status: u8, deadline_s: i32) -> ActionProposal {
        ActionProposal {
            header: Header::at(Time {
                sec: deadline_s - 5,
                nanosec: 0,
            }),
            session_id: "s1".into(),
            proposal_id: 1_000 + u64::from(step),
            step,
            state: BehaviourState {
                level: 2,
                feedback: 0,
                previous_score: -2,
            },
            action: 3,
            level: 2,
            feedback: 1,
            temperature: 235.0,
            success_std: 0.31,
            reason: format!("state visited {step} times (T 235 > 100)"),
            countdown: 5.0,
            deadline: Time {
                sec: deadline_s,
                nanosec: 0,
            },
            status,
            ..Default::default()
        }
    }

    /// Settled as `status`, `after` seconds from the proposal, playing `played` (level,
    /// feedback).
    fn settled(step: u8, status: u8, after: f32, played: (u8, u8)) -> ActionProposal {
        ActionProposal {
            played_action: if played.1 == 0 {
                played.0.saturating_sub(1)
            } else {
                2 + played.1
            },
            played_level: played.0,
            played_feedback: played.1,
            command_id: if matches!(status, ActionProposal::ACCEPTED | ActionProposal::REPLACED) {
                100 + u64::from(step)
            } else {
                0
            },
            response_time: after,
            ..proposal(step, status, 0)
        }
    }

    /// Sequences 1..5 played; 2 accepted, 3 replaced by level 3, 4 proposed twice (a pause)
    /// and run out, 5 proposed with no settlement in the log, 6 withdrawn when the session
    /// ended (never played); a proposal of another session for step 2 stays out.
    fn supervised_log() -> SessionLog {
        let mut results: Vec<SequenceResult> = (1..=5)
            .map(|i| result(i, 2, 1, 10 * i32::from(i)))
            .collect();
        results[2].level = 3;
        results[2].overridden = true;
        let other = ActionProposal {
            session_id: "s2".into(),
            ..settled(2, ActionProposal::REPLACED, 0.5, (1, 0))
        };
        let p4 = proposal(4, ActionProposal::PROPOSED, 45);
        let proposals = vec![
            proposal(2, ActionProposal::PROPOSED, 25),
            other,
            settled(2, ActionProposal::ACCEPTED, 2.1, (2, 1)),
            proposal(3, ActionProposal::PROPOSED, 35),
            settled(3, ActionProposal::REPLACED, 1.2, (3, 0)),
            p4.clone(),
            // The recorder's durable history again: the same proposal, not a second one.
            p4,
            // Paused, then proposed again with a fresh countdown.
            ActionProposal {
                countdown: 4.0,
                ..proposal(4, ActionProposal::PROPOSED, 60)
            },
            settled(4, ActionProposal::TIMED_OUT, 5.0, (2, 1)),
            proposal(5, ActionProposal::PROPOSED, 55),
            proposal(6, ActionProposal::PROPOSED, 65),
            settled(6, ActionProposal::WITHDRAWN, 0.0, (0, 0)),
        ];
        // As a bag is read: by the suite's rule for what arrives twice.
        let mut once = session_log::Once::new();
        let proposals = proposals
            .into_iter()
            .filter(|p| once.arrive(p, "test") == Ok(session_log::Arrival::New))
            .collect();
        SessionLog {
            results,
            proposals,
            repeats: once.repeats() as usize,
            ..Default::default()
        }
    }

    #[test]
    fn each_proposal_says_what_the_therapist_was_asked_and_answered() {
        let log = supervised_log();
        let described = |step| {
            log.proposal_for("s1", step)
                .map(|p| p.describe())
                .unwrap_or_else(|| panic!("no proposal for {step}"))
        };
        assert_eq!(
            described(2),
            "proposed L2 + encouraging (T 235, σ 0.31): accepted after 2.1 s"
        );
        assert_eq!(
            described(3),
            "proposed L2 + encouraging (T 235, σ 0.31): replaced by L3 after 1.2 s"
        );
        assert_eq!(
            described(4),
            "proposed L2 + encouraging (T 235, σ 0.31), 2 times: ran out after 5.0 s: played"
        );
        assert_eq!(
            described(5),
            "proposed L2 + encouraging (T 235, σ 0.31): no answer recorded"
        );
        assert_eq!(
            described(6),
            "proposed L2 + encouraging (T 235, σ 0.31): withdrawn (the session ended first)"
        );
        assert!(log.proposal_for("s1", 1).is_none());
        // The last proposal stands for the step: the one after the pause.
        let p4 = log.proposal_for("s1", 4).expect("step 4");
        assert_eq!((p4.proposed.countdown, p4.proposed.deadline.sec), (4.0, 60));
        assert_eq!(
            log.proposal_for("s2", 2).map(|p| p.describe()),
            Some("proposed L2 + encouraging (T 235, σ 0.31): replaced by L1 after 0.5 s".into()),
            "a settlement without its proposal stands for both"
        );

        // No user model, a small temperature, challenging feedback.
        let p = ActionProposal {
            success_std: -1.0,
            temperature: 0.42,
            feedback: 2,
            level: 3,
            ..proposal(7, ActionProposal::PROPOSED, 75)
        };
        let replaced = ActionProposal {
            success_std: -1.0,
            ..settled(7, ActionProposal::REPLACED, 0.25, (3, 1))
        };
        let log7 = SessionLog {
            proposals: vec![p, replaced],
            ..Default::default()
        };
        assert_eq!(
            log7.proposal_for("s1", 7).map(|p| p.describe()),
            Some(
                "proposed L3 + challenging (T 0.42, no user model): replaced by L3 + \
                 encouraging after 0.2 s"
                    .into()
            )
        );
    }

    #[test]
    fn the_summary_counts_proposals_and_how_they_ended() {
        let log = SessionLog {
            // Only s1's, as from_bag keeps them.
            proposals: supervised_log()
                .proposals
                .into_iter()
                .filter(|p| p.session_id == "s1")
                .collect(),
            ..supervised_log()
        };
        let t = log.summary().expect("summary").proposals;
        assert_eq!(
            t,
            ProposalTally {
                proposed: 5,
                accepted: 1,
                replaced: 1,
                timed_out: 1,
                withdrawn: 1,
                unsettled: 1,
                mean_response_time: Some((f64::from(2.1f32) + f64::from(1.2f32)) / 2.0),
            }
        );
        assert_eq!(
            t.sentence(),
            "Proposals to the therapist 5: accepted 1, replaced 1, ran out 1, withdrawn 1, \
             no answer recorded 1; mean answer 1.6 s."
        );
        assert_eq!(
            ProposalTally::default().sentence(),
            "No action was proposed to the therapist."
        );

        let html = report_html(&log).expect("report");
        assert!(
            html.contains("Proposals to the therapist 5: accepted 1"),
            "{html}"
        );
        // The table's rows: the proposal in its own column, beside how the action was chosen.
        let rows: Vec<&str> = html.split("<tr").skip(2).collect();
        assert_eq!(rows.len(), 5, "a row per played sequence");
        let asked = |row: &str| {
            let start = row.find("<td class=\"asked\">").expect("the column") + 18;
            row[start..start + row[start..].find("</td>").expect("cell end")].to_string()
        };
        assert_eq!(asked(rows[0]), "", "sequence 1 was not proposed");
        assert_eq!(
            asked(rows[1]),
            "proposed L2 + encouraging (T 235, σ 0.31): accepted after 2.1 s<br>\
             <small>state visited 2 times (T 235 &gt; 100)</small>"
        );
        assert!(
            rows[2].contains("<td>therapist override</td>"),
            "{}",
            rows[2]
        );
        assert!(asked(rows[2]).contains("replaced by L3 after 1.2 s"));
        assert!(asked(rows[3]).contains("ran out after 5.0 s: played"));
        assert!(asked(rows[4]).contains("no answer recorded"));
        // Sequence 6 never played: its proposal is listed after the table.
        let after = &html[html.find("</table>").expect("table end")..];
        assert!(
            after.contains(
                "<h2>Proposals of sequences not played</h2><ul><li>sequence 6: proposed L2 + \
                 encouraging (T 235, σ 0.31): withdrawn (the session ended first)</li></ul>"
            ),
            "{after}"
        );
        assert!(!after.contains("sequence 5:"), "sequence 5 played");

        // Without proposals: the column stays empty and nothing is listed after the table.
        let plain = SessionLog {
            proposals: Vec::new(),
            ..log
        };
        let html = report_html(&plain).expect("report");
        assert!(html.contains("No action was proposed to the therapist."));
        assert_eq!(html.matches("<td class=\"asked\"></td>").count(), 5);
        assert!(!html.contains("not played"));
    }

    #[test]
    fn proposals_are_read_from_a_bag_and_a_bag_without_them_still_reports() {
        use qt_therapy_msgs::topics::{ACTION_PROPOSAL, SEQUENCE_RESULT};
        let options = bag_file::WriterOptions::default();
        let write = |with_proposals: bool| {
            let mut w = bag_file::BagWriter::new(std::io::Cursor::new(Vec::new()), "t", &options)
                .expect("writer");
            let results = w.add_topic(SEQUENCE_RESULT).expect("topic");
            let proposals = with_proposals.then(|| w.add_topic(ACTION_PROPOSAL).expect("topic"));
            let log = supervised_log();
            for (k, r) in log.results.iter().enumerate() {
                w.write(results, 1_000 + k as u64, r).expect("writes");
            }
            if let Some(topic) = proposals {
                for (k, p) in log.proposals.iter().enumerate() {
                    w.write(topic, 2_000 + k as u64, p).expect("writes");
                }
                // A recorder that joined again: the durable topics' history once more.
                w.write(topic, 3_000, &log.proposals[0]).expect("writes");
                w.write(results, 3_001, &log.results[0]).expect("writes");
            }
            let bytes = w.finish().expect("finishes").into_inner();
            bag_file::BagReader::from_bytes(&bytes, "t", &bag_file::ReadOptions::default())
                .expect("reads")
        };
        let log = SessionLog::from_bag(&write(true), None).expect("decodes");
        assert_eq!(log.proposals.len(), 10, "s1's, not s2's, each once");
        assert_eq!((log.results.len(), log.repeats), (5, 2));
        let t = log.summary().expect("summary").proposals;
        assert_eq!(
            (t.proposed, t.accepted, t.replaced, t.timed_out),
            (5, 1, 1, 1)
        );

        let log = SessionLog::from_bag(&write(false), None).expect("decodes");
        assert!(log.proposals.is_empty());
        assert!(
            report_html(&log)
                .expect("report")
                .contains("No action was proposed to the therapist.")
        );
    }

    #[test]
    fn a_sample_bag_without_proposals_still_reports() {
        let bag = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../bags/cluster1_seed11_pause_override.mcap");
        let reader = bag_file::BagReader::open(&bag).expect("the sample bag");
        // Supervised autonomy was off: the proposals' topic has no message (its channel may
        // be there, the recorder takes every topic of the graph).
        let proposals = reader
            .messages::<qt_therapy_msgs::ActionProposal>(
                qt_therapy_msgs::topics::ACTION_PROPOSAL.name,
            )
            .map(|m| m.len())
            .unwrap_or(0);
        assert_eq!(proposals, 0, "the sample bag holds proposals");
        let log = SessionLog::from_bag(&reader, None).expect("decodes");
        let s = log.summary().expect("summary");
        assert!(s.tally.sequences > 0 && s.overrides > 0, "{s:?}");
        assert_eq!(s.proposals, ProposalTally::default());
        let html = report_html(&log).expect("report");
        assert!(html.contains("No action was proposed to the therapist."));
    }
}
