"""Open3D side by side with ringscan's pipeline stages on the same real sweeps.

Run through tools/pipeline_open3d.sh, which makes the venv, dumps the sweeps with
`cargo run --release --example pipeline_dump -- DIR` and then runs this with DIR.

For each dumped sweep (NAME.xyz.f32 and the files next to it, see tools/pipeline_dump.rs):
1. voxel counts: Open3D's voxel_down_sample(leaf) point count against ringscan's count with
   the same grid origin (min bound - leaf/2), leaves 0.05, 0.1, 0.2, 0.5 m; must be equal;
2. clustering: Open3D's cluster_dbscan(eps=0.5, min_points=1) on ringscan's 0.1 m voxelised
   sweep, as a partition, against ringscan's clusters (tolerance 0.5 m) on the same points,
   sizes [1, inf) and [10, 2000] (Open3D's clusters filtered by size); must be identical;
3. timing, one thread (OMP_NUM_THREADS=1): voxel_down_sample(0.1) + segment_plane(0.15, 3,
   200) + cluster_dbscan(eps 0.5, min_points 10) on the outliers of the plane, median of
   --repeat runs, per stage and in total.
Exit status 1 if a count or a partition differs.
"""

import json
import os
import sys
import time

import numpy as np
import open3d as o3d


def load_xyz(path):
    return np.fromfile(path, dtype="<f4").reshape(-1, 3).astype(np.float64)


def cloud(xyz):
    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(xyz)
    return pc


def partition(labels, lo, hi):
    """Set of frozensets of indices, clusters (label >= 0) with lo <= size <= hi."""
    groups = {}
    for i, l in enumerate(labels):
        if l >= 0:
            groups.setdefault(int(l), []).append(i)
    return {frozenset(g) for g in groups.values() if lo <= len(g) <= hi}


def median_ms(samples):
    return 1000.0 * float(np.median(samples))


def main():
    d = sys.argv[1]
    repeat = int(sys.argv[2]) if len(sys.argv) > 2 else 10
    ok = True
    print(f"open3d {o3d.__version__}, OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}")
    for name in ["os2_128", "hdl32"]:
        info = json.load(open(os.path.join(d, f"{name}.json")))
        xyz = load_xyz(os.path.join(d, f"{name}.xyz.f32"))
        assert len(xyz) == info["points"]
        pc = cloud(xyz)
        print(f"\n== {name}: {len(xyz)} points")

        # 1. Voxel counts with aligned grids.
        for leaf, mine in info["voxel_counts_open3d_origin"].items():
            theirs = len(pc.voxel_down_sample(float(leaf)).points)
            same = theirs == mine
            ok &= same
            print(f"voxel leaf {leaf} m: open3d {theirs}, ringscan {mine}: {'same' if same else 'DIFFERENT'}")

        # 2. Partition on the same voxelised points.
        down = load_xyz(os.path.join(d, f"{name}.down.xyz.f32"))
        o3d_labels = np.asarray(cloud(down).cluster_dbscan(eps=0.5, min_points=1))
        for suffix, lo, hi in [("labels", 1, float("inf")), ("labels10", 10, 2000)]:
            mine = np.fromfile(os.path.join(d, f"{name}.down.{suffix}.i32"), dtype="<i4")
            a, b = partition(o3d_labels, lo, hi), partition(mine, lo, hi)
            same = a == b
            ok &= same
            print(
                f"clusters eps 0.5 m on {len(down)} voxelised points, sizes [{lo}, {hi}]: "
                f"open3d {len(a)}, ringscan {len(b)}: {'same partition' if same else 'DIFFERENT'}"
                + ("" if same else f" ({len(a - b)} only in open3d, {len(b - a)} only in ringscan)")
            )

        # 3. Timing of the reference pipeline.
        t_vox, t_plane, t_db, t_all = [], [], [], []
        for _ in range(repeat):
            t0 = time.perf_counter()
            dpc = pc.voxel_down_sample(0.1)
            t1 = time.perf_counter()
            _, inliers = dpc.segment_plane(distance_threshold=0.15, ransac_n=3, num_iterations=200)
            rest = dpc.select_by_index(inliers, invert=True)
            t2 = time.perf_counter()
            labels = np.asarray(rest.cluster_dbscan(eps=0.5, min_points=10))
            t3 = time.perf_counter()
            t_vox.append(t1 - t0)
            t_plane.append(t2 - t1)
            t_db.append(t3 - t2)
            t_all.append(t3 - t0)
        print(
            f"open3d one thread, median of {repeat}: voxel_down_sample {median_ms(t_vox):.2f} ms "
            f"({len(dpc.points)} points), segment_plane {median_ms(t_plane):.2f} ms "
            f"({len(inliers)} inliers), cluster_dbscan {median_ms(t_db):.2f} ms "
            f"({labels.max() + 1} clusters), total {median_ms(t_all):.2f} ms"
        )
    print("\nall counts and partitions agree" if ok else "\nSOME COUNTS OR PARTITIONS DIFFER")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
