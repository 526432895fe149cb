//! The paper's Figs. 4 and 5 as SVG: per epoch the mean ± std band across runs, one line per
//! configuration (three rewards and the transfer into that model), one panel per user model;
//! and the per-child study's curves: per session, one line per policy, one panel per metric.

use crate::experiments::EpochMetrics;
use crate::grid::Curve;
use plotters::coord::Shift;
use plotters::prelude::*;

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

/// A mean line over its ± std band, named in the legend; `points` are (x, mean, std).
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

/// The per-child study: per session of the run, the mean over children (± std over seeds) of
/// each policy, one panel per metric.
pub fn per_child_svg(
    results: &[crate::per_child::ChildResult],
    subtitle: &str,
) -> Result<String, String> {
    use crate::per_child::{Arm, Metric, curve};
    panels_svg((1500, 480), subtitle, Metric::ALL.len(), |i, panel| {
        let metric = Metric::ALL[i];
        let curves: Vec<(Arm, Vec<crate::per_child::MeanStd>)> = Arm::ALL
            .iter()
            .map(|&a| (a, curve(results, a, metric)))
            .collect();
        let sessions = curves.first().map_or(1, |c| c.1.len()).max(2);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (_, c) in &curves {
            for m in c {
                lo = lo.min(m.mean - m.std);
                hi = hi.max(m.mean + m.std);
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
        for (i, (arm, c)) in curves.iter().enumerate() {
            let points: Vec<(f64, f64, f64)> = c
                .iter()
                .enumerate()
                .map(|(k, m)| ((k + 1) as f64, m.mean, m.std))
                .collect();
            draw_band(&mut chart, &points, COLOURS[i % COLOURS.len()], arm.name())?;
        }
        draw_legend(&mut chart)?;
        Ok(())
    })
}
