#!/usr/bin/env python3
"""Write Livox CustomMsg bags from a simulator truth file, with `rosbags` (PyPI).

Usage:
    tools/make_livox_custommsg_bag.py --truth RUN.truth --out DIR [--period-ms 100] [--imu SAMPLES]

The truth file is what `simulate --model mid360 --truth FILE` (or `ringscan::sim::truth`)
writes: one record per simulated return, sensor-frame x y z (f32 m), firing time (ns), ring
(the Livox line). Every `--period-ms` window of firing times, from the first, becomes one
message with the fields livox_ros_driver(2) fills: header stamp = timebase = the window's first
time, point_num, lidar_id 0, and per point offset_time = time - timebase (ns), x y z as
written in the truth, line = ring, and, since the truth keeps neither, reflectivity
(37 * i + 11) % 256 and tag (i % 4) * 16 for the file's i-th record (the reading test applies
the same rule). Output, topic /livox/lidar, record time = the header stamp:

    DIR/custom.ros1.bag        ROS 1, livox_ros_driver/CustomMsg
    DIR/custom.ros1-driver2.bag ROS 1, livox_ros_driver2/CustomMsg
    DIR/custom.sqlite3/        rosbag2 sqlite3, livox_ros_driver2/msg/CustomMsg (CDR)
    DIR/custom.mcap/           rosbag2 MCAP, livox_ros_driver2/msg/CustomMsg (CDR)

With --imu, every bag also holds /livox/imu: one sensor_msgs/Imu per record of SAMPLES
(little-endian i64 stamp in ns, then gyro x y z and acceleration x y z as f64: the values the
driver publishes, acceleration in g), header stamp = record time = the stamp, orientation and
covariances zero, written in stamp order among the CustomMsgs.

The paths are printed one per line. Run as a script, it uses tools/.venv-bags (python3 -m venv,
pip install rosbags at the pin tools/make_test_bags.py uses), made on first use, and re-runs
itself inside it. RINGSCAN_BAGS_NO_VENV=1 uses the current interpreter.
"""

import argparse
import os
import shutil
import struct
import subprocess
import sys
import venv

TOOLS = os.path.dirname(os.path.abspath(__file__))
VENV = os.path.join(TOOLS, ".venv-bags")
REQUIREMENT = "rosbags==0.11.9"

CUSTOM_POINT = """uint32 offset_time
float32 x
float32 y
float32 z
uint8 reflectivity
uint8 tag
uint8 line
"""


def custom_msg(pkg):
    return f"""std_msgs/Header header
uint64 timebase
uint32 point_num
uint8 lidar_id
uint8[3] rsvd
{pkg}/CustomPoint[] points
"""


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


def read_truth(path):
    b = open(path, "rb").read()
    if b[:8] != b"RSTRUTH1" or struct.unpack_from("<I", b, 8)[0] != 40:
        sys.exit(f"{path}: not a ringscan truth file")
    out = []
    for at in range(16, len(b) - 39, 40):
        x, y, z = struct.unpack_from("<fff", b, at)
        (t,) = struct.unpack_from("<q", b, at + 24)
        ring = b[at + 38]
        out.append((t, x, y, z, ring))
    return out


def windows(truth, period_ns):
    """Consecutive runs of records whose time is in one period window from the first."""
    groups, start, cur = [], None, None
    for i, r in enumerate(truth):
        w = (r[0] - truth[0][0]) // period_ns
        if cur is None or w != cur:
            if start is not None:
                groups.append((start, i))
            start, cur = i, w
    if start is not None:
        groups.append((start, len(truth)))
    return groups


def messages(truth, groups, store, pkg, ros2):
    import numpy as np

    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    Msg = store.types[f"{pkg}/msg/CustomMsg"]
    Point = store.types[f"{pkg}/msg/CustomPoint"]
    out = []
    for k, (a, b) in enumerate(groups):
        base = truth[a][0]
        pts = []
        for i in range(a, b):
            t, x, y, z, ring = truth[i]
            pts.append(Point(offset_time=t - base, x=x, y=y, z=z,
                             reflectivity=(37 * i + 11) % 256, tag=(i % 4) * 16, line=ring))
        stamp = Time(sec=base // 1_000_000_000, nanosec=base % 1_000_000_000)
        header = Header(stamp=stamp, frame_id="livox_frame") if ros2 else \
            Header(seq=k, stamp=stamp, frame_id="livox_frame")
        out.append((base, Msg(header=header, timebase=base, point_num=len(pts), lidar_id=0,
                              rsvd=np.zeros(3, dtype=np.uint8), points=pts)))
    return out


def read_imu(path):
    with open(path, "rb") as f:
        data = f.read()
    rec = struct.Struct("<q6d")
    if len(data) % rec.size:
        sys.exit(f"{path}: not whole IMU records of {rec.size} bytes")
    return [(r[0], r[1:]) for r in rec.iter_unpack(data)]


def imu_msg(store, t, v, ros2):
    """A sensor_msgs/Imu as the Livox drivers fill it."""
    import numpy as np

    m = store.types
    Time = m["builtin_interfaces/msg/Time"]
    Header = m["std_msgs/msg/Header"]
    Quaternion = m["geometry_msgs/msg/Quaternion"]
    Vector3 = m["geometry_msgs/msg/Vector3"]
    Imu = m["sensor_msgs/msg/Imu"]
    stamp = Time(sec=t // 1_000_000_000, nanosec=t % 1_000_000_000)
    header = Header(stamp=stamp, frame_id="livox_frame") if ros2 else Header(seq=0, stamp=stamp, frame_id="livox_frame")
    zeros = np.zeros(9, dtype=np.float64)
    return Imu(
        header=header,
        orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=0.0),
        orientation_covariance=zeros,
        angular_velocity=Vector3(x=v[0], y=v[1], z=v[2]),
        angular_velocity_covariance=zeros,
        linear_acceleration=Vector3(x=v[3], y=v[4], z=v[5]),
        linear_acceleration_covariance=zeros,
    )


def main():
    ensure_venv()
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--truth", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--period-ms", type=float, default=100.0)
    ap.add_argument("--imu", help="IMU samples to write on /livox/imu (see above)")
    args = ap.parse_args()

    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.rosbag2.writer import StoragePlugin
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    truth = read_truth(args.truth)
    groups = windows(truth, int(args.period_ms * 1e6))
    os.makedirs(args.out, exist_ok=True)
    topic = "/livox/lidar"
    samples = read_imu(args.imu) if args.imu else []

    def with_imu(store, conn, imu_conn, lidar_msgs, ros2):
        """(conn, time, message, type) of the CustomMsgs and the IMU samples, in time order."""
        out = [(t, 0, conn, msg) for t, msg in lidar_msgs]
        for t, v in samples:
            out.append((t, 1, imu_conn, imu_msg(store, t, v, ros2)))
        out.sort(key=lambda m: (m[0], m[1]))
        return out

    for name, pkg in [("custom.ros1.bag", "livox_ros_driver"), ("custom.ros1-driver2.bag", "livox_ros_driver2")]:
        store = get_typestore(Stores.ROS1_NOETIC)
        types = get_types_from_msg(CUSTOM_POINT, f"{pkg}/msg/CustomPoint")
        types.update(get_types_from_msg(custom_msg(pkg), f"{pkg}/msg/CustomMsg"))
        store.register(types)
        path = os.path.join(args.out, name)
        if os.path.exists(path):
            os.remove(path)
        w = Writer1(path)
        w.open()
        conn = w.add_connection(topic, f"{pkg}/msg/CustomMsg", typestore=store)
        imu_conn = w.add_connection("/livox/imu", "sensor_msgs/msg/Imu", typestore=store) if samples else None
        for t, _, c, msg in with_imu(store, conn, imu_conn, messages(truth, groups, store, pkg, ros2=False), False):
            w.write(c, t, store.serialize_ros1(msg, c.msgtype))
        w.close()
        print(path)

    pkg = "livox_ros_driver2"
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = get_types_from_msg(CUSTOM_POINT, f"{pkg}/msg/CustomPoint")
    types.update(get_types_from_msg(custom_msg(pkg), f"{pkg}/msg/CustomMsg"))
    store.register(types)
    msgs = messages(truth, groups, store, pkg, ros2=True)
    for storage, plugin in [("sqlite3", StoragePlugin.SQLITE3), ("mcap", StoragePlugin.MCAP)]:
        path = os.path.join(args.out, f"custom.{storage}")
        shutil.rmtree(path, ignore_errors=True)
        w = Writer2(path, version=9, storage_plugin=plugin)
        w.open()
        conn = w.add_connection(topic, f"{pkg}/msg/CustomMsg", typestore=store)
        imu_conn = w.add_connection("/livox/imu", "sensor_msgs/msg/Imu", typestore=store) if samples else None
        for t, _, c, msg in with_imu(store, conn, imu_conn, msgs, True):
            w.write(c, t, store.serialize_cdr(msg, c.msgtype))
        w.close()
        print(path)


if __name__ == "__main__":
    main()
