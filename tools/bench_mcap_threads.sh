#!/usr/bin/env bash
# `ringscan decode … --out` with its MCAP chunks compressed on 1..N threads, whole-process
# timings (median of BENCH_ROUNDS runs, the variants alternating within each round), into
# tmpfs and onto disk; then the per-chunk compression cost that projects the figures to more
# cores. Run by hand on a quiet machine (the load average is printed before and after).
#
#   tools/bench_mcap_threads.sh
#
# Inputs, made with the project's tools unless already there (deleted afterwards if made here):
# * hdl32e: `tools/make_big_capture.py --mb 200` (the HDL-32E Monterey capture repeated);
# * ouster: `tools/make_big_ouster_capture.py` of ouster-sdk's OS-1-128_v2.3.0_1024x10_lb_n3.pcap
#   (RNG15_RFL8_NIR8, "LOW_DATA"), 1000 frames, fragmented at MTU 1500.
#
# Environment (all optional):
#   BENCH_INPUTS        "hdl32e ouster"
#   BENCH_TARGETS       "shm disk"   (shm = /dev/shm/…, disk = BENCH_DIR)
#   BENCH_THREADS       "1 2 … nproc"
#   BENCH_COMPRESSIONS  "zstd:-3"    (e.g. "zstd:-3 zstd:-1 zstd:1 lz4 none" for the table of
#                                     compression × threads)
#   BENCH_CHUNK_SIZES   "4"          (MiB; e.g. "1 2 4 8 16")
#   BENCH_FIELDS        "default"    (e.g. "default minimal")
#   BENCH_ROUNDS        5
#   BENCH_NO_OUT        1            (also time `decode` without --out, the decoding alone)
#   BENCH_PROJECT       1            (per-chunk cost and the projection, bench_mcap_threads)
#   BENCH_DIR           bench-data/mcap-threads (git-ignored; the disk target and scratch)
#   BENCH_REPORT        /tmp/bench_mcap_threads.md (raw rows stay in BENCH_DIR/results.txt)
#   CARGO_TARGET_DIR
#
# Projection to 16 cores (stated as one, not measured): the caller's own work W (decode, encode
# and write, measured as `--compression none` into tmpfs) plus the file's compression CPU C (the
# sum of every chunk compressed alone on one thread), shared by 16 cores but never below W:
# wall ≈ max(W, (W + C) / 16).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
CAPTURES="$ROOT/../shared/captures"
VCALIB="$CAPTURES/ros-drivers__velodyne/velodyne_pointcloud/params/32db.yaml"
O="$CAPTURES/ouster-lidar__ouster-sdk/tests/pcaps"
OMETA="$O/OS-1-128_v2.3.0_1024x10.json"
DIR="${BENCH_DIR:-$ROOT/bench-data/mcap-threads}"
SHM="/dev/shm/ringscan-bench-mcap-threads"
ROUNDS=${BENCH_ROUNDS:-5}
INPUTS=${BENCH_INPUTS:-"hdl32e ouster"}
TARGETS=${BENCH_TARGETS:-"shm disk"}
THREADS=${BENCH_THREADS:-$(seq -s ' ' 1 "$(nproc)")}
COMPRESSIONS=${BENCH_COMPRESSIONS:-"zstd:-3"}
CHUNKS=${BENCH_CHUNK_SIZES:-4}
FIELDS=${BENCH_FIELDS:-default}
REPORT=${BENCH_REPORT:-/tmp/bench_mcap_threads.md}
TARGET="${CARGO_TARGET_DIR:-$ROOT/target}"
mkdir -p "$DIR" "$SHM"
made=()
cleanup() {
    for f in "${made[@]}"; do rm -f "$f"; done
    rm -f "$SHM"/out.mcap "$DIR"/out.mcap "$SHM"/sweeps.mcap "$DIR"/time.txt "$DIR"/run.json
    rmdir "$SHM" 2>/dev/null || true
}
trap cleanup EXIT

cargo build --release --quiet --bin ringscan --example bench_mcap_threads
BIN="$TARGET/release/ringscan"

make_input() { # name: sets PATHS[name], making the capture if absent
    local p
    case $1 in
        hdl32e)
            p="$DIR/big200.pcap"
            if [ ! -f "$p" ]; then python3 tools/make_big_capture.py --mb 200 --out "$p" >/dev/null; made+=("$p"); fi ;;
        ouster)
            p="$DIR/os1-128-lb-1000-frag.pcap"
            if [ ! -f "$p" ]; then
                python3 tools/make_big_ouster_capture.py --in "$O/OS-1-128_v2.3.0_1024x10_lb_n3.pcap" \
                    --meta "$OMETA" --frames 1000 --out-fragmented "$p" --mtu 1500 >/dev/null
                made+=("$p")
            fi ;;
        *) echo "unknown input $1" >&2; exit 2 ;;
    esac
    PATHS[$1]=$p
}
input_args() { # name -> decode arguments
    case $1 in
        hdl32e) echo "--model hdl32e --calib $VCALIB" ;;
        ouster) echo "--calib $OMETA" ;;
    esac
}
out_for() { case $1 in shm) echo "$SHM/out.mcap" ;; disk) echo "$DIR/out.mcap" ;; esac; }

declare -A PATHS
for i in $INPUTS; do make_input "$i"; done

results="$DIR/results.txt"
: > "$results"
{
    echo "machine: $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs); kernel $(uname -r)"
    echo "disk target: $DIR ($(df -T "$DIR" | awk 'NR==2 {print $2}')); tmpfs target: $SHM"
    echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
} | tee "$REPORT.head"

# Capture facts (duration, points) once per input.
declare -A DURATION POINTS
for i in $INPUTS; do
    # shellcheck disable=SC2046
    read -r d p < <("$BIN" decode "${PATHS[$i]}" $(input_args "$i") --json |
        python3 -c 'import json,sys; j=json.load(sys.stdin); print(j["capture"]["duration_s"], j["points"])')
    DURATION[$i]=$d; POINTS[$i]=$p
    echo "input $i: ${PATHS[$i]} ($(stat -c %s "${PATHS[$i]}") bytes), $p points, $d s of capture" | tee -a "$REPORT.head"
done

run() { # input target compression chunk fields threads round
    local i=$1 tgt=$2 c=$3 ch=$4 f=$5 t=$6 r=$7 out
    if [ "$tgt" = none ]; then
        # shellcheck disable=SC2046
        /usr/bin/time -f "%e %U %S" -o "$DIR/time.txt" "$BIN" decode "${PATHS[$i]}" $(input_args "$i") >/dev/null
        read -r wall user sys < "$DIR/time.txt"
        echo "$i none - - - - $r $wall $user $sys 0 0" >> "$results"
        return
    fi
    out=$(out_for "$tgt")
    rm -f "$out"
    # shellcheck disable=SC2046
    /usr/bin/time -f "%e %U %S" -o "$DIR/time.txt" "$BIN" decode "${PATHS[$i]}" $(input_args "$i") \
        --out "$out" --compression "$c" --chunk-size "$ch" --fields "$f" --threads "$t" --json > "$DIR/run.json"
    read -r wall user sys < "$DIR/time.txt"
    local unc
    unc=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["output"]["chunks_uncompressed"])' "$DIR/run.json")
    echo "$i $tgt $c $ch $f $t $r $wall $user $sys $(stat -c %s "$out") $unc" >> "$results"
    rm -f "$out"
}

FIRST_CHUNK=${CHUNKS%% *}
for r in $(seq "$ROUNDS"); do
    for i in $INPUTS; do
        if [ "${BENCH_NO_OUT:-1}" = 1 ]; then run "$i" none - - - - "$r"; fi
        # The caller's own work (decode, encode, write; nothing to compress), for the projection.
        if [ "${BENCH_PROJECT:-1}" = 1 ] && [[ " $COMPRESSIONS " != *" none "* ]]; then
            run "$i" shm none "$FIRST_CHUNK" default 1 "$r"
        fi
        for tgt in $TARGETS; do
            for c in $COMPRESSIONS; do
                for ch in $CHUNKS; do
                    for f in $FIELDS; do
                        for t in $THREADS; do run "$i" "$tgt" "$c" "$ch" "$f" "$t" "$r"; done
                    done
                done
            done
        done
    done
    echo "round $r done, load average $(cut -d' ' -f1-3 /proc/loadavg)" >&2
done
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)" | tee -a "$REPORT.head"

# Per-chunk compression cost (one thread, as a worker pays it) for the projection.
proj="$DIR/projection.txt"
: > "$proj"
if [ "${BENCH_PROJECT:-1}" = 1 ]; then
    for i in $INPUTS; do
        # shellcheck disable=SC2046
        "$BIN" decode "${PATHS[$i]}" $(input_args "$i") --compression none --threads 1 --out "$SHM/sweeps.mcap" >/dev/null
        "$TARGET/release/examples/bench_mcap_threads" "$SHM/sweeps.mcap" --only chunks \
            --rounds 3 --compressions "$(echo "$COMPRESSIONS" | tr ' ' ',')" \
            --chunk-sizes "$(echo "$CHUNKS" | tr ' ' ',')" | sed "s/^/$i: /" >> "$proj"
        rm -f "$SHM/sweeps.mcap"
    done
fi

python3 - "$results" "$proj" "$REPORT" "$REPORT.head" <<'EOF'
import statistics, sys, collections, re
results, proj, report, head = sys.argv[1:5]
rows = collections.defaultdict(list)
for line in open(results):
    i, tgt, c, ch, f, t, r, wall, user, sys_, size, unc = line.split()
    rows[(i, tgt, c, ch, f, t)].append((float(wall), float(user) + float(sys_), int(size), int(unc)))
facts = {}
for line in open(head):
    m = re.match(r"input (\S+): .*?, (\d+) points, ([0-9.]+) s of capture", line)
    if m:
        facts[m.group(1)] = (int(m.group(2)), float(m.group(3)))
out = [open(head).read(), ""]
out.append("| input | target | compression | chunk MiB | fields | threads | wall s, median | walls | CPU s, median | real-time factor | vs 1 thread | MCAP MB | chunks uncompressed |")
out.append("|---|---|---|---:|---|---:|---:|---|---:|---:|---:|---:|---:|")
med = {}
for key in rows:
    med[key] = statistics.median(x[0] for x in rows[key])
for key in sorted(rows, key=lambda k: (k[0], k[1] != "none", k[1], k[2], float(k[3]) if k[3] != "-" else 0, k[4], int(k[5]) if k[5] != "-" else 0)):
    i, tgt, c, ch, f, t = key
    r = rows[key]
    wall = med[key]
    cpu = statistics.median(x[1] for x in r)
    dur = facts.get(i, (0, 0.0))[1]
    one = med.get((i, tgt, c, ch, f, "1"))
    speed = f"{one / wall:.2f}×" if one and t != "-" else ""
    walls = ", ".join(f"{x[0]:.2f}" for x in r)
    size = f"{r[0][2] / 1e6:.0f}" if tgt != "none" else ""
    unc = str(max(x[3] for x in r)) if tgt != "none" else ""
    label = "no --out (decoding only)" if tgt == "none" else tgt
    out.append(f"| {i} | {label} | {c} | {ch} | {f} | {t} | {wall:.3f} | {walls} | {cpu:.2f} | **{dur / wall:.1f}×** | {speed} | {size} | {unc} |")
text = open(proj).read()
if text:
    out.append("")
    out.append("Per-chunk compression cost, one thread (bench_mcap_threads --only chunks):")
    out.append("")
    out.append("```")
    out.append(text.rstrip())
    out.append("```")
    # Projection: the caller's serial work (decode, encode, write: the --compression none run on
    # tmpfs, else no --out) plus the compression CPU of the file, shared by N cores, bounded below
    # by the caller's own work.
    out.append("")
    out.append("| input | compression | caller's work s (decode + encode + write, `--compression none`) | compression CPU s per file (sum of chunks) | projected wall, 16 cores | projected real-time factor |")
    out.append("|---|---|---:|---:|---:|---:|")
    for line in text.splitlines():
        m = re.match(r"(\S+): \| (\S+) \| (\d+) \| \d+ \| [0-9.]+ \| [0-9.]+ \| \d+ \| ([0-9.]+) \|", line)
        if not m:
            continue
        i, c, ch, cpu = m.group(1), m.group(2), m.group(3), float(m.group(4))
        serial = med.get((i, "shm", "none", ch, "default", "1")) or med.get((i, "none", "-", "-", "-", "-"))
        if serial is None:
            continue
        dur = facts.get(i, (0, 0.0))[1]
        wall16 = max(serial, (serial + cpu) / 16)
        out.append(f"| {i} | {c} ({ch} MiB chunks) | {serial:.3f} | {cpu:.3f} | {wall16:.3f} (projection) | {dur / wall16:.0f}× (projection) |")
text = "\n".join(out) + "\n"
open(report, "w").write(text)
print(text)
EOF
rm -f "$REPORT.head"
