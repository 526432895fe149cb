//! The bag recorder's run loop, on any bus (`node_shell::Bus`: DDS for `bag record`, in
//! process in the cross-node tests): taps the suite's topics and writes every message into one MCAP file
//! (`<output>.partial` until a clean exit renames it). A chunk is closed and handed to the OS
//! at least every `flush_interval_s`, so a killed recorder loses at most that much; SIGINT or
//! SIGTERM drains the queue and writes the summary. A recorder started on the output of one
//! that was killed (a launcher's respawn) carries the dead one's `.partial` file over into its
//! own bag first, so the session stays one bag and nothing already on disk is overwritten.
//! Transient-local topics hand the new recorder their history again; what it carried over is
//! not written twice. Log times are the recorder's steady clock (RustDDS's receive time, which
//! the suite's patch keeps there), so they stay in order when the wall clock is stepped; each
//! step the recorder sees is written into the bag (`bag_file::CLOCK_STEP`), and `bag info`
//! tells it.

use crate::dds_types::bus_type;
use crate::params::RecorderParams;
use anyhow::{Context as _, bail};
use bag_file::qos::offered_qos_yaml;
use bag_file::{BagReader, BagWriter, Compression, Stamp, WriterOptions, partial_path};
use node_shell::{Bus, Clock};
use qt_therapy_msgs::topics::{QosKind, TopicInfo, all_topics};
use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio::sync::mpsc;

/// A topic found on the bus beside the suite's (over DDS with `--all`: any other topic of the
/// ROS 2 graph), to record as its publisher sends it.
#[derive(Debug, Clone)]
pub struct ForeignTopic {
    pub topic: String,
    /// `pkg/msg/Type`.
    pub type_name: String,
    /// Its definition as rosbag2 stores it (`ros2msg`), or why there is none: the bag then
    /// says so (`bag info`), and its messages are recorded all the same.
    pub definition: Result<String, String>,
    /// The QoS class nearest to what its publisher offers.
    pub qos: QosKind,
}

/// One message of a foreign topic, as it arrived.
#[derive(Debug, Clone)]
pub struct ForeignSample {
    pub topic: String,
    pub stamp: Stamp,
    /// CDR with its encapsulation header.
    pub payload: Vec<u8>,
}

/// What finds the topics beside the suite's and taps them (their samples go to the receiver
/// given to [`run`]); asked at every flush.
pub trait Discover<B> {
    /// The topics found since the last call (their taps already started).
    fn discover(&mut self, bus: &mut B) -> impl std::future::Future<Output = Vec<ForeignTopic>>;
}

/// No topics beside the suite's (the in-process bus, or a recording of chosen topics).
pub struct SuiteOnly;

impl<B> Discover<B> for SuiteOnly {
    async fn discover(&mut self, _bus: &mut B) -> Vec<ForeignTopic> {
        Vec::new()
    }
}

/// The next foreign sample, or never without a receiver.
async fn next_foreign(rx: &mut Option<mpsc::Receiver<ForeignSample>>) -> Option<ForeignSample> {
    match rx {
        Some(rx) => rx.recv().await,
        None => std::future::pending().await,
    }
}

/// The node's name on the graph (and its parameter file's).
pub const NODE: &str = "bag_recorder";

/// What to record where.
#[derive(Debug, Clone)]
pub struct Recording {
    /// The bag to write (an .mcap file); it must not exist.
    pub output: PathBuf,
    /// Topics of the suite to record; empty: every one.
    pub topics: Vec<String>,
    /// Overrides the parameters' compression.
    pub compression: Option<Compression>,
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

/// Moves a dead recorder's `<output>.partial` aside (never overwritten) and reads what it holds
/// up to its first damage (the chunk cut short by the kill).
fn take_over_partial(output: &Path, clock: Clock) -> anyhow::Result<Option<(PathBuf, BagReader)>> {
    let partial = partial_path(output);
    if !partial.exists() {
        return Ok(None);
    }
    // Named by the time, and never over a file there (the wall clock may have been set back).
    let stamp = clock.now_nanos();
    let mut n = 0;
    let aside = loop {
        let mut name = partial.clone().into_os_string();
        name.push(format!(".crashed-{stamp}"));
        if n > 0 {
            name.push(format!("-{n}"));
        }
        let name = PathBuf::from(name);
        if !name.exists() {
            break name;
        }
        n += 1;
    };
    std::fs::rename(&partial, &aside).with_context(|| {
        format!(
            "moving the unfinished {} of a recorder that died aside",
            partial.display()
        )
    })?;
    let reader = BagReader::open(&aside)
        .with_context(|| format!("reading {} (a recorder that died)", aside.display()))?;
    if let Some(e) = reader.damage() {
        tracing::warn!(bag = %aside.display(), "carrying over what precedes the damage: {e}");
    }
    Ok(Some((aside, reader)))
}

/// A message as its publisher sent it: channel, source time and bytes.
type SentKey = (u16, u64, Vec<u8>);

/// Writes every message of `old` into `writer`, on the channel of the same topic (added when
/// `channels` lacks it), with its original times and sequence numbers. Returns how many, and
/// the keys of those on transient-local channels, which DDS will deliver again.
fn carry_over(
    old: &BagReader,
    writer: &mut BagWriter<std::io::BufWriter<std::fs::File>>,
    channels: &mut BTreeMap<String, u16>,
) -> anyhow::Result<(usize, HashSet<SentKey>)> {
    let mut ids = BTreeMap::new();
    for c in old.channels() {
        let id = match channels.get(&c.topic) {
            Some(id) => *id,
            None => {
                let schema = c.schema.as_ref().map(|s| String::from_utf8_lossy(&s.data));
                let qos = c.metadata.get("offered_qos_profiles").cloned();
                let id = writer.add_channel(
                    &c.topic,
                    c.type_name(),
                    schema.as_deref().unwrap_or(""),
                    qos.as_deref().unwrap_or(""),
                )?;
                channels.insert(c.topic.clone(), id);
                id
            }
        };
        ids.insert(c.id, id);
    }
    let redelivered: HashSet<u16> = old
        .channels()
        .filter(|c| matches!(c.offered_qos(), Some(QosKind::State | QosKind::Durable)))
        .filter_map(|c| ids.get(&c.id).copied())
        .collect();
    let mut n = 0;
    let mut sent = HashSet::new();
    for m in old.raw_messages() {
        let Some(id) = ids.get(&m.channel_id) else {
            continue;
        };
        let stamp = Stamp {
            log_time: m.log_time,
            publish_time: m.publish_time,
            sequence: m.sequence,
        };
        writer.write_cdr(*id, stamp, &m.data)?;
        if redelivered.contains(id) {
            sent.insert((*id, m.publish_time, m.data.clone()));
        }
        n += 1;
    }
    Ok((n, sent))
}

/// Writes a tapped sample unless it is one carried over from a dead recorder.
fn write_sample(
    writer: &mut BagWriter<std::io::BufWriter<std::fs::File>>,
    carried: &mut HashSet<SentKey>,
    sample: bag_file::suite::Sample,
) -> anyhow::Result<()> {
    if !carried.is_empty()
        && carried.remove(&(
            sample.channel_id,
            sample.stamp.publish_time,
            sample.payload.clone(),
        ))
    {
        return Ok(());
    }
    writer.write_cdr(sample.channel_id, sample.stamp, &sample.payload)?;
    Ok(())
}

/// Writes a sample of a topic beside the suite's on its channel (none yet: not written), unless
/// it is one carried over from a dead recorder (transient-local topics deliver theirs again).
fn write_foreign(
    writer: &mut BagWriter<std::io::BufWriter<std::fs::File>>,
    carried: &mut HashSet<SentKey>,
    channels: &BTreeMap<String, u16>,
    sample: ForeignSample,
) -> anyhow::Result<()> {
    let Some(id) = channels.get(&sample.topic) else {
        return Ok(());
    };
    let sample = bag_file::suite::Sample {
        channel_id: *id,
        stamp: sample.stamp,
        payload: sample.payload,
    };
    write_sample(writer, carried, sample)
}

/// Records `what` with `params` until the node is asked to stop, then finishes the bag;
/// returns how many messages it holds.
pub async fn run<B: Bus + 'static, D: Discover<B>>(
    bus: &mut B,
    params: RecorderParams,
    what: Recording,
    mut beside: D,
    mut foreign: Option<mpsc::Receiver<ForeignSample>>,
) -> anyhow::Result<u64> {
    if !(params.flush_interval_s > 0.0 && params.flush_interval_s <= 60.0) {
        bail!(
            "bag_recorder.flush_interval_s = {} is not in (0, 60]",
            params.flush_interval_s
        );
    }
    let topics = select_topics(&what.topics)?;
    // A recorded session is never overwritten by the next one.
    if what.output.exists() {
        bail!("{} exists; record to a new name", what.output.display());
    }
    let options = writer_options(&params, what.compression)?;
    let taken_over = take_over_partial(&what.output, bus.clock())?;
    let mut writer = BagWriter::create(&what.output, &options)?;
    let capacity = usize::try_from(params.queue_capacity.max(1)).unwrap_or(4096);
    let (tx, mut rx) = mpsc::channel(capacity);
    let mut taps = Vec::new();
    let mut channels = BTreeMap::new();
    for t in &topics {
        let Some(ty) = bus_type::<B>(&t.type_name) else {
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
        channels.insert(t.name.to_string(), id);
        taps.push(ty.tap(bus, t.name, t.qos, id, tx.clone())?);
    }
    drop(tx);
    let mut carried = HashSet::new();
    if let Some((aside, old)) = &taken_over {
        let (n, sent) = carry_over(old, &mut writer, &mut channels)?;
        carried = sent;
        for step in old.clock_steps() {
            writer.write_clock_step(step)?;
        }
        tracing::warn!(
            from = %aside.display(),
            messages = n,
            "a recorder died on this output: carried its messages over"
        );
    }
    // Schemas and channels reach the disk at once, so even an empty recording is readable.
    writer.flush_chunk()?;
    tracing::info!(
        output = %what.output.display(),
        topics = topics.len(),
        compression = ?options.compression,
        "recording"
    );
    let progress = indicatif::ProgressBar::new_spinner();
    let stop = bus.shutdown_signal();
    tokio::pin!(stop);
    let mut flush = tokio::time::interval(Duration::from_secs_f64(params.flush_interval_s));
    // A topic carried over from a recorder that died keeps its channel when found again.
    let mut foreign_channels: BTreeMap<String, u16> = channels.clone();
    let clock = bus.clock();
    let mut steps = clock_steps::ClockSteps::new();
    steps.observe(clock.steady_nanos(), clock.now_nanos());
    loop {
        // Biased: what is ready is taken in this order, never by tokio's random pick, so a
        // run on the in-process bus is the same every time.
        tokio::select! {
            biased;
            _ = &mut stop => break,
            _ = flush.tick() => {
                // What the readers queued before the tick belongs in this flush.
                while let Ok(sample) = rx.try_recv() {
                    write_sample(&mut writer, &mut carried, sample)?;
                }
                if let Some(step) = steps.observe(clock.steady_nanos(), clock.now_nanos()) {
                    tracing::warn!("the wall clock stepped {:+.3} s: recorded in the bag; log \
                        times go on unstepped", step.by_ns as f64 * 1e-9);
                    writer.write_clock_step(step)?;
                }
                // Topics beside the suite's: channels before their first samples are taken.
                for t in beside.discover(bus).await {
                    if foreign_channels.contains_key(&t.topic) {
                        continue;
                    }
                    let (schema, missing) = match &t.definition {
                        Ok(text) => (text.as_str(), None),
                        Err(why) => ("", Some(why.as_str())),
                    };
                    if let Some(why) = missing {
                        tracing::warn!(topic = %t.topic, "recorded without its definition: {why}");
                    } else {
                        tracing::info!(topic = %t.topic, type_name = %t.type_name, "recording a topic of the graph");
                    }
                    let id = writer.add_foreign_channel(&t.topic, &t.type_name, schema, &offered_qos_yaml(t.qos), missing)?;
                    foreign_channels.insert(t.topic.clone(), id);
                }
                writer.flush_chunk()?;
                progress.set_message(format!("{} messages", writer.message_count()));
                progress.tick();
            }
            Some(sample) = rx.recv() => {
                write_sample(&mut writer, &mut carried, sample)?;
            }
            Some(sample) = next_foreign(&mut foreign) => {
                write_foreign(&mut writer, &mut carried, &foreign_channels, sample)?;
            }
        }
    }
    for t in &taps {
        t.abort();
    }
    // What the readers already queued is part of the session.
    while let Ok(sample) = rx.try_recv() {
        write_sample(&mut writer, &mut carried, sample)?;
    }
    if let Some(foreign) = &mut foreign {
        while let Ok(sample) = foreign.try_recv() {
            write_foreign(&mut writer, &mut carried, &foreign_channels, sample)?;
        }
    }
    for t in taps {
        let _ = t.await;
    }
    progress.finish_and_clear();
    let messages = writer.message_count();
    writer
        .finish()
        .with_context(|| format!("finishing {}", what.output.display()))?;
    tracing::info!(output = %what.output.display(), messages, "bag written");
    // Its messages are now in the finished bag.
    if let Some((aside, _)) = taken_over
        && let Err(e) = std::fs::remove_file(&aside)
    {
        tracing::warn!(file = %aside.display(), "could not remove: {e}");
    }
    Ok(messages)
}
