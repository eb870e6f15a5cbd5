#!/usr/bin/env bash
# Fuzz smoke run (CI) and long runs by hand: builds the cargo-fuzz targets and runs each one
# for N seconds, one after the other, on seed corpora made from fixtures/ (and ../shared/captures
# when present). Any crash, panic, timeout or out-of-memory fails the script; libFuzzer leaves
# the input in tools/fuzz/artifacts/<target>/.
#
#   tools/fuzz/smoke.sh [SECONDS] [TARGET...]     (default: 20 s, every target)
#
# Environment: FUZZ_SANITIZER (default "none": the crate forbids unsafe code; set "address" to
# run under ASan), FUZZ_EXTRA (more libFuzzer flags), FUZZ_LOG_DIR (keep the libFuzzer logs
# there), RINGSCAN_FUZZ_STRICT=1 (also check the open issues of harness.rs). Prints one line per target: executions,
# executions per second, coverage (libFuzzer's `cov:` = edges reached) and features.
# See FUZZING.md.
set -euo pipefail

SECONDS_PER_TARGET=${1:-20}
shift || true
ALL_TARGETS=(pcap reassembly velodyne_packet velodyne_stream calib_velodyne decode_to_mcap calib_ouster ouster_packet ouster_stream pipeline_config tum_poses http_response live_view_requests bag_ros1 bag_mcap bag_messages bag_metadata hesai_packet calib_hesai robosense_packet calib_robosense livox_packet livox_control lvx render_messages family_stream)
if [ $# -gt 0 ]; then TARGETS=("$@"); else TARGETS=("${ALL_TARGETS[@]}"); fi
SANITIZER=${FUZZ_SANITIZER:-none}

cd "$(dirname "$0")/../.."
start=$(date +%s)

if ! command -v cargo-fuzz >/dev/null 2>&1; then
  echo "== installing cargo-fuzz"
  cargo install cargo-fuzz --locked
fi
# cargo-fuzz needs nightly-only rustc flags; the stable toolchain here accepts them with this.
export RUSTC_BOOTSTRAP=1

max_len() {
  case "$1" in
    pcap) echo 32768 ;;
    reassembly) echo 8192 ;;
    velodyne_packet) echo 1400 ;;
    velodyne_stream) echo 32768 ;;
    calib_velodyne) echo 65536 ;;
    decode_to_mcap) echo 65536 ;;
    calib_ouster) echo 65536 ;;
    ouster_packet) echo 70000 ;;
    ouster_stream) echo 131072 ;;
    bag_ros1 | bag_mcap) echo 65536 ;;
    bag_messages) echo 16384 ;;
    bag_metadata) echo 8192 ;;
    hesai_packet) echo 1400 ;;
    calib_hesai) echo 73728 ;;
    robosense_packet) echo 1400 ;;
    calib_robosense) echo 16384 ;;
    livox_packet) echo 4096 ;;
    livox_control) echo 1400 ;;
    lvx) echo 16384 ;;
    family_stream) echo 16384 ;;
    *) echo 4096 ;;
  esac
}

echo "== seed corpora"
python3 tools/fuzz/seed_corpus.py

echo "== cargo fuzz build (sanitizer: $SANITIZER, debug assertions on)"
cargo fuzz build --fuzz-dir tools/fuzz -a -s "$SANITIZER"
built=$(date +%s)
echo "   built in $((built - start)) s"

extra_args() {
  case "$1" in
    calib_velodyne) echo "-dict=$PWD/tools/fuzz/dicts/calib_velodyne.dict" ;;
    *) echo "" ;;
  esac
}

logs=${FUZZ_LOG_DIR:-$(mktemp -d)}
mkdir -p "$logs"
status=0
for t in "${TARGETS[@]}"; do
  echo "== $t: ${SECONDS_PER_TARGET} s"
  mkdir -p "tools/fuzz/artifacts/$t"
  # shellcheck disable=SC2086
  if ! cargo fuzz run --fuzz-dir tools/fuzz -a -s "$SANITIZER" "$t" -- \
      -max_total_time="$SECONDS_PER_TARGET" -max_len="$(max_len "$t")" -timeout=10 \
      -rss_limit_mb=2048 -print_final_stats=1 $(extra_args "$t") ${FUZZ_EXTRA:-} >"$logs/$t.log" 2>&1; then
    status=1
    echo "   FAILED: last lines of the log:"
    grep -v -e '^#' -e '^\s*\[' "$logs/$t.log" | tail -40 | cut -c1-300 | sed 's/^/   | /'
  fi
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$logs/$t.log" | tail -1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$logs/$t.log" | tail -1)
  cov=$(grep -oE 'cov: [0-9]+ ft: [0-9]+' "$logs/$t.log" | tail -1)
  echo "   $t: ${execs:-?} execs, ${rate:-?} exec/s, ${cov:-no coverage line}"
done
echo "== fuzz smoke done in $(($(date +%s) - start)) s (build $((built - start)) s)"
exit $status
