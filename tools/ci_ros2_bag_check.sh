#!/usr/bin/env bash
# `--format ros2` rosbag2 directories opened by an independent reader (`rosbags`, PyPI):
# tools/check_ros2_bag.py deserialises every message of every channel with rosbags' own ROS 2
# Humble definitions and with the bag's, compares counts with the yaml and with ringscan's
# `--json`, and compares the point clouds bit for bit with the Foxglove output of the same run.
# Runs: the demo capture (plain, --raw, --pipeline default, --odometry), an Ouster capture with
# its IMU (--raw: the PacketMsg + metadata topics), two sensors in one capture, and a
# `listen --format ros2 --raw` killed with SIGKILL (its directory must still open).
#
#   tools/ci_ros2_bag_check.sh
#
# Venvs: tools/.venv-bags (rosbags; tools/make_test_bags.py makes it) and tools/.venv (the
# official MCAP readers, for the Foxglove side; tools/check_mcap.py makes it).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --quiet --bin ringscan
bin=target/debug/ringscan
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
fail=0
C=../shared/captures
topics() { "$py_bags" -c 'import json,sys; t=json.load(open(sys.argv[1]))["topics"]; print(", ".join("%s %d" % (k, v["messages"]) for k, v in sorted(t.items())))' "$1"; }

python3 tools/make_test_bags.py --help > /dev/null
py_bags=tools/.venv-bags/bin/python
py_fox=tools/.venv/bin/python

check() { # name, required topic suffixes (comma list or -), decode args...
  local name=$1 require=$2; shift 2
  local req=()
  if [ "$require" != "-" ]; then
    IFS=, read -ra rs <<< "$require"
    for r in "${rs[@]}"; do req+=(--require "$r"); done
  fi
  "$bin" decode "$@" --format foxglove --out "$out/$name.mcap" --json > "$out/$name.fox.json"
  tools/check_mcap.sh "$out/$name.mcap" --expect "$out/$name.fox.json" --quiet
  "$py_fox" tools/check_ros2_bag.py --dump-foxglove "$out/$name.mcap" > "$out/$name.points.json"
  "$bin" decode "$@" --format ros2 --out "$out/$name" --json > "$out/$name.ros2.json"
  if "$py_bags" tools/check_ros2_bag.py "$out/$name" --expect "$out/$name.ros2.json" \
      --points "$out/$name.points.json" "${req[@]}" > "$out/$name.check.json"; then
    echo "ok   $name: $(topics "$out/$name.check.json")"
  else
    echo "FAIL $name"; fail=1
  fi
}

check demo - fixtures/demo-vlp16.pcap
check demo-raw /velodyne_packets fixtures/demo-vlp16.pcap --raw
check demo-pipeline /ground,/obstacles,/clusters fixtures/demo-vlp16.pcap --pipeline default
check demo-odometry /tf,/map fixtures/demo-vlp16.pcap --odometry

# The check must be able to fail: clouds decoded with other settings are caught.
"$bin" decode fixtures/demo-vlp16.pcap --format ros2 --max-range 5 --out "$out/demo-range" --json > /dev/null
if "$py_bags" tools/check_ros2_bag.py "$out/demo-range" --points "$out/demo.points.json" --quiet 2> /dev/null; then
  echo "FAIL the point comparison did not catch clouds decoded with --max-range 5"; fail=1
else
  echo "ok   a bag with other points (--max-range 5) is caught"
fi

if [ -d "$C" ]; then
  P=$C/ouster-lidar__ouster-sdk/tests/pcaps
  check ouster-imu /imu,/lidar_packets,/imu_packets,/metadata "$P/OS-0-32-U1_v2.2.0_1024x10.pcap" \
    --calib "$P/OS-0-32-U1_v2.2.0_1024x10.json" --raw
  # Two sensors in one capture: the demo VLP-16 and an Ouster, interleaved by time.
  "$py_bags" - fixtures/demo-vlp16.pcap "$P/OS-0-32-U1_v2.2.0_1024x10.pcap" "$out/two.pcap" <<'PY'
import struct, sys
MAGICS = {0xA1B2C3D4: 1000, 0xA1B23C4D: 1}  # microsecond / nanosecond pcap, little-endian
def records(p):
    b = open(p, "rb").read()
    scale = MAGICS[struct.unpack_from("<I", b, 0)[0]]
    at, out = 24, []
    while at + 16 <= len(b):
        s, frac, incl, _ = struct.unpack_from("<IIII", b, at)
        out.append([s * 1_000_000_000 + frac * scale, b[at + 16: at + 16 + incl]])
        at += 16 + incl
    return b[:24], scale, out
head, scale, a = records(sys.argv[1])
_, _, o = records(sys.argv[2])
shift = a[0][0] - o[0][0]
for r in o:
    r[0] += shift
with open(sys.argv[3], "wb") as f:
    f.write(head)
    for t, d in sorted(a + o, key=lambda r: r[0]):
        f.write(struct.pack("<IIII", t // 1_000_000_000, (t % 1_000_000_000) // scale, len(d), len(d)) + d)
PY
  check two-sensors /points,/imu "$out/two.pcap" --calib "$P/OS-0-32-U1_v2.2.0_1024x10.json" --raw
else
  echo "SKIP Ouster and two-sensor bags: ../shared/captures not found"
fi

# listen --format ros2 --raw killed with SIGKILL: the directory opens, with every file it lists.
port=$((20000 + RANDOM % 20000))
"$bin" listen --sensor 127.0.0.1:$port --format ros2 --raw --out "$out/killed" 2> "$out/listen.err" &
pid=$!
sleep 0.5
"$bin" replay fixtures/demo-vlp16.pcap --to 127.0.0.1 --port-offset $((port - 2368)) --rate 1 --loop 30 > /dev/null &
rpid=$!
sleep 13
kill -9 "$pid"
wait "$pid" 2>/dev/null || true
kill "$rpid" 2>/dev/null || true
wait "$rpid" 2>/dev/null || true
if "$py_bags" tools/check_ros2_bag.py "$out/killed" --require /points --require /velodyne_packets > "$out/killed.check.json"; then
  echo "ok   listen killed with SIGKILL after 13 s: $(topics "$out/killed.check.json") ($(ls "$out/killed" | tr '\n' ' '))"
else
  echo "FAIL listen killed with SIGKILL: the bag does not open"; cat "$out/listen.err" | tail -5; fail=1
fi

exit $fail
