//! The player's plan, sans-IO: which channels of a bag play on which topic (filter, remapping,
//! channels it cannot play and why), and when each message is due after the start of a pass
//! (original timing divided by a rate, or at once; from a start offset).

use crate::reader::BagReader;
use crate::scan::ChannelInfo;
use std::collections::BTreeMap;
use std::time::Duration;

/// How to play a bag.
#[derive(Debug, Clone, PartialEq)]
pub struct PlayOptions {
    /// Speed factor over the original timing; None plays as fast as possible.
    pub rate: Option<f64>,
    /// Skip the first part of the bag: play from (first log time + this).
    pub start_offset: Duration,
    /// Topics to play (bag names); empty plays all.
    pub topics: Vec<String>,
    /// (bag topic, topic to publish on).
    pub remap: Vec<(String, String)>,
}

/// Parses `from:=to` (the ROS remapping syntax).
pub fn parse_remap(rule: &str) -> Result<(String, String), String> {
    match rule.split_once(":=") {
        Some((from, to)) if from.starts_with('/') && to.starts_with('/') && to.len() > 1 => {
            Ok((from.to_string(), to.to_string()))
        }
        _ => Err(format!("remapping {rule:?} is not /from:=/to")),
    }
}

/// A channel that will be played.
#[derive(Debug, Clone, PartialEq)]
pub struct PlayOutput {
    pub channel_id: u16,
    /// The topic in the bag.
    pub source: String,
    /// The topic it is published on (after remapping).
    pub topic: String,
    pub type_name: String,
}

/// A message due `at` after the start of a pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Due {
    /// Index into [`BagReader::raw_messages`].
    pub index: usize,
    /// Index into [`PlayPlan::outputs`].
    pub output: usize,
    pub at: Duration,
}

/// What one pass over the bag does.
#[derive(Debug, Clone, PartialEq)]
pub struct PlayPlan {
    pub outputs: Vec<PlayOutput>,
    /// Channels left out, with the reason (filtered out, or not playable).
    pub skipped: Vec<(String, String)>,
    /// In log-time order.
    pub due: Vec<Due>,
    /// Log-time span of the pass, divided by the rate.
    pub length: Duration,
}

/// Plans one pass. `playable` says why a channel cannot be played (an unknown type or
/// encoding), or Ok.
pub fn plan(
    reader: &BagReader,
    options: &PlayOptions,
    playable: impl Fn(&ChannelInfo) -> Result<(), String>,
) -> Result<PlayPlan, String> {
    if let Some(rate) = options.rate
        && !(rate.is_finite() && rate > 0.0)
    {
        return Err(format!("rate {rate} is not a positive number"));
    }
    let remap: BTreeMap<&str, &str> = options
        .remap
        .iter()
        .map(|(a, b)| (a.as_str(), b.as_str()))
        .collect();
    let mut outputs = Vec::new();
    let mut skipped = Vec::new();
    let mut output_of: BTreeMap<u16, usize> = BTreeMap::new();
    for c in reader.channels() {
        if !options.topics.is_empty() && !options.topics.contains(&c.topic) {
            skipped.push((c.topic.clone(), "not in the topic list".to_string()));
            continue;
        }
        if let Err(reason) = playable(c) {
            skipped.push((c.topic.clone(), reason));
            continue;
        }
        output_of.insert(c.id, outputs.len());
        outputs.push(PlayOutput {
            channel_id: c.id,
            source: c.topic.clone(),
            topic: remap
                .get(c.topic.as_str())
                .unwrap_or(&c.topic.as_str())
                .to_string(),
            type_name: c.type_name().to_string(),
        });
    }
    for wanted in &options.topics {
        if !reader.channels().any(|c| &c.topic == wanted) {
            skipped.push((wanted.clone(), "not in the bag".to_string()));
        }
    }
    // The bag starts at its first message, whatever is filtered out.
    let Some((first, _)) = reader.time_range() else {
        return Ok(PlayPlan {
            outputs,
            skipped,
            due: Vec::new(),
            length: Duration::ZERO,
        });
    };
    let start = first.saturating_add(options.start_offset.as_nanos().min(u64::MAX as u128) as u64);
    let scale = |ns: u64| match options.rate {
        // A tiny rate can stretch a bag past what a Duration holds: such messages never come.
        Some(rate) => Duration::try_from_secs_f64(ns as f64 * 1e-9 / rate).unwrap_or(Duration::MAX),
        None => Duration::ZERO,
    };
    let due: Vec<Due> = reader
        .raw_messages()
        .iter()
        .enumerate()
        .filter(|(_, m)| m.log_time >= start)
        .filter_map(|(index, m)| {
            output_of.get(&m.channel_id).map(|&output| Due {
                index,
                output,
                at: scale(m.log_time - start),
            })
        })
        .collect();
    let length = due.last().map_or(Duration::ZERO, |d| d.at);
    Ok(PlayPlan {
        outputs,
        skipped,
        due,
        length,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::writer::{BagWriter, WriterOptions};
    use qt_therapy_msgs::std_msgs::StringMsg;
    use qt_therapy_msgs::topics::{ROBOT_EMOTION, ROBOT_SPEECH};
    use std::io::Cursor;

    const S: u64 = 1_000_000_000;

    fn bag() -> BagReader {
        let mut w = BagWriter::new(Cursor::new(Vec::new()), "plan", &WriterOptions::default())
            .expect("writer");
        let speech = w.add_topic(ROBOT_SPEECH).expect("channel");
        let emotion = w.add_topic(ROBOT_EMOTION).expect("channel");
        let other = w
            .add_channel("/other", "other_pkg/msg/Thing", "int32 x\n", "")
            .expect("channel");
        let say = |s: &str| StringMsg { data: s.into() };
        w.write(speech, 100 * S, &say("hello")).expect("write");
        w.write(emotion, 101 * S, &say("QT/happy")).expect("write");
        w.write_cdr(other, Default::default(), &[0, 1, 0, 0, 1, 0, 0, 0])
            .expect("write");
        w.write(speech, 103 * S, &say("bye")).expect("write");
        let bytes = w.finish().expect("finish").into_inner();
        BagReader::from_bytes(&bytes, "plan", &Default::default()).expect("reads")
    }

    fn known(c: &ChannelInfo) -> Result<(), String> {
        match crate::suite::suite_type(c.type_name()) {
            Some(_) => Ok(()),
            None => Err(format!("unknown type {}", c.type_name())),
        }
    }

    fn options() -> PlayOptions {
        PlayOptions {
            rate: Some(1.0),
            start_offset: Duration::ZERO,
            topics: vec![],
            remap: vec![],
        }
    }

    #[test]
    fn original_timing_scaled_by_rate_from_an_offset() {
        let reader = bag();
        // The unknown type at log time 0 starts the bag; it cannot be played.
        let p = plan(&reader, &options(), known).expect("plans");
        assert_eq!(
            p.skipped,
            vec![(
                "/other".to_string(),
                "unknown type other_pkg/msg/Thing".to_string()
            )]
        );
        let at: Vec<f64> = p.due.iter().map(|d| d.at.as_secs_f64()).collect();
        assert_eq!(at, vec![100.0, 101.0, 103.0]);

        let fast = PlayOptions {
            rate: Some(10.0),
            start_offset: Duration::from_secs(101),
            ..options()
        };
        let p = plan(&reader, &fast, known).expect("plans");
        let at: Vec<f64> = p.due.iter().map(|d| d.at.as_secs_f64()).collect();
        assert_eq!(at, vec![0.0, 0.2]);
        assert_eq!(p.length, Duration::from_millis(200));

        let asap = PlayOptions {
            rate: None,
            ..options()
        };
        let p = plan(&reader, &asap, known).expect("plans");
        assert!(p.due.iter().all(|d| d.at == Duration::ZERO));
        assert_eq!(p.due.len(), 3);
    }

    #[test]
    fn filter_and_remap() {
        let reader = bag();
        let o = PlayOptions {
            topics: vec![ROBOT_SPEECH.name.to_string(), "/missing".into()],
            remap: vec![parse_remap("/qt_robot/speech/say:=/qt_robot/emotion/show").expect("rule")],
            ..options()
        };
        let p = plan(&reader, &o, known).expect("plans");
        assert_eq!(p.outputs.len(), 1);
        assert_eq!(p.outputs[0].source, ROBOT_SPEECH.name);
        assert_eq!(p.outputs[0].topic, ROBOT_EMOTION.name);
        assert_eq!(p.due.len(), 2);
        assert!(
            p.skipped
                .contains(&("/missing".to_string(), "not in the bag".to_string()))
        );
        assert!(parse_remap("a:=b").is_err());
        assert!(parse_remap("/a=/b").is_err());
        assert!(
            plan(
                &reader,
                &PlayOptions {
                    rate: Some(0.0),
                    ..options()
                },
                known
            )
            .is_err()
        );
        assert!(
            plan(
                &reader,
                &PlayOptions {
                    rate: Some(f64::NAN),
                    ..options()
                },
                known
            )
            .is_err()
        );
    }
}
