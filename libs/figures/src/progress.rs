//! A child's progress across sessions, one point per session in the order played: the score
//! out of the best possible and the level played (two panels on one axis of sessions), and the
//! expected engagement. Each session's spread (its lowest and highest level, its sequences'
//! lowest and highest engagement) is a bar around its mean, so a session that moved between
//! levels does not look like one that stayed. And what the robot believes about the child: per
//! level the chance of a right answer now, with a whisker of one standard deviation, beside a
//! pale bar where it stood at the session's start. The words come from the caller (the report
//! is in English and German).

use crate::engagement::PlotError;
use plotters::prelude::*;

const FONT: &str = "DejaVu Sans, sans-serif";
/// Colours with at least 4.5:1 contrast on white where they carry a mark a reader must see.
const SCORE: RGBColor = RGBColor(21, 101, 192);
const BEST: RGBColor = RGBColor(187, 222, 251);
const LEVEL: RGBColor = RGBColor(106, 27, 154);
const ENGAGED: RGBColor = RGBColor(46, 125, 50);
const AXIS: RGBColor = RGBColor(69, 90, 100);

/// One session.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SessionPoint {
    /// The paper's score, sum of L·O, and the best possible with these levels, sum of L.
    pub score: i32,
    pub max_score: i32,
    /// The level of each sequence played (none: the session stopped before its first).
    pub levels: Vec<u8>,
    /// Each sequence's expected engagement E, where a face was seen.
    pub engagement: Vec<f64>,
}

/// The figures' words, in the report's language.
#[derive(Debug, Clone, Copy)]
pub struct ProgressWords<'a> {
    pub score_title: &'a str,
    pub engagement_title: &'a str,
    /// The axis of sessions (`session`).
    pub session: &'a str,
    pub score: &'a str,
    pub best_possible: &'a str,
    pub level: &'a str,
    pub mean_and_range: &'a str,
    pub engagement: &'a str,
}

fn draw_err<E: std::fmt::Debug>(e: E) -> PlotError {
    PlotError::Draw(format!("{e:?}"))
}

fn mean(v: impl Iterator<Item = f64>) -> Option<(f64, f64, f64)> {
    let v: Vec<f64> = v.collect();
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (!v.is_empty()).then(|| (v.iter().sum::<f64>() / v.len() as f64, lo, hi))
}

/// The axis of sessions: 1..=n, labelled with whole numbers only (at most about 12 labels).
fn session_labels(n: usize) -> (std::ops::Range<f64>, usize) {
    (0.5..n as f64 + 0.5, n.clamp(1, 12))
}

fn whole(v: &f64) -> String {
    if (v - v.round()).abs() < 1e-6 {
        format!("{v:.0}")
    } else {
        String::new()
    }
}

/// Score of the maximum (top panel) and level played (bottom panel) per session, as SVG.
pub fn score_and_level_svg(
    points: &[SessionPoint],
    words: &ProgressWords<'_>,
) -> Result<String, PlotError> {
    if points.is_empty() {
        return Err(PlotError::Empty);
    }
    let (x_range, x_labels) = session_labels(points.len());
    let low = points.iter().map(|p| p.score.min(0)).min().unwrap_or(0);
    let high = points
        .iter()
        .map(|p| p.max_score.max(p.score))
        .max()
        .unwrap_or(1);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, 560)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let (top, bottom) = root.split_vertically(300);
        let mut chart = ChartBuilder::on(&top)
            .caption(words.score_title, (FONT, 24))
            .margin(10)
            .x_label_area_size(34)
            .y_label_area_size(64)
            // Headroom above the bars for the legend, so it covers none of them.
            .build_cartesian_2d(
                x_range.clone(),
                f64::from(low) - 1.0..f64::from(high) * 1.35 + 2.0,
            )
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_labels(x_labels)
            .x_label_formatter(&whole)
            .y_label_formatter(&whole)
            .y_desc(words.score)
            .label_style((FONT, 18).into_font().color(&AXIS))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(draw_err)?;
        let at = |i: usize| i as f64 + 1.0;
        // The best possible score as a wide pale bar, the score as a narrow dark one inside it.
        type Bar<'w> = (f64, RGBColor, &'w str, fn(&SessionPoint) -> i32);
        let bars: [Bar; 2] = [
            (0.38, BEST, words.best_possible, |p| p.max_score),
            (0.2, SCORE, words.score, |p| p.score),
        ];
        for (half_width, colour, label, value) in bars {
            chart
                .draw_series(points.iter().enumerate().map(|(i, p)| {
                    let x = at(i);
                    Rectangle::new(
                        [(x - half_width, 0.0), (x + half_width, f64::from(value(p)))],
                        colour.filled(),
                    )
                }))
                .map_err(draw_err)?
                .label(label)
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 6), (x + 14, y + 6)], colour.filled())
                });
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font((FONT, 18))
            .background_style(WHITE.mix(0.9))
            .border_style(AXIS)
            .draw()
            .map_err(draw_err)?;

        let mut chart = ChartBuilder::on(&bottom)
            .margin(10)
            .x_label_area_size(48)
            .y_label_area_size(64)
            .build_cartesian_2d(x_range, 0.5..4.3)
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_labels(x_labels)
            .y_labels(4)
            .x_label_formatter(&whole)
            .y_label_formatter(&|v| if *v <= 3.0 { whole(v) } else { String::new() })
            .x_desc(words.session)
            .y_desc(words.level)
            .label_style((FONT, 18).into_font().color(&AXIS))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(draw_err)?;
        let levels: Vec<(f64, (f64, f64, f64))> = points
            .iter()
            .enumerate()
            .filter_map(|(i, p)| Some((at(i), mean(p.levels.iter().map(|l| f64::from(*l)))?)))
            .collect();
        spread_series(&mut chart, &levels, LEVEL, words.mean_and_range)?;
    }
    Ok(svg)
}

/// Each session's mean as a point on a line, its lowest to highest as a bar.
fn spread_series<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<
        'a,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    points: &[(f64, (f64, f64, f64))],
    colour: RGBColor,
    label: &str,
) -> Result<(), PlotError> {
    chart
        .draw_series(points.iter().map(|&(x, (m, lo, hi))| {
            ErrorBar::new_vertical(x, lo, m, hi, colour.stroke_width(2), 10)
        }))
        .map_err(draw_err)?;
    chart
        .draw_series(LineSeries::new(
            points.iter().map(|&(x, (m, _, _))| (x, m)),
            colour.stroke_width(1),
        ))
        .map_err(draw_err)?;
    chart
        .draw_series(
            points
                .iter()
                .map(|&(x, (m, _, _))| Circle::new((x, m), 5, colour.filled())),
        )
        .map_err(draw_err)?
        .label(label)
        .legend(move |(x, y)| Circle::new((x + 7, y), 5, colour.filled()));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font((FONT, 18))
        .background_style(WHITE.mix(0.9))
        .border_style(AXIS)
        .draw()
        .map_err(draw_err)?;
    Ok(())
}

/// The expected engagement per session (its sequences' mean, lowest and highest E), as SVG.
pub fn engagement_across_sessions_svg(
    points: &[SessionPoint],
    words: &ProgressWords<'_>,
) -> Result<String, PlotError> {
    if points.is_empty() {
        return Err(PlotError::Empty);
    }
    let (x_range, x_labels) = session_labels(points.len());
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, 320)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(words.engagement_title, (FONT, 24))
            .margin(10)
            .x_label_area_size(48)
            .y_label_area_size(64)
            .build_cartesian_2d(x_range.clone(), -1.1..1.8)
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_labels(x_labels)
            .y_labels(7)
            .x_label_formatter(&whole)
            .y_label_formatter(&|v| {
                if *v <= 1.0 {
                    format!("{v:.1}")
                } else {
                    String::new()
                }
            })
            .x_desc(words.session)
            .y_desc(words.engagement)
            .label_style((FONT, 18).into_font().color(&AXIS))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(draw_err)?;
        chart
            .draw_series(LineSeries::new(
                [(x_range.start, 0.0), (x_range.end, 0.0)],
                AXIS.stroke_width(1),
            ))
            .map_err(draw_err)?;
        let engagement: Vec<(f64, (f64, f64, f64))> = points
            .iter()
            .enumerate()
            .filter_map(|(i, p)| Some((i as f64 + 1.0, mean(p.engagement.iter().copied())?)))
            .collect();
        spread_series(&mut chart, &engagement, ENGAGED, words.mean_and_range)?;
    }
    Ok(svg)
}

/// The belief at one level, in percent: the chance of a right answer now with its standard
/// deviation, and at the session's start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeliefBar {
    pub now: f64,
    pub now_sd: f64,
    pub session_start: f64,
}

/// The belief figure's words, in the report's language.
#[derive(Debug, Clone, Copy)]
pub struct BeliefWords<'a> {
    pub title: &'a str,
    /// The y axis (`chance of a right answer, %`).
    pub right: &'a str,
    /// Before the level's number on the x axis (`level`).
    pub level: &'a str,
    pub now: &'a str,
    pub session_start: &'a str,
}

/// Per level 1..3 the chance of a right answer the robot believes now (a dark bar with a
/// whisker of ± 1 standard deviation, clipped to 0..100 %) and at the session's start (a pale
/// bar on its left), as SVG.
pub fn belief_svg(levels: &[BeliefBar; 3], words: &BeliefWords<'_>) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, 360)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(words.title, (FONT, 24))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(64)
            // Headroom above 100 % for the legend, so it covers no bar or whisker.
            .build_cartesian_2d(0.5..3.5, 0.0..140.0)
            .map_err(draw_err)?;
        let level_label = |v: &f64| {
            if (v - v.round()).abs() < 1e-6 && (1.0..=3.0).contains(v) {
                format!("{} {v:.0}", words.level)
            } else {
                String::new()
            }
        };
        chart
            .configure_mesh()
            // Half steps, so each level's whole number is a key point; only those are named.
            .x_labels(7)
            .y_labels(8)
            .x_label_formatter(&level_label)
            .y_label_formatter(&|v| if *v <= 100.0 { whole(v) } else { String::new() })
            .y_desc(words.right)
            .label_style((FONT, 18).into_font().color(&AXIS))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(draw_err)?;
        let at = |k: usize| k as f64 + 1.0;
        let clip = |v: f64| v.clamp(0.0, 100.0);
        chart
            .draw_series(levels.iter().enumerate().map(|(k, b)| {
                let x = at(k) - 0.2;
                Rectangle::new(
                    [(x - 0.07, 0.0), (x + 0.07, clip(b.session_start))],
                    BEST.filled(),
                )
            }))
            .map_err(draw_err)?
            .label(words.session_start)
            .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], BEST.filled()));
        chart
            .draw_series(levels.iter().enumerate().map(|(k, b)| {
                let x = at(k) + 0.05;
                Rectangle::new([(x - 0.14, 0.0), (x + 0.14, clip(b.now))], SCORE.filled())
            }))
            .map_err(draw_err)?
            .label(words.now)
            .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], SCORE.filled()));
        chart
            .draw_series(levels.iter().enumerate().map(|(k, b)| {
                ErrorBar::new_vertical(
                    at(k) + 0.05,
                    clip(b.now - b.now_sd),
                    clip(b.now),
                    clip(b.now + b.now_sd),
                    AXIS.stroke_width(2),
                    16,
                )
            }))
            .map_err(draw_err)?;
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font((FONT, 18))
            .background_style(WHITE.mix(0.9))
            .border_style(AXIS)
            .draw()
            .map_err(draw_err)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    const WORDS: ProgressWords<'static> = ProgressWords {
        score_title: "Score and level",
        engagement_title: "Engagement",
        session: "session",
        score: "score",
        best_possible: "best possible",
        level: "level",
        mean_and_range: "mean, lowest to highest",
        engagement: "E",
    };

    fn point(score: i32, levels: &[u8], engagement: &[f64]) -> SessionPoint {
        SessionPoint {
            score,
            max_score: levels.iter().map(|l| i32::from(*l)).sum(),
            levels: levels.to_vec(),
            engagement: engagement.to_vec(),
        }
    }

    #[test]
    fn one_bar_and_one_point_per_session_and_nothing_without_sessions() {
        let points = [
            point(4, &[1, 2, 2], &[0.5, 0.1]),
            point(-1, &[3, 2], &[]),
            point(0, &[], &[]),
        ];
        let svg = score_and_level_svg(&points, &WORDS).expect("draws");
        assert!(
            svg.starts_with("<svg") && svg.contains("viewBox"),
            "{}",
            &svg[..80]
        );
        // Per session a best-possible bar and a score bar (and the two legend marks).
        assert_eq!(svg.matches(r##"fill="#BBDEFB""##).count(), 3 + 1, "{svg}");
        assert_eq!(svg.matches(r##"fill="#1565C0""##).count(), 3 + 1);
        // A level point for the two sessions that played, and the legend's.
        assert_eq!(svg.matches(r##"fill="#6A1B9A""##).count(), 2 + 1);
        for word in ["Score and level", "session", "best possible"] {
            assert!(svg.contains(word), "{word}");
        }
        let svg = engagement_across_sessions_svg(&points, &WORDS).expect("draws");
        let points_drawn = svg.matches(r##"fill="#2E7D32""##).count();
        assert_eq!(points_drawn, 1 + 1, "one session saw a face");
        assert!(matches!(
            score_and_level_svg(&[], &WORDS),
            Err(PlotError::Empty)
        ));
        // Fifty sessions: whole-number labels only, at most about a dozen.
        let many: Vec<SessionPoint> = (0..50)
            .map(|k| point(k % 7 - 2, &[2; 10], &[0.2]))
            .collect();
        let svg = score_and_level_svg(&many, &WORDS).expect("draws");
        assert!(
            !svg.contains("\n2.5\n") && svg.contains("\n50\n"),
            "session labels"
        );
    }

    #[test]
    fn the_belief_has_a_bar_a_whisker_and_a_session_start_per_level() {
        let words = BeliefWords {
            title: "What the robot believes",
            right: "right, %",
            level: "level",
            now: "now, ± 1 sd",
            session_start: "at the session's start",
        };
        let bars = [
            BeliefBar {
                now: 85.0,
                now_sd: 6.0,
                session_start: 80.0,
            },
            BeliefBar {
                now: 68.0,
                now_sd: 10.0,
                session_start: 55.0,
            },
            // A whisker past 100 % is clipped to the axis.
            BeliefBar {
                now: 97.0,
                now_sd: 12.0,
                session_start: 30.0,
            },
        ];
        let svg = belief_svg(&bars, &words).expect("draws");
        assert!(svg.starts_with("<svg") && svg.contains("viewBox"));
        // Per level a pale and a dark bar (and the legend's marks).
        assert_eq!(svg.matches(r##"fill="#BBDEFB""##).count(), 3 + 1, "{svg}");
        assert_eq!(svg.matches(r##"fill="#1565C0""##).count(), 3 + 1);
        for word in [
            "What the robot believes",
            "level 1",
            "level 3",
            "now, ± 1 sd",
        ] {
            assert!(svg.contains(word), "{word}");
        }
        // The bars grow with the chance: level 2's start bar is shorter than its now bar.
        let heights: Vec<f64> = svg
            .lines()
            .filter(|l| l.contains("<rect") && l.contains("#BBDEFB"))
            .filter_map(|l| {
                let h = l.split("height=\"").nth(1)?.split('"').next()?;
                h.parse().ok()
            })
            .collect();
        assert_eq!(heights.len(), 4, "{heights:?}");
        assert!(
            heights[0] > heights[1] && heights[1] > heights[2],
            "{heights:?}"
        );
    }
}
