//! Fuzz target: any bytes through the bag reader and everything built on it (summary, typed
//! CDR decoding of every suite topic, the player's plan). Nothing may panic, abort or hang.
#![no_main]

use bag::schedule::{PlayOptions, plan};
use bag::{BagInfo, BagReader, ReadOptions};
use libfuzzer_sys::fuzz_target;
use std::time::Duration;

fuzz_target!(|data: &[u8]| {
    // A small chunk limit keeps each run's memory bounded the same way production's does.
    let options = ReadOptions {
        max_chunk_bytes: 4 << 20,
    };
    let Ok(reader) = BagReader::from_bytes(data, "fuzz", &options) else {
        return;
    };
    let _ = BagInfo::of(&reader).to_text();
    for channel in reader.channels() {
        if let Some(t) = bag::suite::suite_type(channel.type_name()) {
            for m in reader
                .raw_messages()
                .iter()
                .filter(|m| m.channel_id == channel.id)
            {
                let _ = t.check_cdr(&m.data);
            }
        }
    }
    for rate in [Some(1.0), Some(1e-300), None] {
        let o = PlayOptions {
            rate,
            start_offset: Duration::from_millis(5),
            topics: vec![],
            remap: vec![],
        };
        let _ = plan(&reader, &o, |_| Ok(()));
    }
});
