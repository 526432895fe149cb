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
//! tells it. Every closed chunk is on disk (fdatasync), so a power cut keeps the bag readable
//! up to its last one. A full disk pauses the recording instead of ending the node: it says
//! which disk, and records again into the same bag once there is room.

use crate::dds_types::bus_type;
use crate::params::RecorderParams;
use anyhow::{Context as _, bail};
use bag_file::qos::offered_qos_yaml;
use bag_file::{
    BagReader, BagWriter, Compression, FileBagWriter, Stamp, WriterOptions, partial_path,
};
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
    atomic_file::rename(&partial, &aside).with_context(|| {
        format!(
            "moving the unfinished {} of a recorder that died aside",
            partial.display()
        )
    })?;
    let reader = match BagReader::open(&aside) {
        Ok(r) => r,
        // Cut before its first chunk reached the disk (a power cut): nothing to carry over.
        Err(e) => {
            tracing::warn!(
                bag = %aside.display(),
                "the unfinished bag of a recorder that died holds nothing readable ({e}): left \
                 as it is, recording anew"
            );
            return Ok(None);
        }
    };
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
    writer: &mut FileBagWriter,
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
    writer: &mut FileBagWriter,
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
    writer: &mut FileBagWriter,
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

/// Adds the channel of a topic beside the suite's, unless the bag has one for it already.
fn add_foreign(
    writer: &mut FileBagWriter,
    channels: &mut BTreeMap<String, u16>,
    t: &ForeignTopic,
) -> anyhow::Result<()> {
    if channels.contains_key(&t.topic) {
        return Ok(());
    }
    let (schema, missing) = match &t.definition {
        Ok(text) => (text.as_str(), None),
        Err(why) => ("", Some(why.as_str())),
    };
    let id = writer.add_foreign_channel(
        &t.topic,
        &t.type_name,
        schema,
        &offered_qos_yaml(t.qos),
        missing,
    )?;
    channels.insert(t.topic.clone(), id);
    Ok(())
}

/// The bag open for writing: the writer, its channels by topic, and what it carried over from
/// a recorder that died on the same output (messages DDS will deliver again, and the file they
/// came from, removed once the bag is finished).
struct OpenBag {
    writer: FileBagWriter,
    carried: HashSet<SentKey>,
    aside: Option<PathBuf>,
}

/// Creates the bag at `what.output` (carrying a dead recorder's `.partial` over first) with a
/// channel for each of `topics`, in order, so its channel ids are the same every time; the
/// schemas and channels reach the disk at once, so even an empty recording is readable.
fn open_bag(
    what: &Recording,
    options: &WriterOptions,
    topics: &[TopicInfo],
    clock: Clock,
) -> anyhow::Result<(OpenBag, BTreeMap<String, u16>)> {
    let taken_over = take_over_partial(&what.output, clock)?;
    let mut writer = BagWriter::create(&what.output, options)?;
    let mut channels = BTreeMap::new();
    for t in topics {
        let id = writer.add_channel(
            t.name,
            &t.type_name,
            &t.schema_text,
            &offered_qos_yaml(t.qos),
        )?;
        channels.insert(t.name.to_string(), id);
    }
    let mut carried = HashSet::new();
    let mut aside = None;
    if let Some((from, old)) = taken_over {
        let (n, sent) = carry_over(&old, &mut writer, &mut channels)?;
        carried = sent;
        for step in old.clock_steps() {
            writer.write_clock_step(step)?;
        }
        tracing::warn!(
            from = %from.display(),
            messages = n,
            "a recorder died on this output, or the disk was full: carried its messages over"
        );
        aside = Some(from);
    }
    writer.flush_chunk()?;
    Ok((
        OpenBag {
            writer,
            carried,
            aside,
        },
        channels,
    ))
}

/// Where the recording stands: writing, or paused because the disk is full.
enum Sink {
    Writing(Box<OpenBag>),
    /// Messages are counted, not written, until there is room again; the bag on disk keeps
    /// every message up to its last complete chunk.
    DiskFull {
        since_ns: i64,
        missed: u64,
        /// Dead recorders' files the paused bag had carried over (removed once a bag holding
        /// their messages is finished).
        asides: Vec<PathBuf>,
    },
}

/// What a failed write of the bag means: a full disk pauses the recording (the node keeps
/// running and says which disk), anything else ends it.
fn on_write_error(
    e: anyhow::Error,
    sink: &mut Sink,
    output: &Path,
    clock: Clock,
) -> anyhow::Result<()> {
    let full = e.chain().any(|c| {
        c.downcast_ref::<bag_file::BagError>()
            .is_some_and(|b| b.is_no_space())
    });
    if !full {
        return Err(e);
    }
    let dir = output_dir(output);
    let free = atomic_file::disk_space(dir).map(|s| s.free).unwrap_or(0);
    tracing::error!(
        "disk full: the bag {} cannot be written ({} bytes free on the disk of {}): recording \
         paused, the node keeps running; the bag keeps every message up to its last complete \
         chunk, and recording goes on when there is space again ({e:#})",
        output.display(),
        free,
        dir.display()
    );
    let asides = match sink {
        Sink::Writing(open) => open.aside.take().into_iter().collect(),
        Sink::DiskFull { asides, .. } => std::mem::take(asides),
    };
    // The writer is dropped, not finished: a summary needs space, and the reader does without.
    *sink = Sink::DiskFull {
        since_ns: clock.now_nanos(),
        missed: 0,
        asides,
    };
    Ok(())
}

/// The directory of a bag (where its disk is measured).
fn output_dir(output: &Path) -> &Path {
    match output.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// Records `what` with `params` until the node is asked to stop, then finishes the bag;
/// returns how many messages it holds. A full disk pauses the recording instead of ending it:
/// the node keeps running, says which disk, and records again once there is room (the bag
/// then carries over what it had, and the messages of the pause are missing from it).
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
    let clock = bus.clock();
    let (open, channels) = open_bag(&what, &options, &topics, clock)?;
    let capacity = usize::try_from(params.queue_capacity.max(1)).unwrap_or(4096);
    let (tx, mut rx) = mpsc::channel(capacity);
    let mut taps = Vec::new();
    for t in &topics {
        let Some(ty) = bus_type::<B>(&t.type_name) else {
            bail!(
                "{} has type {}, which the recorder does not know",
                t.name,
                t.type_name
            );
        };
        taps.push(ty.tap(bus, t.name, t.qos, channels[t.name], tx.clone())?);
    }
    drop(tx);
    let mut sink = Sink::Writing(Box::new(open));
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
    let mut steps = clock_steps::ClockSteps::new();
    steps.observe(clock.steady_nanos(), clock.now_nanos());
    // Every topic found beside the suite's: a bag reopened after a full disk gets their channels.
    let mut known_foreign: Vec<ForeignTopic> = Vec::new();
    loop {
        // Biased: what is ready is taken in this order, never by tokio's random pick, so a
        // run on the in-process bus is the same every time.
        let written = tokio::select! {
            biased;
            _ = &mut stop => break,
            _ = flush.tick() => {
                let chunk = params.chunk_size_bytes;
                let mut r = match resume_if_room(&mut sink, &what, &options, &topics, clock, chunk)? {
                    Some(ch) => reopened(&mut sink, ch, &mut foreign_channels, &known_foreign),
                    None => Ok(()),
                };
                // What the readers queued before the tick belongs in this flush.
                while let Ok(sample) = rx.try_recv() {
                    r = r.and_then(|()| record(&mut sink, sample));
                }
                if let Some(step) = steps.observe(clock.steady_nanos(), clock.now_nanos()) {
                    match &mut sink {
                        Sink::Writing(open) => {
                            tracing::warn!("the wall clock stepped {:+.3} s: recorded in the bag; log \
                                times go on unstepped", step.by_ns as f64 * 1e-9);
                            r = r.and_then(|()| open.writer.write_clock_step(step).map_err(anyhow::Error::from));
                        }
                        Sink::DiskFull { .. } => tracing::warn!("the wall clock stepped {:+.3} s \
                            while the disk is full: not recorded in the bag", step.by_ns as f64 * 1e-9),
                    }
                }
                // Topics beside the suite's: channels before their first samples are taken
                // (while the disk is full, once it has room again).
                for t in beside.discover(bus).await {
                    if let Some(why) = t.definition.as_ref().err() {
                        tracing::warn!(topic = %t.topic, "recorded without its definition: {why}");
                    } else {
                        tracing::info!(topic = %t.topic, type_name = %t.type_name, "recording a topic of the graph");
                    }
                    if let Sink::Writing(open) = &mut sink {
                        r = r.and_then(|()| add_foreign(&mut open.writer, &mut foreign_channels, &t));
                    }
                    known_foreign.push(t);
                }
                let r = r.and_then(|()| match &mut sink {
                    Sink::Writing(open) => open.writer.flush_chunk().map_err(anyhow::Error::from),
                    Sink::DiskFull { .. } => Ok(()),
                });
                if let Sink::Writing(open) = &sink {
                    progress.set_message(format!("{} messages", open.writer.message_count()));
                    progress.tick();
                }
                r
            }
            Some(sample) = rx.recv() => record(&mut sink, sample),
            Some(sample) = next_foreign(&mut foreign) => record_foreign(&mut sink, &foreign_channels, sample),
        };
        if let Err(e) = written {
            on_write_error(e, &mut sink, &what.output, clock)?;
        }
    }
    for t in &taps {
        t.abort();
    }
    // What the readers already queued is part of the session.
    if let Some(ch) = resume_if_room(
        &mut sink,
        &what,
        &options,
        &topics,
        clock,
        params.chunk_size_bytes,
    )? && let Err(e) = reopened(&mut sink, ch, &mut foreign_channels, &known_foreign)
    {
        on_write_error(e, &mut sink, &what.output, clock)?;
    }
    while let Ok(sample) = rx.try_recv() {
        if let Err(e) = record(&mut sink, sample) {
            on_write_error(e, &mut sink, &what.output, clock)?;
        }
    }
    if let Some(foreign) = &mut foreign {
        while let Ok(sample) = foreign.try_recv() {
            if let Err(e) = record_foreign(&mut sink, &foreign_channels, sample) {
                on_write_error(e, &mut sink, &what.output, clock)?;
            }
        }
    }
    for t in taps {
        let _ = t.await;
    }
    progress.finish_and_clear();
    let open = match sink {
        Sink::Writing(open) => *open,
        Sink::DiskFull { missed, .. } => {
            tracing::error!(
                "disk full: the bag stays at {}, readable up to its last complete chunk ({missed} \
                 messages since the disk filled are not in it)",
                partial_path(&what.output).display()
            );
            return Ok(0);
        }
    };
    let messages = open.writer.message_count();
    let finished = open.writer.finish();
    if let Err(e) = finished {
        if e.is_no_space() {
            tracing::error!(
                "disk full: the bag stays at {}, readable up to its last complete chunk ({e})",
                partial_path(&what.output).display()
            );
            return Ok(messages);
        }
        return Err(e).with_context(|| format!("finishing {}", what.output.display()));
    }
    tracing::info!(output = %what.output.display(), messages, "bag written");
    // Its messages are now in the finished bag.
    if let Some(aside) = open.aside
        && let Err(e) = std::fs::remove_file(&aside)
    {
        tracing::warn!(file = %aside.display(), "could not remove: {e}");
    }
    Ok(messages)
}

/// Writes a sample of a topic beside the suite's, or counts it as missed while the disk is
/// full.
fn record_foreign(
    sink: &mut Sink,
    channels: &BTreeMap<String, u16>,
    sample: ForeignSample,
) -> anyhow::Result<()> {
    match sink {
        Sink::Writing(open) => write_foreign(&mut open.writer, &mut open.carried, channels, sample),
        Sink::DiskFull { missed, .. } => {
            *missed += 1;
            Ok(())
        }
    }
}

/// A bag reopened after a full disk (`channels`: its channels by topic, those it carried over
/// included): the topics beside the suite's found so far get their channels back.
fn reopened(
    sink: &mut Sink,
    channels: BTreeMap<String, u16>,
    foreign_channels: &mut BTreeMap<String, u16>,
    known_foreign: &[ForeignTopic],
) -> anyhow::Result<()> {
    *foreign_channels = channels;
    if let Sink::Writing(open) = sink {
        for t in known_foreign {
            add_foreign(&mut open.writer, foreign_channels, t)?;
        }
    }
    Ok(())
}

/// Writes a tapped sample, or counts it as missed while the disk is full.
fn record(sink: &mut Sink, sample: bag_file::suite::Sample) -> anyhow::Result<()> {
    match sink {
        Sink::Writing(open) => write_sample(&mut open.writer, &mut open.carried, sample),
        Sink::DiskFull { missed, .. } => {
            *missed += 1;
            Ok(())
        }
    }
}

/// Records again once the disk has room for the paused bag to be carried over (its size, a
/// chunk and a MiB to spare): the paused `.partial` is moved aside and copied into a new one.
/// Returns the new bag's channels by topic when it reopened.
fn resume_if_room(
    sink: &mut Sink,
    what: &Recording,
    options: &WriterOptions,
    topics: &[TopicInfo],
    clock: Clock,
    chunk_size: i64,
) -> anyhow::Result<Option<BTreeMap<String, u16>>> {
    let Sink::DiskFull {
        since_ns,
        missed,
        asides,
    } = sink
    else {
        return Ok(None);
    };
    let partial = partial_path(&what.output);
    let size = std::fs::metadata(&partial).map_or(0, |m| m.len());
    let needed = size + chunk_size.max(0) as u64 + (1 << 20);
    let free = atomic_file::disk_space(output_dir(&what.output)).map_or(0, |s| s.free);
    if free < needed {
        return Ok(None);
    }
    match open_bag(what, options, topics, clock) {
        Ok((open, channels)) => {
            tracing::warn!(
                "disk space again ({free} bytes free): recording into {} again; {missed} \
                 messages of the {:.1} s the disk was full are not in the bag",
                what.output.display(),
                (clock.now_nanos() - *since_ns) as f64 / 1e9
            );
            // The older files' messages are in the one carried over now.
            for a in asides.drain(..) {
                if let Err(e) = std::fs::remove_file(&a) {
                    tracing::warn!(file = %a.display(), "could not remove: {e}");
                }
            }
            *sink = Sink::Writing(Box::new(open));
            Ok(Some(channels))
        }
        Err(e) => {
            tracing::warn!("disk space again, but the bag cannot be reopened yet: {e:#}");
            Ok(None)
        }
    }
}
