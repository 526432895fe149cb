//! `bag play`: publishes a bag's messages on their topics over DDS with the recorded timing
//! (scaled by a rate, or at once), filtered and remapped, from a start offset, once or in a
//! loop. A damaged bag plays up to its first bad record; channels of unknown types are skipped.

use anyhow::{Context as _, bail};
use bag::dds_types::{CdrPublisher, bus_type};
use bag::params::PlayerParams;
use bag_file::schedule::{PlayOptions, parse_remap, plan};
use bag_file::suite::suite_type;
use bag_file::{BagReader, ChannelInfo};
use node_shell::{NodeShell, Outbox, ShellOptions};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::rosgraph_msgs::Clock;
use qt_therapy_msgs::topics::Topic;
use qt_therapy_msgs::topics::{QosKind, all_topics};
use std::path::PathBuf;
use std::time::Duration;
use tokio::time::Instant;

#[derive(clap::Args, Debug)]
pub struct PlayArgs {
    /// The bag to play.
    pub bag: PathBuf,
    /// Speed over the recorded timing [default: the parameter file's]
    #[arg(long, conflicts_with = "fast")]
    pub rate: Option<f64>,
    /// Publish every message at once, ignoring the timing.
    #[arg(long)]
    pub fast: bool,
    /// Topics to play [default: the parameter file's list; empty = all]
    #[arg(long, num_args = 1..)]
    pub topics: Vec<String>,
    /// Remappings /from:=/to (added to the parameter file's).
    #[arg(long, num_args = 1..)]
    pub remap: Vec<String>,
    /// Play again from the start offset after the end, until SIGINT/SIGTERM.
    #[arg(long = "loop")]
    pub looped: bool,
    /// Seconds of the bag to skip at its start [default: the parameter file's]
    #[arg(long)]
    pub start_offset: Option<f64>,
    /// Publish the bag's time on /clock (rosgraph_msgs/Clock, best effort) this many times a
    /// second, as `ros2 bag play --clock` does (40 when given without a rate): nodes with
    /// use_sim_time follow the played bag.
    #[arg(long, value_name = "HZ", num_args = 0..=1, default_missing_value = "40")]
    pub clock: Option<f64>,
    #[command(flatten)]
    pub shell: ShellOptions,
}

/// Why a channel cannot be played, if it cannot.
fn playable(c: &ChannelInfo) -> Result<(), String> {
    if c.message_encoding != "cdr" {
        return Err(format!(
            "message encoding {:?} is not cdr",
            c.message_encoding
        ));
    }
    if c.schema_encoding() != "ros2msg" {
        return Err(format!(
            "schema encoding {:?} is not ros2msg",
            c.schema_encoding()
        ));
    }
    match suite_type(c.type_name()) {
        Some(_) => Ok(()),
        None => Err(format!(
            "type {:?} is not one of the suite's",
            c.type_name()
        )),
    }
}

/// A duration in seconds from the command line or the parameter file.
fn seconds(value: f64, what: &str) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(value)
        .map_err(|_| anyhow::anyhow!("{what} = {value} s is not a non-negative duration"))
}

/// `/clock` as rosbag2's player publishes it (`rclcpp::ClockQoS`: best effort, volatile).
const CLOCK: Topic<Clock> = Topic::new("/clock", QosKind::Features);

/// The bag's time while it plays, for `/clock`: the first played message's log time plus the
/// time played since, times the rate; as fast as possible, the last played message's.
struct BagClock {
    outbox: Outbox<Clock>,
    first_log_time: i64,
    first_at: Duration,
    rate: Option<f64>,
    last_played: i64,
}

impl BagClock {
    fn now(&self, start: Instant) -> i64 {
        match self.rate {
            Some(rate) => {
                let played = start.elapsed().saturating_sub(self.first_at).as_secs_f64() * rate;
                self.first_log_time + (played * 1e9) as i64
            }
            None => self.last_played,
        }
    }

    fn tick(&self, start: Instant) {
        self.outbox.send(Clock {
            clock: Time::from_nanos(self.now(start)),
        });
    }
}

/// The next tick of the `/clock` interval (never without one).
async fn next_tick(ticks: &mut Option<tokio::time::Interval>) {
    match ticks {
        Some(t) => {
            t.tick().await;
        }
        None => std::future::pending().await,
    }
}

/// The log time of the bag's `index`th message.
fn messages_log_time(reader: &BagReader, index: usize) -> i64 {
    reader
        .raw_messages()
        .get(index)
        .map_or(0, |m| m.log_time as i64)
}

/// A year from now: "never" for a player.
fn far_future() -> Instant {
    Instant::now() + Duration::from_secs(365 * 24 * 3600)
}

fn options(args: &PlayArgs, params: &PlayerParams) -> anyhow::Result<PlayOptions> {
    let offset = seconds(
        args.start_offset.unwrap_or(params.start_offset_s),
        "start offset",
    )?;
    let fast = args.fast || params.as_fast_as_possible;
    let rules = params.remap.iter().chain(&args.remap);
    Ok(PlayOptions {
        rate: if fast {
            None
        } else {
            Some(args.rate.unwrap_or(params.rate))
        },
        start_offset: offset,
        topics: if args.topics.is_empty() {
            params.topics.clone()
        } else {
            args.topics.clone()
        },
        remap: rules
            .map(|r| parse_remap(r).map_err(anyhow::Error::msg))
            .collect::<anyhow::Result<_>>()?,
    })
}

pub async fn run(args: PlayArgs) -> anyhow::Result<()> {
    let reader =
        BagReader::open(&args.bag).with_context(|| format!("reading {}", args.bag.display()))?;
    let (mut shell, params): (NodeShell, PlayerParams) =
        NodeShell::start("bag_player", &args.shell)?;
    if let Some(damage) = reader.damage() {
        tracing::warn!(
            "{damage}; playing the {} messages before it",
            reader.raw_messages().len()
        );
    }
    let options = options(&args, &params)?;
    let plan = plan(&reader, &options, playable).map_err(anyhow::Error::msg)?;
    for (topic, reason) in &plan.skipped {
        tracing::warn!(topic, "not played: {reason}");
    }
    if plan.outputs.is_empty() {
        bail!("{}: nothing to play", args.bag.display());
    }
    let mut publishers: Vec<Box<dyn CdrPublisher<NodeShell>>> = Vec::new();
    for out in &plan.outputs {
        let ty = bus_type::<NodeShell>(&out.type_name).context("a planned type is known")?;
        // Offer what the recording publisher offered; else what the suite's table says.
        let qos = reader
            .channel(out.channel_id)
            .and_then(ChannelInfo::offered_qos)
            .or_else(|| {
                all_topics()
                    .into_iter()
                    .find(|t| t.name == out.topic)
                    .map(|t| t.qos)
            })
            .unwrap_or(QosKind::Reliable);
        // Publisher names live as long as the process; there is one per played channel.
        let name: &'static str = Box::leak(out.topic.clone().into_boxed_str());
        publishers.push(ty.publisher(&mut shell, name, qos)?);
    }
    let (mut clock, mut ticks) = match args.clock {
        None => (None, None),
        Some(hz) if hz.is_finite() && hz > 0.0 => {
            let first = plan
                .due
                .first()
                .map(|d| (messages_log_time(&reader, d.index), d.at));
            let (first_log_time, first_at) = first.unwrap_or((0, Duration::ZERO));
            let clock = BagClock {
                outbox: shell.publisher(CLOCK)?,
                first_log_time,
                first_at,
                rate: options.rate,
                last_played: first_log_time,
            };
            let ticks = tokio::time::interval(Duration::from_secs_f64(1.0 / hz));
            (Some(clock), Some(ticks))
        }
        Some(hz) => bail!("--clock {hz}: the rate must be a positive number of Hz"),
    };
    let linger = seconds(params.linger_s, "bag_player.linger_s")?;
    let wait = seconds(
        params.wait_for_subscribers_s,
        "bag_player.wait_for_subscribers_s",
    )?;
    let deadline = Instant::now().checked_add(wait).unwrap_or_else(far_future);
    for p in &publishers {
        let left = deadline.saturating_duration_since(Instant::now());
        if !p.wait_for_subscribers(&shell, left).await {
            tracing::warn!(
                topic = p.topic(),
                "no subscriber matched; publishing anyway"
            );
        }
    }
    let messages = reader.raw_messages();
    tracing::info!(
        messages = plan.due.len(),
        topics = publishers.len(),
        seconds = plan.length.as_secs_f64(),
        "playing"
    );
    let progress = indicatif::ProgressBar::new(plan.due.len() as u64);
    let stop = shell.shutdown_signal();
    tokio::pin!(stop);
    let (mut published, mut failed, mut passes) = (0u64, 0u64, 0u64);
    let mut stopped = false;
    'passes: loop {
        let start = Instant::now();
        progress.reset();
        for due in &plan.due {
            let at = start.checked_add(due.at).unwrap_or_else(far_future);
            loop {
                tokio::select! {
                    _ = &mut stop => {
                        stopped = true;
                        break 'passes;
                    }
                    _ = next_tick(&mut ticks), if ticks.is_some() => {
                        if let Some(c) = &clock {
                            c.tick(start);
                        }
                    }
                    _ = tokio::time::sleep_until(at) => break,
                }
            }
            if let Some(c) = &mut clock {
                c.last_played = messages[due.index].log_time as i64;
            }
            match publishers[due.output].publish_cdr(&messages[due.index].data) {
                Ok(()) => published += 1,
                Err(e) => {
                    failed += 1;
                    tracing::warn!(topic = publishers[due.output].topic(), "{e}");
                }
            }
            progress.inc(1);
        }
        passes += 1;
        if !args.looped && !params.looped {
            break;
        }
    }
    progress.finish_and_clear();
    // The bag's last time, so a late subscriber's clock ends where the bag did.
    if let Some(c) = &clock {
        c.outbox.send(Clock {
            clock: Time::from_nanos(c.last_played),
        });
    }
    // Stay a moment so reliable samples still in flight get delivered (not after a signal).
    if !stopped {
        tokio::select! {
            _ = &mut stop => {}
            _ = tokio::time::sleep(linger) => {}
        }
    }
    tracing::info!(published, failed, passes, "playback done");
    println!(
        "{}",
        serde_json::json!({"event": "played", "published": published, "failed": failed, "passes": passes})
    );
    drop(publishers);
    shell.stop().await;
    Ok(())
}
