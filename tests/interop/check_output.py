#!/usr/bin/env python3
"""Reads an MCAP file that levelscan wrote with the reference decoder (foxglove's `mcap` and
`mcap-ros2-support`), checks what Foxglove and `ros2 bag` expect of it, and prints what it
found as one JSON object for tests/bag_interop.rs to compare with levelscan's own output.

    check_output.py OUT.mcap [--input BAG] [--require-topic T ...]

Checks (each failure exits non-zero with one line `check_output: OUT.mcap: what`):
- the header's profile is `ros2`; every schema's encoding is `ros2msg`, every channel's
  message encoding `cdr` (the MCAP spec's ROS 2 appendix);
- the file reads whole with CRCs validated, by the streaming reader (records in order, data
  section CRC) and by the seeking reader (through its summary);
- the summary has a statistics record whose per-channel counts equal the messages read, and
  chunk indexes that cover every chunk;
- every message decodes with mcap-ros2-support's CDR decoder against its schema;
- with --input (an MCAP file or a rosbag2 directory with MCAP storage, read the same way):
  every input message is in the output, same topic, log time and bytes; (a ROS 1 .bag input:
  same topics, counts and log times, the bytes being CDR in the output).

Printed: {"profile", "library", "topics": {topic: {"type", "schema_encoding",
"message_encoding", "count"}}, "chunks", "chunk_compression": [...], "messages": {topic:
[decoded message as JSON, with "log_time" (ns)]}} for the levelscan topics /attitude,
/scan_level, /level_status, /odom_matched, /match_status.
"""

import argparse
import json
import math
import sys
from collections import Counter, defaultdict
from pathlib import Path

from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory

DUMPED = ("/attitude", "/scan_level", "/level_status", "/odom_matched", "/match_status")


def fail(path, what):
    print(f"check_output: {path}: {what}", file=sys.stderr)
    sys.exit(1)


def to_json(value):
    """A decoded ROS message (mcap_ros2's dynamic classes) as plain JSON values."""
    if isinstance(value, (bool, int, str)) or value is None:
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)  # NaN, inf as strings
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple)):
        return [to_json(v) for v in value]
    if hasattr(value, "tolist"):
        return to_json(value.tolist())
    slots = getattr(value, "__slots__", None)
    if slots:
        return {k: to_json(getattr(value, k)) for k in slots}
    return {k: to_json(v) for k, v in vars(value).items() if not k.startswith("_")}


def stream_pass(path):
    """Every record in file order with CRCs checked: the chunks' compressions, their count."""
    compressions, chunks = set(), 0
    with open(path, "rb") as f:
        for record in StreamReader(f, skip_magic=False, emit_chunks=True, validate_crcs=True).records:
            if isinstance(record, Chunk):
                chunks += 1
                compressions.add(record.compression)
    return chunks, sorted(compressions)


def read_mcap(path, decode):
    """(header, summary, [(topic, type, log_time, data, decoded or None)]) via the summary."""
    factories = [DecoderFactory()] if decode else []
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=factories)
        header, summary = reader.get_header(), reader.get_summary()
        rows = []
        if decode:
            for schema, channel, message, msg in reader.iter_decoded_messages(log_time_order=False):
                rows.append((channel.topic, schema.name, message.log_time, bytes(message.data), msg))
        else:
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                rows.append((channel.topic, schema.name if schema else "", message.log_time,
                             bytes(message.data), None))
    return header, summary, rows


def input_messages(bag):
    """(kind, [(topic, log_time, data)]) of an input bag: MCAP file, rosbag2 dir or ROS 1 bag."""
    p = Path(bag)
    if p.is_dir():
        files = sorted(p.glob("*.mcap"))
        if not files:
            fail(bag, "no MCAP file in the rosbag2 directory")
        rows = []
        for file in files:
            rows += [(t, lt, d) for t, _, lt, d, _ in read_mcap(file, False)[2]]
        return "mcap", rows
    with open(p, "rb") as f:
        magic = f.read(13)
    if magic.startswith(b"#ROSBAG V2.0"):
        from rosbags.rosbag1 import Reader
        with Reader(p) as r:
            return "ros1", [(c.topic, t, bytes(d)) for c, t, d in r.messages()]
    return "mcap", [(t, lt, d) for t, _, lt, d, _ in read_mcap(p, False)[2]]


def check_copied(path, rows, bag):
    kind, inputs = input_messages(bag)
    if kind == "mcap":
        have = Counter((t, lt, d) for t, _, lt, d, _ in rows)
        want = Counter(inputs)
    else:
        have = Counter((t, lt) for t, _, lt, _, _ in rows)
        want = Counter((t, lt) for t, lt, _ in inputs)
    missing = want - have
    if missing:
        (topic, lt, *_), n = next(iter(missing.items()))
        fail(path, f"{sum(missing.values())} input messages not copied through "
                   f"(first: {topic} at log time {lt}, {n}x)")
    return len(inputs)


def check(path, args):
    chunks, compressions = stream_pass(path)
    header, summary, rows = read_mcap(path, True)
    if header.profile != "ros2":
        fail(path, f"profile {header.profile!r}, not 'ros2'")
    if summary is None:
        fail(path, "no summary section")
    for s in summary.schemas.values():
        if s.encoding != "ros2msg":
            fail(path, f"schema {s.name}: encoding {s.encoding!r}, not 'ros2msg'")
    topics = {}
    for c in summary.channels.values():
        if c.message_encoding != "cdr":
            fail(path, f"channel {c.topic}: message encoding {c.message_encoding!r}, not 'cdr'")
        schema = summary.schemas.get(c.schema_id)
        topics[c.topic] = {"type": schema.name if schema else None,
                           "schema_encoding": schema.encoding if schema else None,
                           "message_encoding": c.message_encoding, "count": 0}
    counts = Counter(t for t, *_ in rows)
    for t, n in counts.items():
        topics[t]["count"] = n
    if summary.statistics is None:
        fail(path, "summary without a statistics record")
    by_channel = {summary.channels[i].topic: n
                  for i, n in summary.statistics.channel_message_counts.items()}
    if {t: n for t, n in by_channel.items() if n} != dict(counts):
        fail(path, f"statistics {by_channel} but messages read {dict(counts)}")
    if summary.statistics.message_count != len(rows):
        fail(path, f"statistics say {summary.statistics.message_count} messages, read {len(rows)}")
    if chunks and len(summary.chunk_indexes) != chunks:
        fail(path, f"{chunks} chunks but {len(summary.chunk_indexes)} chunk indexes")
    for t in args.require_topic:
        if not counts.get(t):
            fail(path, f"no message on {t}")
    copied = check_copied(path, rows, args.input) if args.input else None
    messages = defaultdict(list)
    for topic, _, log_time, _, msg in sorted(rows, key=lambda r: r[2]):
        if topic in DUMPED:
            m = to_json(msg)
            m["log_time"] = log_time
            messages[topic].append(m)
    return {"profile": header.profile, "library": header.library, "topics": topics,
            "chunks": chunks, "chunk_indexes": len(summary.chunk_indexes),
            "chunk_compression": compressions, "copied": copied, "messages": messages}


def main(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("output", help="an MCAP file written by levelscan")
    p.add_argument("--input", help="the bag it was made from: every message must be copied")
    p.add_argument("--require-topic", action="append", default=[])
    args = p.parse_args(argv)
    try:
        result = check(args.output, args)
    except Exception as e:  # the reference reader refused the file: that is the finding
        fail(args.output, f"{type(e).__name__}: {e}")
    json.dump(result, sys.stdout)
    print()


if __name__ == "__main__":
    main(sys.argv[1:])
