//! The paper's Figs. 4 and 5 as SVG: per epoch the mean ± std band across runs, one line per
//! configuration (three rewards and the transfer into that model), one panel per user model;
//! and the per-child study's curves (per session, one line per policy, one panel per metric)
//! and paired differences (per child, one panel per comparison). Counterfactual evaluation's
//! figures are in `evaluation`.

pub mod evaluation;

use crate::experiments::grid::Curve;
use plotters::coord::Shift;
use plotters::prelude::*;
use q_learning::training::EpochMetrics;

const COLOURS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
];

/// Which metric a figure shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Figure {
    /// Fig. 4: mean accumulated score per session.
    Score,
    /// Fig. 5: mean engagement.
    Engagement,
}

impl Figure {
    fn value(self, e: &EpochMetrics) -> f64 {
        match self {
            Figure::Score => e.score,
            Figure::Engagement => e.engagement,
        }
    }

    fn label(self) -> &'static str {
        match self {
            Figure::Score => "performance score (mean per session)",
            Figure::Engagement => "engagement (mean per session)",
        }
    }
}

fn err<E: std::fmt::Debug>(e: E) -> String {
    format!("{e:?}")
}

type Chart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// A mean line over its band, named in the legend; `points` are (x, mean, half-width).
fn draw_band(
    chart: &mut Chart<'_, '_>,
    points: &[(f64, f64, f64)],
    colour: RGBColor,
    label: &str,
) -> Result<(), String> {
    let band: Vec<(f64, f64)> = points
        .iter()
        .map(|&(x, m, s)| (x, m + s))
        .chain(points.iter().rev().map(|&(x, m, s)| (x, m - s)))
        .collect();
    chart
        .draw_series(std::iter::once(Polygon::new(
            band,
            colour.mix(0.15).filled(),
        )))
        .map_err(err)?;
    chart
        .draw_series(LineSeries::new(
            points.iter().map(|&(x, m, _)| (x, m)),
            colour.stroke_width(2),
        ))
        .map_err(err)?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(3)));
    Ok(())
}

/// The legend, below the curves (each figure leaves room for it there).
fn draw_legend<'a, 'b: 'a>(chart: &mut Chart<'a, 'b>) -> Result<(), String> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(err)
}

/// An SVG `size` pixels large: `subtitle` on top, then `count` panels side by side, panel i
/// drawn by `draw(i, panel)`. Every figure of the policy's commands is one.
pub(crate) fn panels_svg(
    size: (u32, u32),
    subtitle: &str,
    count: usize,
    mut draw: impl FnMut(usize, &DrawingArea<SVGBackend<'_>, Shift>) -> Result<(), String>,
) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root
            .titled(
                subtitle,
                ("sans-serif", 14).into_font().color(&BLACK.mix(0.7)),
            )
            .map_err(err)?;
        for (i, panel) in root
            .split_evenly((1, count.max(1)))
            .iter()
            .enumerate()
            .take(count)
        {
            draw(i, panel)?;
        }
        root.present().map_err(err)?;
    }
    Ok(svg)
}

/// Draws the figure; `subtitle` says where the numbers came from.
pub fn curves_svg(curves: &[Curve], figure: Figure, subtitle: &str) -> Result<String, String> {
    let mut clusters: Vec<usize> = curves.iter().map(|c| c.config.cluster).collect();
    clusters.sort_unstable();
    clusters.dedup();
    let width = 40 + 600 * clusters.len().max(1) as u32;
    panels_svg((width, 500), subtitle, clusters.len(), |i, panel| {
        let k = clusters[i];
        let mine: Vec<&Curve> = curves.iter().filter(|c| c.config.cluster == k).collect();
        let epochs = mine.iter().map(|c| c.mean.len()).max().unwrap_or(1).max(2);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for c in &mine {
            for (m, s) in c.mean.iter().zip(&c.std) {
                lo = lo.min(figure.value(m) - figure.value(s));
                hi = hi.max(figure.value(m) + figure.value(s));
            }
        }
        if !(lo.is_finite() && hi.is_finite()) {
            (lo, hi) = (0.0, 1.0);
        }
        // Room below the curves for the legend.
        let range = (hi - lo).max(0.1);
        let (bottom, top) = (lo - 0.32 * range, hi + 0.05 * range);
        let mut chart = ChartBuilder::on(panel)
            .caption(format!("M{} (cluster {k})", k + 1), ("sans-serif", 20))
            .margin(14)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(1.0..epochs as f64, bottom..top)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("epoch (100 sessions)")
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y:.2}"))
            .y_desc(figure.label())
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(err)?;
        for (i, c) in mine.iter().enumerate() {
            let points: Vec<(f64, f64, f64)> = c
                .mean
                .iter()
                .zip(&c.std)
                .enumerate()
                .map(|(e, (m, s))| ((e + 1) as f64, figure.value(m), figure.value(s)))
                .collect();
            draw_band(
                &mut chart,
                &points,
                COLOURS[i % COLOURS.len()],
                &c.config.name,
            )?;
        }
        draw_legend(&mut chart)?;
        Ok(())
    })
}

/// The per-child study: per session of the run, the mean over children of each policy with
/// its 95 % t interval over children (each child: the mean over seeds), one panel per metric.
pub fn per_child_svg(
    results: &[crate::child_study::per_child::ChildResult],
    subtitle: &str,
) -> Result<String, String> {
    use crate::child_study::per_child::{Arm, Metric, curve};
    panels_svg((1500, 480), subtitle, Metric::ALL.len(), |i, panel| {
        let metric = Metric::ALL[i];
        // Per policy, (x, mean, half-width of the interval).
        type Points = Vec<(f64, f64, f64)>;
        let curves: Vec<(Arm, Points)> = Arm::ALL
            .iter()
            .map(|&a| {
                let points = curve(results, a, metric)
                    .into_iter()
                    .enumerate()
                    .map(|(k, (m, interval))| {
                        (
                            (k + 1) as f64,
                            m,
                            interval.map_or(0.0, |i| 0.5 * (i.high - i.low)),
                        )
                    })
                    .collect();
                (a, points)
            })
            .collect();
        let sessions = curves.first().map_or(1, |c| c.1.len()).max(2);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (_, c) in &curves {
            for &(_, m, h) in c {
                lo = lo.min(m - h);
                hi = hi.max(m + h);
            }
        }
        if !(lo.is_finite() && hi.is_finite()) {
            (lo, hi) = (0.0, 1.0);
        }
        let range = (hi - lo).max(0.1);
        let (bottom, top) = (lo - 0.45 * range, hi + 0.05 * range);
        let mut chart = ChartBuilder::on(panel)
            .caption(format!("{} per session", metric.name()), ("sans-serif", 20))
            .margin(14)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(1.0..sessions as f64, bottom..top)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("session with the child")
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y:.2}"))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(err)?;
        for (i, (arm, points)) in curves.iter().enumerate() {
            draw_band(&mut chart, points, COLOURS[i % COLOURS.len()], arm.name())?;
        }
        draw_legend(&mut chart)?;
        Ok(())
    })
}

/// The per-child study's paired differences, one panel per comparison: each child's
/// difference (sorted; a bar for its 95 % interval over seeds, grey where it is a tie), the
/// zero line, and the mean over children with its 95 % t interval as a band.
pub fn per_child_paired_svg(
    comparisons: &[(String, crate::stats::PairedComparison)],
    unit_label: &str,
    subtitle: &str,
) -> Result<String, String> {
    use crate::stats::Verdict;
    panels_svg((1500, 480), subtitle, comparisons.len(), |i, panel| {
        let (name, c) = &comparisons[i];
        let mut units = c.per_unit.clone();
        units.sort_by(|a, b| a.difference.total_cmp(&b.difference));
        let (mut lo, mut hi) = (0.0f64, 0.0f64);
        for u in &units {
            let (l, h) = u
                .interval
                .map_or((u.difference, u.difference), |i| (i.low, i.high));
            lo = lo.min(l);
            hi = hi.max(h);
        }
        if let Some(t) = c.all.t_interval {
            lo = lo.min(t.low);
            hi = hi.max(t.high);
        }
        let pad = ((hi - lo) * 0.06).max(0.05);
        let n = units.len().max(1) as f64;
        let mut chart = ChartBuilder::on(panel)
            .caption(
                format!(
                    "{name}: {} wins, {} ties, {} losses",
                    c.all.wins, c.all.ties, c.all.losses
                ),
                ("sans-serif", 17),
            )
            .margin(14)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(0.0..n + 1.0, (lo - pad)..(hi + pad))
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("child (sorted by difference)")
            .y_desc(unit_label)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y:.1}"))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(err)?;
        let colour = COLOURS[0];
        if let Some(t) = c.all.t_interval {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(0.0, t.low), (n + 1.0, t.high)],
                    colour.mix(0.15).filled(),
                )))
                .map_err(err)?;
        }
        for (y, style) in [
            (0.0, BLACK.stroke_width(1)),
            (c.all.mean, colour.stroke_width(2)),
        ] {
            chart
                .draw_series(LineSeries::new([(0.0, y), (n + 1.0, y)], style))
                .map_err(err)?;
        }
        for (k, u) in units.iter().enumerate() {
            let x = k as f64 + 1.0;
            let c = match u.verdict {
                Verdict::Win => COLOURS[2],
                Verdict::Loss => COLOURS[1],
                Verdict::Tie => RGBColor(128, 128, 128),
            };
            if let Some(i) = u.interval {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(x, i.low), (x, i.high)],
                        c.stroke_width(2),
                    )))
                    .map_err(err)?;
            }
            chart
                .draw_series(std::iter::once(Circle::new(
                    (x, u.difference),
                    4,
                    c.filled(),
                )))
                .map_err(err)?;
        }
        Ok(())
    })
}
