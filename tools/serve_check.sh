#!/usr/bin/env bash
# The live view seen by an independent client: `ringscan decode --serve` and `listen --serve`
# (fed by `ringscan replay`) on loopback; a Python client (the `websockets` package, speaking
# foxglove.websocket.v1) subscribes to /points and decodes the payloads with the protobuf
# runtime from the schema the server advertises; they are compared with the MCAP file the same
# run writes (official `mcap` reader) and with the run's --json summary.
# Usage: tools/serve_check.sh   (creates tools/.venv-serve on first use)
set -euo pipefail
cd "$(dirname "$0")/.."
venv=tools/.venv-serve
if ! "$venv/bin/python" -c 'import websockets, google.protobuf, mcap, zstandard, lz4' 2>/dev/null; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check -r tools/requirements-serve.txt
fi
cargo build --quiet --bin ringscan
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
"$venv/bin/python" tools/serve_client.py --bin target/debug/ringscan --pcap fixtures/demo-vlp16.pcap --tmp "$out"
