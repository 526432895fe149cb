//! The figures of counterfactual evaluation: the logged policy's actual value beside the
//! importance-sampling estimates of the new one, with their 95 % intervals; and for the
//! validation in simulation, every seed's interval against the exact value.

use crate::off_policy::{Estimate, Estimates, Evaluation, Validation};
use crate::plots::panels_svg;
use plotters::prelude::*;

const LOGGED: RGBColor = RGBColor(90, 90, 90);
const WEIGHTED: RGBColor = RGBColor(31, 119, 180);
const PER_DECISION: RGBColor = RGBColor(214, 39, 40);
const TRUTH: RGBColor = RGBColor(44, 160, 44);

fn err<E: std::fmt::Debug>(e: E) -> String {
    format!("{e:?}")
}

fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08).max(0.1);
    (lo - pad, hi + pad)
}

fn rows(e: &Estimates) -> Vec<(&'static str, Option<Estimate>, RGBColor)> {
    vec![
        ("logged policy (actual)", Some(e.logged), LOGGED),
        ("new policy: weighted IS", e.weighted_is, WEIGHTED),
        (
            "new policy: per-decision IS",
            Some(e.per_decision_is),
            PER_DECISION,
        ),
    ]
}

/// Two panels (discounted return, score): a point and its 95 % interval per estimator.
pub fn evaluation_svg(e: &Evaluation, subtitle: &str) -> Result<String, String> {
    let quantities = [
        ("discounted return per session", &e.discounted_return),
        ("score L·O per session", &e.score),
    ];
    panels_svg((1100, 360), subtitle, 2, |i, panel| {
        let (name, estimates) = quantities[i];
        let rows = rows(estimates);
        let (lo, hi) = span(
            rows.iter()
                .flat_map(|(_, x, _)| x.iter().flat_map(|x| [x.low, x.high, x.value])),
        );
        let mut chart = ChartBuilder::on(panel)
            .caption(name, ("sans-serif", 18))
            .margin(14)
            .x_label_area_size(36)
            .y_label_area_size(190)
            .build_cartesian_2d(lo..hi, -0.5..(rows.len() as f64 - 0.5))
            .map_err(err)?;
        let labels: Vec<&str> = rows.iter().map(|r| r.0).collect();
        chart
            .configure_mesh()
            .y_labels(rows.len())
            .y_label_formatter(&|y| {
                let i = y.round();
                if (y - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < labels.len() {
                    labels[labels.len() - 1 - i as usize].to_string()
                } else {
                    String::new()
                }
            })
            .x_label_formatter(&|x| format!("{x:.1}"))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(err)?;
        for (i, (_, x, colour)) in rows.iter().enumerate() {
            let y = (rows.len() - 1 - i) as f64;
            let Some(x) = x else { continue };
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(x.low, y), (x.high, y)],
                    colour.stroke_width(3),
                )))
                .map_err(err)?;
            chart
                .draw_series(std::iter::once(Circle::new(
                    (x.value, y),
                    6,
                    colour.filled(),
                )))
                .map_err(err)?;
        }
        Ok(())
    })
}

/// Per estimator of the discounted return, each seed's interval (sorted by estimate) and the
/// exact value as a line: the coverage the docs report, as a picture.
pub fn validation_svg(v: &Validation, subtitle: &str) -> Result<String, String> {
    let truth = v.truth.discounted_return;
    type Pick = fn(&Evaluation) -> Option<Estimate>;
    let picks: [(&str, Pick, RGBColor); 2] = [
        ("weighted IS", |e| e.discounted_return.weighted_is, WEIGHTED),
        (
            "per-decision IS",
            |e| Some(e.discounted_return.per_decision_is),
            PER_DECISION,
        ),
    ];
    panels_svg((1100, 420), subtitle, 2, |i, panel| {
        let (name, pick, colour) = picks[i];
        let mut intervals: Vec<Estimate> = v.per_seed.iter().filter_map(pick).collect();
        intervals.sort_by(|a, b| a.value.total_cmp(&b.value));
        let covered = intervals.iter().filter(|x| x.contains(truth)).count();
        let (lo, hi) = span(
            intervals
                .iter()
                .flat_map(|x| [x.low, x.high])
                .chain([truth, v.logging_truth.discounted_return]),
        );
        let n = intervals.len().max(1);
        let mut chart = ChartBuilder::on(panel)
            .caption(
                format!(
                    "{name}: {covered} of {} intervals hold the truth",
                    intervals.len()
                ),
                ("sans-serif", 18),
            )
            .margin(14)
            .x_label_area_size(36)
            .y_label_area_size(50)
            .build_cartesian_2d(0.0..n as f64 + 1.0, lo..hi)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("seed (sorted by estimate)")
            .y_desc("discounted return per session")
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y:.1}"))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(err)?;
        for (i, x) in intervals.iter().enumerate() {
            let c = if x.contains(truth) { colour } else { BLACK };
            let xi = i as f64 + 1.0;
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(xi, x.low), (xi, x.high)],
                    c.mix(0.6).stroke_width(2),
                )))
                .map_err(err)?;
            chart
                .draw_series(std::iter::once(Circle::new((xi, x.value), 2, c.filled())))
                .map_err(err)?;
        }
        for (value, label, c) in [
            (truth, "new policy's exact value", TRUTH),
            (
                v.logging_truth.discounted_return,
                "logging policy's exact value",
                LOGGED,
            ),
        ] {
            chart
                .draw_series(LineSeries::new(
                    [(0.0, value), (n as f64 + 1.0, value)],
                    c.stroke_width(2),
                ))
                .map_err(err)?
                .label(label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(3))
                });
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(err)?;
        Ok(())
    })
}
