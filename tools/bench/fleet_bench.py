#!/usr/bin/env python3
"""Runner of tools/bench_fleet.sh (must-show 4): 16 Velodyne captures of >= 50 MB each (made by
tools/make_big_capture.py, each from a different real capture where there are several) and one
corrupt capture, decoded to Parquet (one row per point) by ringscan.fleet on a local Ray
instance with 1 and then 2 worker CPUs (one task per capture, one decoding thread per task).

Checks: the summary tables of the two runs are equal (timings and paths aside), the corrupt
capture is a row with its error and the {len(made)} others complete, every capture's Parquet tables of
the two runs are equal once sorted. Times: from the first task submitted to the table (Ray's
start-up and a warm-up task excluded). Prints one JSON line per run and a Markdown table.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
CAPS = os.environ.get("RINGSCAN_CAPTURES") or os.path.join(ROOT, "..", "shared", "captures")
SOURCES = [
    ("Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap", "hdl32e", "ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml"),
    ("jerry73204__rust-lidar-utils/test_files/hdl32_example.pcap", "hdl32e", "ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml"),
]


def run(workers, captures, out, options):
    import ray
    from ringscan import fleet

    ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    try:
        # Warm-up: Ray Data's executor and one worker process, not timed.
        ray.data.from_items([1]).map(lambda r: r).take_all()
        t0 = time.perf_counter()
        table = fleet.decode_ray(captures, out, options=options)
        elapsed = time.perf_counter() - t0
    finally:
        ray.shutdown()
    return table, elapsed


def sorted_table(path):
    import pyarrow.parquet as pq

    t = pq.read_table(path)
    t = t.cast(t.schema.set(0, t.schema.field(0).with_type(__import__("pyarrow").string())))
    return t.sort_by([(c, "ascending") for c in t.column_names])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--captures", type=int, default=16)
    ap.add_argument("--mb", type=float, default=50)
    ap.add_argument("--dir", required=True)
    ap.add_argument("--report", required=True)
    a = ap.parse_args()
    os.makedirs(a.dir, exist_ok=True)
    inputs = os.path.join(a.dir, "inputs")
    os.makedirs(inputs, exist_ok=True)
    made = []
    for i in range(a.captures):
        rel, _model, _calib = SOURCES[i % len(SOURCES)]
        p = os.path.join(inputs, f"cap{i:02d}.pcap")
        if i < len(SOURCES):
            subprocess.run([sys.executable, os.path.join(ROOT, "tools/make_big_capture.py"), "--in", os.path.join(CAPS, rel), "--out", p, "--mb", str(a.mb), "--quiet"], check=True)
        else:
            shutil.copyfile(made[i % len(SOURCES)], p)
        made.append(p)
    corrupt = os.path.join(inputs, "corrupt.pcap")
    with open(made[0], "rb") as f:
        head = f.read(5_000_000)
    with open(corrupt, "wb") as f:
        # A valid header and records, then a record that claims a gigabyte: a hard error.
        f.write(head[:24] + b"\x00" * 8 + (1_000_000_000).to_bytes(4, "little") * 2 + head[40:])
    captures = made + [corrupt]
    options = {"model": "hdl32e", "calib": [os.path.join(CAPS, SOURCES[0][2])]}
    load0 = open("/proc/loadavg").read().split()[:3]
    runs = {}
    for workers in (1, 2):
        out = os.path.join(a.dir, f"out-{workers}")
        shutil.rmtree(out, ignore_errors=True)
        table, elapsed = run(workers, captures, out, options)
        rows = table.to_pylist()
        runs[workers] = (rows, elapsed)
        pts = sum(r["points"] or 0 for r in rows)
        print(json.dumps({"workers": workers, "elapsed_s": elapsed, "points": pts, "load": open("/proc/loadavg").read().split()[:3]}), flush=True)
    load1 = open("/proc/loadavg").read().split()[:3]
    drop = {"decode_s", "parquet", "mcap"}
    same_summary = [{k: v for k, v in r.items() if k not in drop} for r in runs[1][0]] == [
        {k: v for k, v in r.items() if k not in drop} for r in runs[2][0]
    ]
    status = {r["capture"]: r for r in runs[2][0]}
    corrupt_row = status[corrupt]
    others_ok = all(status[c]["status"] == "ok" for c in made)
    same_points = True
    for r1, r2 in zip(runs[1][0], runs[2][0]):
        if r1["status"] == "ok":
            same_points &= sorted_table(r1["parquet"]).equals(sorted_table(r2["parquet"]))
    total_mb = sum(os.path.getsize(c) for c in made) / 1e6
    t1, t2 = runs[1][1], runs[2][1]
    text = "\n".join(
        [
            f"Load average at start {' '.join(load0)}, at end {' '.join(load1)}.",
            "",
            "| Ray workers (local) | captures | MB | points | s (Ray start-up excluded) | MB/s | speed-up |",
            "|---|---|---|---|---|---|---|",
            f"| 1 | {len(captures)} ({len(made)} + 1 corrupt) | {total_mb:.0f} | {sum(r['points'] or 0 for r in runs[1][0])} | {t1:.1f} | {total_mb / t1:.0f} | 1.00x |",
            f"| 2 | {len(captures)} ({len(made)} + 1 corrupt) | {total_mb:.0f} | {sum(r['points'] or 0 for r in runs[2][0])} | {t2:.1f} | {total_mb / t2:.0f} | {t1 / t2:.2f}x |",
            "",
            f"Same summary tables: {same_summary}; same Parquet tables (sorted): {same_points}; "
            f"the {len(made)} others complete: {others_ok}; corrupt capture reported: {corrupt_row['status']} "
            f"({corrupt_row['error_type']}: {corrupt_row['error']}).",
        ]
    )
    open(a.report, "w").write(text + "\n")
    print(text)
    shutil.rmtree(a.dir, ignore_errors=True)
    ok = same_summary and same_points and others_ok and corrupt_row["status"] == "error"
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
