#!/usr/bin/env bash
# Side-by-side speed and memory benchmark of ringscan's Velodyne path against velodyne_decoder.
#
#   tools/bench_velodyne.sh            # 200 MB comparison input, then 1 GB for memory
#
# Environment (all optional):
#   BENCH_INPUT   real capture to repeat (default: the HDL-32E Monterey capture in ../shared/captures)
#   BENCH_MODEL   ringscan model id (hdl32e); BENCH_VD_MODEL velodyne_decoder Model name (HDL32E)
#   BENCH_CALIB   calibration file both decoders use (default: ros-drivers 32db.yaml)
#   BENCH_SIZES   input sizes in MB, the first is the comparison input (default 200,1000)
#   BENCH_ROUNDS  rounds of the side-by-side runs, best kept (default 3)
#   BENCH_DIR     scratch directory for the big captures and MCAP files (default bench-data/,
#                 git-ignored; the captures are deleted when done, the folder too if it was made here)
#   BENCH_REPORT  where the Markdown report is written (default /tmp/bench_velodyne.md; the raw
#                 records go next to it as .jsonl)
#   CARGO_TARGET_DIR as usual.
#
# Creates tools/.venv-bench with velodyne-decoder 3.1.0 (+ numpy, dpkt), builds ringscan
# (release), makes the inputs with tools/make_big_capture.py and runs tools/bench/run_bench.py,
# everything pinned to one CPU (taskset -c 0) with RAYON/OMP threads = 1. Nothing is appended to
# BENCHMARKS.md automatically: copy the figures there by hand, with this command.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
CAPTURES="$ROOT/../shared/captures"
INPUT="${BENCH_INPUT:-$CAPTURES/Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap}"
MODEL="${BENCH_MODEL:-hdl32e}"
VD_MODEL="${BENCH_VD_MODEL:-HDL32E}"
CALIB="${BENCH_CALIB:-$CAPTURES/ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml}"
SIZES="${BENCH_SIZES:-200,1000}"
ROUNDS="${BENCH_ROUNDS:-3}"
DIR="${BENCH_DIR:-$ROOT/bench-data}"
REPORT="${BENCH_REPORT:-/tmp/bench_velodyne.md}"
TARGET="${CARGO_TARGET_DIR:-$ROOT/target}"
VENV="$ROOT/tools/.venv-bench"

for f in "$INPUT" "$CALIB"; do
    [ -f "$f" ] || { echo "bench_velodyne: $f not found" >&2; exit 1; }
done
INPUT="$(realpath "$INPUT")"
CALIB="$(realpath "$CALIB")"

# /usr/bin/time (GNU time) for the peak RSS.
if ! /usr/bin/time -v true >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        apt-get update -qq && apt-get install -y -qq time >/dev/null
    else
        echo "bench_velodyne: GNU time (/usr/bin/time) is needed: apt-get install time" >&2
        exit 1
    fi
fi

# The reference.
if ! "$VENV/bin/python" -c 'import velodyne_decoder, numpy, dpkt' 2>/dev/null; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q 'velodyne-decoder==3.1.0' numpy dpkt
fi
"$VENV/bin/python" - <<'EOF'
from importlib.metadata import version
assert version("velodyne-decoder") == "3.1.0", version("velodyne-decoder")
EOF

# ringscan.
cargo build --release --bin ringscan --example bench_decode_mem >&2

PIN=""
if command -v taskset >/dev/null && taskset -c 0 true 2>/dev/null; then
    PIN="taskset -c 0"
fi
export RAYON_NUM_THREADS=1 OMP_NUM_THREADS=1

MADE_DIR=0
[ -d "$DIR" ] || MADE_DIR=1
mkdir -p "$DIR"
cleanup() {
    rm -f "$DIR"/big-*.pcap "$DIR"/big-*.pcap.part "$DIR"/big-*.mcap "$DIR"/*.time
    if [ "$MADE_DIR" = 1 ]; then rmdir "$DIR" 2>/dev/null || true; fi
}
trap cleanup EXIT

python3 "$ROOT/tools/bench/run_bench.py" \
    --ringscan "$TARGET/release/ringscan" \
    --mem-bin "$TARGET/release/examples/bench_decode_mem" \
    --vd-python "$VENV/bin/python" \
    --input "$INPUT" --model "$MODEL" --vd-model "$VD_MODEL" --calib "$CALIB" \
    --sizes "$SIZES" --rounds "$ROUNDS" --dir "$DIR" --pin "$PIN" \
    --results "${REPORT%.md}.jsonl" --report "$REPORT"
echo "report: $REPORT (records: ${REPORT%.md}.jsonl)" >&2
