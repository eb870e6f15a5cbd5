#!/usr/bin/env bash
# `ringscan decode … --out` end to end, one row per chunk compression, side by side in one run:
# process wall time (including the final fsync of the MCAP), CPU time, output size, compression
# ratio (point bytes / file bytes) and real-time factor (capture duration / wall).
#
#   tools/bench_mcap_e2e.sh [MB]          (default 200: the HDL-32E Monterey capture repeated)
#
# Environment: BENCH_COMPRESSIONS (default "zstd:1 zstd:-1 zstd:-3 lz4 none"), BENCH_ROUNDS
# (default 3: the rounds are interleaved and the median wall is kept), BENCH_TASKSET (e.g.
# "taskset -c 0" to pin to one CPU), BENCH_DIR (default bench-data/, git-ignored; the input is
# deleted afterwards unless it was there before), CARGO_TARGET_DIR. Prints a Markdown table.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
MB=${1:-200}
CAPTURES="$ROOT/../shared/captures"
CALIB="$CAPTURES/ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml"
DIR="${BENCH_DIR:-$ROOT/bench-data}"
ROUNDS=${BENCH_ROUNDS:-3}
COMPRESSIONS=${BENCH_COMPRESSIONS:-"zstd:1 zstd:-1 zstd:-3 lz4 none"}
TARGET="${CARGO_TARGET_DIR:-$ROOT/target}"
mkdir -p "$DIR"
INPUT="$DIR/big${MB}.pcap"
made=0
if [ ! -f "$INPUT" ]; then
    python3 tools/make_big_capture.py --mb "$MB" --out "$INPUT"
    made=1
fi
cargo build --release --quiet --bin ringscan
BIN="$TARGET/release/ringscan"

# Capture duration and point count from a decode without output.
read -r duration points < <("$BIN" decode "$INPUT" --model hdl32e --calib "$CALIB" --json |
    python3 -c 'import json,sys; j=json.load(sys.stdin); print(j["capture"]["duration_s"], j["points"])')
echo "input: $INPUT ($(stat -c %s "$INPUT") bytes), $points points, ${duration} s of capture"
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg), CPUs: $(nproc)"

results=$(mktemp)
for round in $(seq "$ROUNDS"); do
    for c in $COMPRESSIONS; do
        out="$DIR/e2e.mcap"
        rm -f "$out"
        # shellcheck disable=SC2086
        /usr/bin/time -f "%e %U %S" -o "$DIR/time.txt" ${BENCH_TASKSET:-} \
            "$BIN" decode "$INPUT" --model hdl32e --calib "$CALIB" --out "$out" --compression "$c" >/dev/null
        read -r wall user sys < "$DIR/time.txt"
        echo "$c $round $wall $user $sys $(stat -c %s "$out")" >> "$results"
        rm -f "$out"
    done
done
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"

python3 - "$results" "$duration" "$points" "$COMPRESSIONS" <<'EOF'
import statistics, sys
path, duration, points, order = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), sys.argv[4].split()
rows = {}
for line in open(path):
    c, _r, wall, user, sys_, size = line.split()
    rows.setdefault(c, []).append((float(wall), float(user), float(sys_), int(size)))
point_bytes = points * 24
print()
print("| compression | wall (s), median | walls | CPU user + sys (s), median | real-time factor | MCAP size (MB) | ratio (point bytes / file) |")
print("|---|---:|---|---:|---:|---:|---:|")
for c in order:
    r = rows[c]
    wall = statistics.median(x[0] for x in r)
    cpu = statistics.median(x[1] + x[2] for x in r)
    size = r[0][3]
    walls = ", ".join(f"{x[0]:.2f}" for x in r)
    print(f"| {c} | {wall:.3f} | {walls} | {cpu:.2f} | **{duration / wall:.1f}×** | {size / 1e6:.0f} | {point_bytes / size:.2f} |")
EOF
rm -f "$results" "$DIR/time.txt"
if [ "$made" = 1 ]; then rm -f "$INPUT"; fi
