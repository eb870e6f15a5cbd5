#!/usr/bin/env python3
"""velodyne_decoder side of tools/bench_velodyne.sh: one JSON object per measurement on stdout.

    python vd_bench.py read_pcap   CAPTURE MODEL CALIB
    python vd_bench.py in_memory   CAPTURE MODEL CALIB [--repeat N]

MODEL is a velodyne_decoder Model name (HDL32E, VLP16, ...); CALIB a calibration file
(velodyne_decoder reads the ROS yaml). Range filters are disabled as in the goldens
(min_range 0, max_range 1000 m, full azimuth): every non-zero distance is a point, so the point
counts must equal ringscan's.

read_pcap: the whole `velodyne_decoder.read_pcap(path, config)` loop (dpkt parsing + the C++
StreamDecoder + the numpy arrays it returns), wall time from the call to the last scan.

in_memory: the 1206-byte payloads and their pcap times are loaded first (not timed). Then, timed:
  * stream_decoder: `StreamDecoder(config).decode(stamp, payload)` for every payload held in a
    Python list, plus `finish()` (the per-packet Python call and the bytes -> C++ conversion are
    part of it);
  * scan_decoder: the C++ core alone. Payloads are converted to `VelodynePacket`s and grouped into
    one `PacketVector` per rotation (a group ends after the packet whose block-0 azimuth wraps past
    the group's first azimuth) before timing; only `ScanDecoder(config).decode(packets)` per group
    is timed (it decodes the packets and returns the scan as a numpy array).
Each is run --repeat times; the best run is reported (and every run's time).
"""

import json
import struct
import sys
import time

import dpkt
import velodyne_decoder as vd


def config(model, calib):
    return vd.Config(
        model=getattr(vd.Model, model),
        calibration=vd.Calibration.read(calib),
        min_range=0.0,
        max_range=1000.0,
    )


def read_pcap(path, model, calib):
    cfg = config(model, calib)
    t0 = time.perf_counter()
    points = 0
    scans = 0
    for _stamp, pts in vd.read_pcap(path, cfg):
        points += len(pts)
        scans += 1
    wall = time.perf_counter() - t0
    return {"what": "vd_read_pcap", "points": points, "scans": scans, "wall_s": wall, "points_per_s": points / wall}


def load_payloads(path):
    out = []
    with open(path, "rb") as f:
        for stamp, buf in dpkt.pcap.Reader(f):
            try:
                data = dpkt.ethernet.Ethernet(buf)
            except dpkt.dpkt.UnpackError:
                continue
            while hasattr(data, "data"):
                data = data.data
            if len(data) == vd.PACKET_SIZE:
                out.append((stamp, bytes(data)))
    return out


def groups_by_rotation(payloads):
    """Lists of indices, one per rotation (ends after the packet whose block-0 azimuth wraps)."""
    groups = []
    cur = []
    start = None
    covered = 0
    prev = None
    for i, (_s, p) in enumerate(payloads):
        az = struct.unpack_from("<H", p, 2)[0]
        if start is None:
            start = az
        if prev is not None:
            covered += (az - prev) % 36000
        prev = az
        cur.append(i)
        if covered >= 36000 - 1:
            groups.append(cur)
            cur = []
            start = None
            covered = 0
            prev = None
    if cur:
        groups.append(cur)
    return groups


def in_memory(path, model, calib, repeat):
    t0 = time.perf_counter()
    payloads = load_payloads(path)
    load_s = time.perf_counter() - t0
    results = []

    # StreamDecoder, per packet, from a list of (stamp, bytes).
    runs = []
    points = 0
    for _ in range(repeat):
        dec = vd.StreamDecoder(config(model, calib))
        points = 0
        t0 = time.perf_counter()
        for stamp, p in payloads:
            r = dec.decode(stamp, p)
            if r is not None:
                points += len(r[1])
        r = dec.finish()
        if r is not None:
            points += len(r[1])
        runs.append(time.perf_counter() - t0)
    best = min(runs)
    results.append({
        "what": "vd_stream_decoder_in_memory", "points": points, "packets": len(payloads),
        "wall_s": best, "runs_s": runs, "points_per_s": points / best, "load_s": load_s,
    })

    # ScanDecoder on PacketVectors built beforehand: the C++ decode loop alone.
    t0 = time.perf_counter()
    vectors = []
    for g in groups_by_rotation(payloads):
        pv = vd.PacketVector()
        for i in g:
            stamp, p = payloads[i]
            pv.append(vd.VelodynePacket(stamp, p))
        vectors.append(pv)
    prep_s = time.perf_counter() - t0
    runs = []
    for _ in range(repeat):
        dec = vd.ScanDecoder(config(model, calib))
        points = 0
        t0 = time.perf_counter()
        for pv in vectors:
            _stamp, pts = dec.decode(pv)
            points += len(pts)
        runs.append(time.perf_counter() - t0)
    best = min(runs)
    results.append({
        "what": "vd_scan_decoder_in_memory", "points": points, "packets": len(payloads),
        "scans": len(vectors), "wall_s": best, "runs_s": runs, "points_per_s": points / best,
        "prepare_s": prep_s,
    })
    return results


def main():
    argv = sys.argv[1:]
    repeat = 3
    if "--repeat" in argv:
        i = argv.index("--repeat")
        repeat = int(argv[i + 1])
        del argv[i : i + 2]
    if len(argv) != 4 or argv[0] not in ("read_pcap", "in_memory"):
        sys.exit(__doc__)
    cmd, path, model, calib = argv
    if cmd == "read_pcap":
        print(json.dumps(read_pcap(path, model, calib)))
    else:
        for r in in_memory(path, model, calib, repeat):
            print(json.dumps(r))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
