#!/usr/bin/env python3
"""A Foxglove WebSocket client (the `websockets` package) against `ringscan --serve`.

Runs, on loopback:
  1. `ringscan decode PCAP --out A.mcap --serve 127.0.0.1:0 --serve-rate 1 --json`;
  2. `ringscan listen --sensor 127.0.0.1:PORT --out B.mcap --serve 127.0.0.1:0 --json`, fed by
     `ringscan replay PCAP --port-offset N`, stopped with SIGINT.
Each time the client offers the subprotocol foxglove.websocket.v1, reads serverInfo and advertise,
subscribes to /points and reads messageData frames (0x01, u32 LE subscription id, u64 LE log
time, payload) until the server closes. Payloads are decoded with the protobuf runtime from the
FileDescriptorSet the server advertised (base64), not with ringscan's encoder. Checks:
  - at least 2 sweeps received;
  - they are the last N /points messages of the MCAP file the same run wrote (read with the
    official `mcap` reader), byte for byte and with the same log times;
  - frame_id = the sensor name in --json, point_stride 24, the default fields in order;
  - points of the sweeps received + those of the sweeps before the subscription = --json points;
  - the run's --json `serve` object counts the messages sent and no drop.
Exit status 1 on any failure.
"""

import argparse
import base64
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import threading
import time

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.websocket.v1"
FIELDS = ["x", "y", "z", "intensity", "t", "ring", "return"]


class Run:
    """A ringscan process whose stderr is read on a thread, for the live view's address."""

    def __init__(self, args, wait_listen, wait_addr=True):
        env = dict(os.environ, RINGSCAN_LOG="info")
        self.p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
        self.lines = []
        self.addr = None
        self.listening = not wait_listen
        self.cv = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()
        deadline = time.time() + 30
        with self.cv:
            while (wait_addr and self.addr is None) or not self.listening:
                if self.p.poll() is not None or time.time() > deadline:
                    raise SystemExit("ringscan did not start serving:\n" + "".join(self.lines))
                self.cv.wait(0.1)

    def _read(self):
        for line in self.p.stderr:
            with self.cv:
                self.lines.append(line)
                if "ws://" in line:
                    self.addr = line.split("ws://", 1)[1].split()[0]
                if "listening on UDP ports" in line:
                    self.listening = True
                self.cv.notify_all()

    def finish(self, sig=None):
        if sig is not None:
            self.p.send_signal(sig)
        out = self.p.stdout.read()
        code = self.p.wait(timeout=60)
        if code != 0:
            raise SystemExit(f"ringscan exited with {code}:\n" + "".join(self.lines))
        return json.loads(out)


def open_ws(addr):
    return connect(f"ws://{addr}/", subprotocols=[SUBPROTOCOL], max_size=None, open_timeout=10)


class Client:
    def __init__(self, ws):
        self.ws = ws
        if self.ws.subprotocol != SUBPROTOCOL:
            raise SystemExit(f"server selected subprotocol {self.ws.subprotocol!r}")
        self.channels = {}
        self.server_info = None

    def _text(self, text):
        msg = json.loads(text)
        if msg["op"] == "serverInfo":
            self.server_info = msg
        elif msg["op"] == "advertise":
            for c in msg["channels"]:
                self.channels[c["id"]] = c
        else:
            raise SystemExit(f"unexpected op {msg['op']!r}")

    def wait_channel(self, topic):
        while True:
            for c in self.channels.values():
                if c["topic"] == topic:
                    return c
            m = self.ws.recv(timeout=30)
            if not isinstance(m, str):
                raise SystemExit("binary message before subscribing")
            self._text(m)

    def subscribe(self, sub_id, channel_id):
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": sub_id, "channelId": channel_id}]}))

    def receive_all(self):
        """messageData frames until the server closes the connection."""
        frames = []
        try:
            while True:
                m = self.ws.recv(timeout=30)
                if isinstance(m, str):
                    self._text(m)
                    continue
                op, sub, log_time = struct.unpack_from("<BIQ", m, 0)
                if op != 0x01:
                    raise SystemExit(f"binary opcode {op}")
                frames.append((sub, log_time, bytes(m[13:])))
        except Exception as e:  # ConnectionClosedOK / ConnectionClosedError end the stream
            if "ConnectionClosed" not in type(e).__name__:
                raise
        return frames


def message_class(channel):
    """The message class of an advertised protobuf channel, built from its schema alone."""
    if channel["encoding"] != "protobuf":
        raise SystemExit(f"encoding {channel['encoding']!r}")
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    pending = list(fds.file)
    added = set()
    while pending:
        progress = False
        for f in list(pending):
            if all(d in added for d in f.dependency):
                pool.Add(f)
                added.add(f.name)
                pending.remove(f)
                progress = True
        if not progress:
            raise SystemExit("schema: unresolved imports " + str([f.name for f in pending]))
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))


def mcap_points(path):
    with open(path, "rb") as f:
        return [(m.log_time, bytes(m.data)) for _, _, m in make_reader(f).iter_messages(topics=["/points"])]


def check(label, frames, channel, file_msgs, summary, sub_id):
    errors = []
    cls = message_class(channel)
    if channel["schemaName"] != "foxglove.PointCloud":
        errors.append(f"schemaName {channel['schemaName']}")
    n = len(frames)
    if n < 2:
        errors.append(f"{n} sweeps received")
    if n > len(file_msgs):
        errors.append(f"{n} received but {len(file_msgs)} in the MCAP")
        n = 0
    start = len(file_msgs) - n
    name = summary["sensors"][0]["name"]
    points = 0
    for i, (sub, log_time, payload) in enumerate(frames[: n or 0]):
        ft, fp = file_msgs[start + i]
        if sub != sub_id:
            errors.append(f"sweep {start + i}: subscription {sub}")
        if log_time != ft:
            errors.append(f"sweep {start + i}: log time {log_time} != MCAP {ft}")
        if payload != fp:
            errors.append(f"sweep {start + i}: payload differs from the MCAP message")
        pc = cls.FromString(payload)
        if pc.frame_id != name:
            errors.append(f"sweep {start + i}: frame_id {pc.frame_id!r} != {name!r}")
        if pc.point_stride != 24 or [f.name for f in pc.fields] != FIELDS:
            errors.append(f"sweep {start + i}: stride {pc.point_stride}, fields {[f.name for f in pc.fields]}")
        if len(pc.data) % pc.point_stride:
            errors.append(f"sweep {start + i}: data not a whole number of points")
        points += len(pc.data) // max(pc.point_stride, 1)
    missed = sum(len(cls.FromString(p).data) // 24 for _, p in file_msgs[:start])
    if missed + points != summary["points"]:
        errors.append(f"points: {missed} before the subscription + {points} received != {summary['points']}")
    if len(file_msgs) != summary["sweeps"]:
        errors.append(f"MCAP /points messages {len(file_msgs)} != --json sweeps {summary['sweeps']}")
    serve = summary.get("serve") or {}
    if serve.get("messages_sent", -1) < len(frames):
        errors.append(f"serve.messages_sent {serve.get('messages_sent')} < {len(frames)} received")
    if serve.get("messages_dropped") != 0:
        errors.append(f"serve.messages_dropped {serve.get('messages_dropped')}")
    print(
        f"{'ok  ' if not errors else 'FAIL'} {label}: {len(frames)} of {len(file_msgs)} sweeps received "
        f"(from sweep {start}), {points} points, frame_id {name!r}; server sent {serve.get('messages_sent')} "
        f"messages, {serve.get('bytes_sent')} bytes, dropped {serve.get('messages_dropped')}"
    )
    for e in errors[:10]:
        print("    " + e)
    return not errors


def free_udp_port():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", required=True, help="the ringscan binary")
    ap.add_argument("--pcap", required=True, help="a single-sensor Velodyne capture (data on port 2368)")
    ap.add_argument("--tmp", required=True, help="a folder for the MCAP files")
    a = ap.parse_args()
    ok = True

    # 1. decode --serve, paced in real time.
    out = os.path.join(a.tmp, "decode.mcap")
    run = Run([a.bin, "decode", a.pcap, "--out", out, "--serve", "127.0.0.1:0", "--serve-rate", "1", "--json"], False)
    with open_ws(run.addr) as ws:
        c = Client(ws)
        ch = c.wait_channel("/points")
        c.subscribe(5, ch["id"])
        frames = c.receive_all()
    summary = run.finish()
    if (c.server_info or {}).get("name") != "ringscan":
        print(f"FAIL serverInfo {c.server_info}")
        ok = False
    ok &= check("decode --serve", frames, ch, mcap_points(out), summary, 5)

    # 2. listen --serve fed by replay.
    port = free_udp_port()
    out = os.path.join(a.tmp, "listen.mcap")
    run = Run([a.bin, "listen", "--sensor", f"127.0.0.1:{port}", "--out", out, "--serve", "127.0.0.1:0", "--json"], True)
    with open_ws(run.addr) as ws:
        c = Client(ws)
        replay = subprocess.Popen(
            [a.bin, "replay", a.pcap, "--to", "127.0.0.1", "--port-offset", str(port - 2368), "--rate", "1"],
            stdout=subprocess.DEVNULL,
        )
        ch = c.wait_channel("/points")
        c.subscribe(9, ch["id"])
        got = []
        reader = threading.Thread(target=lambda: got.extend(c.receive_all()))
        reader.start()
        if replay.wait(timeout=120) != 0:
            raise SystemExit("replay failed")
        time.sleep(0.5)
        summary = run.finish(signal.SIGINT)
        reader.join(timeout=30)
    if summary["receive"]["queue_dropped"] != 0:
        print(f"FAIL listen: receive queue dropped {summary['receive']['queue_dropped']}")
        ok = False
    ok &= check("listen --serve", got, ch, mcap_points(out), summary, 9)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
