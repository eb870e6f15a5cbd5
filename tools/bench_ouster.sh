#!/usr/bin/env bash
# Side-by-side speed and memory benchmark of ringscan's Ouster path against ouster-sdk.
#
#   tools/bench_ouster.sh              # 1,000 frames for speed, 4,000 more for memory
#
# Environment (all optional):
#   BENCH_INPUT   real Ouster capture to repeat (default: ouster-sdk's OS-2-128-U1 2.3.0 capture
#                 in ../shared/captures: one 1024x10 frame, 128 beams, RNG19_RFL8_SIG16_NIR16)
#   BENCH_META    its metadata JSON (default: the matching OS-2-128-U1_v2.3.0_1024x10.json)
#   BENCH_FRAMES  frames per input, comma-separated; the first is the comparison input, the
#                 others are only for the peak-memory check (default 1000,4000)
#   BENCH_ROUNDS  interleaved rounds of the side-by-side runs, best kept (default 5)
#   BENCH_DIR     scratch directory for the big captures (default bench-data/ouster, git-ignored;
#                 the captures are deleted when done, the folder too if it was made here)
#   BENCH_REPORT  where the Markdown report is written (default /tmp/bench_ouster.md; the raw
#                 records go next to it as .jsonl)
#   BENCH_EXTRA_RINGSCAN  other ringscan binaries run in the same rounds, as
#                 LABEL=PATH[,LABEL=PATH...] (e.g. a build of an earlier commit, for before/after)
#   CARGO_TARGET_DIR as usual.
#
# Creates tools/.venv-bench-ouster with ouster-sdk 1.0.1 (+ numpy), builds ringscan and the
# example bench_ouster_decode_mem (release), makes the inputs with
# tools/make_big_ouster_capture.py (unfragmented, and fragmented at MTU 1500) and runs
# tools/bench/ouster_run_bench.py: everything pinned to one CPU (taskset -c 0) with
# OMP / OPENBLAS / RAYON threads = 1. Nothing is written to BENCHMARKS.md automatically: copy
# the figures there by hand, with this command.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
PCAPS="$ROOT/../shared/captures/ouster-lidar__ouster-sdk/tests/pcaps"
INPUT="${BENCH_INPUT:-$PCAPS/OS-2-128-U1_v2.3.0_1024x10.pcap}"
META="${BENCH_META:-$PCAPS/OS-2-128-U1_v2.3.0_1024x10.json}"
FRAMES="${BENCH_FRAMES:-1000,4000}"
ROUNDS="${BENCH_ROUNDS:-5}"
DIR="${BENCH_DIR:-$ROOT/bench-data/ouster}"
REPORT="${BENCH_REPORT:-/tmp/bench_ouster.md}"
TARGET="${CARGO_TARGET_DIR:-$ROOT/target}"
VENV="$ROOT/tools/.venv-bench-ouster"

for f in "$INPUT" "$META"; do
    [ -f "$f" ] || { echo "bench_ouster: $f not found" >&2; exit 1; }
done
INPUT="$(realpath "$INPUT")"
META="$(realpath "$META")"

# /usr/bin/time (GNU time) for the peak RSS.
if ! /usr/bin/time -v true >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        apt-get update -qq && apt-get install -y -qq time >/dev/null
    else
        echo "bench_ouster: GNU time (/usr/bin/time) is needed: apt-get install time" >&2
        exit 1
    fi
fi

# The reference.
if ! "$VENV/bin/python" -c 'import ouster.sdk, numpy' 2>/dev/null; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q 'ouster-sdk==1.0.1' numpy
fi
"$VENV/bin/python" - <<'EOF'
from importlib.metadata import version
assert version("ouster-sdk") == "1.0.1", version("ouster-sdk")
EOF

# ringscan.
cargo build --release --bin ringscan --example bench_ouster_decode_mem >&2

PIN=""
if command -v taskset >/dev/null && taskset -c 0 true 2>/dev/null; then
    PIN="taskset -c 0"
fi
export RAYON_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1

MADE_DIR=0
[ -d "$DIR" ] || MADE_DIR=1
mkdir -p "$DIR"
cleanup() {
    rm -f "$DIR"/ouster-*.pcap "$DIR"/ouster-*.pcap.part
    if [ "$MADE_DIR" = 1 ]; then rmdir "$DIR" 2>/dev/null || true; fi
}
trap cleanup EXIT

EXTRA=()
if [ -n "${BENCH_EXTRA_RINGSCAN:-}" ]; then
    IFS=, read -ra PAIRS <<<"$BENCH_EXTRA_RINGSCAN"
    for p in "${PAIRS[@]}"; do EXTRA+=(--extra-ringscan "$p"); done
fi

python3 "$ROOT/tools/bench/ouster_run_bench.py" "${EXTRA[@]}" \
    --ringscan "$TARGET/release/ringscan" \
    --mem-bin "$TARGET/release/examples/bench_ouster_decode_mem" \
    --sdk-python "$VENV/bin/python" \
    --input "$INPUT" --meta "$META" \
    --frames "$FRAMES" --rounds "$ROUNDS" --dir "$DIR" --pin "$PIN" \
    --results "${REPORT%.md}.jsonl" --report "$REPORT"
echo "report: $REPORT (records: ${REPORT%.md}.jsonl)" >&2
