#!/usr/bin/env bash
# Velodyne and Ouster decoding, two commits side by side (issue #21: "the Velodyne and Ouster
# figures unchanged after the layout move"). Run by hand on a quiet machine:
#
#   tools/ab_decode.sh 6572b1f HEAD            # before the family layout vs now
#
# Each commit is checked out (detached worktree under BENCH_DIR) and built in release into one
# shared target directory, one after the other (only ringscan itself recompiles); its
# `ringscan`, `bench_decode_mem` and `bench_ouster_decode_mem` are copied aside. Then, for
# BENCH_ROUNDS rounds with the two commits' order swapped every round, everything pinned to
# CPU 0:
# * whole process: `ringscan decode INPUT` (no --out) on the 200 MB HDL-32E capture
#   (`make_big_capture.py --mb 200`) and on the 1000-frame OS-2-128 capture, unfragmented and
#   fragmented at MTU 1500 (`make_big_ouster_capture.py`), as in BENCHMARKS.md#decode-speed;
# * the decoders alone on payloads in memory (`bench_decode_mem`, `bench_ouster_decode_mem`,
#   one repeat per round).
# Medians per commit and the ratio after/before go to BENCH_REPORT (default /tmp/ab_decode.md).
#
# Environment: BENCH_ROUNDS (5), BENCH_DIR (bench-data/ab-decode), BENCH_REPORT, and
# BENCH_KEEP=1 to keep the worktrees and binaries.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
A=${1:?usage: tools/ab_decode.sh REV_BEFORE [REV_AFTER]}
B=${2:-HEAD}
ROUNDS=${BENCH_ROUNDS:-5}
DIR="${BENCH_DIR:-$ROOT/bench-data/ab-decode}"
REPORT=${BENCH_REPORT:-/tmp/ab_decode.md}
CAPTURES="$ROOT/../shared/captures"
VIN="$CAPTURES/Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap"
VCALIB="$CAPTURES/ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml"
OP="$CAPTURES/ouster-lidar__ouster-sdk/tests/pcaps"
OIN="$OP/OS-2-128-U1_v2.3.0_1024x10.pcap"
OMETA="$OP/OS-2-128-U1_v2.3.0_1024x10.json"
for f in "$VIN" "$VCALIB" "$OIN" "$OMETA"; do
    [ -f "$f" ] || { echo "ab_decode: $f not found" >&2; exit 1; }
done
mkdir -p "$DIR"
PIN=""
if command -v taskset >/dev/null && taskset -c 0 true 2>/dev/null; then PIN="taskset -c 0"; fi

cleanup() {
    rm -f "$DIR"/hdl32e.pcap "$DIR"/os2.pcap "$DIR"/os2-frag.pcap
    if [ "${BENCH_KEEP:-0}" != 1 ]; then
        for r in a b; do
            git worktree remove --force "$DIR/src-$r" 2>/dev/null || true
            rm -rf "$DIR/bin-$r"
        done
    fi
}
trap cleanup EXIT

build() { # label rev (skipped when a kept build of the same commit is there)
    local wt="$DIR/src-$1"
    if [ -f "$DIR/bin-$1/rev" ] && [ "$(cat "$DIR/bin-$1/rev")" = "$(git rev-parse --short "$2")" ]; then
        return
    fi
    git worktree remove --force "$wt" 2>/dev/null || true
    git worktree add --detach "$wt" "$2" >/dev/null 2>&1
    (cd "$wt" && CARGO_TARGET_DIR="$DIR/target" cargo build --release --quiet \
        --bin ringscan --example bench_decode_mem --example bench_ouster_decode_mem)
    mkdir -p "$DIR/bin-$1"
    cp "$DIR/target/release/ringscan" "$DIR/target/release/examples/bench_decode_mem" \
        "$DIR/target/release/examples/bench_ouster_decode_mem" "$DIR/bin-$1/"
    git -C "$wt" rev-parse --short HEAD >"$DIR/bin-$1/rev"
}
build a "$A"
build b "$B"

python3 tools/make_big_capture.py --in "$VIN" --mb 200 --out "$DIR/hdl32e.pcap" >/dev/null
python3 tools/make_big_ouster_capture.py --in "$OIN" --meta "$OMETA" --frames 1000 \
    --out "$DIR/os2.pcap" --out-fragmented "$DIR/os2-frag.pcap" --mtu 1500 >/dev/null

RAW="$DIR/results.txt"
: >"$RAW"
wall() { # label name cmd... : one whole-process wall time
    local l=$1 n=$2; shift 2
    local t0 t1
    t0=$(date +%s.%N)
    $PIN "$@" >/dev/null 2>&1
    t1=$(date +%s.%N)
    echo "$l $n $(echo "$t1 - $t0" | bc)" >>"$RAW"
}
mem() { # label name cmd... : the in-memory decoders' JSON lines
    local l=$1 n=$2; shift 2
    $PIN "$@" 2>/dev/null | sed "s/^/$l $n /" >>"$RAW"
}
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg)" >&2
LOAD0=$(cut -d' ' -f1-3 /proc/loadavg)
for r in $(seq 1 "$ROUNDS"); do
    if [ $((r % 2)) = 1 ]; then order="a b"; else order="b a"; fi
    for l in $order; do
        bin="$DIR/bin-$l"
        wall "$l" hdl32e-decode "$bin/ringscan" decode "$DIR/hdl32e.pcap" --model hdl32e --calib "$VCALIB"
        wall "$l" os2-decode "$bin/ringscan" decode "$DIR/os2.pcap" --calib "$OMETA"
        wall "$l" os2-frag-decode "$bin/ringscan" decode "$DIR/os2-frag.pcap" --calib "$OMETA"
        mem "$l" hdl32e-mem "$bin/bench_decode_mem" "$DIR/hdl32e.pcap" --model hdl32e --calib "$VCALIB" --repeat 1
        mem "$l" os2-mem "$bin/bench_ouster_decode_mem" "$DIR/os2.pcap" --calib "$OMETA" --repeat 1
    done
    echo "round $r done, load average $(cut -d' ' -f1-3 /proc/loadavg)" >&2
done
LOAD1=$(cut -d' ' -f1-3 /proc/loadavg)

python3 - "$RAW" "$(cat "$DIR/bin-a/rev")" "$(cat "$DIR/bin-b/rev")" "$LOAD0" "$LOAD1" "$ROUNDS" >"$REPORT" <<'EOF'
import json, statistics, sys
raw, ra, rb, l0, l1, rounds = sys.argv[1:]
rows = {}
for line in open(raw):
    label, name, rest = line.rstrip("\n").split(" ", 2)
    if name.endswith("-mem"):
        j = json.loads(rest)
        key, secs = f"{name}:{j['what']}", j.get("wall_s", j.get("elapsed_s"))
    else:
        key, secs = name, float(rest)
    rows.setdefault(key, {}).setdefault(label, []).append(float(secs))
print(f"# Decoding, {ra} (before) vs {rb} (after), median of {rounds} alternating rounds, CPU 0\n")
print(f"load average before {l0}, after {l1}\n")
print("| what | before s, median | after s, median | after / before (medians) | after / before (fastest runs) | runs before | runs after |")
print("|---|---|---|---|---|---|---|")
for key, v in rows.items():
    a, b = statistics.median(v["a"]), statistics.median(v["b"])
    fa = " ".join(f"{x:.3f}" for x in v["a"])
    fb = " ".join(f"{x:.3f}" for x in v["b"])
    print(f"| {key} | {a:.3f} | {b:.3f} | {b / a:.3f} | {min(v['b']) / min(v['a']):.3f} | {fa} | {fb} |")
EOF
cat "$REPORT"
