#!/usr/bin/env bash
# `ringscan listen` killed with SIGKILL mid-recording: the chunks written before the kill can
# still be read. Replays a real capture (looped) into `listen --out`, kills the listener with
# SIGKILL after a few seconds, then reads the cut file with the official Python MCAP reader
# (tools/listen_kill9.py: StreamReader, chunk by chunk) and prints what it holds.
#
#   tools/listen_kill9.sh [SECONDS]      # default 4 s before the kill
#
# Uses tools/.venv (the official readers, pinned in tools/requirements-check.txt; created by
# tools/check_mcap.py on first use). Needs ../shared/captures.
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-4}
cargo build --quiet --release --bin ringscan
bin=target/release/ringscan
pcap=../shared/captures/jerry73204__rust-lidar-utils/test_files/hdl32_example.pcap
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
port=$((20000 + RANDOM % 20000))

# The venv with the official readers (check_mcap.py makes it), checked on a finalised file first.
"$bin" decode "$pcap" --out "$out/ref.mcap" --json > "$out/ref.json"
tools/check_mcap.sh "$out/ref.mcap" --expect "$out/ref.json" --quiet
py=tools/.venv/bin/python

"$bin" listen --sensor 127.0.0.1:$port --out "$out/killed.mcap" 2> "$out/listen.err" &
pid=$!
sleep 0.5
"$bin" replay "$pcap" --to 127.0.0.1 --port-offset $((port - 2368)) --rate 1 --loop 40 > /dev/null &
rpid=$!
sleep "$secs"
kill -9 "$pid"
wait "$pid" 2>/dev/null || true
kill "$rpid" 2>/dev/null || true
wait "$rpid" 2>/dev/null || true
echo "listen killed with SIGKILL after ${secs}s; the file has $(stat -c %s "$out/killed.mcap") bytes"
"$py" tools/listen_kill9.py "$out/killed.mcap"
