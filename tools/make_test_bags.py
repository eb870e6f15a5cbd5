#!/usr/bin/env python3
"""Write a pcap's packets as ROS bags of every container ringscan reads, with `rosbags`.

Usage:
    tools/make_test_bags.py --pcap CAPTURE.pcap --out DIR [--name NAME] [--metadata META.json]
                            [--max-packets N] [--packets-per-scan N] [--variants V,V,...]
                            [--chunk-bytes N]

Velodyne (no --metadata): every 1206-byte UDP payload becomes a `VelodynePacket` (stamp = the
pcap record time, exact to the ns), `--packets-per-scan` of them per `velodyne_msgs/VelodyneScan`
on /velodyne_packets (header stamp = the first packet's; record time = the last packet's).
Other payloads (position packets) have no place in that message and are left out.

Ouster (--metadata): every UDP payload to the metadata's lidar port becomes an
`ouster_ros/PacketMsg` (ROS 1) / `ouster_sensor_msgs/msg/PacketMsg` (ROS 2) on
/ouster/lidar_packets, to its IMU port on /ouster/imu_packets, record time = the pcap record
time; the metadata JSON is one `std_msgs/String` on /ouster/metadata, recorded first.

Variants (default: all): ros1-none, ros1-bz2, ros1-lz4 (ROS 1 bags, chunk compression);
sqlite3-none, sqlite3-file, sqlite3-message, mcap-none, mcap-file, mcap-message (rosbag2
directories, zstd compression of the whole file or of each message). Output:
DIR/NAME.<variant>.bag for ROS 1, DIR/NAME.<variant>/ for rosbag2.

Run as a script, it creates tools/.venv-bags (python3 -m venv, pip install rosbags) on first
use and re-runs itself inside it. Set RINGSCAN_BAGS_NO_VENV=1 to use the current interpreter.
"""

import argparse
import json
import os
import shutil
import struct
import subprocess
import sys
import venv

TOOLS = os.path.dirname(os.path.abspath(__file__))
VENV = os.path.join(TOOLS, ".venv-bags")
REQUIREMENT = "rosbags==0.11.9"
ALL_VARIANTS = [
    "ros1-none", "ros1-bz2", "ros1-lz4",
    "sqlite3-none", "sqlite3-file", "sqlite3-message",
    "mcap-none", "mcap-file", "mcap-message",
]


def ensure_venv():
    if os.environ.get("RINGSCAN_BAGS_NO_VENV") == "1" or sys.prefix == VENV:
        return
    py = os.path.join(VENV, "bin", "python")
    stamp = os.path.join(VENV, ".requirement")
    if not (os.path.exists(stamp) and open(stamp).read() == REQUIREMENT):
        if not os.path.exists(py):
            venv.create(VENV, with_pip=True)
        subprocess.run([py, "-m", "pip", "install", "-q", REQUIREMENT], check=True)
        with open(stamp, "w") as f:
            f.write(REQUIREMENT)
    os.execv(py, [py, os.path.abspath(__file__)] + sys.argv[1:])


def read_pcap(path):
    """[(time_ns, dst_port, payload)] of every unfragmented IPv4 UDP datagram (Ethernet links)."""
    data = open(path, "rb").read()
    magic = data[:4]
    e = "<" if magic in (b"\xd4\xc3\xb2\xa1", b"\x4d\x3c\xb2\xa1") else ">"
    nanos = magic in (b"\x4d\x3c\xb2\xa1", b"\xa1\xb2\x3c\x4d")
    linktype = struct.unpack(e + "I", data[20:24])[0] & 0xFFFF
    if linktype != 1:
        raise SystemExit(f"{path}: link type {linktype}, only Ethernet (1) is read here")
    out, at = [], 24
    while at + 16 <= len(data):
        sec, frac, cap, _orig = struct.unpack(e + "IIII", data[at:at + 16])
        frame = data[at + 16:at + 16 + cap]
        at += 16 + cap
        t = sec * 1_000_000_000 + (frac if nanos else frac * 1000)
        eth = 14
        ethertype = struct.unpack(">H", frame[12:14])[0]
        if ethertype == 0x8100:
            eth, ethertype = 18, struct.unpack(">H", frame[16:18])[0]
        if ethertype != 0x0800 or frame[eth + 9] != 17:
            continue
        ihl = (frame[eth] & 0x0F) * 4
        flags_frag = struct.unpack(">H", frame[eth + 6:eth + 8])[0]
        if flags_frag & 0x3FFF:
            continue  # fragments: not in the captures used here
        udp = eth + ihl
        dport, ulen = struct.unpack(">HH", frame[udp + 2:udp + 6])
        out.append((t, dport, frame[udp + 8:udp + ulen]))
    return out


VELODYNE_PACKET = "time stamp\nuint8[1206] data\n"
VELODYNE_SCAN = "Header header\nVelodynePacket[] packets\n"
VELODYNE_PACKET2 = "builtin_interfaces/Time stamp\nuint8[1206] data\n"
VELODYNE_SCAN2 = "std_msgs/Header header\nVelodynePacket[] packets\n"
PACKET_MSG = "uint8[] buf\n"


def typestores():
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ros1 = get_typestore(Stores.ROS1_NOETIC)
    types = {}
    types.update(get_types_from_msg(VELODYNE_PACKET, "velodyne_msgs/msg/VelodynePacket"))
    types.update(get_types_from_msg(VELODYNE_SCAN, "velodyne_msgs/msg/VelodyneScan"))
    types.update(get_types_from_msg(PACKET_MSG, "ouster_ros/msg/PacketMsg"))
    ros1.register(types)
    ros2 = get_typestore(Stores.ROS2_HUMBLE)
    types = {}
    types.update(get_types_from_msg(VELODYNE_PACKET2, "velodyne_msgs/msg/VelodynePacket"))
    types.update(get_types_from_msg(VELODYNE_SCAN2, "velodyne_msgs/msg/VelodyneScan"))
    types.update(get_types_from_msg(PACKET_MSG, "ouster_sensor_msgs/msg/PacketMsg"))
    ros2.register(types)
    return ros1, ros2


def messages(datagrams, metadata, per_scan, ros2, store):
    """[(topic, msgtype, record_time_ns, message)] in record order."""
    out = []
    if metadata is None:
        Time = store.types["builtin_interfaces/msg/Time"]
        Header = store.types["std_msgs/msg/Header"]
        Packet = store.types["velodyne_msgs/msg/VelodynePacket"]
        Scan = store.types["velodyne_msgs/msg/VelodyneScan"]
        import numpy as np

        pkts = [(t, p) for t, _, p in datagrams if len(p) == 1206]
        for i in range(0, len(pkts), per_scan):
            group = pkts[i:i + per_scan]

            def stamp(t):
                return Time(sec=t // 1_000_000_000, nanosec=t % 1_000_000_000)

            packets = [Packet(stamp=stamp(t), data=np.frombuffer(p, dtype=np.uint8)) for t, p in group]
            if ros2:
                header = Header(stamp=stamp(group[0][0]), frame_id="velodyne")
            else:
                header = Header(seq=i // per_scan, stamp=stamp(group[0][0]), frame_id="velodyne")
            out.append(("/velodyne_packets", "velodyne_msgs/msg/VelodyneScan", group[-1][0],
                        Scan(header=header, packets=packets)))
        return out
    import numpy as np

    String = store.types["std_msgs/msg/String"]
    pkt_type = "ouster_sensor_msgs/msg/PacketMsg" if ros2 else "ouster_ros/msg/PacketMsg"
    Packet = store.types[pkt_type]
    meta = json.loads(metadata)
    lidar_port = meta.get("udp_port_lidar", meta.get("config_params", {}).get("udp_port_lidar", 7502))
    imu_port = meta.get("udp_port_imu", meta.get("config_params", {}).get("udp_port_imu", 7503))
    out.append(("/ouster/metadata", "std_msgs/msg/String", datagrams[0][0], String(data=metadata)))
    for t, port, p in datagrams:
        topic = {lidar_port: "/ouster/lidar_packets", imu_port: "/ouster/imu_packets"}.get(port)
        if topic:
            out.append((topic, pkt_type, t, Packet(buf=np.frombuffer(p, dtype=np.uint8))))
    return out


def write_ros1(path, msgs, store, compression, chunk_bytes):
    from rosbags.rosbag1 import Writer

    if os.path.exists(path):
        os.remove(path)
    w = Writer(path)
    if chunk_bytes:
        w.chunk_threshold = chunk_bytes
    if compression != "none":
        w.set_compression({"bz2": Writer.CompressionFormat.BZ2, "lz4": Writer.CompressionFormat.LZ4}[compression])
    with w:
        conns = {}
        for topic, msgtype, t, msg in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=store)
            w.write(conns[topic], t, store.serialize_ros1(msg, msgtype))


def write_rosbag2(path, msgs, store, storage, compression):
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.writer import CompressionFormat, CompressionMode, StoragePlugin

    if os.path.exists(path):
        shutil.rmtree(path)
    plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
    w = Writer(path, version=9, storage_plugin=plugin)
    if compression != "none":
        mode = {"file": CompressionMode.FILE, "message": CompressionMode.MESSAGE}[compression]
        w.set_compression(mode, CompressionFormat.ZSTD)
    with w:
        conns = {}
        for topic, msgtype, t, msg in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=store)
            w.write(conns[topic], t, store.serialize_cdr(msg, msgtype))


def main():
    ensure_venv()
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pcap", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--name")
    ap.add_argument("--metadata", help="Ouster metadata JSON (else Velodyne)")
    ap.add_argument("--max-packets", type=int, default=0, help="only the first N datagrams")
    ap.add_argument("--packets-per-scan", type=int, default=76)
    ap.add_argument("--variants", default=",".join(ALL_VARIANTS))
    ap.add_argument("--chunk-bytes", type=int, default=0,
                    help="ROS 1: start a new chunk past this many bytes (rosbags' default: 1 MiB)")
    a = ap.parse_args()
    datagrams = read_pcap(a.pcap)
    if a.max_packets:
        datagrams = datagrams[:a.max_packets]
    metadata = open(a.metadata).read() if a.metadata else None
    name = a.name or os.path.splitext(os.path.basename(a.pcap))[0]
    os.makedirs(a.out, exist_ok=True)
    ros1, ros2 = typestores()
    m1 = m2 = None
    for v in a.variants.split(","):
        container, compression = v.split("-")
        if container == "ros1":
            m1 = m1 or messages(datagrams, metadata, a.packets_per_scan, False, ros1)
            path = os.path.join(a.out, f"{name}.{v}.bag")
            write_ros1(path, m1, ros1, compression, a.chunk_bytes)
        else:
            m2 = m2 or messages(datagrams, metadata, a.packets_per_scan, True, ros2)
            path = os.path.join(a.out, f"{name}.{v}")
            write_rosbag2(path, m2, ros2, container, compression)
        print(path)


if __name__ == "__main__":
    main()
