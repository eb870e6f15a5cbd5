#!/usr/bin/env bash
# ringscan's pipeline stages side by side with Open3D on the same real sweeps.
#
#   tools/pipeline_open3d.sh            # checks + Open3D timing + ringscan criterion bench
#
# Environment (optional):
#   REPEAT       Open3D timing runs per sweep, median kept (default 10)
#   NO_BENCH=1   skip `cargo bench --bench pipeline` (checks and Open3D timing only)
#   CPU          the CPU both sides are pinned to with taskset (default 0)
#
# 1. Makes tools/.venv-open3d (git-ignored) with open3d-cpu 0.20.0 and numpy 2.4.6, if absent.
# 2. `cargo run --release --example pipeline_dump -- target/pipeline-open3d`: ringscan decodes
#    the OS-2-128 frame and the HDL-32E sweep from ../shared/captures and dumps them with its
#    voxel counts and cluster labels (tools/pipeline_dump.rs).
# 3. tools/pipeline_open3d.py: voxel counts and cluster partitions against Open3D (exit 1 on
#    any difference), then Open3D's voxel_down_sample + segment_plane + cluster_dbscan timed
#    with one thread (OMP_NUM_THREADS=1).
# 4. `cargo bench --bench pipeline` (tools/bench/pipeline.rs): ringscan's stages on the same
#    sweeps, pinned to the same CPU.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/tools/.venv-open3d"
DIR="${CARGO_TARGET_DIR:-$ROOT/target}/pipeline-open3d"
CPU="${CPU:-0}"

if ! "$VENV/bin/python" -c "import open3d, numpy" 2>/dev/null; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install --quiet open3d-cpu==0.20.0 numpy==2.4.6
fi

cargo run --quiet --release --example pipeline_dump -- "$DIR"
OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 taskset -c "$CPU" \
    "$VENV/bin/python" "$ROOT/tools/pipeline_open3d.py" "$DIR" "${REPEAT:-10}"

if [ -z "${NO_BENCH:-}" ]; then
    cargo bench --bench pipeline --no-run --quiet
    taskset -c "$CPU" cargo bench --quiet --bench pipeline 2>&1 | grep -E "^[a-z_0-9/]+ +time:|^[a-z_0-9/]+$|time:" || true
fi
