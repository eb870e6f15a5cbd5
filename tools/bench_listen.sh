#!/usr/bin/env bash
# Load benchmark of `ringscan listen` (by hand, not in CI): loopback senders at 1x, 5x, 10x and
# more of real packet rates, count only and with --out; a garbage flood. See
# tools/bench_listen.py for the scenarios and what is measured.
#
#   tools/bench_listen.sh [SECONDS] [RAMP_SECONDS]     # default 60 and 10
#
# Environment (optional): BENCH_DIR scratch folder (default bench-data/listen, git-ignored;
# deleted when done if made here), BENCH_REPORT (default /tmp/bench_listen.md), BENCH_ONLY
# (comma-separated scenario names), BENCH_THREADS (listen --threads with --out; default its own,
# the machine's cores).
#
# Inputs, made here:
# * HDL-64E S3: 10 s of the simulator (`--model hdl64e-s3 --mode dual`, 10 Hz, the
#   ros-drivers 64e_s3-xiesc.yaml calibration), replayed and looped; its packet rate is the
#   sensor's in dual return (about 5,800 data packets/s), so 10x is about 58,000 packets/s;
# * Ouster: ouster-sdk's OS-2-128-U1 2.3.0 capture (RNG19_RFL8_SIG16_NIR16, 128 beams, 1024x10:
#   the packet format of an OS-1-128 RNG19 stream) repeated into BENCH_OUSTER_FRAMES (default
#   2000, 3.2 GB of scratch) continuous frames by tools/make_big_ouster_capture.py; sent once per
#   scenario (so 20 s at 10x), never looped.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
SECS=${1:-60}
RAMP=${2:-10}
C=../shared/captures
O=$C/ouster-lidar__ouster-sdk/tests/pcaps
CALIB=$C/ros-drivers__velodyne/velodyne_pointcloud/params/64e_s3-xiesc.yaml
DIR=${BENCH_DIR:-bench-data/listen}
made=0
if [ ! -d "$DIR" ]; then mkdir -p "$DIR"; made=1; fi
cleanup() { rm -f "$DIR/hdl64e.pcap" "$DIR/ouster.pcap"; if [ "$made" = 1 ]; then rmdir "$DIR" 2>/dev/null || true; fi; }
trap cleanup EXIT

cargo build --quiet --release --bin ringscan --example simulate
target/release/examples/simulate --model hdl64e-s3 --mode dual --seconds 10 --calib "$CALIB" --out "$DIR/hdl64e.pcap"
python3 tools/make_big_ouster_capture.py --in "$O/OS-2-128-U1_v2.3.0_1024x10.pcap" \
  --meta "$O/OS-2-128-U1_v2.3.0_1024x10.json" --frames "${BENCH_OUSTER_FRAMES:-2000}" --out "$DIR/ouster.pcap" > /dev/null
echo "machine: $(nproc) cores; load average $(cut -d' ' -f1-3 /proc/loadavg); net.core.rmem_max $(cat /proc/sys/net/core/rmem_max)"
python3 tools/bench_listen.py --bin target/release/ringscan \
  --hdl64 "$DIR/hdl64e.pcap" --hdl64-calib "$CALIB" \
  --ouster "$DIR/ouster.pcap" --ouster-meta "$O/OS-2-128-U1_v2.3.0_1024x10.json" \
  --seconds "$SECS" --ramp-seconds "$RAMP" --only "${BENCH_ONLY:-}" \
  ${BENCH_THREADS:+--threads "$BENCH_THREADS"} \
  --report "${BENCH_REPORT:-/tmp/bench_listen.md}"
