#!/usr/bin/env bash
# Speed of `ringscan decode` on ROS bags against the same packets from a pcap, side by side in
# one run; and, on an Ouster bag, against ouster-sdk's own bag source.
#
#   tools/bench_bags.sh
#
# Inputs (made in BENCH_DIR, deleted at the end):
#   velodyne.pcap  tools/make_big_capture.py of the HDL-32E Monterey capture, BENCH_MB MB
#   velodyne.{ros1-none,ros1-lz4,sqlite3-none,mcap-none}  tools/make_test_bags.py of it: its data
#                  packets, 180 per VelodyneScan (one turn); the pcap also holds the 10 % position
#                  packets, which the bags cannot carry
#   ouster.pcap    tools/make_big_ouster_capture.py of the OS-2-128 capture, BENCH_FRAMES frames
#   ouster.{ros1-none,sqlite3-none,mcap-none}  its lidar + IMU packets as PacketMsg, metadata inside
# Each command runs BENCH_ROUNDS times pinned to CPU 0 (taskset -c 0), the commands of a group
# alternating within each round; the median wall time and the largest peak RSS are reported
# (/usr/bin/time). `decode` without --out: reading, decoding
# and sweep assembly; with --out: MCAP written too (zstd chunks).
#
# Reference: velodyne_decoder's read_bag needs the ROS 1 `rosbag` Python package, which PyPI
# does not have; ouster-sdk 1.0.1's bag source (ouster.sdk.open_source on the ROS 1 bag,
# frames + XYZLut, as the goldens were made) is timed instead, in tools/.venv-bags-ref
# (created here: ouster-sdk==1.0.1).
#
# Environment: BENCH_MB (default 100), BENCH_FRAMES (default 600), BENCH_ROUNDS (default 5),
# BENCH_DIR (default bench-data/bags), BENCH_REPORT (default /tmp/bench_bags.md), BENCH_KEEP=1
# (keep the inputs in BENCH_DIR afterwards).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
CAPTURES="$ROOT/../shared/captures"
MB="${BENCH_MB:-100}"
FRAMES="${BENCH_FRAMES:-600}"
ROUNDS="${BENCH_ROUNDS:-5}"
DIR="${BENCH_DIR:-$ROOT/bench-data/bags}"
REPORT="${BENCH_REPORT:-/tmp/bench_bags.md}"
BIN="${CARGO_TARGET_DIR:-$ROOT/target}/release/ringscan"
VPCAP_IN="$CAPTURES/Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap"
VCALIB="$CAPTURES/ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml"
OPCAP_IN="$CAPTURES/ouster-lidar__ouster-sdk/tests/pcaps/OS-2-128-U1_v2.3.0_1024x10.pcap"
OMETA="$CAPTURES/ouster-lidar__ouster-sdk/tests/pcaps/OS-2-128-U1_v2.3.0_1024x10.json"
REF="$ROOT/tools/.venv-bags-ref"

cargo build --release --quiet --bin ringscan
mkdir -p "$DIR"
[ -n "${BENCH_KEEP:-}" ] || trap 'rm -rf "$DIR"' EXIT

echo "== inputs"
python3 tools/make_big_capture.py --in "$VPCAP_IN" --out "$DIR/velodyne.pcap" --mb "$MB" >/dev/null
python3 tools/make_test_bags.py --pcap "$DIR/velodyne.pcap" --out "$DIR" --name velodyne \
    --packets-per-scan 180 --variants ros1-none,ros1-lz4,sqlite3-none,mcap-none >/dev/null
python3 tools/make_big_ouster_capture.py --meta "$OMETA" --in "$OPCAP_IN" --frames "$FRAMES" \
    --out "$DIR/ouster.pcap" >/dev/null
python3 tools/make_test_bags.py --pcap "$DIR/ouster.pcap" --metadata "$OMETA" --out "$DIR" \
    --name ouster --variants ros1-none,sqlite3-none,mcap-none >/dev/null
du -sh "$DIR"/* | sed 's|'"$DIR"'/||'

# One entry: a label and its command, quoted for eval.
declare -a LABELS=() CMDS=()
add() {
    local label=$1; shift
    LABELS+=("$label"); CMDS+=("$(printf '%q ' "$@")")
}
# compare: runs the entries added since the last call ROUNDS times, alternating them within each
# round (this host's speed drifts by tens of percent over minutes: consecutive runs of one
# variant would compare the minutes, not the inputs); prints each one's median wall seconds, its
# summary and the largest peak RSS as Markdown rows.
compare() {
    local -A times=() rss=()
    local i t m
    for _ in $(seq "$ROUNDS"); do
        for i in "${!LABELS[@]}"; do
            eval "/usr/bin/time -f '%e %M' -o '$DIR/time.txt' taskset -c 0 ${CMDS[$i]}" \
                >"$DIR/stdout.$i.txt"
            read -r t m <"$DIR/time.txt"
            times[$i]+="$t "
            [ "$m" -gt "${rss[$i]:-0}" ] && rss[$i]=$m
        done
    done
    for i in "${!LABELS[@]}"; do
        local median summary
        median=$(printf '%s\n' ${times[$i]} | sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}')
        summary=$(python3 -c 'import json,sys
try:
    d=json.load(open(sys.argv[1])); print(d["sweeps"], d["points"], d["capture"]["datagrams"])
except Exception:
    print(open(sys.argv[1]).read().strip())' "$DIR/stdout.$i.txt")
        printf '| %s | %s | %s | %d |\n' "${LABELS[$i]}" "$median" "$summary" $((rss[$i] / 1024)) | tee -a "$REPORT"
    done
    LABELS=(); CMDS=()
}

{
    echo "Run $(date -u +%Y-%m-%dT%H:%MZ), $(nproc) CPUs (pinned to CPU 0), ROUNDS=$ROUNDS (variants alternating in each round), BENCH_MB=$MB, BENCH_FRAMES=$FRAMES"
    echo
    echo "| input | median s | sweeps points datagrams | max RSS MiB |"
    echo "|---|---|---|---|"
} >"$REPORT"
echo "== Velodyne (HDL-32E), decode only"
add "velodyne.pcap" "$BIN" decode "$DIR/velodyne.pcap" --calib "$VCALIB" --json
for v in ros1-none.bag ros1-lz4.bag sqlite3-none mcap-none; do
    add "velodyne.$v" "$BIN" decode "$DIR/velodyne.$v" --calib "$VCALIB" --json
done
compare
echo "== Velodyne, decode to MCAP"
add "velodyne.pcap --out" "$BIN" decode "$DIR/velodyne.pcap" --calib "$VCALIB" --json --out "$DIR/o.mcap"
add "velodyne.ros1-none.bag --out" "$BIN" decode "$DIR/velodyne.ros1-none.bag" --calib "$VCALIB" --json --out "$DIR/o.mcap"
compare
echo "== Ouster (OS-2-128), decode only"
add "ouster.pcap" "$BIN" decode "$DIR/ouster.pcap" --calib "$OMETA" --json
for v in ros1-none.bag sqlite3-none mcap-none; do
    add "ouster.$v" "$BIN" decode "$DIR/ouster.$v" --json
done
echo "== ouster-sdk 1.0.1 bag source (reference)"
if [ ! -x "$REF/bin/python" ] || ! "$REF/bin/python" -c 'import ouster.sdk' 2>/dev/null; then
    python3 -m venv "$REF" && "$REF/bin/pip" install -q ouster-sdk==1.0.1 || true
fi
if "$REF/bin/python" -c 'import ouster.sdk' 2>/dev/null; then
    cat >"$DIR/sdk_bag.py" <<'EOF'
import sys
import numpy as np
from ouster.sdk import open_source
from ouster.sdk.core import XYZLut, ChanField
src = open_source(sys.argv[1], collate=False)
info = src.sensor_info[0]
lut = XYZLut(info, use_extrinsics=False)
frames = points = 0
for scans in src:
    for scan in scans:
        if scan is None:
            continue
        rng = scan.field(ChanField.RANGE)
        xyz = lut(rng)
        frames += 1
        points += int(np.count_nonzero(rng))
print(frames, points, "(ouster-sdk frames, points)")
EOF
    add "ouster.ros1-none.bag, ouster-sdk" "$REF/bin/python" "$DIR/sdk_bag.py" "$DIR/ouster.ros1-none.bag"
else
    echo "ouster-sdk could not be installed: reference not run" | tee -a "$REPORT"
fi
compare
echo "== report: $REPORT"
cat "$REPORT"
