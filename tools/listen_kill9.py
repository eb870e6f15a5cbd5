#!/usr/bin/env python3
"""Read what an MCAP file cut short (a `ringscan listen` killed with SIGKILL) still holds.

Usage:
    tools/.venv/bin/python tools/listen_kill9.py FILE.mcap

Reads FILE.mcap front to back with the official `mcap` package's StreamReader (no summary
section needed), decoding every complete chunk; point clouds are decoded with
`mcap-protobuf-support` and their points counted (data length / point_stride). Stops at the
first record that is cut short and says where. Prints one JSON object:

    {"file", "bytes", "chunks", "messages": {topic: n}, "points", "truncated_at", "error"}

Exit status 0 when at least one complete chunk with at least one point cloud was read, else 1.
"""

import json
import os
import sys

from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap_protobuf.decoder import DecoderFactory


def main():
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    path = sys.argv[1]
    size = os.path.getsize(path)
    schemas, channels, messages = {}, {}, {}
    chunks, points, error = 0, 0, None
    decoders = DecoderFactory()
    with open(path, "rb") as f:
        reader = StreamReader(f, skip_magic=False, emit_chunks=True)
        last_ok = 0
        try:
            for record in reader.records:
                inner = [record]
                if isinstance(record, Chunk):
                    inner = breakup_chunk(record, validate_crc=True)
                    chunks += 1
                for r in inner:
                    if isinstance(r, Schema):
                        schemas[r.id] = r
                    elif isinstance(r, Channel):
                        channels[r.id] = r
                    elif isinstance(r, Message):
                        ch = channels[r.channel_id]
                        messages[ch.topic] = messages.get(ch.topic, 0) + 1
                        if ch.topic.endswith("points"):
                            schema = schemas[ch.schema_id]
                            decode = decoders.decoder_for(ch.message_encoding, schema)
                            msg = decode(r.data)
                            points += len(msg.data) // max(msg.point_stride, 1)
                last_ok = f.tell()
        except Exception as e:  # the cut: whatever the reader says about it
            error = f"{type(e).__name__}: {e}"
    out = {
        "file": path,
        "bytes": size,
        "chunks": chunks,
        "messages": messages,
        "points": points,
        "truncated_at": last_ok if error else None,
        "error": error,
    }
    print(json.dumps(out))
    return 0 if chunks > 0 and points > 0 else 1


if __name__ == "__main__":
    sys.exit(main())
