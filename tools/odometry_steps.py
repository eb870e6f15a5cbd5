#!/usr/bin/env python3
"""Per-sweep errors of an odometry trajectory against the simulator's truth: for each pair of
consecutive poses, the true motion between their stamps against the estimated one, and the
absolute rotation error (the estimate aligned to the truth at its first pose), roll / pitch /
yaw in degrees, in the sensor frame. Used to find where the KITTI-style errors of
tools/odometry_eval.py come from (BENCHMARKS.md "Odometry").

Usage: odometry_steps.py TRUTH.tum EST.tum [FIRST LAST]   (sweep indices, default all)
Run with the virtual environment tools/odometry_eval.sh makes (numpy):
    tools/.venv-kiss/bin/python tools/odometry_steps.py target/odometry-eval/urban.truth.tum \
        target/odometry-eval/urban.p2l.tum 60 95
"""
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import odometry_eval as ev  # noqa: E402


def main():
    truth = ev.read_tum(sys.argv[1])
    est = ev.read_tum(sys.argv[2])

    def at(t):
        i = int(np.searchsorted(truth[:, 0], t))
        i = min(max(i, 1), len(truth) - 1)
        a, b = truth[i - 1], truth[i]
        s = (t - a[0]) / (b[0] - a[0])
        m = np.eye(4)
        m[:3, 3] = a[1:4] + s * (b[1:4] - a[1:4])
        m[:3, :3] = ev.quat_to_r(ev.slerp(a[4:8], b[4:8], s))
        return m

    def pose(r):
        m = np.eye(4)
        m[:3, 3] = r[1:4]
        m[:3, :3] = ev.quat_to_r(r[4:8])
        return m

    def rpy(r):
        return np.degrees(
            [
                math.atan2(r[2, 1], r[2, 2]),
                -math.asin(max(-1.0, min(1.0, r[2, 0]))),
                math.atan2(r[1, 0], r[0, 0]),
            ]
        )

    g = [at(r[0]) for r in est]
    e = [pose(r) for r in est]
    align = g[0] @ np.linalg.inv(e[0])
    lo = int(sys.argv[3]) if len(sys.argv) > 3 else 1
    hi = int(sys.argv[4]) if len(sys.argv) > 4 else len(est)
    print("sweep  speed m/s  yaw rate deg/s  step error roll/pitch/yaw deg  abs error roll/pitch/yaw deg  step error xyz cm")
    for k in range(max(lo, 1), min(hi, len(est))):
        dg = np.linalg.inv(g[k - 1]) @ g[k]
        de = np.linalg.inv(e[k - 1]) @ e[k]
        dt = est[k, 0] - est[k - 1, 0]
        err = np.linalg.inv(dg) @ de
        ab = np.linalg.inv(g[k]) @ align @ e[k]
        print(
            f"{k:5d} {np.linalg.norm(dg[:3, 3]) / dt:9.1f} {rpy(dg[:3, :3])[2] / dt:14.2f}  "
            f"{np.array2string(rpy(err[:3, :3]), precision=4):>30}  "
            f"{np.array2string(rpy(ab[:3, :3]), precision=3):>28}  "
            f"{np.array2string(err[:3, 3] * 100, precision=2)}"
        )


if __name__ == "__main__":
    main()
