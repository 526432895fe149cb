#!/usr/bin/env python3
"""Recording throughput: our bag writer (Rust) against the Python `mcap` writer on the same
messages, one run, ratios printed.

Run from the workspace root:  python3 bench/bag/bench_record.py [zstd|lz4]
(builds the `bench_record` benchmark binary with --release; needs the `mcap` package)

Messages: one SYNTHETIC hour of a session's traffic from the example (OpenFace frames and
engagement labels at 30 Hz, heartbeats of five nodes at 10 Hz, expected engagement at 1 Hz, a
game sequence every 30 s): about 400,000 CDR payloads. Both writers get the same payloads, the
same schemas and channels, 1 MiB chunks, the same compression at its default level, one
thread, and write to a file on the same disk; best of 3 runs each.
  - write:        CDR payloads -> MCAP, both sides (the like-for-like figure)
  - encode+write: Rust only: typed message -> CDR -> MCAP (what `bag record` does per message
                  after DDS; Python is still given pre-encoded payloads)
"""
import json
import os
import struct
import subprocess
import sys
import tempfile
import time

from mcap.writer import CompressionType, Writer

REPEATS = 3


def run(cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def load(dump):
    with open(dump, "rb") as f:
        data = f.read()
    out, pos = [], 0
    while pos < len(data):
        kind, log_time, length = struct.unpack_from("<BQI", data, pos)
        pos += 13
        out.append((kind, log_time, data[pos:pos + length]))
        pos += length
    return out


def python_write(path, channels, payloads, compression):
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=1024 * 1024, compression=compression)
        w.start(profile="ros2", library="python-mcap bench")
        ids = []
        for c in channels:
            schema = w.register_schema(c["type"], "ros2msg", c["schema"].encode())
            ids.append(w.register_channel(c["topic"], "cdr", schema,
                                          {"offered_qos_profiles": c["qos"]}))
        for seq, (kind, log_time, payload) in enumerate(payloads):
            w.add_message(ids[kind], log_time, payload, log_time, sequence=seq)
        w.finish()


def main():
    codec = sys.argv[1] if len(sys.argv) > 1 else "zstd"
    compression = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}[codec]
    tmp = tempfile.mkdtemp(prefix="bag_bench_")
    run(["cargo", "build", "--release", "-q", "-p", "suite_bench", "--bin", "bench_record"])
    rust = json.loads(run(["target/release/bench_record", tmp, codec]))
    channels = json.load(open(os.path.join(tmp, "channels.json")))
    payloads = load(os.path.join(tmp, "payloads.bin"))
    assert len(payloads) == rust["messages"]
    best = float("inf")
    path = os.path.join(tmp, "python_write.mcap")
    for _ in range(REPEATS):
        start = time.perf_counter()
        python_write(path, channels, payloads, compression)
        best = min(best, time.perf_counter() - start)
    py_size = os.path.getsize(path)
    n = rust["messages"]
    mb = rust["payload_bytes"] / 1e6
    print(f"{n} messages, {mb:.1f} MB of CDR payloads, chunks {codec}, best of {REPEATS}")
    print(f"  python mcap  write:        {best:7.3f} s  {n / best:10.0f} msg/s  "
          f"file {py_size / 1e6:.1f} MB")
    print(f"  rust bag     write:        {rust['write_s']:7.3f} s  {n / rust['write_s']:10.0f} msg/s  "
          f"file {rust['file_bytes'] / 1e6:.1f} MB")
    print(f"  rust bag     encode+write: {rust['encode_write_s']:7.3f} s  "
          f"{n / rust['encode_write_s']:10.0f} msg/s")
    print(f"ratio write (rust / python throughput):        {best / rust['write_s']:.1f}x")
    print(f"ratio encode+write vs python write:           {best / rust['encode_write_s']:.1f}x")
    print(f"one hour of this traffic records in {rust['encode_write_s']:.2f} s of one core "
          f"({rust['encode_write_s'] / 3600 * 100:.3f} % of the hour)")


if __name__ == "__main__":
    main()
