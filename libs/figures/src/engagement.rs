//! The paper's Fig. 2: expected engagement over one session, with the moments the user
//! answered (black crosses) and the ends of game stages (red lines, labelled with the stage's
//! sequence length). Takes plain series, so it draws from study CSVs today and bags later.

use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Named first so the PNG renderer (usvg, which does not resolve the generic `sans-serif`
/// here) finds an installed face; SVG viewers fall back to their sans-serif.
const FONT: &str = "DejaVu Sans, sans-serif";

/// Everything the figure shows; times are seconds since the session start.
#[derive(Debug, Clone, Copy)]
pub struct EngagementPlot<'a> {
    pub title: &'a str,
    /// Start of each second drawn, ascending (gaps allowed).
    pub seconds: &'a [f64],
    /// Per-second expected engagement (NaN: no face that second); drawn thin.
    pub engagement: &'a [f64],
    /// Smoothed expected engagement; drawn bold, the crosses sit on it.
    pub smoothed: &'a [f64],
    pub answers: &'a [f64],
    /// End of each stage and the sequence length played in it.
    pub stage_ends: &'a [(f64, u8)],
}

/// Why the figure could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("drawing {0}")]
    Draw(String),
    #[error("series lengths differ: {seconds} seconds, {engagement} values, {smoothed} smoothed")]
    Lengths {
        seconds: usize,
        engagement: usize,
        smoothed: usize,
    },
    #[error("nothing to draw: the session has no seconds")]
    Empty,
    #[error(transparent)]
    Figure(#[from] crate::FigureError),
}

fn draw_err<E: std::fmt::Debug>(e: E) -> PlotError {
    PlotError::Draw(format!("{e:?}"))
}

/// Runs of consecutive finite points, so seconds without a face leave gaps in the line, and
/// so do seconds never reported (a camera that went silent): no line bridges them.
fn segments(xs: &[f64], ys: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for (&x, &y) in xs.iter().zip(ys) {
        let Some(run) = out.last_mut() else { break };
        let silent_before = run.last().is_some_and(|&(previous, _)| x - previous > 1.5);
        match (y.is_finite(), silent_before) {
            (true, false) => run.push((x, y)),
            (true, true) => out.push(vec![(x, y)]),
            (false, _) if !run.is_empty() => out.push(Vec::new()),
            (false, _) => {}
        }
    }
    out.retain(|r| !r.is_empty());
    out
}

/// Index of the second drawn nearest to `t` (the later one on a tie). By time, not by
/// position: a session's seconds need not start at 0 nor follow one another without gaps.
/// `seconds` is ascending and not empty.
fn nearest_second(seconds: &[f64], t: f64) -> usize {
    let after = seconds.partition_point(|&s| s < t);
    match (after.checked_sub(1), seconds.get(after)) {
        (Some(before), Some(&s)) if t - seconds[before] < s - t => before,
        (_, Some(_)) => after,
        (Some(before), None) => before,
        (None, None) => 0,
    }
}

/// Draws the figure as an SVG document.
pub fn engagement_svg(plot: &EngagementPlot<'_>) -> Result<String, PlotError> {
    let n = plot.seconds.len();
    if plot.engagement.len() != n || plot.smoothed.len() != n {
        return Err(PlotError::Lengths {
            seconds: n,
            engagement: plot.engagement.len(),
            smoothed: plot.smoothed.len(),
        });
    }
    let last = plot.seconds.last().copied().ok_or(PlotError::Empty)?;
    let x_max = plot.answers.iter().copied().fold(last, f64::max) + 1.0;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1180, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        // The legend gets its own panel on the right: the curve fills the whole plot area.
        let (left, legend) = root.split_horizontally(1000);
        let mut chart = ChartBuilder::on(&left)
            .caption(plot.title, (FONT, 20))
            .margin(12)
            .x_label_area_size(42)
            .y_label_area_size(56)
            .build_cartesian_2d(0.0..x_max, -1.1..1.25)
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_desc("time since session start [s]")
            .y_desc("expected engagement E")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.1}"))
            .light_line_style(WHITE.mix(0.0))
            .label_style((FONT, 14))
            .draw()
            .map_err(draw_err)?;
        let raw_style = ShapeStyle::from(&RGBColor(150, 180, 220)).stroke_width(1);
        for run in segments(plot.seconds, plot.engagement) {
            chart
                .draw_series(LineSeries::new(run, raw_style))
                .map_err(draw_err)?;
        }
        let smooth_style = ShapeStyle::from(&RGBColor(20, 60, 150)).stroke_width(2);
        for run in segments(plot.seconds, plot.smoothed) {
            chart
                .draw_series(LineSeries::new(run, smooth_style))
                .map_err(draw_err)?;
        }
        let red = ShapeStyle::from(&RED).stroke_width(2);
        let mut stage_start = 0.0;
        for &(end, length) in plot.stage_ends {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    [(end, -1.1), (end, 1.1)],
                    red,
                )))
                .map_err(draw_err)?;
            let middle = (stage_start + end) / 2.0;
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("L = {length}"),
                    (middle, 1.2),
                    (FONT, 14).into_font().color(&RED),
                )))
                .map_err(draw_err)?;
            stage_start = end;
        }
        // A cross sits on the smoothed curve at the second of the answer (on 0 if none).
        let value_at = |t: f64| {
            Some(plot.smoothed[nearest_second(plot.seconds, t)])
                .filter(|v| v.is_finite())
                .unwrap_or(0.0)
        };
        let cross = BLACK.stroke_width(2);
        chart
            .draw_series(
                plot.answers
                    .iter()
                    .map(|&t| Cross::new((t, value_at(t)), 6, cross)),
            )
            .map_err(draw_err)?;
        let label = |text: &str, y: i32| Text::new(text.to_string(), (44, y - 8), (FONT, 14));
        let entries: [(&str, i32); 4] = [
            ("per second", 90),
            ("smoothed (α = 0.75)", 118),
            ("end of stage", 146),
            ("answer given", 174),
        ];
        for (i, &(text, y)) in entries.iter().enumerate() {
            match i {
                0 => legend.draw(&PathElement::new([(10, y), (36, y)], raw_style)),
                1 => legend.draw(&PathElement::new([(10, y), (36, y)], smooth_style)),
                2 => legend.draw(&PathElement::new([(23, y - 8), (23, y + 8)], red)),
                _ => legend.draw(&Cross::new((23, y), 6, cross)),
            }
            .map_err(draw_err)?;
            legend.draw(&label(text, y)).map_err(draw_err)?;
        }
        root.present().map_err(draw_err)?;
    }
    Ok(svg)
}

/// Draws the figure and writes `<stem>.svg` and `<stem>.png`.
pub fn write_engagement_plot(
    stem: &Path,
    plot: &EngagementPlot<'_>,
) -> Result<(PathBuf, PathBuf), PlotError> {
    let svg = engagement_svg(plot)?;
    Ok(crate::write_svg_and_png(stem, &svg)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_split_the_line() {
        let runs = segments(
            &[0.0, 1.0, 2.0, 3.0, 4.0],
            &[0.1, f64::NAN, 0.2, 0.3, f64::NAN],
        );
        assert_eq!(runs, vec![vec![(0.0, 0.1)], vec![(2.0, 0.2), (3.0, 0.3)]]);
        // Seconds 3 to 6 never reported.
        let runs = segments(&[0.0, 1.0, 2.0, 7.0, 8.0], &[0.1, 0.2, 0.3, 0.4, 0.5]);
        assert_eq!(
            runs,
            vec![
                vec![(0.0, 0.1), (1.0, 0.2), (2.0, 0.3)],
                vec![(7.0, 0.4), (8.0, 0.5)]
            ]
        );
    }

    #[test]
    fn an_answer_finds_its_second_by_time() {
        // Contiguous seconds from 0: as rounding the time (ties go to the later second).
        let contiguous: Vec<f64> = (0..5).map(f64::from).collect();
        for (t, want) in [(-3.0, 0), (0.4, 0), (1.5, 2), (2.6, 3), (9.0, 4)] {
            assert_eq!(nearest_second(&contiguous, t), want, "t = {t}");
        }
        // A source first seen at 5 s, silent from 7 s to 10 s.
        let gappy = [5.0, 6.0, 7.0, 10.0, 11.0];
        for (t, want) in [(1.0, 0), (6.2, 1), (8.4, 2), (8.6, 3), (10.4, 3), (30.0, 4)] {
            assert_eq!(nearest_second(&gappy, t), want, "t = {t}");
        }
    }

    #[test]
    fn draws_an_svg_with_crosses_and_stage_lines() {
        let seconds: Vec<f64> = (0..60).map(f64::from).collect();
        let engagement: Vec<f64> = seconds.iter().map(|s| (s / 7.0).sin()).collect();
        let plot = EngagementPlot {
            title: "test",
            seconds: &seconds,
            engagement: &engagement,
            smoothed: &engagement,
            answers: &[10.0, 30.0],
            stage_ends: &[(30.0, 7)],
        };
        let svg = engagement_svg(&plot).expect("draws");
        assert!(svg.starts_with("<svg"));
        assert!(svg.contains("L = 7") && svg.contains("answer given"));
        let short = EngagementPlot {
            smoothed: &engagement[..3],
            ..plot
        };
        assert!(matches!(
            engagement_svg(&short),
            Err(PlotError::Lengths { .. })
        ));
    }
}
