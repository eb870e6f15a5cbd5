#!/usr/bin/env python3
"""A Foxglove WebSocket protocol client for `ringscan listen --serve` (tests and by hand).

Usage:
    tools/serve_client.py ws://127.0.0.1:8765 [--topic-suffix points] [--messages N]
        [--timeout S]

Connects with the `foxglove.sdk.v1` (formerly `foxglove.websocket.v1`) subprotocol, waits for the server's `advertise`,
subscribes to every channel whose topic ends with --topic-suffix (schema foxglove.PointCloud,
protobuf), then reads binary Message Data frames (opcode 1: u8 opcode, u32 subscription id,
u64 log time, payload) until N messages or the timeout. Each payload is parsed as a
foxglove.PointCloud by hand (protobuf wire format: point_stride = field 4, fixed32; data =
field 6, bytes). Prints one JSON object:

    {"server": name, "channels": [{"id", "topic", "schemaName", "encoding"}],
     "messages": [{"topic", "log_time", "point_stride", "points", "byte_sum", "frame_id"}]}

(`byte_sum`: the sum of the point data bytes modulo 2^32, to compare with a file.)

Runs inside tools/.venv-serve (created on first use with the pinned `websockets`).
"""

import json
import os
import struct
import subprocess
import sys
import time
import venv

TOOLS = os.path.dirname(os.path.abspath(__file__))
VENV = os.path.join(TOOLS, ".venv-serve")
REQUIREMENT = "websockets==15.0.1"


def ensure_venv():
    if os.path.realpath(sys.prefix) == os.path.realpath(VENV):
        return
    python = os.path.join(VENV, "bin", "python")
    stamp = os.path.join(VENV, ".requirement")
    have = open(stamp).read().strip() if os.path.exists(stamp) else None
    if have != REQUIREMENT or not os.path.exists(python):
        venv.create(VENV, with_pip=True, clear=True)
        subprocess.run([python, "-m", "pip", "install", "--quiet", REQUIREMENT], check=True)
        with open(stamp, "w") as f:
            f.write(REQUIREMENT)
    os.execv(python, [python, os.path.abspath(__file__), *sys.argv[1:]])


def varint(b, i):
    v, shift = 0, 0
    while True:
        c = b[i]
        i += 1
        v |= (c & 0x7F) << shift
        if c < 0x80:
            return v, i
        shift += 7


def point_cloud(payload):
    """point_stride, data length, byte sum (mod 2^32) of data and frame_id of a
    foxglove.PointCloud."""
    i, stride, data_len, frame, byte_sum = 0, 0, 0, "", 0
    while i < len(payload):
        key, i = varint(payload, i)
        field, wire = key >> 3, key & 7
        if wire == 0:
            _, i = varint(payload, i)
        elif wire == 1:
            i += 8
        elif wire == 5:
            if field == 4:
                stride = struct.unpack_from("<I", payload, i)[0]
            i += 4
        elif wire == 2:
            n, i = varint(payload, i)
            if field == 6:
                data_len = n
                byte_sum = sum(payload[i:i + n]) & 0xFFFFFFFF
            elif field == 2:
                frame = payload[i:i + n].decode()
            i += n
        else:
            raise ValueError(f"wire type {wire}")
    return stride, data_len, byte_sum, frame


def main():
    ensure_venv()
    import argparse

    from websockets.sync.client import connect

    ap = argparse.ArgumentParser()
    ap.add_argument("url")
    ap.add_argument("--topic-suffix", default="points")
    ap.add_argument("--messages", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=30)
    a = ap.parse_args()
    out = {"server": None, "channels": [], "messages": []}
    deadline = time.monotonic() + a.timeout
    subs = {}
    # foxglove.sdk.v1 is the foxglove SDK's name of the protocol first published as
    # foxglove.websocket.v1 (same messages); v1.1 would change the advertise message.
    with connect(a.url, subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"], max_size=None,
                 open_timeout=a.timeout) as ws:
        while time.monotonic() < deadline and len(out["messages"]) < a.messages:
            try:
                frame = ws.recv(timeout=max(0.05, deadline - time.monotonic()))
            except TimeoutError:
                break
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg.get("op") == "serverInfo":
                    out["server"] = msg.get("name")
                elif msg.get("op") == "advertise":
                    new = []
                    for ch in msg["channels"]:
                        out["channels"].append({k: ch.get(k) for k in ("id", "topic", "schemaName", "encoding")})
                        if ch["topic"].endswith(a.topic_suffix) and ch["id"] not in subs.values():
                            sid = len(subs) + 1
                            subs[sid] = ch["id"]
                            new.append({"id": sid, "channelId": ch["id"]})
                    if new:
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                continue
            if frame[0] != 1:
                continue
            sid, log_time = struct.unpack_from("<IQ", frame, 1)
            stride, data_len, byte_sum, frame_id = point_cloud(frame[13:])
            topic = next((c["topic"] for c in out["channels"] if c["id"] == subs.get(sid)), None)
            out["messages"].append({"topic": topic, "log_time": log_time, "point_stride": stride,
                                    "points": data_len // max(stride, 1), "byte_sum": byte_sum,
                                    "frame_id": frame_id})
    print(json.dumps(out))
    return 0 if len(out["messages"]) >= a.messages else 1


if __name__ == "__main__":
    sys.exit(main())
