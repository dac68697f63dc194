#!/usr/bin/env python3
"""Reads a bag written by `levelscan simulate -o run.mcap` with the reference readers
(foxglove's `mcap` and `mcap-ros2-support`) and prints what it found as one JSON object, for
tests/bag_write.rs to check.

    read_simulated.py RUN.mcap

Exits 3 with a message naming the module when `mcap` or `mcap_ros2` is not installed (the
test then skips), 1 when the file does not read.

Printed: {"profile", "library", "schemas": {name: encoding}, "channels": {topic: {"type",
"message_encoding", "qos"}}, "statistics": {topic: count} (from the summary),
"chunk_indexes", "chunks_with_message_indexes", "compression": [...], "counts": {topic:
decoded messages}, "first": {topic: the first message, decoded, as JSON}}.
"""

import json
import math
import sys

try:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
except ImportError as e:  # the Rust test skips on exit code 3
    print(f"read_simulated: missing Python module: {e.name}", file=sys.stderr)
    sys.exit(3)


def plain(value):
    """A decoded ROS message (or field) as JSON-able data; NaN as None."""
    if hasattr(value, "__slots__"):
        return {k: plain(getattr(value, k)) for k in value.__slots__}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, float) and math.isnan(value):
        return None
    if hasattr(value, "tolist"):
        return plain(value.tolist())
    return value


def main(path):
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        summary = reader.get_summary()
        if summary is None:
            print(f"read_simulated: {path}: no summary section", file=sys.stderr)
            return 1
        topic_of = {cid: c.topic for cid, c in summary.channels.items()}
        out = {
            "profile": header.profile,
            "library": header.library,
            "schemas": {s.name: s.encoding for s in summary.schemas.values()},
            "channels": {
                c.topic: {
                    "type": summary.schemas[c.schema_id].name,
                    "message_encoding": c.message_encoding,
                    "qos": c.metadata.get("offered_qos_profiles"),
                }
                for c in summary.channels.values()
            },
            "statistics": {
                topic_of[cid]: n
                for cid, n in summary.statistics.channel_message_counts.items()
            },
            "chunk_indexes": len(summary.chunk_indexes),
            "chunks_with_message_indexes": sum(
                1 for ci in summary.chunk_indexes if ci.message_index_offsets
            ),
            "compression": sorted({ci.compression for ci in summary.chunk_indexes}),
            "counts": {},
            "first": {},
        }
        # Decoding every message through the summary's indexes (the seeking path).
        for _schema, channel, message, decoded in reader.iter_decoded_messages():
            topic = channel.topic
            out["counts"][topic] = out["counts"].get(topic, 0) + 1
            if topic not in out["first"]:
                first = plain(decoded)
                first["log_time"] = message.log_time
                out["first"][topic] = first
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
