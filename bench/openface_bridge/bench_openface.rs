//! The OpenFace bridge's cost, two ways (bench/openface_bridge/rows_over_dds.sh runs both):
//!   bench_openface core [--rows N]   the core alone on full-width rows: rows per second
//!   bench_openface write --file F --rate R --seconds S   appends rows at R per second
//! Rows are as wide as OpenFace 2.2 writes them with every output on (714 columns: gaze, eye
//! landmarks, pose, 2-D and 3-D landmarks, shape parameters, AU intensities and presence).

use clap::{Parser, Subcommand};
use openface_bridge::{Bridge, OpenFaceBridgeParams, StampSource};
use std::io::Write as _;
use std::time::{Duration, Instant};

#[derive(Parser)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Time the core on full-width rows.
    Core {
        #[arg(long, default_value_t = 200_000)]
        rows: u32,
    },
    /// Append full-width rows to a CSV at a steady rate, as OpenFace does.
    Write {
        #[arg(long)]
        file: std::path::PathBuf,
        #[arg(long, default_value_t = 240.0)]
        rate: f64,
        #[arg(long, default_value_t = 20.0)]
        seconds: f64,
    },
}

/// OpenFace 2.2's header with every output on.
fn header() -> String {
    let mut n: Vec<String> = ["frame", "face_id", "timestamp", "confidence", "success"]
        .map(String::from)
        .to_vec();
    for eye in 0..2 {
        for a in ["x", "y", "z"] {
            n.push(format!("gaze_{eye}_{a}"));
        }
    }
    n.extend(["gaze_angle_x", "gaze_angle_y"].map(String::from));
    for a in ["x", "y", "X", "Y", "Z"] {
        n.extend((0..56).map(|i| format!("eye_lmk_{a}_{i}")));
    }
    n.extend(
        [
            "pose_Tx", "pose_Ty", "pose_Tz", "pose_Rx", "pose_Ry", "pose_Rz",
        ]
        .map(String::from),
    );
    for a in ["x", "y", "X", "Y", "Z"] {
        n.extend((0..68).map(|i| format!("{a}_{i}")));
    }
    n.extend(["p_scale", "p_rx", "p_ry", "p_rz", "p_tx", "p_ty"].map(String::from));
    n.extend((0..34).map(|i| format!("p_{i}")));
    let aus = [
        "01", "02", "04", "05", "06", "07", "09", "10", "12", "14", "15", "17", "20", "23", "25",
        "26",
    ];
    n.extend(aus.iter().chain(["45"].iter()).map(|a| format!("AU{a}_r")));
    n.extend(
        aus.iter()
            .chain(["28", "45"].iter())
            .map(|a| format!("AU{a}_c")),
    );
    n.join(", ")
}

/// Frame `k` (30 fps), values written as OpenFace writes them (3 decimals, 2 for AUs).
fn row(k: u32, width: usize) -> String {
    let mut r = format!("{k}, 0, {:.3}, 0.98, 1", f64::from(k - 1) / 30.0);
    for c in 5..width {
        let v = (f64::from(k) * 0.37 + c as f64 * 1.3).sin() * 100.0;
        let _ = std::fmt::Write::write_fmt(&mut r, format_args!(", {v:.3}"));
    }
    r
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Core { rows } => {
            let header = header();
            let width = header.split(',').count();
            // Rows made before timing, so only the bridge is measured.
            let lines: Vec<String> = (1..=1000).map(|k| row(k, width)).collect();
            let params = OpenFaceBridgeParams {
                csv_path: "-".into(),
                ..Default::default()
            };
            let mut bridge = Bridge::new(&params, StampSource::OpenFace);
            bridge.line(&header, 1, 0)?;
            let started = Instant::now();
            let mut published = 0u64;
            for i in 0..rows {
                let k = i as usize % lines.len();
                if k == 0 && i > 0 {
                    // A new run every 1000 rows: a (face, frame) read twice in a run is a repeat.
                    bridge.line(&header, u64::from(i) + 1, i64::from(i))?;
                }
                bridge.line(&lines[k], u64::from(i) + 2, i64::from(i))?;
                bridge.end_of_read(i64::from(i));
                for m in bridge.due(i64::MAX) {
                    published += std::hint::black_box(m).features.len() as u64 / 32;
                }
            }
            let secs = started.elapsed().as_secs_f64();
            let per_row_us = secs / f64::from(rows) * 1e6;
            // 8 cameras at 30 fps: the share of one core the core alone needs.
            let share = 240.0 * per_row_us * 1e-6 * 100.0;
            println!(
                "{{\"columns\": {width}, \"rows\": {rows}, \"published\": {published}, \"rows_per_s\": {:.0}, \"us_per_row\": {per_row_us:.2}, \"core_share_at_240_rows_per_s_pct\": {share:.3}}}",
                f64::from(rows) / secs
            );
        }
        Command::Write {
            file,
            rate,
            seconds,
        } => {
            let header = header();
            let width = header.split(',').count();
            let mut f = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&file)?;
            writeln!(f, "{header}")?;
            let every = Duration::from_secs_f64(1.0 / rate);
            let start = Instant::now();
            let total = (rate * seconds) as u32;
            for k in 1..=total {
                writeln!(f, "{}", row(k, width))?;
                f.flush()?;
                let due = every * k;
                if let Some(wait) = due.checked_sub(start.elapsed()) {
                    std::thread::sleep(wait);
                }
            }
            println!(
                "{{\"written\": {total}, \"seconds\": {:.2}}}",
                start.elapsed().as_secs_f64()
            );
        }
    }
    Ok(())
}
