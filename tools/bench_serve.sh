#!/usr/bin/env bash
# What --serve costs: decode wall time without / with the live view and its clients, and listen
# fed at 10x real time with a reading and a never-reading client (tools/bench_serve.py).
# Usage: tools/bench_serve.sh [COPIES=100]   (release build; input: the demo capture repeated)
set -euo pipefail
cd "$(dirname "$0")/.."
copies=${1:-100}
venv=tools/.venv-serve
if ! "$venv/bin/python" -c 'import websockets, google.protobuf, mcap, zstandard, lz4' 2>/dev/null; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check -r tools/requirements-serve.txt
fi
cargo build --quiet --release --bin ringscan
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
python3 tools/make_big_capture.py --in fixtures/demo-vlp16.pcap --out "$out/big.pcap" --copies "$copies" >/dev/null
echo "$(date -u '+%Y-%m-%d %H:%M UTC'); $(nproc) CPUs; load $(cut -d' ' -f1-3 /proc/loadavg); commit $(git rev-parse --short HEAD)"
"$venv/bin/python" tools/bench_serve.py --bin target/release/ringscan --pcap "$out/big.pcap" --tmp "$out"
