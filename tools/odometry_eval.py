#!/usr/bin/env python3
"""KITTI-style relative pose errors of odometry trajectories against the simulator's truth,
and the degeneracy figures of ringscan's report.

Usage: odometry_eval.py TRUTH.tum --est NAME=FILE.tum [--est NAME=FILE.tum ...]
       [--segment 100] [--report ringscan.json --expect x,y,yaw|none] [--name NAME]

- TRUTH.tum: the simulator's `--poses-out` (world_from_sensor every 1 ms, TUM: t x y z qx qy
  qz qw, seconds on the packets' clock). Each estimated pose (stamped with its sweep's first
  firing) is compared with the truth interpolated at its stamp (linear in translation, slerp
  in rotation); both trajectories are expressed from their first pose.
- Relative errors (Geiger et al., KITTI odometry devkit): from every sweep i, the first sweep
  j whose travelled distance along the truth from i reaches SEGMENT metres; the error
  E = (Tgt_i^-1 Tgt_j)^-1 (Test_i^-1 Test_j); translation error |t(E)| / SEGMENT (in % of
  distance), rotation error angle(E) / SEGMENT (in deg per 100 m); averaged over every i that
  has such a j. Also the worst segment and the absolute end-point drift.
- --report / --expect: the share of sweeps whose degeneracy flag is set and whose named
  degenerate axes are exactly EXPECT (a comma list of x, y, z, roll, pitch, yaw), or, with
  `none`, the share of sweeps with no flag.
"""
import argparse
import json
import math
import sys

import numpy as np


def quat_to_r(q):
    x, y, z, w = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def read_tum(path):
    rows = []
    for line in open(path):
        if line.startswith("#"):
            continue
        v = line.split()
        if len(v) == 8:
            rows.append([float(x) for x in v])
    return np.array(rows)


def slerp(q0, q1, s):
    q0, q1 = q0 / np.linalg.norm(q0), q1 / np.linalg.norm(q1)
    d = float(np.dot(q0, q1))
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + s * (q1 - q0)
        return q / np.linalg.norm(q)
    th = math.acos(d)
    return (math.sin((1 - s) * th) * q0 + math.sin(s * th) * q1) / math.sin(th)


def truth_at(truth, t):
    ts = truth[:, 0]
    k = int(np.searchsorted(ts, t))
    if k <= 0 or k >= len(ts):
        if abs(t - ts[min(max(k, 0), len(ts) - 1)]) > 0.002:
            raise ValueError(f"time {t:.6f} outside the truth ({ts[0]:.6f} .. {ts[-1]:.6f})")
        k = min(max(k, 1), len(ts) - 1)
    a, b = truth[k - 1], truth[k]
    s = 0.0 if b[0] == a[0] else (t - a[0]) / (b[0] - a[0])
    m = np.eye(4)
    m[:3, 3] = a[1:4] + s * (b[1:4] - a[1:4])
    m[:3, :3] = quat_to_r(slerp(a[4:8], b[4:8], s))
    return m


def to_mats(rows):
    out = []
    for r in rows:
        m = np.eye(4)
        m[:3, 3] = r[1:4]
        m[:3, :3] = quat_to_r(r[4:8])
        out.append(m)
    return out


def angle_deg(r):
    return math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(r) - 1) / 2))))


def relative_errors(gt, est, segment):
    dist = [0.0]
    for a, b in zip(gt[:-1], gt[1:]):
        dist.append(dist[-1] + np.linalg.norm(b[:3, 3] - a[:3, 3]))
    errs = []
    for i in range(len(gt)):
        j = next((k for k in range(i, len(gt)) if dist[k] - dist[i] >= segment), None)
        if j is None:
            break
        dg = np.linalg.inv(gt[i]) @ gt[j]
        de = np.linalg.inv(est[i]) @ est[j]
        e = np.linalg.inv(dg) @ de
        errs.append((np.linalg.norm(e[:3, 3]) / segment, angle_deg(e[:3, :3]) / segment))
    return np.array(errs), dist[-1]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("truth")
    ap.add_argument("--est", action="append", default=[])
    ap.add_argument("--segment", type=float, default=100.0)
    ap.add_argument("--report")
    ap.add_argument("--expect")
    ap.add_argument("--name", default="")
    a = ap.parse_args()
    truth = read_tum(a.truth)
    print(f"== {a.name}: truth {a.truth} ({len(truth)} poses, {truth[-1,0]-truth[0,0]:.1f} s)")
    results = {}
    for spec in a.est:
        name, path = spec.split("=", 1)
        rows = read_tum(path)
        est = to_mats(rows)
        gt = [truth_at(truth, r[0]) for r in rows]
        g0, e0 = np.linalg.inv(gt[0]), np.linalg.inv(est[0])
        gt = [g0 @ g for g in gt]
        est = [e0 @ e for e in est]
        errs, length = relative_errors(gt, est, a.segment)
        end = np.linalg.inv(gt[-1]) @ est[-1]
        if len(errs) == 0:
            print(f"{name:10s}: {len(rows)} sweeps, path {length:.1f} m: shorter than one {a.segment:.0f} m segment")
            results[name] = None
            continue
        t_pct, r_deg100 = 100 * errs[:, 0].mean(), 100 * errs[:, 1].mean()
        results[name] = (t_pct, r_deg100)
        print(
            f"{name:10s}: {len(rows)} sweeps, path {length:.1f} m, {len(errs)} segments of {a.segment:.0f} m: "
            f"translation {t_pct:.3f} % (worst {100*errs[:,0].max():.3f} %), "
            f"rotation {r_deg100:.4f} deg/100 m (worst {100*errs[:,1].max():.4f}); "
            f"end drift {np.linalg.norm(end[:3,3]):.3f} m, {angle_deg(end[:3,:3]):.3f} deg"
        )
    for name, res in results.items():
        if res is not None:
            ok = res[0] <= 0.5 and res[1] <= 0.1
            print(f"{name:10s}: targets 0.5 % and 0.1 deg/100 m: {'MET' if ok else 'MISSED'}")
    if a.report:
        rep = json.load(open(a.report))["sweeps"]
        rows = [r for r in rep if r["status"] != "initialized"]
        flagged = sum(1 for r in rows if r["degenerate"])
        if a.expect and a.expect != "none":
            named = sum(1 for r in rows if r["degenerate"] and r["degeneracy"] and r["degeneracy"]["axes"] == a.expect)
            share = named / max(1, len(rows))
            print(
                f"degeneracy: {flagged}/{len(rows)} registered sweeps flagged, {named} named exactly '{a.expect}' "
                f"({100*share:.1f} %; target >= 95 %: {'MET' if share >= 0.95 else 'MISSED'})"
            )
        else:
            share = 1 - flagged / max(1, len(rows))
            print(
                f"degeneracy: {flagged}/{len(rows)} registered sweeps flagged "
                f"({100*share:.1f} % unflagged; target: no flag: {'MET' if flagged == 0 else 'MISSED'})"
            )
        ev = [r["degeneracy"]["eigenvalues"][0] for r in rows if r["degeneracy"]]
        if ev:
            print(f"smallest normalised eigenvalue: min {min(ev):.2e}, median {np.median(ev):.2e}, max {max(ev):.2e}")


if __name__ == "__main__":
    sys.exit(main())
