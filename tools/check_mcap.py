#!/usr/bin/env python3
"""Check an MCAP written by ringscan with the official MCAP readers.

Usage:
    tools/check_mcap.py FILE.mcap [--expect EXPECT.json] [--quiet]

Reads FILE.mcap with the `mcap` package (indexed reader, and a second linear pass over every
record with CRC checks), decodes every message with the schema embedded in the file
(`mcap-protobuf-support` for protobuf, `mcap-ros2-support` for CDR, `json` for JSON channels)
and prints one JSON object on stdout:

    {"file", "header": {"profile", "library"},
     "statistics": {...}, "chunks": {"count", "compression": {name: n}},
     "channels": [{"id", "topic", "schema", "schema_encoding", "message_encoding", "metadata"}],
     "messages": {topic: count},
     "attachments": [{"name", "media_type", "size", "sha256", "log_time"}],
     "point_clouds": {topic: {"messages", "points", "point_stride", "fields", "frame_ids",
                              "sum_x", "sum_y", "sum_z", "sum_intensity", "sum_ring", "sum_return",
                              "t_min", "t_max", "timestamp_min_ns", "timestamp_max_ns"}},
     "raw": {topic: {"packets", "payload_bytes", "sources"}},
     "scenes": {topic: {"messages", "deletions", "entities", "cubes", "cube_points", "frame_ids"}},
     "transforms": {topic: [{"parent", "child", "translation", "rotation"}]},
     "totals": {"sweeps", "points"},
     "ok": bool, "errors": [...]}

`totals` counts the point clouds on `/points` and `/<name>/points` topics only (one message per
sweep); pipeline outputs (`/ground`, `/map`, ...) are listed under `point_clouds` but not summed.

--expect takes ringscan's `--json` output (or any JSON object) and compares `sweeps`, `points`
and, when present, `topics` or `output.topics` ({topic: count} or [{"topic", "messages"}]) with
the file. With `--pipeline` output (`pipeline.counts` in the JSON), it also compares the ground
and obstacle points and the clusters over every `ground` / `obstacles` / `clusters` topic, and
checks that the cubes' `points` metadata sum to the obstacle points.

`foxglove.SceneUpdate` (clusters) and `foxglove.FrameTransform` (`/tf_static`) messages are
decoded with mcap-protobuf-support like every protobuf channel, from the schema in the file.

Exit status: 0 when the file is valid and matches, 1 on any error or mismatch (each printed on
stderr), 2 on bad usage.

Run as `tools/check_mcap.py` (or `tools/check_mcap.sh`), the script creates tools/.venv with the
pinned tools/requirements-check.txt on first use (and again when that file changes), then
re-runs itself inside it. Set RINGSCAN_CHECK_NO_VENV=1 to use the current interpreter as is.
"""

import argparse
import hashlib
import json
import os
import re
import subprocess
import sys
import venv

TOOLS = os.path.dirname(os.path.abspath(__file__))
VENV = os.path.join(TOOLS, ".venv")
REQUIREMENTS = os.path.join(TOOLS, "requirements-check.txt")
STAMP = os.path.join(VENV, ".requirements-sha256")
POINTS_TOPIC = re.compile(r"(^|/)points$")
POINT_CLOUD_SCHEMAS = ("foxglove.PointCloud", "sensor_msgs/msg/PointCloud2")
# foxglove.PackedElementField.NumericType -> numpy type
FOXGLOVE_TYPES = {1: "u1", 2: "i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4", 7: "<f4", 8: "<f8"}
# sensor_msgs/msg/PointField datatype -> numpy type
ROS2_TYPES = {1: "i1", 2: "u1", 3: "<i2", 4: "<u2", 5: "<i4", 6: "<u4", 7: "<f4", 8: "<f8"}


def _venv_python():
    return os.path.join(VENV, "Scripts" if os.name == "nt" else "bin", "python")


def ensure_venv():
    """Re-executes this script inside tools/.venv, creating or updating it first."""
    if os.environ.get("RINGSCAN_CHECK_NO_VENV") == "1":
        return
    if os.path.realpath(sys.prefix) == os.path.realpath(VENV):
        return
    with open(REQUIREMENTS, "rb") as f:
        want = hashlib.sha256(f.read()).hexdigest()
    have = None
    if os.path.exists(STAMP):
        with open(STAMP) as f:
            have = f.read().strip()
    python = _venv_python()
    if have != want or not os.path.exists(python):
        with _lock():
            _prepare_venv(python, want)
    os.execv(python, [python, os.path.abspath(__file__), *sys.argv[1:]])


class _lock:
    """Serialises venv preparation between concurrent runs (POSIX; a no-op elsewhere)."""

    def __enter__(self):
        self.f = open(VENV + ".lock", "w")
        try:
            import fcntl

            fcntl.flock(self.f, fcntl.LOCK_EX)
        except ImportError:
            pass
        return self

    def __exit__(self, *exc):
        self.f.close()


def _prepare_venv(python, want):
    # Another run may have finished the job while this one waited for the lock.
    if os.path.exists(STAMP) and os.path.exists(python):
        with open(STAMP) as f:
            if f.read().strip() == want:
                return
    print(f"check_mcap: preparing {VENV} from {REQUIREMENTS}", file=sys.stderr)
    try:
        if not os.path.exists(python):
            venv.create(VENV, with_pip=True)
        subprocess.run(
            [python, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", "-r", REQUIREMENTS],
            check=True,
            stdout=sys.stderr,
        )
    except (OSError, subprocess.CalledProcessError) as e:
        sys.exit(
            f"check_mcap: could not prepare {VENV}: {e}\n"
            "  (needs python3 with venv/ensurepip, e.g. Debian's python3-venv, and access to PyPI;"
            " or set RINGSCAN_CHECK_NO_VENV=1 with the packages of tools/requirements-check.txt installed)"
        )
    with open(STAMP, "w") as f:
        f.write(want + "\n")


class Check:
    def __init__(self):
        self.errors = []

    def fail(self, msg):
        self.errors.append(msg)

    def expect_eq(self, what, found, expected):
        if found != expected:
            self.fail(f"{what}: expected {expected!r}, found {found!r}")


class JsonDecoderFactory:
    """Decodes `json` channels (the official readers leave JSON to the caller)."""

    def decoder_for(self, message_encoding, schema):
        if message_encoding != "json":
            return None
        return lambda data: json.loads(data)


class PointStats:
    def __init__(self):
        self.messages = 0
        self.points = 0
        self.sums = {k: 0.0 for k in ("x", "y", "z", "intensity")}
        self.ring = 0
        self.ret = 0
        self.t_min = None
        self.t_max = None
        self.ts_min = None
        self.ts_max = None
        self.strides = set()
        self.fields = None
        self.frame_ids = set()

    def add(self, check, topic, frame_id, stamp_ns, stride, fields, data, n_declared=None):
        """`fields`: [(name, offset, numpy type)]. Adds one cloud's points."""
        import numpy as np

        self.messages += 1
        self.frame_ids.add(frame_id)
        self.strides.add(stride)
        self.ts_min = stamp_ns if self.ts_min is None else min(self.ts_min, stamp_ns)
        self.ts_max = stamp_ns if self.ts_max is None else max(self.ts_max, stamp_ns)
        layout = [(name, off, t) for name, off, t in fields]
        if self.fields is None:
            self.fields = layout
        elif self.fields != layout:
            check.fail(f"{topic}: field layout changed between messages: {self.fields} then {layout}")
        if stride <= 0:
            check.fail(f"{topic}: point stride {stride}")
            return
        if len(data) % stride != 0:
            check.fail(f"{topic}: data length {len(data)} is not a multiple of the stride {stride}")
            return
        n = len(data) // stride
        if n_declared is not None and n_declared != n:
            check.fail(f"{topic}: width x height = {n_declared} but data holds {n} points")
        self.points += n
        names = [f[0] for f in fields]
        for need in ("x", "y", "z"):
            if need not in names:
                check.fail(f"{topic}: no field {need!r} (fields: {names})")
                return
        for name, off, t in fields:
            if off + np.dtype(t).itemsize > stride:
                check.fail(f"{topic}: field {name} at {off} ({t}) overruns the stride {stride}")
                return
        if n == 0:
            return
        dtype = np.dtype(
            {"names": names, "formats": [f[2] for f in fields], "offsets": [f[1] for f in fields], "itemsize": stride}
        )
        arr = np.frombuffer(data, dtype=dtype, count=n)
        for k in ("x", "y", "z", "intensity"):
            if k in names:
                self.sums[k] += float(arr[k].astype(np.float64).sum())
        if "ring" in names:
            self.ring += int(arr["ring"].astype(np.int64).sum())
        if "return" in names:
            self.ret += int(arr["return"].astype(np.int64).sum())
        if "t" in names:
            t_min, t_max = int(arr["t"].min()), int(arr["t"].max())
            self.t_min = t_min if self.t_min is None else min(self.t_min, t_min)
            self.t_max = t_max if self.t_max is None else max(self.t_max, t_max)

    def to_json(self):
        return {
            "messages": self.messages,
            "points": self.points,
            "point_stride": sorted(self.strides),
            "fields": [{"name": n, "offset": o, "type": t} for n, o, t in (self.fields or [])],
            "frame_ids": sorted(self.frame_ids),
            "sum_x": self.sums["x"],
            "sum_y": self.sums["y"],
            "sum_z": self.sums["z"],
            "sum_intensity": self.sums["intensity"],
            "sum_ring": self.ring,
            "sum_return": self.ret,
            "t_min": self.t_min,
            "t_max": self.t_max,
            "timestamp_min_ns": self.ts_min,
            "timestamp_max_ns": self.ts_max,
        }


def add_point_cloud(check, stats, topic, schema_name, msg):
    if schema_name == "foxglove.PointCloud":
        fields = []
        for f in msg.fields:
            t = FOXGLOVE_TYPES.get(f.type)
            if t is None:
                check.fail(f"{topic}: field {f.name} has unknown NumericType {f.type}")
                return
            fields.append((f.name, f.offset, t))
        stamp = msg.timestamp.seconds * 1_000_000_000 + msg.timestamp.nanos
        stats.add(check, topic, msg.frame_id, stamp, msg.point_stride, fields, msg.data)
    else:  # sensor_msgs/msg/PointCloud2
        fields = []
        for f in msg.fields:
            t = ROS2_TYPES.get(f.datatype)
            if t is None or f.count != 1:
                check.fail(f"{topic}: field {f.name} has datatype {f.datatype} x {f.count}")
                return
            fields.append((f.name, f.offset, t))
        if msg.is_bigendian:
            check.fail(f"{topic}: big-endian point data")
            return
        if msg.row_step != msg.width * msg.point_step:
            check.fail(f"{topic}: row_step {msg.row_step} != width {msg.width} x point_step {msg.point_step}")
        if len(msg.data) != msg.row_step * msg.height:
            check.fail(f"{topic}: data length {len(msg.data)} != row_step x height {msg.row_step * msg.height}")
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        stats.add(
            check, topic, msg.header.frame_id, stamp, msg.point_step, fields, bytes(msg.data), msg.width * msg.height
        )


def read_file(path, check):
    from mcap.reader import make_reader
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader
    from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
    from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

    out = {"file": path}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[ProtobufDecoderFactory(), Ros2DecoderFactory(), JsonDecoderFactory()])
        header = reader.get_header()
        out["header"] = {"profile": header.profile, "library": header.library}
        summary = reader.get_summary()
        if summary is None:
            check.fail("no summary section: readers must scan the whole file")
            return out
        stats = summary.statistics
        if stats is None:
            check.fail("no statistics record in the summary")
        else:
            out["statistics"] = {
                "message_count": stats.message_count,
                "schema_count": stats.schema_count,
                "channel_count": stats.channel_count,
                "attachment_count": stats.attachment_count,
                "metadata_count": stats.metadata_count,
                "chunk_count": stats.chunk_count,
                "message_start_time": stats.message_start_time,
                "message_end_time": stats.message_end_time,
            }
        compressions = {}
        for ci in summary.chunk_indexes:
            compressions[ci.compression or "none"] = compressions.get(ci.compression or "none", 0) + 1
        out["chunks"] = {"count": len(summary.chunk_indexes), "compression": compressions}

        channels = []
        for cid in sorted(summary.channels):
            ch = summary.channels[cid]
            schema = summary.schemas.get(ch.schema_id)
            if schema is None:
                check.fail(f"{ch.topic}: channel has no schema")
            channels.append(
                {
                    "id": cid,
                    "topic": ch.topic,
                    "schema": schema.name if schema else None,
                    "schema_encoding": schema.encoding if schema else None,
                    "message_encoding": ch.message_encoding,
                    "metadata": dict(ch.metadata),
                }
            )
        out["channels"] = channels
        topics = {c["id"]: c["topic"] for c in channels}
        if len(set(topics.values())) != len(topics):
            check.fail(f"several channels share a topic: {sorted(topics.values())}")

        counts = {t: 0 for t in topics.values()}
        clouds = {}
        raw = {}
        scenes = {}
        transforms = {}
        last_seq = {}
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            topic = channel.topic
            counts[topic] = counts.get(topic, 0) + 1
            if message.publish_time != message.log_time:
                check.fail(f"{topic}: publish_time {message.publish_time} != log_time {message.log_time}")
            prev = last_seq.get(topic)
            if prev is not None and message.sequence != (prev + 1) % (1 << 32):
                check.fail(f"{topic}: sequence {message.sequence} after {prev}")
            last_seq[topic] = message.sequence
            name = schema.name if schema else None
            if name in POINT_CLOUD_SCHEMAS:
                add_point_cloud(check, clouds.setdefault(topic, PointStats()), topic, name, decoded)
            elif name == "foxglove.SceneUpdate":
                sc = scenes.setdefault(
                    topic,
                    {"messages": 0, "deletions": 0, "entities": 0, "cubes": 0, "cube_points": 0, "frame_ids": set()},
                )
                sc["messages"] += 1
                sc["deletions"] += len(decoded.deletions)
                for e in decoded.entities:
                    sc["entities"] += 1
                    sc["cubes"] += len(e.cubes)
                    sc["frame_ids"].add(e.frame_id)
                    for kv in e.metadata:
                        if kv.key == "points":
                            sc["cube_points"] += int(kv.value)
                    for c in e.cubes:
                        if not (c.size.x >= 0 and c.size.y >= 0 and c.size.z >= 0):
                            check.fail(f"{topic}: cube of entity {e.id} has size {c.size}")
            elif name == "foxglove.FrameTransform":
                t, q = decoded.translation, decoded.rotation
                transforms.setdefault(topic, []).append(
                    {
                        "parent": decoded.parent_frame_id,
                        "child": decoded.child_frame_id,
                        "translation": [t.x, t.y, t.z],
                        "rotation": [q.x, q.y, q.z, q.w],
                    }
                )
                norm = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w) ** 0.5
                if abs(norm - 1.0) > 1e-6:
                    check.fail(f"{topic}: rotation of {decoded.child_frame_id} has norm {norm}")
            elif name == "ringscan.RawPacket":
                r = raw.setdefault(topic, {"packets": 0, "payload_bytes": 0, "sources": set()})
                r["packets"] += 1
                r["payload_bytes"] += len(decoded.payload)
                r["sources"].add(f"{decoded.source_address}:{decoded.source_port}->{decoded.destination_port}")
                stamp = decoded.timestamp.seconds * 1_000_000_000 + decoded.timestamp.nanos
                if stamp != message.log_time:
                    check.fail(f"{topic}: packet timestamp {stamp} != log_time {message.log_time}")
        out["messages"] = dict(sorted(counts.items()))
        out["point_clouds"] = {t: s.to_json() for t, s in sorted(clouds.items())}
        out["raw"] = {t: {**r, "sources": sorted(r["sources"])} for t, r in sorted(raw.items())}
        out["scenes"] = {t: {**sc, "frame_ids": sorted(sc["frame_ids"])} for t, sc in sorted(scenes.items())}
        out["transforms"] = dict(sorted(transforms.items()))

        if stats is not None:
            stat_counts = {topics.get(cid, f"#{cid}"): n for cid, n in stats.channel_message_counts.items()}
            for t, n in counts.items():
                if stat_counts.get(t, 0) != n:
                    check.fail(f"{t}: statistics say {stat_counts.get(t, 0)} messages, the file holds {n}")
            check.expect_eq("statistics.message_count", stats.message_count, sum(counts.values()))
            check.expect_eq("statistics.chunk_count", stats.chunk_count, len(summary.chunk_indexes))
            check.expect_eq("statistics.attachment_count", stats.attachment_count, len(summary.attachment_indexes))
        if sum(counts.values()) > 0 and not summary.chunk_indexes:
            check.fail("messages but no chunk indexes")

        attachments = []
        for a in reader.iter_attachments():
            attachments.append(
                {
                    "name": a.name,
                    "media_type": a.media_type,
                    "size": len(a.data),
                    "sha256": hashlib.sha256(a.data).hexdigest(),
                    "log_time": a.log_time,
                }
            )
        out["attachments"] = attachments

    # A linear pass over every record, checking CRCs: the data section stands on its own.
    linear = {}
    channel_topics = {}
    with open(path, "rb") as f:
        for record in StreamReader(f, skip_magic=False, emit_chunks=False, validate_crcs=True).records:
            if isinstance(record, Channel):
                channel_topics[record.id] = record.topic
            elif isinstance(record, Message):
                t = channel_topics.get(record.channel_id, f"#{record.channel_id}")
                linear[t] = linear.get(t, 0) + 1
    for t, n in out["messages"].items():
        if linear.get(t, 0) != n:
            check.fail(f"{t}: linear read finds {linear.get(t, 0)} messages, indexed read {n}")

    sweeps = sum(s.messages for t, s in clouds.items() if POINTS_TOPIC.search(t))
    points = sum(s.points for t, s in clouds.items() if POINTS_TOPIC.search(t))
    out["totals"] = {"sweeps": sweeps, "points": points}
    return out


def compare_expect(check, out, expect):
    totals = out.get("totals", {})
    for key in ("sweeps", "points"):
        if key in expect:
            check.expect_eq(f"--expect {key}", totals.get(key), expect[key])
        else:
            check.fail(f"--expect file has no {key!r}")
    output = expect.get("output") if isinstance(expect.get("output"), dict) else {}
    # Attachments: the calibration files ringscan says it stored, by name and size.
    if "attachments" in output:
        want = sorted((a["name"], a["size"]) for a in output["attachments"])
        got = sorted((a["name"], a["size"]) for a in out.get("attachments", []))
        check.expect_eq("--expect attachments (name, size)", got, want)
    # Schema of the point topics follows the format ringscan reports.
    fmt = output.get("format")
    if fmt:
        schema = {"foxglove": "foxglove.PointCloud", "ros2": "sensor_msgs/msg/PointCloud2"}.get(fmt)
        for c in out.get("channels", []):
            if POINTS_TOPIC.search(c.get("topic", "")):
                check.expect_eq(f"schema of {c['topic']}", c.get("schema"), schema)
    # Per sensor: its points topic carries the model and address ringscan reported.
    for s in expect.get("sensors", []):
        topic = s.get("topic")
        if not topic:
            continue
        chans = [c for c in out.get("channels", []) if c.get("topic") == topic]
        if not chans:
            check.fail(f"sensor {s.get('address')}: topic {topic} missing")
            continue
        md = chans[0].get("metadata", {})
        check.expect_eq(f"{topic} metadata model", md.get("model"), s.get("model"))
        check.expect_eq(f"{topic} metadata source_address", md.get("source_address"), s.get("address"))
    # Pipeline outputs: totals over every sensor's ground / obstacles / clusters topics.
    counts = (expect.get("pipeline") or {}).get("counts") if isinstance(expect.get("pipeline"), dict) else None
    if counts and (expect.get("pipeline") or {}).get("outputs", True):
        clouds = out.get("point_clouds", {})
        scenes = out.get("scenes", {})
        ends = lambda t, leaf: t == "/" + leaf or t.endswith("/" + leaf)
        ground = sum(c["points"] for t, c in clouds.items() if ends(t, "ground"))
        obstacles = sum(c["points"] for t, c in clouds.items() if ends(t, "obstacles"))
        clusters = sum(sc["entities"] for t, sc in scenes.items() if ends(t, "clusters"))
        cube_points = sum(sc["cube_points"] for t, sc in scenes.items() if ends(t, "clusters"))
        check.expect_eq("--expect pipeline.counts.ground (ground points)", ground, counts.get("ground"))
        check.expect_eq("--expect pipeline.counts.obstacles (obstacle points)", obstacles, counts.get("obstacles"))
        check.expect_eq("--expect pipeline.counts.clusters (SceneUpdate entities)", clusters, counts.get("clusters"))
        check.expect_eq("cubes' points metadata vs obstacle points", cube_points, obstacles)
    topics = expect.get("topics")
    if topics is None and isinstance(expect.get("output"), dict):
        # ringscan --json nests the per-topic counts under "output".
        topics = expect["output"].get("topics")
    if topics is None:
        return
    if isinstance(topics, list):
        topics = {t["topic"]: t.get("messages", t.get("count")) for t in topics}
    found = out.get("messages", {})
    for t, n in topics.items():
        check.expect_eq(f"--expect topics[{t}]", found.get(t, 0), n)
    for t, n in found.items():
        if n > 0 and t not in topics:
            check.fail(f"topic {t} holds {n} messages but --expect does not list it")


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("file", help="the MCAP file")
    parser.add_argument("--expect", metavar="FILE.json", help="ringscan --json output to compare against")
    parser.add_argument("--quiet", action="store_true", help="print nothing on stdout")
    args = parser.parse_args(argv)

    check = Check()
    expect = None
    if args.expect:
        try:
            with open(args.expect) as f:
                expect = json.load(f)
        except (OSError, ValueError) as e:
            print(f"check_mcap: cannot read --expect {args.expect}: {e}", file=sys.stderr)
            return 1
        if not isinstance(expect, dict):
            print(f"check_mcap: --expect {args.expect} is not a JSON object", file=sys.stderr)
            return 1
    try:
        out = read_file(args.file, check)
    except Exception as e:  # a reader or decoder refusing the file is the finding
        out = {"file": args.file}
        check.fail(f"reading failed: {type(e).__name__}: {e}")
    if expect is not None:
        compare_expect(check, out, expect)
    out["ok"] = not check.errors
    out["errors"] = check.errors
    if not args.quiet:
        print(json.dumps(out, indent=2))
    for e in check.errors:
        print(f"check_mcap: {args.file}: {e}", file=sys.stderr)
    return 0 if not check.errors else 1


if __name__ == "__main__":
    ensure_venv()
    sys.exit(main(sys.argv[1:]))
