//! The in-process writer and the reader agree: every topic of the suite comes back typed and
//! equal, in log-time order, for each compression; the file carries what rosbag2 writes
//! (profile, schemas, QoS metadata, summary); a file bag appears only when finished; and a
//! flushed chunk is readable while the bag is still being written.

mod common;

use bag_file::{
    BagInfo, BagReader, BagWriter, Compression, ReadOptions, WriterOptions, partial_path,
};
use common::{Expected, in_log_time_order, session_bytes, write_session};
use qt_therapy_msgs::topics::*;
use qt_therapy_msgs::{MessageDefinition, topics::QosKind};
use serde::Serialize;

fn options(compression: Compression) -> WriterOptions {
    WriterOptions {
        compression,
        // Small chunks, so the session spans several.
        chunk_size: 16 * 1024,
        compression_threads: 0,
    }
}

fn typed_equal<M: MessageDefinition + Serialize>(
    reader: &BagReader,
    topic: Topic<M>,
    expected: &[Expected],
) {
    let got = reader.messages::<M>(topic.name).expect("typed read");
    let want: Vec<&Expected> = expected.iter().filter(|e| e.topic == topic.name).collect();
    assert_eq!(got.len(), want.len(), "{}", topic.name);
    for (g, w) in got.iter().zip(want) {
        assert_eq!(g.log_time, w.log_time);
        assert_eq!(g.publish_time, w.publish_time);
        assert_eq!(
            serde_json::to_value(&g.message).expect("json"),
            w.message,
            "{}",
            topic.name
        );
    }
}

#[test]
fn every_topic_round_trips_typed_in_log_time_order() {
    for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
        let (bytes, expected) = session_bytes(&options(compression));
        let reader = BagReader::from_bytes(&bytes, "session", &ReadOptions::default())
            .expect("reads")
            .strict()
            .expect("undamaged");
        assert!(reader.is_complete());
        let sorted = in_log_time_order(&expected);
        let raw: Vec<(String, u64)> = reader
            .iter()
            .map(|(c, m)| (c.topic.clone(), m.log_time))
            .collect();
        let want: Vec<(String, u64)> = sorted
            .iter()
            .map(|e| (e.topic.clone(), e.log_time))
            .collect();
        assert_eq!(raw, want, "{compression:?}");
        typed_equal(&reader, OPENFACE_FEATURES, &sorted);
        typed_equal(&reader, ENGAGEMENT_ESTIMATE, &sorted);
        typed_equal(&reader, EXPECTED_ENGAGEMENT, &sorted);
        typed_equal(&reader, THERAPIST_COMMAND, &sorted);
        typed_equal(&reader, GAME_STATE, &sorted);
        typed_equal(&reader, SEQUENCE_RESULT, &sorted);
        typed_equal(&reader, TABLET_TASK, &sorted);
        typed_equal(&reader, TABLET_ANSWER, &sorted);
        typed_equal(&reader, DECISION, &sorted);
        typed_equal(&reader, USER_MODEL_INFO, &sorted);
        typed_equal(&reader, HEARTBEAT, &sorted);
        typed_equal(&reader, ROBOT_SPEECH, &sorted);
        typed_equal(&reader, ROBOT_EMOTION, &sorted);
        typed_equal(&reader, ROBOT_GESTURE, &sorted);
        let (chunks, by_compression) = reader.chunks();
        assert!(chunks > 1, "{compression:?}: {chunks} chunks");
        let name = match compression {
            Compression::Zstd => "zstd",
            Compression::Lz4 => "lz4",
            Compression::None => "",
        };
        assert_eq!(by_compression.get(name), Some(&chunks));
    }
}

#[test]
fn the_file_is_shaped_like_rosbag2s() {
    let (bytes, _) = session_bytes(&options(Compression::Zstd));
    let reader = BagReader::from_bytes(&bytes, "session", &ReadOptions::default()).expect("reads");
    assert_eq!(reader.profile(), Some("ros2"));
    let all = all_topics();
    assert_eq!(reader.channels().count(), all.len());
    for t in &all {
        let c = reader.topic_channels(t.name);
        assert_eq!(c.len(), 1, "{}", t.name);
        let c = c[0];
        assert_eq!(c.message_encoding, "cdr");
        let schema = c.schema.as_ref().expect("schema");
        assert_eq!(schema.name, t.type_name);
        assert_eq!(schema.encoding, "ros2msg");
        assert_eq!(String::from_utf8_lossy(&schema.data), t.schema_text);
        assert_eq!(c.offered_qos(), Some(t.qos), "{}", t.name);
    }
    // One schema per type: the three String topics share one.
    let strings: Vec<u16> = [ROBOT_SPEECH.name, ROBOT_EMOTION.name, ROBOT_GESTURE.name]
        .iter()
        .map(|t| {
            reader.topic_channels(t)[0]
                .schema
                .as_ref()
                .map_or(0, |s| s.id)
        })
        .collect();
    assert!(strings.iter().all(|&id| id == strings[0] && id != 0));
    // rosbag2's metadata record, and the summary statistics the `mcap` crate reads back.
    let (name, meta) = &reader.metadata()[0];
    assert_eq!(name, "rosbag2");
    let text = &meta["serialized_metadata"];
    assert!(text.contains("storage_identifier: mcap"), "{text}");
    assert!(text.contains("name: /qt_therapy/game/state"), "{text}");
    let summary = mcap::Summary::read(&bytes)
        .expect("summary")
        .expect("present");
    let stats = summary.stats.expect("statistics");
    assert_eq!(stats.message_count, reader.raw_messages().len() as u64);
    assert!(!summary.chunk_indexes.is_empty());
    let info = BagInfo::of(&reader);
    assert_eq!(info.ros_distro.as_deref(), Some("jazzy"));
    let state = info
        .topics
        .iter()
        .find(|t| t.topic == GAME_STATE.name)
        .expect("listed");
    assert_eq!((state.count, state.qos.as_deref()), (4, Some("state")));
    // From the user model info at 0 ms to the last expected engagement at 3005 ms.
    assert_eq!(info.duration_ns, 3_005_000_000);
    assert!(info.to_text().contains("Topic: /qt_therapy/game/state"));
}

#[test]
fn channels_copied_from_another_bag_keep_their_schema_metadata_and_messages() {
    let (bytes, _) = session_bytes(&options(Compression::Zstd));
    let source = BagReader::from_bytes(&bytes, "source", &ReadOptions::default()).expect("reads");
    let mut w = BagWriter::new(
        std::io::Cursor::new(Vec::new()),
        "copy",
        &options(Compression::Lz4),
    )
    .expect("writer");
    let mut ids = std::collections::BTreeMap::new();
    for c in source.channels() {
        ids.insert(c.id, w.add_channel_like(c).expect("channel"));
    }
    for m in source.raw_messages() {
        let stamp = bag_file::Stamp {
            log_time: m.log_time,
            publish_time: m.publish_time,
            sequence: m.sequence,
        };
        w.write_cdr(ids[&m.channel_id], stamp, &m.data)
            .expect("write");
    }
    let copy = w.finish().expect("finish").into_inner();
    let copy = BagReader::from_bytes(&copy, "copy", &ReadOptions::default())
        .expect("reads")
        .strict()
        .expect("undamaged");
    let strip = |r: &BagReader| {
        let mut channels: Vec<_> = r
            .channels()
            .map(|c| {
                let s = c.schema.as_ref().expect("schema");
                let schema = (s.name.clone(), s.encoding.clone(), s.data.clone());
                (
                    c.topic.clone(),
                    c.message_encoding.clone(),
                    schema,
                    c.metadata.clone(),
                )
            })
            .collect();
        channels.sort();
        channels
    };
    assert_eq!(strip(&copy), strip(&source));
    let messages = |r: &BagReader| -> Vec<_> {
        r.iter()
            .map(|(c, m)| {
                (
                    c.topic.clone(),
                    m.log_time,
                    m.publish_time,
                    m.sequence,
                    m.data.clone(),
                )
            })
            .collect()
    };
    assert_eq!(messages(&copy), messages(&source));
    let (_, meta) = &copy.metadata()[0];
    let text = &meta["serialized_metadata"];
    assert!(
        text.contains("name: /qt_therapy/game/state\n      type: qt_therapy_msgs/msg/GameState"),
        "{text}"
    );
    assert!(text.contains("durability: transient_local"), "{text}");
}

#[test]
fn file_bags_appear_when_finished_and_flushed_chunks_are_readable_meanwhile() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("session.mcap");
    let partial = partial_path(&path);
    let mut w = BagWriter::create(&path, &options(Compression::Zstd)).expect("create");
    let expected = write_session(&mut w);
    w.flush_chunk().expect("flush");
    assert!(!path.exists() && partial.exists());
    // What a recovery after a crash here would read: everything, but no summary.
    let reader = BagReader::open(&partial).expect("reads");
    assert!(reader.damage().is_none(), "{:?}", reader.damage());
    assert!(!reader.is_complete());
    assert_eq!(reader.raw_messages().len(), expected.len());
    w.finish().expect("finish");
    assert!(path.exists() && !partial.exists());
    let reader = BagReader::open(&path).expect("reads");
    assert!(reader.is_complete());
    assert_eq!(reader.raw_messages().len(), expected.len());
}

#[test]
fn typed_reads_refuse_the_wrong_type_or_topic() {
    let (bytes, _) = session_bytes(&options(Compression::Lz4));
    let reader = BagReader::from_bytes(&bytes, "session", &ReadOptions::default()).expect("reads");
    let e = reader
        .messages::<qt_therapy_msgs::Decision>(GAME_STATE.name)
        .expect_err("wrong type");
    assert!(
        e.to_string().contains("qt_therapy_msgs/msg/GameState"),
        "{e}"
    );
    let e = reader
        .messages::<qt_therapy_msgs::Decision>("/nowhere")
        .expect_err("no topic");
    assert!(e.to_string().contains("/nowhere"), "{e}");
    assert_eq!(QosKind::State, GAME_STATE.qos);
    let states = reader.topic(GAME_STATE).expect("typed by the topic");
    assert_eq!(states.len(), 4);
    assert_eq!(states[3].message.status, "giving feedback");
}

#[test]
fn a_step_of_the_wall_clock_is_recorded_read_back_and_told_by_bag_info() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("session.mcap");
    let mut w = BagWriter::create(&path, &options(Compression::Zstd)).expect("create");
    let state = w.add_topic(GAME_STATE).expect("topic");
    let t0: u64 = 1_796_667_366_000_000_000;
    w.write(state, t0, &qt_therapy_msgs::GameState::default())
        .expect("write");
    let step = clock_steps::Step {
        at_steady_ns: t0 as i64 + 500_000_000,
        by_ns: -3_600_000_000_000,
    };
    w.write_clock_step(step).expect("step");
    w.write(
        state,
        t0 + 1_000_000_000,
        &qt_therapy_msgs::GameState::default(),
    )
    .expect("write");
    w.finish().expect("finish");
    let reader = BagReader::open(&path).expect("reads");
    assert_eq!(reader.clock_steps(), vec![step]);
    assert_eq!(reader.raw_messages().len(), 2);
    let text = BagInfo::of(&reader).to_text();
    let line = text
        .lines()
        .find(|l| l.starts_with("Clock steps:"))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(
        line.contains("-3600.000s at 2026-12-07 18:16:06.500000000 UTC"),
        "{line}"
    );
}
