#!/usr/bin/env bash
# ouster-sdk 1.0.1's reading of the zone-monitor packet of the real capture
# ouster-lidar__ouster-sdk/tests/pcaps/imu_zm_no_lidar.pcap, as JSON in the shape of ringscan's
# `/zones` messages: the reference the zone values in tests/ouster_stream.rs and
# tests/ouster_cli.rs were taken from (each key renamed to ringscan's: `*_range` → `*_range_mm`).
# Makes tools/.venv-ouster-zones (git-ignored) on first use.
#
#   tools/ouster_zone_reference.sh
set -euo pipefail
cd "$(dirname "$0")/.."
venv=tools/.venv-ouster-zones
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet ouster-sdk==1.0.1
fi
P=../shared/captures/ouster-lidar__ouster-sdk/tests/pcaps
"$venv/bin/python" - "$P/imu_zm_no_lidar.pcap" "$P/imu_zm_no_lidar_0.json" <<'PY'
import json, sys
from ouster.sdk import pcap

pcap_path, meta = sys.argv[1:3]
out = []
for frames in pcap.PcapFrameSetSource(pcap_path, meta=[meta]):
    for f in frames:
        if f is None or not f.has_field("ZONE_STATES"):
            continue
        rename = {"min_range": "min_range_mm", "max_range": "max_range_mm",
                  "mean_range": "mean_range_mm"}
        zones = []
        for z in f.field("ZONE_STATES"):
            d = {rename.get(k, k): int(z[k]) for k in z.dtype.names}
            d["live"] = bool(d["live"])
            zones.append(d)
        out.append({
            "timestamp_ns": int(f.field("ZONE_TIMESTAMP")[0]),
            "frame_id": int(f.frame_id),
            "alert_flags": int(f.field("ZONE_ALERT_FLAGS")[0]),
            "live_zoneset_hash": bytes(f.field("LIVE_ZONESET_HASH")).hex(),
            "zones": zones,
        })
print(json.dumps(out, indent=1, sort_keys=True))
PY
