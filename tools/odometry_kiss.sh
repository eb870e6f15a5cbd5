#!/usr/bin/env bash
# ringscan's LiDAR odometry beside KISS-ICP on the same decoded sweeps of the real Velodyne
# captures with >= 10 sweeps: trajectory agreement per sweep and ms per sweep, one run each,
# single thread on both sides.
#
#   tools/odometry_kiss.sh [REPEAT]     (default 5 runs of each sequence; median per sweep)
#
# Needs ../shared/captures (or CAPTURES=DIR). Creates tools/.venv-kiss (git-ignored) with
# kiss-icp 1.3.0 from PyPI on first use. Outputs go to target/odometry-kiss/.
set -euo pipefail
cd "$(dirname "$0")/.."
REPEAT=${1:-5}
CAPTURES=${CAPTURES:-../shared/captures}
OUT=target/odometry-kiss
VENV=tools/.venv-kiss
if [ ! -d "$CAPTURES" ]; then
    echo "SKIP: $CAPTURES is absent: no real captures to run on" >&2
    exit 0
fi
if [ ! -x "$VENV/bin/python" ] || ! "$VENV/bin/python" -c "import kiss_icp" 2>/dev/null; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q "kiss-icp==1.3.0" "numpy<3"
fi
# Single thread everywhere: KISS-ICP's registration.max_num_threads = 1 (set in the .py; it
# caps TBB through tbb::global_control), and OpenMP / BLAS pools to 1 for numpy.
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
mkdir -p "$OUT"
cargo build --release --example odometry
BIN=target/release/examples/odometry
PARAMS="$CAPTURES/ros-drivers__velodyne/velodyne_pointcloud/params"
DATA="$CAPTURES/Kitware__VeloView/Testing/Data"
run() { # name model calibration capture
    local name=$1 model=$2 calib=$3 pcap=$4
    "$BIN" --model "$model" --calib "$calib" --dump "$OUT/$name.bin" "$pcap" >/dev/null 2>&1
    "$BIN" --sweeps "$OUT/$name.bin" --repeat "$REPEAT" --trajectory "$OUT/$name.tum" \
        --report "$OUT/$name.json"
    "$VENV/bin/python" tools/odometry_kiss.py "$OUT/$name.bin" "$OUT/$name.tum" "$OUT/$name.json" \
        --repeat "$REPEAT" --out-tum "$OUT/${name}_kiss.tum" --name "$name"
}
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
# The VLP-16 capture's product-id byte says HDL-32E: the model is named.
run vlp16 vlp16 "$PARAMS/VLP16db.yaml" "$DATA/vlp-16-test-90deg-1-50-frames.pcap"
run hdl32e hdl32e "$PARAMS/32db.yaml" "$DATA/monterey-first-100-packets.pcap"
