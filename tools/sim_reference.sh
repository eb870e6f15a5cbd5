#!/usr/bin/env bash
# The reference decoders on the simulator's pcaps: velodyne_decoder 3.1.0 and ouster-sdk 1.0.1
# against ringscan, point by point, and all three against the simulator's ground truth.
#
# 1. creates tools/.venv-ref (velodyne-decoder 3.1.0, dpkt, numpy) and tools/.venv-sim-ouster
#    (ouster-sdk 1.0.1, numpy), git-ignored, unless they exist;
# 2. builds the simulator and the point dumper (cargo examples `simulate`, `dump_points`);
# 3. per case: simulates a MOVING sensor (15 m/s forward, 60 deg/s yaw) in the urban scene with
#    a real calibration / metadata file, writes the truth file, dumps ringscan's points and runs
#    tools/sim_reference.py, which prints the figures and the tolerances.
#
# Usage: tools/sim_reference.sh [SECONDS]   (default 0.3 s of sensor time per case)
# Environment: SIM_REF_VENV_VD / SIM_REF_VENV_OUSTER to point at existing venvs.
# Exit code: 0 when every case agrees within its tolerances, 1 otherwise.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
seconds=${1:-0.3}
vd=${SIM_REF_VENV_VD:-tools/.venv-ref}
os=${SIM_REF_VENV_OUSTER:-tools/.venv-sim-ouster}
if [ ! -x "$vd/bin/python" ]; then
    python3 -m venv "$vd"
    "$vd/bin/pip" install --quiet 'velodyne-decoder==3.1.0' dpkt numpy
fi
if [ ! -x "$os/bin/python" ]; then
    python3 -m venv "$os"
    "$os/bin/pip" install --quiet 'ouster-sdk==1.0.1' numpy
fi
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$root/target}
cargo build --quiet --release --example simulate --example dump_points
bin=$CARGO_TARGET_DIR/release/examples
cap=${SIM_REF_CAPTURES:-$root/../shared/captures}
params=$cap/ros-drivers__velodyne/velodyne_pointcloud/params
meta=$cap/ouster-lidar__ouster-sdk/tests
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
motion=(--scene urban --speed 15 --yaw-rate 60 --seconds "$seconds")
status=0
for case in "vlp16 VLP16db.yaml" "hdl32e 32db.yaml" "vlp32c VeloView-VLP-32C.yaml" \
            "hdl64e-s2 64e_s2.1-sztaki.yaml" "hdl64e-s3 64e_s3-xiesc.yaml"; do
    set -- $case
    model=$1 calib=$params/$2
    pcap=$work/$model.pcap
    "$bin/simulate" --model "$model" --calib "$calib" "${motion[@]}" --out "$pcap" --truth "$pcap.truth" 2>/dev/null
    "$bin/dump_points" --model "$model" --calib "$calib" --out "$pcap.f32" "$pcap" 2>/dev/null
    echo "== $model ($2), moving 15 m/s + 60 deg/s, urban, $seconds s"
    "$vd/bin/python" tools/sim_reference.py velodyne --model "$model" --calib "$calib" \
        --ringscan "$pcap.f32" --truth "$pcap.truth" "$pcap" || status=1
done
for case in "metadata/3_0_1_os-122246000293-128.json -" \
            "metadata/3_0_1_os-122246000293-128.json RNG19_RFL8_SIG16_NIR16" \
            "metadata/3_0_1_os-122246000293-128.json RNG15_RFL8_NIR8" \
            "metadata/3_0_1_os-122246000293-128.json LEGACY" \
            "metadata/2_0_rc2_os-992011000121-32U0_legacy.json -" \
            "pcaps/OS-1-128_767798045_1024x10_20230712_120049.json -" \
            "pcaps/shot_limiting_test.json -"; do
    set -- $case
    m=$meta/$1 profile=$2
    pcap=$work/ouster.pcap
    json=$m
    extra=()
    if [ "$profile" != "-" ]; then
        extra=(--profile "$profile")
        # The reference reads the profile from the metadata: write a copy with it.
        json=$work/meta-$profile.json
        "$os/bin/python" - "$m" "$json" "$profile" <<'PY'
import json, sys
src, dst, profile = sys.argv[1:]
d = json.load(open(src))
d.setdefault("config_params", {})["udp_profile_lidar"] = profile
if "lidar_data_format" in d:
    d["lidar_data_format"]["udp_profile_lidar"] = profile
json.dump(d, open(dst, "w"))
PY
    fi
    "$bin/simulate" --model ouster --metadata "$json" "${motion[@]}" --imu --out "$pcap" --truth "$pcap.truth" 2>/dev/null
    "$bin/dump_points" --metadata "$json" --out "$pcap.f32" "$pcap" 2>/dev/null
    echo "== ouster $1 ${extra[*]:-}, moving 15 m/s + 60 deg/s, urban, $seconds s"
    "$os/bin/python" tools/sim_reference.py ouster --metadata "$json" \
        --ringscan "$pcap.f32" --truth "$pcap.truth" "$pcap" || status=1
done
exit $status
