#!/usr/bin/env python3
"""KISS-ICP on the sweeps ringscan's odometry saw, and the comparison of the two trajectories.

Usage: odometry_kiss.py SWEEPS.bin RINGSCAN.tum RINGSCAN_REPORT.json [--max-range 100]
       [--repeat 5] [--out-tum kiss.tum]

- SWEEPS.bin: the dump of `cargo run --release --example odometry -- --dump` (per sweep: i64
  stamp_ns, u64 n, n records of float32 x, y, z and uint32 t, ns after the sweep's stamp).
- --deskew: KISS-ICP gets each point's time (s) and deskews itself (data.deskew = True; it
  refers each sweep to its last point, so its poses are stamped stamp + max t). Without it,
  no per-point times are given and data.deskew = False.
- KISS-ICP (PyPI kiss-icp) runs its own pipeline (kiss_icp.kiss_icp.KissICP.register_frame) on
  the same points, converted to float64 as ringscan does, with its default configuration except
  data.deskew = False (no per-point times are given to either side), data.max_range as given
  (the voxel size follows, max_range / 100) and registration.max_num_threads = 1. The shell
  wrapper also sets OMP_NUM_THREADS=1. Single thread on both sides.
- Time per sweep: register_frame (range filter, subsampling, ICP, map update), median over
  --repeat runs of the whole sequence on fresh pipelines; ringscan's report holds its own
  median the same way.
- Agreement per sweep: T_kiss^-1 * T_ringscan, translation (cm) and rotation (deg).
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np


def read_sweeps(path):
    data = open(path, "rb").read()
    out, at = [], 0
    while at < len(data):
        stamp, n = np.frombuffer(data, dtype="<i8", count=1, offset=at)[0], np.frombuffer(
            data, dtype="<u8", count=1, offset=at + 8
        )[0]
        at += 16
        rec = np.frombuffer(data, dtype=[("xyz", "<f4", 3), ("t", "<u4")], count=int(n), offset=at)
        at += int(n) * 16
        out.append((int(stamp), rec["xyz"].astype(np.float64), rec["t"].astype(np.float64) * 1e-9))
    return out


def read_tum(path):
    poses = []
    for line in open(path):
        v = [float(x) for x in line.split()]
        if len(v) != 8:
            continue
        t, (x, y, z), (qx, qy, qz, qw) = v[0], v[1:4], v[4:8]
        poses.append((t, to_matrix(np.array([x, y, z]), np.array([qx, qy, qz, qw]))))
    return poses


def to_matrix(t, q):
    x, y, z, w = q / np.linalg.norm(q)
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = r, t
    return m


def to_quat(r):
    w = math.sqrt(max(0.0, 1 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
    return x, y, z, w


def rot_deg(r):
    c = (np.trace(r) - 1) / 2
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def run_kiss(sweeps, max_range, repeat, deskew=False):
    from kiss_icp.config import KISSConfig
    from kiss_icp.kiss_icp import KissICP

    cfg = KISSConfig()
    cfg.data.deskew = deskew
    cfg.data.max_range = max_range
    cfg.mapping.voxel_size = max_range / 100.0
    cfg.registration.max_num_threads = 1
    times = [[] for _ in sweeps]
    poses = None
    for _ in range(max(1, repeat)):
        kiss = KissICP(cfg)
        run = []
        for i, (_, pts, t) in enumerate(sweeps):
            ts = t if deskew else np.array([], dtype=np.float64)
            t0 = time.perf_counter()
            kiss.register_frame(pts, ts)
            times[i].append((time.perf_counter() - t0) * 1e3)
            run.append(kiss.last_pose.copy())
        if poses is None:
            poses = run
    return poses, [float(np.median(t)) for t in times], cfg


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("sweeps")
    ap.add_argument("ringscan_tum")
    ap.add_argument("ringscan_report")
    ap.add_argument("--max-range", type=float, default=100.0)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out-tum")
    ap.add_argument("--name", default="")
    ap.add_argument("--deskew", action="store_true")
    a = ap.parse_args()

    sweeps = read_sweeps(a.sweeps)
    ours = read_tum(a.ringscan_tum)
    report = json.load(open(a.ringscan_report))["sweeps"]
    if len(ours) != len(sweeps) or len(report) != len(sweeps):
        sys.exit(f"{len(sweeps)} sweeps but {len(ours)} ringscan poses / {len(report)} report rows")
    kiss_poses, kiss_ms, cfg = run_kiss(sweeps, a.max_range, a.repeat, a.deskew)
    if a.out_tum:
        with open(a.out_tum, "w") as f:
            for (stamp, _, t), m in zip(sweeps, kiss_poses):
                qx, qy, qz, qw = to_quat(m[:3, :3])
                when = stamp * 1e-9 + (float(t.max()) if a.deskew and len(t) else 0.0)
                f.write(f"{when:.9f} {m[0,3]:.9f} {m[1,3]:.9f} {m[2,3]:.9f} {qx:.9f} {qy:.9f} {qz:.9f} {qw:.9f}\n")

    import kiss_icp

    print(f"== {a.name}: {len(sweeps)} sweeps, {np.mean([len(p) for _, p, _ in sweeps]):.0f} points per sweep")
    print(
        f"KISS-ICP {getattr(kiss_icp, '__version__', '?')}: deskew={cfg.data.deskew} max_range={cfg.data.max_range} "
        f"voxel={cfg.mapping.voxel_size} max_points_per_voxel={cfg.mapping.max_points_per_voxel} "
        f"max_num_threads={cfg.registration.max_num_threads} OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}"
    )
    print(" sweep  points  ringscan_status        dt_cm   drot_deg   ringscan_ms  kiss_ms   path_m")
    worst_t, worst_r = 0.0, 0.0
    path = 0.0
    prev = None
    for i, ((_, m_ours), m_kiss, row) in enumerate(zip(ours, kiss_poses, report)):
        d = np.linalg.inv(m_kiss) @ m_ours
        dt, dr = np.linalg.norm(d[:3, 3]) * 100, rot_deg(d[:3, :3])
        worst_t, worst_r = max(worst_t, dt), max(worst_r, dr)
        if prev is not None:
            path += np.linalg.norm(m_kiss[:3, 3] - prev[:3, 3])
        prev = m_kiss
        print(
            f"{i:6d} {len(sweeps[i][1]):7d}  {row['status'][:20]:20s} {dt:7.2f} {dr:9.4f} {row['ms']:12.3f} {kiss_ms[i]:8.3f} {path:8.2f}"
        )
    r_ms = [r["ms"] for r in report]
    print(
        f"worst disagreement: {worst_t:.3g} cm, {worst_r:.3g} deg (bounds 5 cm, 0.5 deg): "
        f"{'MET' if worst_t <= 5 and worst_r <= 0.5 else 'MISSED'}"
    )
    print(
        f"ms per sweep (mean of per-sweep medians over {a.repeat} runs): ringscan {np.mean(r_ms):.3f}, "
        f"KISS-ICP {np.mean(kiss_ms):.3f}, ratio KISS/ringscan {np.mean(kiss_ms) / np.mean(r_ms):.2f}x; "
        f"medians {np.median(r_ms):.3f} / {np.median(kiss_ms):.3f}"
    )


if __name__ == "__main__":
    main()
