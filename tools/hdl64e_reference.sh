#!/usr/bin/env bash
# Side-by-side check of ringscan's HDL-64E S2 / S3 decoding against velodyne_decoder 3.1.0.
#
# 1. creates a venv in tools/.venv-ref (git-ignored) with velodyne-decoder 3.1.0, dpkt, numpy;
# 2. builds the simulator and the point dumper (cargo examples `simulate`, `dump_points`);
# 3. for each case: simulates an HDL-64E pcap with a real calibration (the ray-cast room), then
#    a pcap of random packets (raw distances over the whole range), decodes each with both and
#    compares point by point (tools/hdl64e_reference.py).
#
# Usage: tools/hdl64e_reference.sh [SECONDS]   (default 0.3 s of sensor time per case)
# HDL64E_PROFILE=dev builds the two examples in the dev profile with every feature, which reuses
# the library `cargo test --all-features` has just built (CI: a release build of its own took
# 4 to 5 minutes of the step's 5); default: release.
# Exit code: 0 when every case agrees within the tolerances printed, 1 otherwise.
# HDL-64E dual: velodyne_decoder reads block i as the strongest and i + 2 as the last, and so
# does ringscan (VelodyneModel::dual_strongest_first).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
seconds=${1:-0.3}
venv=tools/.venv-ref
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install --quiet 'velodyne-decoder==3.1.0' dpkt numpy
fi
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$root/target}
if [ "${HDL64E_PROFILE:-release}" = dev ]; then
    cargo build --quiet --all-features --example simulate --example dump_points
    bin=$CARGO_TARGET_DIR/debug/examples
else
    cargo build --quiet --release --example simulate --example dump_points
    bin=$CARGO_TARGET_DIR/release/examples
fi
params=${HDL64E_CALIB_DIR:-$root/../shared/captures/ros-drivers__velodyne/velodyne_pointcloud/params}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
status=0
for case in "hdl64e-s2 64e_s2.1-sztaki.yaml strongest" "hdl64e-s2 64e_s2.1-sztaki.yaml dual" \
            "hdl64e-s3 64e_s3-xiesc.yaml strongest" "hdl64e-s3 64e_s3-xiesc.yaml dual"; do
    set -- $case
    model=$1 calib=$params/$2 mode=$3
    pcap=$work/$model-$mode.pcap
    "$bin/simulate" --model "$model" --mode "$mode" --calib "$calib" --seconds "$seconds" --out "$pcap" 2>/dev/null
    "$bin/dump_points" --model "$model" --mode "$mode" --calib "$calib" --out "$pcap.ringscan.f32" "$pcap"
    echo "== $model $mode ($2)"
    "$venv/bin/python" tools/hdl64e_reference.py --model "$model" --calib "$calib" \
        --ringscan "$pcap.ringscan.f32" "$pcap" || status=1
done
# Random packets: raw distances over the whole range (far side of 25.04 m and its edge).
for case in "hdl64e-s2 64e_s2.1-sztaki.yaml strongest" "hdl64e-s2 64e_s2.1-sztaki.yaml dual" \
            "hdl64e-s3 64e_s3-xiesc.yaml strongest" "hdl64e-s3 64e_s3-xiesc.yaml dual"; do
    set -- $case
    model=$1 calib=$params/$2 mode=$3
    pcap=$work/random-$model-$mode.pcap
    "$venv/bin/python" tools/hdl64e_reference.py --make-random "$pcap" --mode "$mode" --packets 2000
    "$bin/dump_points" --model "$model" --mode "$mode" --calib "$calib" --out "$pcap.ringscan.f32" "$pcap"
    echo "== random packets: $model $mode ($2)"
    "$venv/bin/python" tools/hdl64e_reference.py --model "$model" --calib "$calib" \
        --ringscan "$pcap.ringscan.f32" "$pcap" || status=1
done
exit $status
