//! The paper's Figs. 4 and 5: mean ± std across runs per epoch, one line per configuration,
//! one panel per user model; score (Fig. 4) or engagement (Fig. 5).

use crate::experiments::Curve;
use plotters::prelude::*;

const COLOURS: [RGBColor; 5] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
];

fn err<E: std::fmt::Debug>(e: E) -> String {
    format!("{e:?}")
}

/// `score` true: Fig. 4 (mean accumulated score); false: Fig. 5 (mean engagement).
pub fn curves_svg(curves: &[Curve], models: usize, score: bool) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1200, 460)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let panels = root.split_evenly((1, models.max(1)));
        for (m, panel) in panels.iter().enumerate() {
            let mine: Vec<&Curve> = curves.iter().filter(|c| c.config.model == m).collect();
            let epochs = mine.iter().map(|c| c.mean.len()).max().unwrap_or(1).max(2);
            let value =
                |e: &crate::experiments::EpochMetrics| if score { e.score } else { e.engagement };
            let (lo, hi) = mine
                .iter()
                .flat_map(|c| {
                    c.mean
                        .iter()
                        .zip(&c.std)
                        .map(|(a, s)| (value(a) - value(s), value(a) + value(s)))
                })
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), (a, b)| {
                    (l.min(a), h.max(b))
                });
            let (lo, hi) = if lo.is_finite() {
                (
                    lo - 0.05 * (hi - lo).abs().max(0.1),
                    hi + 0.05 * (hi - lo).abs().max(0.1),
                )
            } else {
                (0.0, 1.0)
            };
            let mut chart = ChartBuilder::on(panel)
                .caption(
                    format!(
                        "M{} ({})",
                        m + 1,
                        if score {
                            "performance score"
                        } else {
                            "engagement"
                        }
                    ),
                    ("sans-serif", 18),
                )
                .margin(12)
                .x_label_area_size(38)
                .y_label_area_size(50)
                .build_cartesian_2d(1.0..epochs as f64, lo..hi)
                .map_err(err)?;
            chart
                .configure_mesh()
                .x_desc("epoch (100 sessions)")
                .y_desc(if score {
                    "mean score per session"
                } else {
                    "mean engagement"
                })
                .draw()
                .map_err(err)?;
            for (i, c) in mine.iter().enumerate() {
                let colour = COLOURS[i % COLOURS.len()];
                let upper: Vec<(f64, f64)> = c
                    .mean
                    .iter()
                    .zip(&c.std)
                    .enumerate()
                    .map(|(e, (a, s))| ((e + 1) as f64, value(a) + value(s)))
                    .collect();
                let lower: Vec<(f64, f64)> = c
                    .mean
                    .iter()
                    .zip(&c.std)
                    .enumerate()
                    .rev()
                    .map(|(e, (a, s))| ((e + 1) as f64, value(a) - value(s)))
                    .collect();
                let band: Vec<(f64, f64)> = upper.into_iter().chain(lower).collect();
                chart
                    .draw_series(std::iter::once(Polygon::new(
                        band,
                        colour.mix(0.15).filled(),
                    )))
                    .map_err(err)?;
                chart
                    .draw_series(LineSeries::new(
                        c.mean
                            .iter()
                            .enumerate()
                            .map(|(e, a)| ((e + 1) as f64, value(a))),
                        colour.stroke_width(2),
                    ))
                    .map_err(err)?
                    .label(c.config.name.clone())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(3))
                    });
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::LowerRight)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()
                .map_err(err)?;
        }
        root.present().map_err(err)?;
    }
    Ok(svg)
}
