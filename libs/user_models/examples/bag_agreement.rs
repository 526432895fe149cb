//! Reads session bags as user-model records and compares each sequence's per-second
//! engagement, recomputed from the ExpectedEngagement topic over the robot's talking period,
//! with the values the game manager put into its SequenceResult during the session.
//!   cargo run -p user_models --example bag_agreement -- out/session-*/session.mcap

use anyhow::Context;
use bag_file::BagReader;
use qt_therapy_msgs::SequenceResult;
use qt_therapy_msgs::topics::SEQUENCE_RESULT;
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let paths: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    anyhow::ensure!(!paths.is_empty(), "usage: bag_agreement BAG...");
    let (mut same, mut total, mut seconds) = (0usize, 0usize, 0usize);
    for path in &paths {
        let read = user_models::data::bag::read_bag(path)
            .with_context(|| format!("reading {}", path.display()))?;
        for w in &read.warnings {
            println!("warning: {w}");
        }
        let reader = BagReader::open(path)?;
        let results = reader.messages::<SequenceResult>(SEQUENCE_RESULT.name)?;
        let mut records = read.records.clone();
        records.sort_by(|a, b| a.time.total_cmp(&b.time));
        for (r, m) in records.iter().zip(&results) {
            let game: Vec<f64> = m
                .message
                .engagement_per_second
                .iter()
                .map(|v| f64::from(*v))
                .collect();
            total += 1;
            seconds += game.len();
            let agree = game == r.engagement_per_second;
            same += usize::from(agree);
            println!(
                "{} seq {:>2} L{} F{} PS {:+} O {:+} rt {:.2} s  seconds: bag {:>2}, game {:>2}  E bag {:+.3} game {:+.3}  {}",
                r.session_id,
                m.message.sequence_index,
                r.level.get(),
                u8::from(r.feedback),
                r.previous_score,
                r.outcome.sign(),
                r.response_time,
                r.engagement_per_second.len(),
                game.len(),
                r.engagement.unwrap_or(f64::NAN),
                m.message.engagement,
                if agree { "same" } else { "DIFFERENT" }
            );
        }
    }
    println!(
        "{same} of {total} sequences ({seconds} seconds) have the game manager's per-second values exactly"
    );
    Ok(())
}
