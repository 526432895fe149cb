//! OpenFace's side and a reader's side of the OpenFace bridge, for tests/openface_bridge_dds.rs.
//!
//! `write` is a stand-in for OpenFace 2.2's `FeatureExtraction` writing its CSV, with the habits
//! of the real program (OpenFace, github TadasBaltrusaitis/OpenFace):
//! - `lib/local/Utilities/src/RecorderCSV.cpp` (`RecorderCSV::Open`, `WriteLine`): the file is
//!   opened with `std::ofstream(path, std::ios_base::out)` (an existing file is truncated in
//!   place: same inode); each row ends with `"\n"`, not `std::endl`, so rows reach the file
//!   through the stream's buffer (libstdc++: BUFSIZ, 8192 bytes) in pieces that cut lines;
//!   fixed-point values (timestamp 3 decimals, confidence 2, pose 1 and 3, gaze 6 and 3, AU
//!   intensities 2, AU presence 1).
//! - `exe/FeatureExtraction/FeatureExtraction.cpp` and `lib/local/Utilities/src/SequenceCapture.cpp`:
//!   a webcam's timestamp is the time since capture started when the frame was grabbed, each
//!   frame at the camera's pace (late on a loaded machine); a video file's is its frame number
//!   over the video's rate, processed as fast as the machine goes; when the run ends the recorder is closed (flushed), then, with AUs on,
//!   `FaceAnalyser::PostprocessOutputFile` runs.
//! - `lib/local/FaceAnalyser/src/FaceAnalyser.cpp` (`PostprocessOutputFile`): the whole CSV is
//!   read, the same path opened again with `std::ofstream(.., std::ios_base::out)` (truncated,
//!   same inode), the header written back as it was and every row again: its fields split on
//!   ',', each right-trimmed and written after `", "` (the leading space kept, so the file gets
//!   longer), the AU columns replaced by post-processed values (2 decimals), `std::endl` (a
//!   flush) after every line.
//!
//! The frame number is written in `pose_Tx` so a reader can tell frames apart. One JSON line
//! per frame on standard output: its number, OpenFace timestamp and the wall clock it was
//! produced at; `rewrite` when the rewrite starts.
//!
//! `read` subscribes to /qt_therapy/openface/features with the suite's QoS for it (the
//! engagement classifier's: best effort, keep last 10) and prints each frame it receives with
//! the wall clock it arrived at.

use clap::{Parser, Subcommand};
use node_shell::{NoParameters, NodeShell, ShellOptions, now_nanos};
use qt_therapy_msgs::topics::OPENFACE_FEATURES;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(Parser)]
struct Cli {
    #[command(subcommand)]
    role: Role,
}

#[derive(Subcommand)]
enum Role {
    /// Write an OpenFace run to `out` as FeatureExtraction does.
    Write {
        #[arg(long)]
        out: PathBuf,
        /// Frames in the run.
        #[arg(long)]
        frames: u32,
        /// The camera's frames per second; 0: a video file processed as fast as possible
        /// (timestamps still 1/30 s apart).
        #[arg(long, default_value_t = 30.0)]
        fps: f64,
        /// The first frames without a face (`success` 0), as when the child is not yet seated.
        #[arg(long, default_value_t = 0)]
        lost_first: u32,
        /// No post-processing rewrite at the end (FeatureExtraction without -aus, or killed).
        #[arg(long)]
        no_rewrite: bool,
    },
    /// Print every OpenFaceFeatures received until SIGINT/SIGTERM.
    Read {
        #[command(flatten)]
        shell: ShellOptions,
    },
}

const AUS_R: [&str; 17] = [
    "01", "02", "04", "05", "06", "07", "09", "10", "12", "14", "15", "17", "20", "23", "25", "26",
    "45",
];
const AUS_C: [&str; 18] = [
    "01", "02", "04", "05", "06", "07", "09", "10", "12", "14", "15", "17", "20", "23", "25", "26",
    "28", "45",
];

/// OpenFace 2.2's header with -pose -aus -gaze: `", "` between names.
fn header() -> String {
    let mut names: Vec<String> = ["frame", "face_id", "timestamp", "confidence", "success"]
        .map(String::from)
        .to_vec();
    for eye in 0..2 {
        for axis in ["x", "y", "z"] {
            names.push(format!("gaze_{eye}_{axis}"));
        }
    }
    names.extend(["gaze_angle_x", "gaze_angle_y"].map(String::from));
    for axis in ["x", "y", "X", "Y", "Z"] {
        names.extend((0..56).map(|i| format!("eye_lmk_{axis}_{i}")));
    }
    names.extend(
        [
            "pose_Tx", "pose_Ty", "pose_Tz", "pose_Rx", "pose_Ry", "pose_Rz",
        ]
        .map(String::from),
    );
    names.extend(AUS_R.iter().map(|au| format!("AU{au}_r")));
    names.extend(AUS_C.iter().map(|au| format!("AU{au}_c")));
    names.join(", ")
}

/// Fields before the AU columns (5 + 8 gaze + 280 eye landmarks + 6 pose).
const AU_COLUMN: usize = 5 + 8 + 280 + 6;

/// One row as RecorderCSV::WriteLine writes it (OpenFace 2.2: `", "` between fields).
fn row(frame: u32, timestamp: f64, face: bool) -> String {
    let mut r = format!(
        "{frame}, 0, {timestamp:.3}, {:.2}, {}",
        if face { 0.98 } else { 0.03 },
        u8::from(face)
    );
    let v = |x: f64| if face { x } else { 0.0 };
    for g in [0.02, 0.1, -0.99, -0.03, 0.1, -0.99] {
        let _ = write!(r, ", {:.6}", v(g));
    }
    let _ = write!(r, ", {:.3}, {:.3}", v(0.0), v(0.1));
    for k in 0..280 {
        let _ = write!(r, ", {:.1}", v(300.0 + f64::from(k % 56)));
    }
    let _ = write!(
        r,
        ", {:.1}, {:.1}, {:.1}",
        f64::from(frame),
        v(20.0),
        v(450.0)
    );
    let _ = write!(r, ", {:.3}, {:.3}, {:.3}", v(0.05), v(-0.02), v(0.01));
    for k in 0..AUS_R.len() {
        let _ = write!(r, ", {:.2}", v(0.3 + 0.1 * f64::from(k as u32 % 4)));
    }
    for k in 0..AUS_C.len() {
        let _ = write!(r, ", {:.1}", v(f64::from(u8::from(k % 3 == 0))));
    }
    r
}

fn write_run(
    out: &PathBuf,
    frames: u32,
    fps: f64,
    lost_first: u32,
    rewrite: bool,
) -> anyhow::Result<()> {
    // std::ofstream(path, std::ios_base::out): created, or truncated in place.
    let file = std::fs::OpenOptions::new()
        .create(true)
        .write(true)
        .truncate(true)
        .open(out)?;
    // std::filebuf's buffer: rows reach the file 8 KiB at a time, lines cut anywhere.
    let mut csv = std::io::BufWriter::with_capacity(8192, file);
    // "\n", as RecorderCSV writes it (not std::endl: no flush).
    writeln!(csv, "{}", header())?;
    let start = Instant::now();
    for k in 1..=frames {
        // A video file's frames are timed by their number; a webcam's by the clock when the
        // frame was grabbed (SequenceCapture: ticks since capture started), so a frame grabbed
        // late on a loaded machine carries its late time.
        let mut timestamp = f64::from(k - 1) / 30.0;
        if fps > 0.0 {
            let at = Duration::from_secs_f64(f64::from(k - 1) / fps);
            if let Some(wait) = at.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
            timestamp = (start.elapsed().as_secs_f64() * 1000.0).round() / 1000.0;
        }
        writeln!(csv, "{}", row(k, timestamp, k > lost_first))?;
        println!(
            "{}",
            serde_json::json!({"event": "frame", "frame": k, "timestamp": timestamp, "wall_ns": now_nanos(), "face": k > lost_first})
        );
    }
    // RecorderCSV::Close.
    csv.flush()?;
    drop(csv);
    if rewrite {
        println!(
            "{}",
            serde_json::json!({"event": "rewrite", "wall_ns": now_nanos()})
        );
        postprocess(out)?;
    }
    println!(
        "{}",
        serde_json::json!({"event": "end", "wall_ns": now_nanos()})
    );
    Ok(())
}

/// FaceAnalyser::PostprocessOutputFile.
fn postprocess(out: &PathBuf) -> anyhow::Result<()> {
    let contents = std::fs::read_to_string(out)?;
    let mut lines = contents.lines();
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .truncate(true)
        .open(out)?;
    // Unbuffered writes: every std::endl flushes.
    file.write_all(format!("{}\n", lines.next().unwrap_or_default()).as_bytes())?;
    for line in lines {
        let tokens: Vec<&str> = line.split(',').collect();
        let mut text = tokens[0].trim_end().to_string();
        for (t, token) in tokens.iter().enumerate().skip(1) {
            if (AU_COLUMN..AU_COLUMN + AUS_R.len() + AUS_C.len()).contains(&t) {
                // A post-processed (smoothed, offset) AU value.
                let value: f64 = token.trim().parse().unwrap_or(0.0);
                let _ = write!(text, ", {:.2}", (value * 0.9).max(0.0));
            } else {
                let _ = write!(text, ", {}", token.trim_end());
            }
        }
        text.push('\n');
        file.write_all(text.as_bytes())?;
    }
    Ok(())
}

async fn read(options: &ShellOptions) -> anyhow::Result<()> {
    let (mut shell, _): (NodeShell, NoParameters) = NodeShell::start("openface_reader", options)?;
    let mut frames = shell.subscribe(OPENFACE_FEATURES, 512)?;
    println!("{}", serde_json::json!({"event": "ready"}));
    let stop = shell.shutdown_signal();
    tokio::pin!(stop);
    loop {
        tokio::select! {
            _ = &mut stop => break,
            Some(m) = frames.recv() => println!(
                "{}",
                serde_json::json!({
                    "event": "frame",
                    "frame_id": m.header.frame_id,
                    "face_id": m.face_id,
                    "frame": m.features[0],
                    "stamp_ns": m.header.stamp.to_nanos(),
                    "recv_ns": now_nanos(),
                })
            ),
        }
    }
    shell.stop().await;
    Ok(())
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    match Cli::parse().role {
        Role::Write {
            out,
            frames,
            fps,
            lost_first,
            no_rewrite,
        } => write_run(&out, frames, fps, lost_first, !no_rewrite),
        Role::Read { shell } => read(&shell).await,
    }
}
