#!/usr/bin/env bash
# Side-by-side comparison of two builds of the `pipeline_full` bench on this 2-core host.
#
#   tools/ab_pipeline.sh BEFORE_BINARY AFTER_BINARY [ROUNDS]
#
# Build each side once (`cargo bench --bench pipeline_full --no-run`, then copy
# target/release/deps/pipeline_full-<hash> somewhere), then run this. Each round runs the two
# binaries at the same time, one pinned to each core (`taskset`), and swaps the cores every
# round: on a shared host whose speed drifts by ±25 % over minutes, two runs at the same time
# see the same drift, where runs one after the other do not. Prints, per round and side, the
# OS-2-128 and HDL-32E stage medians (default configuration, 200 runs) and the CPU per run.
# Compare a stage's share of the pipeline (e.g. voxel / (ground + cluster)) round by round;
# the two sides also compete for the shared cache and memory, so absolute times are higher
# than when run alone.
set -euo pipefail
a=${1:?before binary}
b=${2:?after binary}
rounds=${3:-4}
command -v taskset >/dev/null || { echo "taskset (util-linux) is needed" >&2; exit 2; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
summary() { # file input
    grep -A7 -m1 "$2: per run" "$1" |
        awk '/per run/ { cpu = $(NF - 3) } /median/ { printf "%s %s  ", $1, $3 } END { print "CPU " cpu }'
}
for r in $(seq 1 "$rounds"); do
    if [ $((r % 2)) -eq 1 ]; then ca=0 cb=1; else ca=1 cb=0; fi
    taskset -c "$ca" "$a" --bench --warm-up-time 1 --measurement-time 2 >"$tmp/a" 2>&1 &
    taskset -c "$cb" "$b" --bench --warm-up-time 1 --measurement-time 2 >"$tmp/b" 2>&1 &
    wait
    for input in os2-128 hdl32e; do
        echo "round $r $input before (core $ca): $(summary "$tmp/a" "$input")"
        echo "round $r $input after  (core $cb): $(summary "$tmp/b" "$input")"
    done
done
