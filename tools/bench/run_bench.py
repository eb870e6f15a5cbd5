#!/usr/bin/env python3
"""Runs the side-by-side Velodyne benchmark (called by tools/bench_velodyne.sh; stdlib only).

For the first size in --sizes (the comparison input), --rounds rounds, each running in turn:
  vd_read_pcap        velodyne_decoder.read_pcap over the capture (tools/bench/vd_bench.py)
  ringscan_count      ringscan decode IN --model M --calib C --json          (points only)
  ringscan_mcap       ringscan decode IN --model M --calib C --json --out X.mcap (default compression)
  ringscan_mcap_unpinned  the same without the --pin prefix (compression threads may use every CPU)
then, once each (every pass repeated --rounds times inside, best kept):
  vd in_memory        velodyne_decoder StreamDecoder / ScanDecoder on payloads held in memory
  bench_decode_mem    ringscan VelodyneDecoder / VelodyneStream on payloads held in memory
For every further size: ringscan_count and both ringscan_mcap runs once (speed and peak memory).

Every command runs under `/usr/bin/time -v` (peak RSS) with the --pin prefix (taskset). The
capture of each size is made with tools/make_big_capture.py, read once to warm the page cache,
and deleted (with its MCAP) when that size is done. Prints a Markdown report; writes it and the raw
records (JSON lines) to --report / --results.
"""

import argparse
import datetime as dt
import json
import os
import platform
import shlex
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def run(cmd, pin, tag, workdir, env=None):
    """Runs cmd under /usr/bin/time -v; returns (stdout, wall_s, max_rss_kb); CPU times in LAST_CPU."""
    tfile = os.path.join(workdir, f"{tag}.time")
    full = pin + ["/usr/bin/time", "-v", "-o", tfile] + cmd
    print("$ " + " ".join(shlex.quote(c) for c in cmd), file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    p = subprocess.run(full, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        sys.stderr.write(p.stderr)
        sys.exit(f"command failed ({p.returncode}): {' '.join(cmd)}")
    rss = None
    LAST_CPU.clear()
    with open(tfile) as f:
        for line in f:
            if "Maximum resident set size" in line:
                rss = int(line.rsplit(":", 1)[1])
            elif "User time (seconds)" in line:
                LAST_CPU["user_s"] = float(line.rsplit(":", 1)[1])
            elif "System time (seconds)" in line:
                LAST_CPU["sys_s"] = float(line.rsplit(":", 1)[1])
    return p.stdout, wall, rss


LAST_CPU = {}


def jsonl(text):
    return [json.loads(l) for l in text.splitlines() if l.strip().startswith("{")]


def warm(path):
    with open(path, "rb") as f:
        while f.read(1 << 24):
            pass


def loadavg():
    try:
        with open("/proc/loadavg") as f:
            return " ".join(f.read().split()[:3])
    except OSError:
        return "?"


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def mhz():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("cpu MHz"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "?"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--ringscan", required=True)
    ap.add_argument("--mem-bin", required=True, help="the bench_decode_mem example binary")
    ap.add_argument("--vd-python", required=True, help="python of the venv with velodyne-decoder")
    ap.add_argument("--input", required=True, help="real capture to repeat")
    ap.add_argument("--model", default="hdl32e")
    ap.add_argument("--vd-model", default="HDL32E")
    ap.add_argument("--calib", required=True)
    ap.add_argument("--sizes", default="200,1000", help="input sizes in MB, the first is the comparison input")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--dir", required=True, help="scratch directory (captures, MCAP; emptied)")
    ap.add_argument("--pin", default="", help="command prefix, e.g. 'taskset -c 0'")
    ap.add_argument("--results", required=True)
    ap.add_argument("--report", required=True)
    ap.add_argument("--keep", action="store_true", help="keep the captures")
    a = ap.parse_args()

    pin = shlex.split(a.pin)
    sizes = [float(s) for s in a.sizes.split(",") if s]
    os.makedirs(a.dir, exist_ok=True)
    env = dict(os.environ, RAYON_NUM_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    records = []
    started = dt.datetime.now(dt.timezone.utc)

    def add(r):
        r = dict(r, **LAST_CPU)
        records.append(r)
        with open(a.results, "a") as f:
            f.write(json.dumps(r) + "\n")

    open(a.results, "w").close()
    load_before = loadavg()
    rs = [a.ringscan, "decode"]
    common = ["--model", a.model, "--calib", a.calib, "--json"]
    for si, size in enumerate(sizes):
        tag = f"{int(size)}mb"
        cap = os.path.join(a.dir, f"big-{tag}.pcap")
        mcap = os.path.join(a.dir, f"big-{tag}.mcap")
        subprocess.run(
            [sys.executable, os.path.join(ROOT, "tools", "make_big_capture.py"), "--in", a.input, "--mb", str(size), "--out", cap],
            check=True, stdout=sys.stderr,
        )
        cap_bytes = os.path.getsize(cap)
        warm(cap)
        rounds = a.rounds if si == 0 else 1
        for r in range(rounds):
            if si == 0:
                out, wall, rss = run([a.vd_python, os.path.join(HERE, "vd_bench.py"), "read_pcap", cap, a.vd_model, a.calib], pin, f"vd-{tag}-{r}", a.dir, env)
                j = jsonl(out)[0]
                add(dict(j, size=tag, input_bytes=cap_bytes, round=r, process_wall_s=wall, max_rss_kb=rss))
            out, wall, rss = run(rs + [cap] + common, pin, f"rs-{tag}-{r}", a.dir, env)
            j = json.loads(out)
            add({"what": "ringscan_count", "size": tag, "input_bytes": cap_bytes, "round": r, "points": j["points"], "sweeps": j["sweeps"],
                 "elapsed_s": j["elapsed_s"], "process_wall_s": wall, "max_rss_kb": rss, "duration_s": j["capture"]["duration_s"],
                 "missing": j["packets"]["missing"], "malformed": j["packets"]["malformed"]})
            if os.path.exists(mcap):
                os.remove(mcap)
            out, wall, rss = run(rs + [cap] + common + ["--out", mcap], pin, f"rsm-{tag}-{r}", a.dir, env)
            j = json.loads(out)
            add({"what": "ringscan_mcap", "size": tag, "input_bytes": cap_bytes, "round": r, "points": j["points"], "sweeps": j["sweeps"],
                 "elapsed_s": j["elapsed_s"], "process_wall_s": wall, "max_rss_kb": rss, "duration_s": j["capture"]["duration_s"],
                 "mcap_bytes": os.path.getsize(mcap)})
            os.remove(mcap)
            # The same, not pinned: the mcap crate's zstd may use its worker threads on every CPU.
            out, wall, rss = run(rs + [cap] + common + ["--out", mcap], [], f"rsm2-{tag}-{r}", a.dir, env)
            j = json.loads(out)
            add({"what": "ringscan_mcap_unpinned", "size": tag, "input_bytes": cap_bytes, "round": r, "points": j["points"], "sweeps": j["sweeps"],
                 "elapsed_s": j["elapsed_s"], "process_wall_s": wall, "max_rss_kb": rss, "duration_s": j["capture"]["duration_s"],
                 "mcap_bytes": os.path.getsize(mcap)})
            os.remove(mcap)
        if si == 0:
            out, wall, rss = run([a.vd_python, os.path.join(HERE, "vd_bench.py"), "in_memory", cap, a.vd_model, a.calib, "--repeat", str(a.rounds)], pin, f"vdmem-{tag}", a.dir, env)
            for j in jsonl(out):
                add(dict(j, size=tag, input_bytes=cap_bytes, max_rss_kb=rss))
            out, wall, rss = run([a.mem_bin, cap, "--model", a.model, "--calib", a.calib, "--repeat", str(a.rounds)], pin, f"rsmem-{tag}", a.dir, env)
            for j in jsonl(out):
                add(dict(j, size=tag, input_bytes=cap_bytes, max_rss_kb=rss))
        if not a.keep:
            os.remove(cap)

    a.load = (load_before, loadavg())
    report = render(records, a, started, sizes)
    with open(a.report, "w") as f:
        f.write(report)
    print(report)


def best(records, what, size, key="elapsed_s"):
    rs = [r for r in records if r["what"] == what and r["size"] == size]
    return min(rs, key=lambda r: r[key]) if rs else None


def render(records, a, started, sizes):
    tag0 = f"{int(sizes[0])}mb"
    L = []
    mb = lambda b: f"{b / 1e6:.0f} MB"
    mpts = lambda x: f"{x / 1e6:.1f} M"
    L.append(f"Run {started.strftime('%Y-%m-%d %H:%M UTC')}; {os.cpu_count()} CPUs, {cpu_model()} (~{mhz()} MHz); "
             f"pinned with `{a.pin or 'nothing'}`; input: {os.path.relpath(a.input, ROOT) if a.input.startswith(ROOT) else a.input} repeated; "
             f"model {a.model}, calibration {os.path.basename(a.calib)}; best of {a.rounds} rounds; "
             f"load average (1, 5, 15 min) {a.load[0]} before, {a.load[1]} after.")
    L.append("")
    vd = best(records, "vd_read_pcap", tag0, "wall_s")
    rc = best(records, "ringscan_count", tag0)
    rm = best(records, "ringscan_mcap", tag0)
    vsd = best(records, "vd_stream_decoder_in_memory", tag0, "wall_s")
    vsc = best(records, "vd_scan_decoder_in_memory", tag0, "wall_s")
    rdm = best(records, "ringscan_decoder_in_memory", tag0, "wall_s")
    rsm = best(records, "ringscan_stream_in_memory", tag0, "wall_s")
    size_b = (vd or rc)["input_bytes"]
    L.append(f"### Speed, {mb(size_b)} input ({rc['points']:,} points, {rc['duration_s']:.1f} s of capture), single-threaded")
    L.append("")
    L.append("| what | points | time (s) | points/s | ringscan / velodyne_decoder |")
    L.append("|---|---:|---:|---:|---:|")
    rc_pps = rc["points"] / rc["elapsed_s"]
    vd_pps = vd["points"] / vd["wall_s"]
    vsc_pps = vsc["points"] / vsc["wall_s"]
    L.append(f"| velodyne_decoder `read_pcap` (pcap file → scans) | {vd['points']:,} | {vd['wall_s']:.3f} | {mpts(vd_pps)} | |")
    L.append(f"| ringscan `decode` (pcap file → sweeps, no output) | {rc['points']:,} | {rc['elapsed_s']:.3f} | {mpts(rc_pps)} | **{rc_pps / vd_pps:.2f}×** |")
    L.append(f"| velodyne_decoder `StreamDecoder.decode` per packet, payloads in memory | {vsd['points']:,} | {vsd['wall_s']:.3f} | {mpts(vsd['points'] / vsd['wall_s'])} | |")
    L.append(f"| velodyne_decoder C++ core: `ScanDecoder.decode` per rotation, `PacketVector`s in memory | {vsc['points']:,} | {vsc['wall_s']:.3f} | {mpts(vsc_pps)} | |")
    L.append(f"| ringscan `VelodyneDecoder::decode`, payloads in memory | {rdm['points']:,} | {rdm['wall_s']:.3f} | {mpts(rdm['points'] / rdm['wall_s'])} | **{rdm['points'] / rdm['wall_s'] / vsc_pps:.2f}×** vs C++ core |")
    L.append(f"| ringscan `VelodyneStream` (full sweep path), payloads in memory | {rsm['points']:,} | {rsm['wall_s']:.3f} | {mpts(rsm['points'] / rsm['wall_s'])} | {rsm['points'] / rsm['wall_s'] / vsc_pps:.2f}× vs C++ core |")
    L.append("")
    L.append(f"Process wall times (start to exit, interpreter start-up included): velodyne_decoder `read_pcap` "
             f"{vd['process_wall_s']:.3f} s, ringscan `decode` {rc['process_wall_s']:.3f} s "
             f"(ratio {vd['process_wall_s'] / rc['process_wall_s']:.2f}×). Point counts equal: "
             f"{'yes' if vd['points'] == rc['points'] == rdm['points'] == vsc['points'] else 'NO'}.")
    L.append("")
    L.append("### `ringscan decode` to MCAP (default compression)")
    L.append("")
    L.append("| input | CPUs | capture duration (s) | wall (s) | CPU user + sys (s) | real-time factor | points/s | MCAP size |")
    L.append("|---|---|---:|---:|---:|---:|---:|---:|")
    for s in sizes:
        t = f"{int(s)}mb"
        for what, cpus in (("ringscan_mcap", f"1 (`{a.pin}`)" if a.pin else "all"), ("ringscan_mcap_unpinned", f"all ({os.cpu_count()})")):
            r = best(records, what, t, "process_wall_s")
            if r:
                L.append(f"| {mb(r['input_bytes'])} | {cpus} | {r['duration_s']:.1f} | {r['process_wall_s']:.3f} | {r.get('user_s', 0):.2f} + {r.get('sys_s', 0):.2f} | **{r['duration_s'] / r['process_wall_s']:.1f}×** | "
                         f"{mpts(r['points'] / r['process_wall_s'])} | {mb(r['mcap_bytes'])} |")
    L.append("")
    L.append("### Peak memory (maximum resident set size)")
    L.append("")
    L.append("| command | " + " | ".join(mb(best(records, 'ringscan_count', f'{int(s)}mb')['input_bytes']) + " input" for s in sizes) + " |")
    L.append("|---|" + "---:|" * len(sizes))
    for what, label in (("ringscan_count", "ringscan `decode` (no output)"), ("ringscan_mcap", "ringscan `decode --out x.mcap`"), ("ringscan_mcap_unpinned", "ringscan `decode --out x.mcap`, not pinned"), ("vd_read_pcap", "velodyne_decoder `read_pcap`")):
        cells = []
        for s in sizes:
            rs = [r for r in records if r["what"] == what and r["size"] == f"{int(s)}mb"]
            cells.append(f"{max(r['max_rss_kb'] for r in rs) / 1024:.1f} MiB" if rs else "–")
        L.append(f"| {label} | " + " | ".join(cells) + " |")
    L.append("")
    return "\n".join(L)


if __name__ == "__main__":
    main()
