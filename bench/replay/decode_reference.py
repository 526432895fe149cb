"""Reference for bench/replay: Python's mcap + mcap-ros2-support decoding the same hour bag.

Only the decoding the Rust replay also does (its OpenFace frames, decisions and results, from
CDR, in log-time order); no classification, no policy, so the Rust replay does strictly more.
Prints one JSON line: messages decoded and seconds (best of REPEATS, interpreter start left out).
    python3 bench/replay/decode_reference.py HOUR.mcap [REPEATS]
"""

import json
import sys
import time

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

TOPICS = [
    "/qt_therapy/openface/features",
    "/qt_therapy/policy/decision",
    "/qt_therapy/game/sequence_result",
]


def decode_all(path):
    n = 0
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, _channel, _message, _decoded in reader.iter_decoded_messages(
            topics=TOPICS, log_time_order=True
        ):
            n += 1
    return n


def main():
    path = sys.argv[1]
    repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    best = float("inf")
    n = 0
    for _ in range(repeats):
        started = time.perf_counter()
        n = decode_all(path)
        best = min(best, time.perf_counter() - started)
    print(json.dumps({"messages": n, "seconds": best}))


if __name__ == "__main__":
    main()
