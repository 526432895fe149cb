//! `bag record`: taps the suite's topics over DDS and writes every message into one MCAP file
//! (`<output>.partial` until a clean exit renames it). A chunk is closed and handed to the OS
//! at least every `flush_interval_s`, so a killed recorder loses at most that much; SIGINT or
//! SIGTERM drains the queue and writes the summary.

use anyhow::{Context as _, bail};
use bag::params::RecorderParams;
use bag::qos::offered_qos_yaml;
use bag::suite::suite_type;
use bag::{BagWriter, Compression, WriterOptions};
use node_shell::{NodeShell, ShellOptions};
use qt_therapy_msgs::topics::{TopicInfo, all_topics};
use std::path::PathBuf;
use std::time::Duration;
use tokio::sync::mpsc;

#[derive(clap::Args, Debug)]
pub struct RecordArgs {
    /// The bag to write (an .mcap file).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Topics to record [default: the parameter file's list; empty = all]
    #[arg(long, num_args = 1..)]
    pub topics: Vec<String>,
    /// Record every topic of the suite, whatever the parameter file lists.
    #[arg(long, conflicts_with = "topics")]
    pub all: bool,
    /// zstd, lz4 or none [default: the parameter file's]
    #[arg(long)]
    pub compression: Option<Compression>,
    #[command(flatten)]
    pub shell: ShellOptions,
}

/// The suite topics named in `wanted` (all when empty); an unknown name is an error.
fn select_topics(wanted: &[String]) -> anyhow::Result<Vec<TopicInfo>> {
    let all = all_topics();
    if wanted.is_empty() {
        return Ok(all);
    }
    let mut chosen = Vec::new();
    for name in wanted {
        match all.iter().find(|t| t.name == name.as_str()) {
            Some(t) => chosen.push(t.clone()),
            None => {
                let known: Vec<&str> = all.iter().map(|t| t.name).collect();
                bail!("{name:?} is not a topic of the suite; known topics: {known:?}");
            }
        }
    }
    Ok(chosen)
}

fn writer_options(
    params: &RecorderParams,
    cli: Option<Compression>,
) -> anyhow::Result<WriterOptions> {
    let compression = match cli {
        Some(c) => c,
        None => params
            .compression
            .parse()
            .map_err(|e: String| anyhow::anyhow!("bag_recorder.compression: {e}"))?,
    };
    if params.chunk_size_bytes < 1 {
        bail!(
            "bag_recorder.chunk_size_bytes = {} must be positive",
            params.chunk_size_bytes
        );
    }
    Ok(WriterOptions {
        compression,
        chunk_size: params.chunk_size_bytes as u64,
        compression_threads: u32::try_from(params.compression_threads).with_context(|| {
            format!(
                "bag_recorder.compression_threads = {}",
                params.compression_threads
            )
        })?,
    })
}

pub async fn run(args: RecordArgs) -> anyhow::Result<()> {
    let (mut shell, params): (NodeShell, RecorderParams) =
        NodeShell::start("bag_recorder", &args.shell)?;
    if !(params.flush_interval_s > 0.0 && params.flush_interval_s <= 60.0) {
        bail!(
            "bag_recorder.flush_interval_s = {} is not in (0, 60]",
            params.flush_interval_s
        );
    }
    let wanted = if args.all {
        Vec::new()
    } else if args.topics.is_empty() {
        params.topics.clone()
    } else {
        args.topics.clone()
    };
    let topics = select_topics(&wanted)?;
    // A recorded session is never overwritten by the next one.
    if args.output.exists() {
        bail!("{} exists; record to a new name", args.output.display());
    }
    let options = writer_options(&params, args.compression)?;
    let mut writer = BagWriter::create(&args.output, &options)?;
    let capacity = usize::try_from(params.queue_capacity.max(1)).unwrap_or(4096);
    let (tx, mut rx) = mpsc::channel(capacity);
    let mut taps = Vec::new();
    for t in &topics {
        let Some(ty) = suite_type(&t.type_name) else {
            bail!(
                "{} has type {}, which the recorder does not know",
                t.name,
                t.type_name
            );
        };
        let id = writer.add_channel(
            t.name,
            &t.type_name,
            &t.schema_text,
            &offered_qos_yaml(t.qos),
        )?;
        taps.push(ty.tap(&mut shell, t.name, t.qos, id, tx.clone())?);
    }
    drop(tx);
    // Schemas and channels reach the disk at once, so even an empty recording is readable.
    writer.flush_chunk()?;
    tracing::info!(
        output = %args.output.display(),
        topics = topics.len(),
        compression = ?options.compression,
        "recording"
    );
    let progress = indicatif::ProgressBar::new_spinner();
    let stop = shell.shutdown_signal();
    tokio::pin!(stop);
    let mut flush = tokio::time::interval(Duration::from_secs_f64(params.flush_interval_s));
    loop {
        tokio::select! {
            _ = &mut stop => break,
            _ = flush.tick() => {
                // What the readers queued before the tick belongs in this flush.
                while let Ok(sample) = rx.try_recv() {
                    writer.write_cdr(sample.channel_id, sample.stamp, &sample.payload)?;
                }
                writer.flush_chunk()?;
                progress.set_message(format!("{} messages", writer.message_count()));
                progress.tick();
            }
            Some(sample) = rx.recv() => {
                writer.write_cdr(sample.channel_id, sample.stamp, &sample.payload)?;
            }
        }
    }
    for t in &taps {
        t.abort();
    }
    // What the readers already queued is part of the session.
    while let Ok(sample) = rx.try_recv() {
        writer.write_cdr(sample.channel_id, sample.stamp, &sample.payload)?;
    }
    for t in taps {
        let _ = t.await;
    }
    progress.finish_and_clear();
    let messages = writer.message_count();
    writer
        .finish()
        .with_context(|| format!("finishing {}", args.output.display()))?;
    tracing::info!(output = %args.output.display(), messages, "bag written");
    println!(
        "{}",
        serde_json::json!({"event": "recorded", "output": args.output, "messages": messages})
    );
    shell.stop().await;
    Ok(())
}
