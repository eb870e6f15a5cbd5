#!/usr/bin/env python3
"""Open a rosbag2 written by `ringscan ... --format ros2 --out DIR` with `rosbags` and check it.

Usage:
    tools/check_ros2_bag.py DIR [--expect DECODE.json] [--points FOXGLOVE_POINTS.json]
                            [--require TOPIC_SUFFIX ...] [--quiet]
    tools/check_ros2_bag.py --dump-foxglove FILE.mcap      (run with tools/.venv: mcap + protobuf)

Opens DIR with `rosbags.rosbag2.Reader` (an independent reader: it parses metadata.yaml and
every storage file the yaml lists) and deserialises every message of every connection twice:
with the stock ROS 2 Humble type store of `rosbags` (its own copies of the message
definitions; types it does not ship, such as `velodyne_msgs`, from the bag's definitions), and
with a store built from the bag's own `ros2msg` definitions only. Both must consume each
message whole. Checks:

- message counts per topic: the yaml's, the files', and (with --expect, ringscan's `--json`
  of the same run) `output.topics`;
- `sensor_msgs/msg/PointCloud2`: point_step × width = row_step = len(data), height 1; with
  --points (the Foxglove output of the same run, dumped by --dump-foxglove), for every points
  topic the same number of messages, the same field names / offsets / types and the same data
  bytes (SHA-256 of each message's data, in order): bit for bit (a Foxglove topic's sensor
  name compared as ROS 2 takes it: `/vlp16-201/points` is the bag's `/vlp16_201/points`);
- every topic of the bag is a name ROS 2 accepts (rmw's rules: tokens of letters, digits
  and `_`, none starting with a digit);
- `--require`: at least one message on a topic ending in each suffix (e.g. `/imu`, `/clusters`).

Prints one JSON object ({"bag", "topics": {topic: {"type", "messages"}}, "ok", "errors"}) and
exits 0 when every check passes, 1 otherwise.

Run as a script, it uses tools/.venv-bags (rosbags, made by tools/make_test_bags.py) and re-runs
itself there; --dump-foxglove needs tools/.venv (tools/check_mcap.py makes it).
"""

import argparse
import hashlib
import json
import os
import subprocess
import sys

TOOLS = os.path.dirname(os.path.abspath(__file__))
BAGS_VENV = os.path.join(TOOLS, ".venv-bags")
CHECK_VENV = os.path.join(TOOLS, ".venv")

# sensor_msgs/msg/PointField datatype <- foxglove.PackedElementField.NumericType
FOXGLOVE_TO_ROS = {1: 2, 2: 1, 3: 4, 4: 3, 5: 6, 6: 5, 7: 7, 8: 8}



def ros2_accepts(name):
    """rmw's full topic name rules: '/'-separated tokens of ASCII letters, digits and '_',
    none empty or starting with a digit."""
    tokens = name.split("/")
    return (
        name.startswith("/")
        and all(tokens[1:])
        and all(t[0] not in "0123456789" and all(c.isascii() and (c.isalnum() or c == "_") for c in t) for t in tokens[1:])
    )


def as_ros2(topic):
    """A Foxglove topic of ringscan's as the ROS 2 bag names it: a sensor's name with every
    character but letters, digits and '_' as '_', and 'sensor_' before a leading digit."""
    out = []
    for t in topic.split("/"):
        t = "".join(c if c.isascii() and (c.isalnum() or c == "_") else "_" for c in t)
        out.append("sensor_" + t if t[:1].isdigit() else t)
    return "/".join(out)

def ensure_venv(venv_dir, maker):
    if sys.prefix == venv_dir or os.environ.get("RINGSCAN_BAGS_NO_VENV") == "1":
        return
    py = os.path.join(venv_dir, "bin", "python")
    if not os.path.exists(py):
        subprocess.run([sys.executable, os.path.join(TOOLS, maker), "--help"],
                       check=True, stdout=subprocess.DEVNULL)
    os.execv(py, [py, os.path.abspath(__file__)] + sys.argv[1:])


def dump_foxglove(path):
    """Per points topic: fields and SHA-256 of each message's data, from a Foxglove MCAP."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    out = {}
    factory = DecoderFactory()
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            if schema is None or schema.name != "foxglove.PointCloud":
                continue
            msg = factory.decoder_for(channel.message_encoding, schema)(message.data)
            t = out.setdefault(channel.topic, {"fields": None, "stride": None, "data": []})
            t["fields"] = [[x.name, x.offset, FOXGLOVE_TO_ROS.get(x.type, -1)] for x in msg.fields]
            t["stride"] = msg.point_stride
            t["data"].append(hashlib.sha256(msg.data).hexdigest())
    json.dump(out, sys.stdout)
    return 0


def check(args):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    errors = []
    stock = get_typestore(Stores.ROS2_HUMBLE)
    own = get_typestore(Stores.EMPTY)
    topics = {}
    with Reader(args.bag) as reader:
        own_types, extra = {}, {}
        for c in reader.connections:
            if c.msgdef.format.name != "MSG" or not c.msgdef.data:
                errors.append(f"{c.topic}: no ros2msg definition in the storage file")
                continue
            types = get_types_from_msg(c.msgdef.data, c.msgtype)
            own_types.update(types)
            extra.update({k: v for k, v in types.items() if k not in stock.fielddefs})
        own.register(own_types)
        stock.register(extra)
        for c in reader.connections:
            topics.setdefault(c.topic, {"type": c.msgtype, "messages": 0, "yaml": c.msgcount})
        points = {}
        for c, _, raw in reader.messages():
            t = topics[c.topic]
            t["messages"] += 1
            try:
                m = stock.deserialize_cdr(raw, c.msgtype)
                own.deserialize_cdr(raw, c.msgtype)
            except Exception as e:  # any reader complaint is a failure of the bag
                errors.append(f"{c.topic} message {t['messages']}: {type(e).__name__}: {e}")
                continue
            if c.msgtype == "sensor_msgs/msg/PointCloud2":
                data = bytes(m.data)
                if not (m.height == 1 and m.point_step * m.width == m.row_step == len(data)):
                    errors.append(f"{c.topic}: inconsistent cloud layout")
                p = points.setdefault(c.topic, {"fields": None, "stride": None, "data": []})
                p["fields"] = [[f.name, f.offset, f.datatype] for f in m.fields]
                p["stride"] = m.point_step
                p["data"].append(hashlib.sha256(data).hexdigest())
    for topic, t in topics.items():
        if t["messages"] != t["yaml"]:
            errors.append(f"{topic}: metadata.yaml says {t['yaml']} messages, the files hold {t['messages']}")
    if args.expect:
        j = json.load(open(args.expect))
        want = (j.get("output") or {}).get("topics") or {}
        if isinstance(want, list):
            want = {x["topic"]: x["messages"] for x in want}
        for topic, n in want.items():
            got = topics.get(topic, {}).get("messages", 0)
            if got != n:
                errors.append(f"{topic}: ringscan reported {n} messages, the bag holds {got}")
        for topic in topics:
            if topic not in want:
                errors.append(f"{topic}: in the bag but not in ringscan's report")
    for topic in topics:
        if not ros2_accepts(topic):
            errors.append(f"{topic}: not a topic name ROS 2 accepts")
    if args.points:
        # The Foxglove output names topics by the sensor's name; the bag, as ROS 2 takes it.
        fox = {as_ros2(t): f for t, f in json.load(open(args.points)).items()}
        for topic, f in fox.items():
            r = points.get(topic)
            if r is None:
                errors.append(f"{topic}: point clouds in the Foxglove output, none in the bag")
                continue
            if r["fields"] != f["fields"] or r["stride"] != f["stride"]:
                errors.append(f"{topic}: fields differ: {r['fields']} vs {f['fields']}")
            if r["data"] != f["data"]:
                same = sum(a == b for a, b in zip(r["data"], f["data"]))
                errors.append(f"{topic}: point data differ ({len(r['data'])} vs {len(f['data'])} messages, {same} identical)")
        for topic in points:
            if topic not in fox:
                errors.append(f"{topic}: point clouds in the bag, none in the Foxglove output")
    for suffix in args.require or []:
        if not any(t.endswith(suffix) and v["messages"] > 0 for t, v in topics.items()):
            errors.append(f"no message on a topic ending in {suffix}")
    out = {
        "bag": args.bag,
        "topics": {k: {"type": v["type"], "messages": v["messages"]} for k, v in topics.items()},
        "ok": not errors,
        "errors": errors,
    }
    if not args.quiet:
        print(json.dumps(out, indent=1))
    for e in errors:
        print(f"{args.bag}: {e}", file=sys.stderr)
    return 0 if not errors else 1


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag", nargs="?")
    p.add_argument("--expect")
    p.add_argument("--points")
    p.add_argument("--require", action="append")
    p.add_argument("--quiet", action="store_true")
    p.add_argument("--dump-foxglove")
    args = p.parse_args()
    if args.dump_foxglove:
        ensure_venv(CHECK_VENV, "check_mcap.py")
        return dump_foxglove(args.dump_foxglove)
    if not args.bag:
        p.error("a bag directory is needed")
    ensure_venv(BAGS_VENV, "make_test_bags.py")
    return check(args)


if __name__ == "__main__":
    sys.exit(main())
