//! The paper's Fig. 3: (a) users in the PCA plane coloured by cluster; (b) per cluster and
//! level, P(success|L) and E|L with their standard deviation across users.

use plotters::prelude::*;
use std::path::Path;
use user_models::model::UserModelFile;

const COLOURS: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
];

/// A figure that could not be drawn or written.
#[derive(Debug, thiserror::Error)]
#[error("figure: {0}")]
pub struct PlotError(String);

fn err<E: std::fmt::Debug>(e: E) -> PlotError {
    PlotError(format!("{e:?}"))
}

/// Fig. 3a as SVG.
pub fn clusters_svg(file: &UserModelFile) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (560, 460)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let xs: Vec<f64> = file.users.iter().map(|u| u.projection[0]).collect();
        let ys: Vec<f64> = file.users.iter().map(|u| u.projection[1]).collect();
        let span = |v: &[f64]| {
            let (lo, hi) = v
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                    (a.min(*x), b.max(*x))
                });
            let pad = ((hi - lo) * 0.15).max(0.05);
            (lo - pad)..(hi + pad)
        };
        let mut chart = ChartBuilder::on(&root)
            .caption("User clusters in PCA space (Fig. 3a)", ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(span(&xs), span(&ys))
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("first principal component (FPC)")
            .y_desc("second principal component (SPC)")
            .draw()
            .map_err(err)?;
        for c in &file.clusters {
            let colour = COLOURS[c.cluster % COLOURS.len()];
            chart
                .draw_series(
                    file.users
                        .iter()
                        .filter(|u| u.cluster == c.cluster)
                        .map(|u| {
                            Circle::new((u.projection[0], u.projection[1]), 6, colour.filled())
                        }),
                )
                .map_err(err)?
                .label(format!("cluster {} ({} users)", c.cluster, c.users.len()))
                .legend(move |(x, y)| Circle::new((x + 6, y), 5, colour.filled()));
            if let Some(centre) = file.centres.get(c.cluster) {
                chart
                    .draw_series(std::iter::once(Cross::new(
                        (centre[0], centre[1]),
                        9,
                        colour.stroke_width(3),
                    )))
                    .map_err(err)?;
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    Ok(svg)
}

/// Fig. 3b as SVG: two panels, P(success|L) and E|L, a bar per cluster with ±1 std.
pub fn levels_svg(file: &UserModelFile) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 400)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let panels = root.split_evenly((1, 2));
        let k = file.clusters.len().max(1) as f64;
        for (panel, (title, range, pick)) in panels.iter().zip([
            ("P(success | L)", 0.0..1.45, 0usize),
            ("engagement E | L", -1.1..1.6, 1usize),
        ]) {
            let mut chart = ChartBuilder::on(panel)
                .caption(title, ("sans-serif", 18))
                .margin(12)
                .x_label_area_size(35)
                .y_label_area_size(60)
                .build_cartesian_2d(0.5..3.5, range)
                .map_err(err)?;
            chart
                .configure_mesh()
                .x_labels(3)
                .x_label_formatter(&|x| format!("L{:.0}", x))
                .y_desc("mean over sequences, ±1 std across users")
                .disable_x_mesh()
                .draw()
                .map_err(err)?;
            for c in &file.clusters {
                let colour = COLOURS[c.cluster % COLOURS.len()];
                let width = 0.7 / k;
                let offset = -0.35 + width * (c.cluster as f64 + 0.5);
                let values: Vec<(f64, f64, f64)> = c
                    .levels
                    .iter()
                    .map(|l| {
                        let (m, s) = if pick == 0 {
                            (l.success_mean, l.success_std)
                        } else {
                            (l.engagement_mean, l.engagement_std)
                        };
                        (f64::from(l.level) + offset, m, s)
                    })
                    .collect();
                chart
                    .draw_series(values.iter().map(|(x, m, _)| {
                        Rectangle::new(
                            [(x - width / 2.0, 0.0), (x + width / 2.0, *m)],
                            colour.mix(0.75).filled(),
                        )
                    }))
                    .map_err(err)?
                    .label(format!("cluster {} ({} users)", c.cluster, c.users.len()))
                    .legend(move |(x, y)| {
                        Rectangle::new([(x, y - 5), (x + 12, y + 5)], colour.filled())
                    });
                chart
                    .draw_series(values.iter().map(|(x, m, s)| {
                        // The whiskers stop at the quantity's own range.
                        let (low, high) = if pick == 0 { (0.0, 1.0) } else { (-1.0, 1.0) };
                        ErrorBar::new_vertical(
                            *x,
                            (m - s).max(low),
                            *m,
                            (m + s).min(high),
                            BLACK.stroke_width(2),
                            8,
                        )
                    }))
                    .map_err(err)?;
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()
                .map_err(err)?;
        }
        root.present().map_err(err)?;
    }
    Ok(svg)
}

/// Writes `<dir>/clusters.{svg,png}` and `<dir>/levels.{svg,png}`.
pub fn write_figures(
    file: &UserModelFile,
    dir: &Path,
) -> Result<Vec<std::path::PathBuf>, PlotError> {
    let mut written = Vec::new();
    for (name, svg) in [
        ("clusters", clusters_svg(file)?),
        ("levels", levels_svg(file)?),
    ] {
        let (s, p) = figures::write_svg_and_png(&dir.join(name), &svg)
            .map_err(|e| PlotError(e.to_string()))?;
        written.push(s);
        written.push(p);
    }
    Ok(written)
}
