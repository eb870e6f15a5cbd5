#!/usr/bin/env bash
# The fleet on Ray (must-show 4): 16 captures of >= 50 MB + 1 corrupt to Parquet on a local
# Ray instance, 1 then 2 worker CPUs; tools/bench/fleet_bench.py tells what is checked and timed.
#
#   tools/bench_fleet.sh [--captures 16] [--mb 50]
#
# Uses tools/.venv-bench-fleet (git-ignored): the package (release profile) with pyarrow and
# ray[data]. Scratch data in $BENCH_DIR (default bench-data/fleet, deleted after; ~3 GB).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$ROOT/target}
VENV=tools/.venv-bench-fleet
DIR=${BENCH_DIR:-$ROOT/bench-data/fleet}
REPORT=${BENCH_REPORT:-$ROOT/bench-data/fleet-report.md}
if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q --upgrade pip
    "$VENV/bin/pip" install -q 'ray[data]==2.52.1' 'pyarrow==22.0.0' numpy
fi
MATURIN_PEP517_ARGS="--profile release" "$VENV/bin/pip" install -q --force-reinstall --no-deps ./python
while [ -e /work/BENCH_BUSY ]; do echo "waiting: /work/BENCH_BUSY" >&2; sleep 30; done
mkdir -p "$(dirname "$REPORT")"
"$VENV/bin/python" tools/bench/fleet_bench.py --dir "$DIR" --report "$REPORT" "$@"
