//! What `bag info` reports about a bag (topics, types, counts, duration, compression, damage),
//! as a value and as text laid out like `ros2 bag info`.

use crate::reader::BagReader;
use serde::Serialize;
use std::fmt::Write as _;
use time::OffsetDateTime;

/// One topic's line of `bag info`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TopicSummary {
    pub topic: String,
    pub type_name: String,
    pub count: u64,
    pub serialization_format: String,
    /// The offered QoS class (`reliable`, `state`, `features`) when the metadata names one.
    pub qos: Option<String>,
    /// Why the topic has no definition (empty schema), when it has none.
    pub definition_missing: Option<String>,
}

/// A bag's summary.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BagInfo {
    pub file: String,
    pub size_bytes: u64,
    pub profile: String,
    pub library: String,
    pub messages: u64,
    pub start_ns: Option<u64>,
    pub end_ns: Option<u64>,
    pub duration_ns: u64,
    pub chunks: u64,
    /// Compression name ("none" for uncompressed chunks) and chunk count.
    pub compression: Vec<(String, u64)>,
    pub ros_distro: Option<String>,
    /// Footer and closing magic present.
    pub complete: bool,
    /// The first bad record, if any.
    pub damage: Option<String>,
    /// Steps of the wall clock the recorder saw: (log time, by how many ns).
    pub clock_steps: Vec<(i64, i64)>,
    pub topics: Vec<TopicSummary>,
}

impl BagInfo {
    pub fn of(reader: &BagReader) -> BagInfo {
        let counts = reader.counts();
        let topics = reader
            .channels()
            .map(|c| TopicSummary {
                topic: c.topic.clone(),
                type_name: c.type_name().to_string(),
                count: counts.get(&c.id).copied().unwrap_or(0),
                serialization_format: c.message_encoding.clone(),
                qos: c
                    .offered_qos()
                    .map(|k| format!("{k:?}").to_ascii_lowercase()),
                definition_missing: c.schema.as_ref().is_none_or(|s| s.data.is_empty()).then(
                    || {
                        c.metadata
                            .get(crate::writer::DEFINITION_MISSING)
                            .cloned()
                            .unwrap_or_else(|| "the bag holds none".to_string())
                    },
                ),
            })
            .collect();
        let (chunks, compression) = reader.chunks();
        let range = reader.time_range();
        let ros_distro = reader
            .metadata()
            .iter()
            .filter(|(name, _)| name == "rosbag2")
            .filter_map(|(_, m)| m.get("serialized_metadata"))
            .flat_map(|text| text.lines())
            .find_map(|l| l.strip_prefix("ros_distro:"))
            .map(|d| d.trim().to_string());
        BagInfo {
            file: reader.name().to_string(),
            size_bytes: reader.size_bytes(),
            profile: reader.profile().unwrap_or("").to_string(),
            library: reader.library().unwrap_or("").to_string(),
            messages: reader.raw_messages().len() as u64,
            start_ns: range.map(|r| r.0),
            end_ns: range.map(|r| r.1),
            duration_ns: range.map_or(0, |(a, b)| b.saturating_sub(a)),
            chunks,
            compression: compression
                .iter()
                .map(|(c, n)| (if c.is_empty() { "none" } else { c }.to_string(), *n))
                .collect(),
            ros_distro,
            complete: reader.is_complete(),
            damage: reader.damage().map(|e| e.to_string()),
            clock_steps: reader
                .clock_steps()
                .iter()
                .map(|s| (s.at_steady_ns, s.by_ns))
                .collect(),
            topics,
        }
    }

    /// The report, laid out like `ros2 bag info`.
    pub fn to_text(&self) -> String {
        let mut t = String::new();
        let mut line = |k: &str, v: String| {
            let key = if k.is_empty() {
                String::new()
            } else {
                format!("{k}:")
            };
            let _ = writeln!(t, "{key:<19}{v}");
        };
        line("Files", self.file.clone());
        line("Bag size", human_size(self.size_bytes));
        line("Storage id", format!("mcap (profile {:?})", self.profile));
        line(
            "ROS Distro",
            self.ros_distro.clone().unwrap_or_else(|| "unknown".into()),
        );
        line(
            "Duration",
            format!("{:.9}s", self.duration_ns as f64 * 1e-9),
        );
        if let (Some(s), Some(e)) = (self.start_ns, self.end_ns) {
            line("Start", format!("{} ({})", utc(s), secs(s)));
            line("End", format!("{} ({})", utc(e), secs(e)));
        }
        line("Messages", self.messages.to_string());
        let compression: Vec<String> = self
            .compression
            .iter()
            .map(|(c, n)| format!("{c} x{n}"))
            .collect();
        line(
            "Chunks",
            format!("{} [{}]", self.chunks, compression.join(", ")),
        );
        line(
            "Closed cleanly",
            if self.complete {
                "yes"
            } else {
                "no (no footer: recovered up to the last complete record)"
            }
            .into(),
        );
        if let Some(d) = &self.damage {
            line("Damage", d.clone());
        }
        for (i, (at, by)) in self.clock_steps.iter().enumerate() {
            let at = u64::try_from(*at).unwrap_or(0);
            line(
                if i == 0 { "Clock steps" } else { "" },
                format!(
                    "{:+.3}s at {} ({}): the wall clock was stepped; log times go on unstepped, \
                     the stamps of what follows are that far off them",
                    *by as f64 * 1e-9,
                    utc(at),
                    secs(at)
                ),
            );
        }
        let width = self.topics.iter().map(|x| x.topic.len()).max().unwrap_or(0);
        for (i, x) in self.topics.iter().enumerate() {
            let qos = x
                .qos
                .as_deref()
                .map_or(String::new(), |q| format!(" | QoS: {q}"));
            let missing = x
                .definition_missing
                .as_deref()
                .map_or(String::new(), |why| format!(" | No definition: {why}"));
            let text = format!(
                "Topic: {:<width$} | Type: {} | Count: {} | Serialization Format: {}{qos}{missing}",
                x.topic, x.type_name, x.count, x.serialization_format
            );
            line(if i == 0 { "Topic information" } else { "" }, text);
        }
        t
    }
}

fn human_size(bytes: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB"];
    let mut v = bytes as f64;
    let mut unit = 0;
    while v >= 1024.0 && unit + 1 < units.len() {
        v /= 1024.0;
        unit += 1;
    }
    format!("{v:.1} {}", units[unit])
}

fn secs(ns: u64) -> String {
    format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000)
}

/// `YYYY-MM-DD HH:MM:SS.nnnnnnnnn UTC`.
fn utc(ns: u64) -> String {
    // Every u64 of nanoseconds (up to the year 2554) is a date `time` holds.
    match OffsetDateTime::from_unix_timestamp_nanos(i128::from(ns)) {
        Ok(t) => format!(
            "{:04}-{:02}-{:02} {:02}:{:02}:{:02}.{:09} UTC",
            t.year(),
            u8::from(t.month()),
            t.day(),
            t.hour(),
            t.minute(),
            t.second(),
            t.nanosecond()
        ),
        Err(_) => format!("{} s after the epoch", secs(ns)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_and_sizes() {
        assert_eq!(utc(0), "1970-01-01 00:00:00.000000000 UTC");
        // 2024-02-29 12:34:56.5 UTC = 1709210096.5 s
        assert_eq!(
            utc(1_709_210_096_500_000_000),
            "2024-02-29 12:34:56.500000000 UTC"
        );
        assert_eq!(human_size(1536), "1.5 KiB");
        assert_eq!(secs(1_500_000_001), "1.500000001");
    }
}
