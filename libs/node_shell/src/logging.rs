//! Logging for every node: `tracing` to stderr (filtered by `RUST_LOG`, default `info`) and,
//! once the node exists, the same events at INFO and above to `/rosout`, so `ros2 topic echo
//! /rosout` and rqt_console show our nodes beside the robot's own.

use ros2_client::Publisher;
use ros2_client::log::Log;
use std::sync::{Arc, OnceLock};
use tracing::field::{Field, Visit};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::layer::{Context, SubscriberExt};
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::{EnvFilter, Layer};

/// Where the `/rosout` layer sends events once the node has been created.
#[derive(Clone, Default)]
pub struct RosoutSink(Arc<OnceLock<Publisher<Log>>>);

impl RosoutSink {
    pub fn attach(&self, publisher: Publisher<Log>) {
        let _ = self.0.set(publisher);
    }
}

struct RosoutLayer {
    sink: RosoutSink,
    node_name: String,
}

#[derive(Default)]
struct MessageText(String);

impl Visit for MessageText {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.0.insert_str(0, &format!("{value:?}"));
        } else {
            self.0.push_str(&format!(" {}={value:?}", field.name()));
        }
    }
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.0.insert_str(0, value);
        } else {
            self.0.push_str(&format!(" {}={value}", field.name()));
        }
    }
}

impl<S: Subscriber> Layer<S> for RosoutLayer {
    fn on_event(&self, event: &Event<'_>, _ctx: Context<'_, S>) {
        let meta = event.metadata();
        // Only our own events: ros2-client echoes /rosout into tracing itself (forwarding its
        // events would loop), and `log` records bridged from RustDDS are its business.
        if meta.target() == "log"
            || meta.target().starts_with("ros2_client")
            || meta.target().starts_with("rustdds")
        {
            return;
        }
        let level = match *meta.level() {
            Level::ERROR => ros2_client::log::LogLevel::Error,
            Level::WARN => ros2_client::log::LogLevel::Warn,
            Level::INFO => ros2_client::log::LogLevel::Info,
            _ => return,
        };
        let Some(publisher) = self.sink.0.get() else {
            return;
        };
        let mut text = MessageText::default();
        event.record(&mut text);
        // A failed publish cannot be logged from inside the logger; stderr has the line anyway.
        let _ = publisher.publish(Log {
            stamp: ros2_client::builtin_interfaces::Time::now(),
            level: level as u8,
            name: self.node_name.clone(),
            msg: text.0,
            file: meta.file().unwrap_or("").to_string(),
            function: meta.module_path().unwrap_or("").to_string(),
            line: meta.line().unwrap_or(0),
        });
    }
}

/// Logs a line a node's sans-IO core asked for, at its level.
pub fn log_at(level: Level, message: &str) {
    match level {
        Level::ERROR => tracing::error!("{message}"),
        Level::WARN => tracing::warn!("{message}"),
        Level::INFO => tracing::info!("{message}"),
        Level::DEBUG => tracing::debug!("{message}"),
        _ => tracing::trace!("{message}"),
    }
}

/// Installs the process-wide subscriber; returns the sink to attach the node's rosout handle to.
pub fn init_logging(node_name: &str) -> RosoutSink {
    let sink = RosoutSink::default();
    // ros2-client prints every /rosout line to tracing again: never show that echo. Its node
    // also reports "cannot notify spin task" when dropped after we stopped the spinner
    // ourselves (which we must, to free DDS entities before the participant): not an error.
    let filter = EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| EnvFilter::new("info,rustdds=error,ros2_client=error"));
    let _ = tracing_subscriber::registry()
        .with(
            filter
                .add_directive("ros2_client::rosout=off".parse().expect("static directive"))
                .add_directive("ros2_client::node=off".parse().expect("static directive")),
        )
        .with(
            tracing_subscriber::fmt::layer()
                .with_writer(std::io::stderr)
                // Colour for a person at a terminal, never into files, pipes or the journal.
                .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
                .with_target(false),
        )
        .with(RosoutLayer {
            sink: sink.clone(),
            node_name: node_name.to_string(),
        })
        .try_init();
    sink
}
