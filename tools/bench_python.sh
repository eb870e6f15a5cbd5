#!/usr/bin/env bash
# Speed and peak memory of the Python package, side by side in one run (BENCHMARKS.md, "Python"):
# ringscan.open over a ~200 MB Velodyne pcap into NumPy vs velodyne_decoder 3.1.0's read_pcap,
# and an Ouster capture vs ouster-sdk 1.0.1's open_source + XYZLut; tools/bench/python_bench.py
# tells what is timed.
#
#   tools/bench_python.sh [--vel-mb 200] [--ouster-frames 120] [--rounds 3]
#
# Creates tools/.venv-bench-python (git-ignored): the package built with the release profile
# from this clone, velodyne-decoder 3.1.0, ouster-sdk 1.0.1. Scratch captures go to
# $BENCH_DIR (default bench-data/python, deleted after). Waits while /work/BENCH_BUSY exists.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$ROOT/target}
VENV=tools/.venv-bench-python
DIR=${BENCH_DIR:-$ROOT/bench-data/python}
REPORT=${BENCH_REPORT:-$DIR/report.md}
if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q --upgrade pip
    "$VENV/bin/pip" install -q 'velodyne-decoder==3.1.0' 'ouster-sdk==1.0.1' numpy
fi
MATURIN_PEP517_ARGS="--profile release" "$VENV/bin/pip" install -q --force-reinstall --no-deps ./python
"$VENV/bin/pip" install -q numpy
while [ -e /work/BENCH_BUSY ]; do echo "waiting: /work/BENCH_BUSY" >&2; sleep 30; done
PIN=""
if command -v taskset >/dev/null && taskset -c 0 true 2>/dev/null; then PIN="taskset -c 0"; fi
mkdir -p "$DIR"
"$VENV/bin/python" tools/bench/python_bench.py --python "$ROOT/$VENV/bin/python" --dir "$DIR" \
    --pin "$PIN" --report "$REPORT" "$@"
echo "report: $REPORT" >&2
