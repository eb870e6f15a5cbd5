#!/usr/bin/env python3
"""Runner of tools/bench_python.sh: the Python package against velodyne_decoder and ouster-sdk,
side by side in one run, each tool in a process of its own (its peak RSS from wait4).

    python python_bench.py --vel-mb 200 --ouster-frames 120 --rounds 3 --dir DIR --report R.md

Velodyne: a ~200 MB HDL-32E pcap (tools/make_big_capture.py from the Monterey capture) read to
NumPy by `ringscan.open` (sweeps, `.points`), by `ringscan.compat.read_pcap` and by
velodyne_decoder 3.1.0's `read_pcap` (N x 8 arrays), range filters off in all three (every
non-zero distance is a point: the point counts must agree). Ouster: an OS-2-128 capture
(tools/make_big_ouster_capture.py) read by `ringscan.open(calib=meta)` and by ouster-sdk 1.0.1's
`open_source` + `XYZLut` on every frame (tools/bench/ouster_sdk_bench.py's loop). Peak memory
flat in capture size: ringscan.open on a quarter-size Velodyne capture too.

Timed inside each child, from the open call to the last array (interpreter start-up and imports
excluded, and the SETTLE_S after them: importing numpy starts OpenBLAS's worker threads, which
spin for ~0.1 s (perf: `blas_thread_server`) on whichever core is free, so a tool timed at
once shares a core with them); rounds alternate between tools; the best and median rounds are reported. Each round
runs every tool pinned to one core (`--pin`) and again free to use every core: ringscan.open
reads the capture on a thread of its own (`read_ahead`), which only a second core can overlap
with the decoding; the references use one thread either way.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
CAPS = os.environ.get("RINGSCAN_CAPTURES") or os.path.join(ROOT, "..", "shared", "captures")
VEL_IN = os.path.join(CAPS, "Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap")
VEL_CALIB = os.path.join(CAPS, "ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml")
OS_IN = os.path.join(CAPS, "ouster-lidar__ouster-sdk/tests/pcaps/OS-2-128-U1_v2.3.0_1024x10.pcap")
OS_META = os.path.join(CAPS, "ouster-lidar__ouster-sdk/tests/pcaps/OS-2-128-U1_v2.3.0_1024x10.json")

READ_PCAP = r"""
import json, sys, time, MODULE as vd
path, calib = sys.argv[1], sys.argv[2]
cfg = vd.Config(model=vd.Model.HDL32E, calibration=vd.Calibration.read(calib), min_range=0.0, max_range=1000.0)
time.sleep(SETTLE_S)
t0 = time.perf_counter()
frames = points = 0; check = 0.0
for stamp, p in vd.read_pcap(path, cfg):
    frames += 1; points += len(p)
    if len(p): check += float(p[len(p) // 2, 0])
print(json.dumps({"frames": frames, "points": points, "elapsed_s": time.perf_counter() - t0, "check": check}))
"""

# BENCH_SETTLE_S=0 measures without the pause (its effect is in BENCHMARKS.md).
SETTLE = f"SETTLE_S = {float(os.environ.get('BENCH_SETTLE_S', '0.5'))}\n"

CHILD = {
    "ringscan.open": r"""
import json, sys, time, numpy as np, ringscan
path, calib = sys.argv[1], sys.argv[2]
time.sleep(SETTLE_S)
t0 = time.perf_counter()
frames = points = 0; check = 0.0
for s in ringscan.open(path, calib=calib, min_range=0.0, max_range=1000.0):
    p = s.points
    frames += 1; points += len(p)
    if len(p): check += float(p["x"][len(p) // 2])
print(json.dumps({"frames": frames, "points": points, "elapsed_s": time.perf_counter() - t0, "check": check}))
""",
    # The same script for both: the compat module is velodyne_decoder's drop-in.
    "ringscan.compat.read_pcap": READ_PCAP.replace("MODULE", "ringscan.compat"),
    "velodyne_decoder.read_pcap": READ_PCAP.replace("MODULE", "velodyne_decoder"),
    "ringscan.open (Ouster)": r"""
import json, sys, time, numpy as np, ringscan
path, meta = sys.argv[1], sys.argv[2]
time.sleep(SETTLE_S)
t0 = time.perf_counter()
frames = points = 0; check = 0.0
for s in ringscan.open(path, calib=meta):
    p = s.points
    frames += 1; points += len(p)
    if len(p): check += float(p["x"][len(p) // 2])
print(json.dumps({"frames": frames, "points": points, "elapsed_s": time.perf_counter() - t0, "check": check}))
""",
    "ouster-sdk open_source + XYZLut": r"""
import json, sys, time, numpy as np
from ouster.sdk import open_source, core
path, meta = sys.argv[1], sys.argv[2]
time.sleep(SETTLE_S)
t0 = time.perf_counter()
src = open_source(path, meta=[meta])
info = src.sensor_info[0]
lut = core.XYZLut(info, use_extrinsics=False)
frames = points = 0; check = 0.0
for scans in src:
    # ouster-sdk 1.0: a FrameSet (the frames of every sensor) per step.
    for scan in scans:
        if scan is None:
            continue
        rng = scan.field(core.ChanField.RANGE)
        xyz = lut(rng)
        frames += 1; points += int(np.count_nonzero(rng))
        check += float(xyz[xyz.shape[0] // 2, xyz.shape[1] // 2, 0])
print(json.dumps({"frames": frames, "points": points, "elapsed_s": time.perf_counter() - t0, "check": check}))
""",
}


def run_child(python, tool, path, extra, pin):
    cmd = (pin.split() if pin else []) + [python, "-c", SETTLE + CHILD[tool], path, extra]
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _pid, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    out, err = p.stdout.read(), p.stderr.read()
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise SystemExit(f"{tool} failed ({p.returncode}): {err[-3000:]}")
    j = json.loads(out.strip().splitlines()[-1])
    j.update(tool=tool, wall_s=wall, peak_rss_mb=ru.ru_maxrss / 1024.0, bytes=os.path.getsize(path))
    return j


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--python", default=sys.executable, help="the venv's interpreter")
    ap.add_argument("--vel-mb", type=float, default=200)
    ap.add_argument("--ouster-frames", type=int, default=120)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--dir", required=True)
    ap.add_argument("--pin", default="")
    ap.add_argument("--report", required=True)
    a = ap.parse_args()
    os.makedirs(a.dir, exist_ok=True)
    vel = os.path.join(a.dir, "vel-big.pcap")
    vel_small = os.path.join(a.dir, "vel-quarter.pcap")
    ost = os.path.join(a.dir, "ouster-big.pcap")
    gen = lambda *args: subprocess.run([sys.executable, *args], check=True, stdout=subprocess.DEVNULL)  # noqa: E731
    gen(os.path.join(ROOT, "tools/make_big_capture.py"), "--in", VEL_IN, "--out", vel, "--mb", str(a.vel_mb), "--quiet")
    gen(os.path.join(ROOT, "tools/make_big_capture.py"), "--in", VEL_IN, "--out", vel_small, "--mb", str(a.vel_mb / 4), "--quiet")
    gen(os.path.join(ROOT, "tools/make_big_ouster_capture.py"), "--in", OS_IN, "--meta", OS_META, "--frames", str(a.ouster_frames), "--out", ost)
    load = open("/proc/loadavg").read().split()[:3]
    plan = [
        ("velodyne", "ringscan.open", vel, VEL_CALIB),
        ("velodyne", "ringscan.compat.read_pcap", vel, VEL_CALIB),
        ("velodyne", "velodyne_decoder.read_pcap", vel, VEL_CALIB),
        ("velodyne-quarter", "ringscan.open", vel_small, VEL_CALIB),
        ("ouster", "ringscan.open (Ouster)", ost, OS_META),
        ("ouster", "ouster-sdk open_source + XYZLut", ost, OS_META),
    ]
    # Every tool pinned to one core (`--pin`), then free to use the machine's cores: ringscan
    # reads the capture on a thread of its own beside the decoding (`read_ahead`), which only
    # a second core can run at the same time; the references keep to one thread either way.
    modes = [("one core", a.pin)] if a.pin else []
    modes.append((f"{os.cpu_count()} cores", ""))
    results = {}
    for r in range(a.rounds):
        for mode, pin in modes:
            for case, tool, path, extra in plan:
                j = run_child(a.python, tool, path, extra, pin)
                j.update(case=case, round=r, mode=mode)
                print(json.dumps(j), file=sys.stderr, flush=True)
                results.setdefault((mode, case, tool), []).append(j)
    load_end = open("/proc/loadavg").read().split()[:3]

    def best(mode, case, tool):
        return min(x["elapsed_s"] for x in results[(mode, case, tool)])

    def median(mode, case, tool):
        return statistics.median(x["elapsed_s"] for x in results[(mode, case, tool)])

    lines = [
        f"Load average at start {' '.join(load)}, at end {' '.join(load_end)}; {a.rounds} alternating rounds; "
        f"pin: {a.pin or 'none'}.",
        "",
        "| cores | input | tool | MB | frames | points | best s | median s | MB/s (best) | peak RSS MB | vs reference (best; median) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    ref = {"velodyne": "velodyne_decoder.read_pcap", "velodyne-quarter": "velodyne_decoder.read_pcap", "ouster": "ouster-sdk open_source + XYZLut"}
    for mode, _ in modes:
        for case, tool, path, _ in plan:
            rs = results[(mode, case, tool)]
            b = best(mode, case, tool)
            med = median(mode, case, tool)
            rref = ref[case]
            if case == "velodyne-quarter":
                vs = "(peak memory at a quarter of the size)"
            elif tool == rref:
                vs = "reference"
            else:
                vs = (f"{best(mode, case, rref) / b:.2f}x; "
                      f"{median(mode, case, rref) / med:.2f}x faster")
            mb = rs[0]["bytes"] / 1e6
            lines.append(
                f"| {mode} | {case} | {tool} | {mb:.0f} | {rs[0]['frames']} | {rs[0]['points']} | {b:.3f} | {med:.3f} | "
                f"{mb / b:.0f} | {max(x['peak_rss_mb'] for x in rs):.0f} | {vs} |"
            )
    pts = {k[1:]: v[0]["points"] for k, v in results.items() if k[0] == modes[0][0]}
    lines += ["", "Point counts agree (velodyne): " + str(len({pts[("velodyne", t)] for t in ("ringscan.open", "ringscan.compat.read_pcap", "velodyne_decoder.read_pcap")}) == 1)]
    text = "\n".join(lines) + "\n"
    open(a.report, "w").write(text)
    print(text)
    for f in (vel, vel_small, ost):
        os.remove(f)


if __name__ == "__main__":
    main()
