#!/usr/bin/env python3
"""ouster-sdk side of tools/bench_ouster.sh: decode an Ouster pcap to xyz, count pixels.

Usage: python ouster_sdk_bench.py CAPTURE.pcap META.json [--repeat N]

Exactly what the goldens were made with (../shared/captures/golden/README.md):
`ouster.sdk.pcap.PcapFrameSetSource(pcap, meta=[json])`, one LidarFrame per yielded frame set,
and `ouster.sdk.core.XYZLut(info, use_extrinsics=False)` applied to the frame's RANGE field
(float64 metres, H x W x 3). Timed: opening the source, iterating every frame, and the xyz of
every frame (a running sum of the points with range > 0 keeps the work honest). Prints one
JSON object per pass: frames, pixels (H x W per frame), points, elapsed_s, pixels_per_s.
"""

import argparse
import json
import time

import numpy as np
from ouster.sdk import core, pcap


def one_pass(path, meta):
    t0 = time.perf_counter()
    src = pcap.PcapFrameSetSource(path, meta=[meta])
    info = src.sensor_info[0]
    xyzlut = core.XYZLut(info, use_extrinsics=False)
    t_open = time.perf_counter() - t0
    frames = pixels = points = 0
    checksum = 0.0
    for frame_set in src:
        for frame in frame_set:
            if frame is None:
                continue
            rng = frame.field(core.ChanField.RANGE)
            xyz = xyzlut(rng)
            h, w = rng.shape
            frames += 1
            pixels += h * w
            points += int(np.count_nonzero(rng))
            checksum += float(xyz[h // 2, w // 2, 0])
    elapsed = time.perf_counter() - t0
    src.close()
    return {
        "tool": "ouster-sdk",
        "frames": frames,
        "pixels": pixels,
        "points": points,
        "h": info.format.pixels_per_column,
        "w": info.format.columns_per_frame,
        "open_s": t_open,
        "elapsed_s": elapsed,
        "pixels_per_s": pixels / elapsed if elapsed > 0 else 0.0,
        "checksum": checksum,
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("pcap")
    ap.add_argument("meta")
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args()
    for _ in range(a.repeat):
        print(json.dumps(one_pass(a.pcap, a.meta)), flush=True)


if __name__ == "__main__":
    main()
