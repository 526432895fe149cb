#!/usr/bin/env python3
"""Proves our bags read in the standard Python readers: the `mcap` package (with
`mcap-ros2-support` decoding the `ros2msg` schemas and CDR payloads) and `rosbags`.

Run from the workspace root:
    python3 -m venv target/bag-check-venv && . target/bag-check-venv/bin/activate  # (Debian: PEP 668)
    python3 -m pip install -q -r tests/bags/requirements.txt
    python3 tests/bags/check_bag.py              # writes and checks the synthetic test session
    python3 tests/bags/check_bag.py A.mcap ...   # checks bags you recorded (both readers agree)

Without arguments it runs `cargo run -p bag_file --example write_check_bags` to write the synthetic
session with zstd, lz4 and uncompressed chunks, then checks in both readers that the profile,
schemas, channels, QoS metadata, summary and every decoded message match what was written.
Exits non-zero on the first mismatch.
"""
import dataclasses
import json
import math
import os
import subprocess
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.typesys import Stores, get_typestore

# What each QoS class of the suite offers (msgs/src/topics.rs), as rosbags names it.
RELIABILITY = {"features": "BEST_EFFORT", "reliable": "RELIABLE", "state": "RELIABLE",
               "durable": "RELIABLE"}


def fail(msg):
    print(f"FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def plain(value):
    """A decoded message (mcap_ros2 object, rosbags dataclass, numpy array) as JSON-like data."""
    # ROS field names are lower case; constants (upper case) and rosbags' __msgtype__ are not
    # fields of the message.
    if dataclasses.is_dataclass(value):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if not f.name.startswith("__") and not f.name.isupper()}
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if hasattr(value, "__slots__"):
        return {k: plain(getattr(value, k)) for k in value.__slots__ if not k.isupper()}
    return value


def same(got, want, where):
    if isinstance(want, dict):
        if not isinstance(got, dict) or set(got) != set(want):
            fail(f"{where}: fields {sorted(got) if isinstance(got, dict) else got} != {sorted(want)}")
        for k in want:
            same(got[k], want[k], f"{where}.{k}")
    elif isinstance(want, list):
        if not isinstance(got, list) or len(got) != len(want):
            fail(f"{where}: {got!r} != {want!r}")
        for i, (g, w) in enumerate(zip(got, want)):
            same(g, w, f"{where}[{i}]")
    elif isinstance(want, float) or isinstance(got, float):
        # float32 fields: serde prints the shortest f32 text, Python holds the exact value.
        # NaN is a value here (an estimate of a frame without a face), equal to itself.
        if math.isnan(float(got)) and math.isnan(float(want)):
            return
        if not math.isclose(float(got), float(want), rel_tol=1e-6, abs_tol=1e-7):
            fail(f"{where}: {got!r} != {want!r}")
    elif got != want:
        fail(f"{where}: {got!r} != {want!r}")


def by_topic(items):
    out = defaultdict(list)
    for topic, item in items:
        out[topic].append(item)
    return out


def check_mcap(path, expected):
    """The `mcap` package: header, summary, schemas, channels, metadata, decoded messages."""
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        if reader.get_header().profile != "ros2":
            fail(f"{path}: profile {reader.get_header().profile!r}")
        summary = reader.get_summary()
        if summary is None or summary.statistics is None:
            fail(f"{path}: no summary statistics")
        if expected is not None and summary.statistics.message_count != len(expected):
            fail(f"{path}: statistics count {summary.statistics.message_count}")
        if not summary.chunk_indexes:
            fail(f"{path}: no chunk indexes")
        for s in summary.schemas.values():
            if s.encoding != "ros2msg" or "/msg/" not in s.name:
                fail(f"{path}: schema {s.name} {s.encoding}")
        for c in summary.channels.values():
            if c.message_encoding != "cdr" or "offered_qos_profiles" not in c.metadata:
                fail(f"{path}: channel {c.topic} {c.message_encoding} {c.metadata}")
        names = [m.name for m in reader.iter_metadata()]
        if "rosbag2" not in names:
            fail(f"{path}: metadata records {names}")
        decoded = [
            (channel.topic, (message.log_time, message.publish_time, plain(ros)))
            for _, channel, message, ros in reader.iter_decoded_messages(log_time_order=True)
        ]
    compression = {ci.compression for ci in summary.chunk_indexes}
    return by_topic(decoded), compression


def check_rosbags(path):
    """`rosbags`: the rosbag2 reader's topics and QoS, then AnyReader's typed messages."""
    qos = {}
    with Rosbag2Reader(path) as reader:
        for c in reader.connections:
            profiles = c.ext.offered_qos_profiles
            qos[c.topic] = profiles[0].reliability.name if profiles else None
    with AnyReader([Path(path)], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        decoded = [
            (c.topic, (t, plain(reader.deserialize(raw, c.msgtype))))
            for c, t, raw in reader.messages()
        ]
    return by_topic(decoded), qos


def compare(path, expected):
    want = by_topic((e["topic"], e) for e in expected)
    got_mcap, compression = check_mcap(path, expected)
    got_rosbags, qos = check_rosbags(path)
    for topic, items in want.items():
        if len(got_mcap[topic]) != len(items) or len(got_rosbags[topic]) != len(items):
            fail(f"{path} {topic}: {len(items)} written, mcap {len(got_mcap[topic])}, "
                 f"rosbags {len(got_rosbags[topic])}")
        for i, e in enumerate(items):
            log_time, publish_time, m = got_mcap[topic][i]
            if (log_time, publish_time) != (e["log_time"], e["publish_time"]):
                fail(f"{path} {topic}[{i}]: times {log_time} {publish_time}")
            same(m, e["message"], f"{path} mcap {topic}[{i}]")
            t, r = got_rosbags[topic][i]
            if t != e["log_time"]:
                fail(f"{path} {topic}[{i}]: rosbags time {t}")
            same(r, e["message"], f"{path} rosbags {topic}[{i}]")
    return compression, qos


def check_recorded(path):
    """A bag recorded elsewhere: both readers decode every message and agree."""
    got_mcap, _ = check_mcap(path, None)
    got_rosbags, _ = check_rosbags(path)
    if set(got_mcap) != set(got_rosbags):
        fail(f"{path}: topics {sorted(got_mcap)} vs {sorted(got_rosbags)}")
    for topic in got_mcap:
        a, b = got_mcap[topic], got_rosbags[topic]
        if len(a) != len(b):
            fail(f"{path} {topic}: mcap {len(a)}, rosbags {len(b)}")
        for i, ((la, _, ma), (lb, mb)) in enumerate(zip(a, b)):
            if la != lb:
                fail(f"{path} {topic}[{i}]: log times {la} vs {lb}")
            same(ma, mb, f"{path} {topic}[{i}]")
    print(f"ok: {path}: {sum(len(v) for v in got_mcap.values())} messages on "
          f"{len(got_mcap)} topics decode alike in mcap and rosbags")


def main():
    if len(sys.argv) > 1:
        for path in sys.argv[1:]:
            check_recorded(path)
        return
    root = Path(__file__).resolve().parents[2]
    out = tempfile.mkdtemp(prefix="bag_check_")
    subprocess.run(["cargo", "run", "-q", "-p", "bag_file", "--example", "write_check_bags", "--", out],
                   check=True, cwd=root, stdout=subprocess.DEVNULL)
    expected = json.loads(Path(out, "expected.json").read_text())
    qos_class = {e["topic"]: e["qos"] for e in expected}
    for name, codec in [("zstd", "zstd"), ("lz4", "lz4"), ("none", "")]:
        path = os.path.join(out, f"session_{name}.mcap")
        compression, qos = compare(path, expected)
        if compression != {codec}:
            fail(f"{path}: chunk compression {compression}")
        for topic, reliability in qos.items():
            if reliability != RELIABILITY[qos_class[topic]]:
                fail(f"{path} {topic}: rosbags reads QoS reliability {reliability}")
        print(f"ok: {path}: {len(expected)} messages on {len(qos)} topics read alike in "
              f"mcap (CRCs checked) and rosbags, chunks {codec or 'uncompressed'}, QoS as offered")


if __name__ == "__main__":
    main()
