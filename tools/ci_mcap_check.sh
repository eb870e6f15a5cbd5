#!/usr/bin/env bash
# Decodes the demo capture and every real Velodyne capture in ../shared/captures to MCAP (both
# formats, one with --raw), then reads each file back with the official Python MCAP readers
# (tools/check_mcap.sh) and compares channels, message counts, points and attachments with
# what `ringscan decode --json` reported. Chunks compressed on worker threads: the same capture
# with --threads 1 and --threads 4 (small chunks) reads back the same in both formats; and
# --fields minimal reads back with the default output's points and x, y, z, intensity sums.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --quiet --bin ringscan
bin=target/debug/ringscan
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
fail=0

check() { # name, decode args...
  local name=$1; shift
  for fmt in foxglove ros2; do
    local m="$out/$name.$fmt.mcap" j="$out/$name.$fmt.json"
    "$bin" decode "$@" --format "$fmt" --out "$m" --json > "$j"
    if tools/check_mcap.sh "$m" --expect "$j" --quiet; then
      echo "ok   $name ($fmt): $(python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); print(d["sweeps"], "sweeps,", d["points"], "points,", d["output"]["topics"])' "$j")"
    else
      echo "FAIL $name ($fmt)"; fail=1
    fi
  done
}

check_pipeline() { # name, decode args... (foxglove only: the pipeline outputs are protobuf)
  local name=$1; shift
  local m="$out/$name.pipeline.mcap" j="$out/$name.pipeline.json"
  "$bin" decode "$@" --pipeline default --out "$m" --json > "$j"
  if tools/check_mcap.sh "$m" --expect "$j" --quiet; then
    echo "ok   $name (pipeline): $(python3 -c 'import json,sys; d=json.load(open(sys.argv[1]))["pipeline"]["counts"]; print(d["ground"], "ground,", d["obstacles"], "obstacle points,", d["clusters"], "clusters")' "$j")"
  else
    echo "FAIL $name (pipeline)"; fail=1
  fi
  # The check must be able to fail: one obstacle point more in the expectation is a mismatch.
  python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); d["pipeline"]["counts"]["obstacles"]+=1; json.dump(d,open(sys.argv[2],"w"))' "$j" "$j.bad"
  if tools/check_mcap.sh "$m" --expect "$j.bad" --quiet 2>/dev/null; then
    echo "FAIL $name (pipeline): a wrong obstacle count was not caught"; fail=1
  fi
}

check_threads() { # name, decode args...: --threads 1 and 4 read back alike (Python readers)
  local name=$1; shift
  for fmt in foxglove ros2; do
    for t in 1 4; do
      local m="$out/$name.$fmt.t$t.mcap" j="$out/$name.$fmt.t$t.json"
      "$bin" decode "$@" --format "$fmt" --threads "$t" --chunk-size 0.25 --out "$m" --json > "$j"
      if ! tools/check_mcap.sh "$m" --expect "$j" > "$m.check.json"; then
        echo "FAIL $name ($fmt, --threads $t)"; fail=1
      fi
    done
    if python3 - "$out/$name.$fmt.t1.mcap.check.json" "$out/$name.$fmt.t4.mcap.check.json" <<'PY'
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
same = all(a[k] == b[k] for k in ("statistics", "channels", "messages", "point_clouds", "raw", "attachments", "totals"))
same = same and a["chunks"]["count"] == b["chunks"]["count"] and b["chunks"]["count"] > 4
sys.exit(0 if same and a["ok"] and b["ok"] else 1)
PY
    then echo "ok   $name ($fmt): --threads 1 and 4 read back alike"
    else echo "FAIL $name ($fmt): --threads 1 and 4 differ"; fail=1
    fi
  done
}

check_minimal() { # name, decode args...: --fields minimal = the default's x, y, z, intensity
  local name=$1; shift
  for fields in default minimal; do
    local m="$out/$name.$fields.mcap" j="$out/$name.$fields.json"
    "$bin" decode "$@" --fields "$fields" --out "$m" --json > "$j"
    if ! tools/check_mcap.sh "$m" --expect "$j" > "$m.check.json"; then
      echo "FAIL $name (--fields $fields)"; fail=1
    fi
  done
  if python3 - "$out/$name.default.mcap.check.json" "$out/$name.minimal.mcap.check.json" <<'PY'
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
pa = next(v for k, v in a["point_clouds"].items() if k.endswith("points"))
pb = next(v for k, v in b["point_clouds"].items() if k.endswith("points"))
ok = pb["point_stride"] == [16] and [f["name"] for f in pb["fields"]] == ["x", "y", "z", "intensity"]
ok = ok and all(pa[k] == pb[k] for k in ("messages", "points", "sum_x", "sum_y", "sum_z", "sum_intensity"))
sys.exit(0 if ok else 1)
PY
  then echo "ok   $name (--fields minimal): 16-byte records, the default's x, y, z, intensity"
  else echo "FAIL $name (--fields minimal)"; fail=1
  fi
}

check_pipeline demo-vlp16 fixtures/demo-vlp16.pcap
check_threads demo-vlp16 fixtures/demo-vlp16.pcap --raw
check_minimal demo-vlp16 fixtures/demo-vlp16.pcap

"$bin" demo --out "$out/demo.mcap" --json > "$out/demo.json"
if tools/check_mcap.sh "$out/demo.mcap" --expect "$out/demo.json" --quiet; then echo "ok   demo"; else echo "FAIL demo"; fail=1; fi

C=../shared/captures
if [ -d "$C" ]; then
  check monterey "$C/Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap" --calib "$C/ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml" --raw
  check vlp16-90deg "$C/Kitware__VeloView/Testing/Data/vlp-16-test-90deg-1-50-frames.pcap"
  check hdl32-example "$C/jerry73204__rust-lidar-utils/test_files/hdl32_example.pcap"
  check vlp16-example "$C/jerry73204__rust-lidar-utils/test_files/velodyne_example.pcap"
  check velodyne-vlp16 "$C/jerry73204__rust-lidar-utils/velodyne-test/test_files/velodyne_vlp16.pcap"
  check velodyne-vlp32 "$C/jerry73204__rust-lidar-utils/velodyne-test/test_files/velodyne_vlp32.pcap"
  check nebula-vlp16-dual "$C/tier4__nebula/src/nebula_velodyne/nebula_velodyne/test_resources/decoder_ground_truth/vlp16/1673400471837873222/1673400471837873222_0.pcap" --calib "$C/tier4__nebula/src/nebula_velodyne/nebula_velodyne_decoders/calibration/VLP16.yaml"
  check nebula-vlp32c "$C/tier4__nebula/src/nebula_velodyne/nebula_velodyne/test_resources/decoder_ground_truth/vlp32/1713492677464078412/1713492677464078412_0.pcap" --calib "$C/tier4__nebula/src/nebula_velodyne/nebula_velodyne_decoders/calibration/VLP32.yaml"
  O=$C/ouster-lidar__ouster-sdk/tests/pcaps
  check os1-32-legacy "$O/OS-1-32-G_v2.1.1_1024x10.pcap" --calib "$O/OS-1-32-G_v2.1.1_1024x10.json"
  check os0-32-dual "$O/OS-0-32-U1_v2.2.0_1024x10.pcap" --calib "$O/OS-0-32-U1_v2.2.0_1024x10.json"
  check os1-128-lowdata "$O/OS-1-128_v2.3.0_1024x10_lb_n3.pcap" --calib "$O/OS-1-128_v2.3.0_1024x10.json"
  check os1-128-fusa "$O/OS-1-128_767798045_1024x10_20230712_120049.pcap" --calib "$O/OS-1-128_767798045_1024x10_20230712_120049.json"
  check same-ports "$O/same_ports.pcap" --calib "$O/same_ports.1.json" --calib "$O/same_ports.2.json" --raw
  check crc-test "$O/crc_test.pcap" --calib "$O/crc_test.json"
  check_threads os1-128-lowdata "$O/OS-1-128_v2.3.0_1024x10_lb_n3.pcap" --calib "$O/OS-1-128_v2.3.0_1024x10.json"
  check_minimal os1-128-lowdata "$O/OS-1-128_v2.3.0_1024x10_lb_n3.pcap" --calib "$O/OS-1-128_v2.3.0_1024x10.json"
  check_pipeline monterey "$C/Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap" --calib "$C/ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml" --extrinsics hdl32e-201=0.5,0,1.9,0,0,0
  check_pipeline os2-128 "$O/OS-2-128-U1_v2.3.0_1024x10.pcap" --calib "$O/OS-2-128-U1_v2.3.0_1024x10.json"
  check_pipeline same-ports "$O/same_ports.pcap" --calib "$O/same_ports.1.json" --calib "$O/same_ports.2.json"
else
  echo "SKIP: $C is absent: real captures not decoded"
fi
exit $fail
