#!/usr/bin/env python3
"""Side-by-side Ouster benchmark: ringscan vs ouster-sdk (driven by tools/bench_ouster.sh).

Makes the inputs with tools/make_big_ouster_capture.py (unfragmented and fragmented at MTU
1500, at every size of --frames; the first size is the comparison input), warms the page
cache, then in one run, every command pinned with --pin and wrapped in /usr/bin/time -v:

* speed, --rounds rounds interleaved (ouster-sdk, ringscan, on the unfragmented input, then
  the same on the fragmented one); the best round of each is kept, every round is recorded;
* cycles: one more run of each under `perf stat -e cycles,instructions` (when perf works), for
  cycles per pixel; otherwise cycles = the CPU clock of /proc/cpuinfo x the best time;
* in memory: the example bench_ouster_decode_mem on the unfragmented comparison input;
* peak RSS at every size, both tools, both inputs.

Writes every record to --results (JSON lines) and a Markdown report to --report; deletes
the inputs it made.
"""

import argparse
import datetime as dt
import json
import os
import platform
import re
import shlex
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def sh(cmd, **kw):
    return subprocess.run(cmd, check=True, capture_output=True, text=True, **kw)


def timed(cmd, pin, perf=False):
    """Runs cmd (list) pinned, under /usr/bin/time -v (and perf stat). Returns (stdout, facts)."""
    full = shlex.split(pin) + ["/usr/bin/time", "-v"] + cmd
    perf_file = None
    if perf:
        perf_file = "/tmp/bench_ouster_perf.txt"
        full = shlex.split(pin) + [
            "perf", "stat", "-x", ",", "-e", "cycles,instructions", "-o", perf_file,
            "/usr/bin/time", "-v",
        ] + cmd
    t0 = time.perf_counter()
    r = subprocess.run(full, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        sys.exit(f"command failed ({r.returncode}): {' '.join(full)}\n{r.stderr[-3000:]}")
    facts = {"process_wall_s": wall}
    m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", r.stderr)
    if m:
        facts["max_rss_kb"] = int(m.group(1))
    m = re.search(r"User time \(seconds\): ([\d.]+)", r.stderr)
    if m:
        facts["user_s"] = float(m.group(1))
    m = re.search(r"System time \(seconds\): ([\d.]+)", r.stderr)
    if m:
        facts["sys_s"] = float(m.group(1))
    if perf_file and os.path.exists(perf_file):
        with open(perf_file) as f:
            for line in f:
                parts = line.strip().split(",")
                if len(parts) > 2 and parts[2] in ("cycles", "instructions") and parts[0].isdigit():
                    facts[parts[2]] = int(parts[0])
        os.remove(perf_file)
    return r.stdout, facts


def last_json(text):
    lines = [line for line in text.splitlines() if line.startswith("{")]
    return json.loads(lines[-1])


def machine_facts():
    facts = {}
    with open("/proc/cpuinfo") as f:
        info = f.read()
    m = re.search(r"model name\s*: (.*)", info)
    facts["cpu"] = m.group(1).strip() if m else platform.processor()
    m = re.search(r"cpu MHz\s*: ([\d.]+)", info)
    facts["mhz"] = float(m.group(1)) if m else None
    facts["cpus"] = os.cpu_count()
    facts["loadavg"] = open("/proc/loadavg").read().split()[:3]
    try:
        facts["rustc"] = sh(["rustc", "--version"]).stdout.strip()
    except Exception:  # noqa: BLE001
        facts["rustc"] = None
    facts["kernel"] = platform.release()
    return facts


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--ringscan", required=True)
    ap.add_argument("--mem-bin", required=True)
    ap.add_argument("--sdk-python", required=True)
    ap.add_argument("--input", required=True)
    ap.add_argument("--meta", required=True)
    ap.add_argument("--frames", default="1000,4000")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--dir", required=True)
    ap.add_argument("--pin", default="")
    ap.add_argument("--results", required=True)
    ap.add_argument("--report", required=True)
    ap.add_argument("--keep", action="store_true", help="keep the generated inputs")
    ap.add_argument("--extra-ringscan", action="append", default=[], metavar="LABEL=PATH",
                    help="another ringscan binary run in the same rounds (e.g. before=...)")
    a = ap.parse_args()

    sizes = [int(x) for x in a.frames.split(",") if x]
    binaries = {"ringscan": a.ringscan}
    for e in a.extra_ringscan:
        label, _, path = e.partition("=")
        binaries[f"ringscan ({label})"] = path
    tools = ["ouster-sdk", *binaries]
    made = []
    records = []
    started = dt.datetime.now(dt.timezone.utc)
    facts = machine_facts()
    facts["started_utc"] = started.strftime("%Y-%m-%d %H:%M UTC")
    facts["sdk"] = sh([a.sdk_python, "-c",
                       "from importlib.metadata import version as v; import sys;"
                       "print(v('ouster-sdk'), v('numpy'), sys.version.split()[0])"]).stdout.split()

    def record(r):
        r["time_utc"] = dt.datetime.now(dt.timezone.utc).strftime("%H:%M:%S")
        r["loadavg"] = open("/proc/loadavg").read().split()[0]
        records.append(r)
        with open(a.results, "a") as f:
            f.write(json.dumps(r) + "\n")
        print(json.dumps(r), file=sys.stderr, flush=True)

    open(a.results, "w").close()
    try:
        inputs = {}
        for n in sizes:
            u = os.path.join(a.dir, f"ouster-{n}.pcap")
            fr = os.path.join(a.dir, f"ouster-{n}-frag1500.pcap")
            made += [u, fr]
            out = sh([sys.executable, os.path.join(ROOT, "tools", "make_big_ouster_capture.py"),
                      "--in", a.input, "--meta", a.meta, "--frames", str(n),
                      "--out", u, "--out-fragmented", fr]).stdout
            gen = json.loads(out)
            record({"what": "input", **gen})
            inputs[n] = {"unfragmented": (u, gen["out"]["bytes"]),
                         "fragmented": (fr, gen["out_fragmented"]["bytes"]), "gen": gen}

        def sdk_cmd(path):
            return [a.sdk_python, os.path.join(HERE, "ouster_sdk_bench.py"), path, a.meta]

        def rs_cmd(tool, path):
            return [binaries[tool], "decode", path, "--calib", a.meta, "--json"]

        def run(tool, variant, n, perf=False, rnd=None):
            path, size = inputs[n][variant]
            cmd = sdk_cmd(path) if tool == "ouster-sdk" else rs_cmd(tool, path)
            out, pf = timed(cmd, a.pin, perf)
            j = last_json(out)
            if tool == "ouster-sdk":
                frames, points, elapsed = j["frames"], j["points"], j["elapsed_s"]
                pixels = j["pixels"]
            else:
                frames, points, elapsed = j["sweeps"], j["points"], j["elapsed_s"]
                hw = inputs[n]["gen"]["pixels_per_column"] * inputs[n]["gen"]["columns_per_frame"]
                pixels = frames * hw
                pf["missing"] = j["packets"]["missing"]
                pf["malformed"] = j["packets"]["malformed"]
            r = {"what": "speed" if not perf else "cycles", "tool": tool, "input": variant,
                 "frames_in_input": n, "bytes": size, "frames": frames, "pixels": pixels,
                 "points": points, "elapsed_s": elapsed, "round": rnd,
                 "pixels_per_s": pixels / elapsed, "gb_per_s": size / elapsed / 1e9,
                 "command": " ".join(shlex.split(a.pin) + cmd), **pf}
            record(r)
            return r

        n0 = sizes[0]
        # Warm the page cache.
        for v in ("unfragmented", "fragmented"):
            subprocess.run(["cat", inputs[n0][v][0]], stdout=subprocess.DEVNULL, check=True)
        for rnd in range(a.rounds):
            for v in ("unfragmented", "fragmented"):
                for tool in tools:
                    run(tool, v, n0, rnd=rnd)
        perf_ok = subprocess.run(["perf", "stat", "-e", "cycles", "true"],
                                 capture_output=True).returncode == 0
        if perf_ok:
            for v in ("unfragmented", "fragmented"):
                for tool in tools:
                    run(tool, v, n0, perf=True)
        # In memory (ringscan only).
        out, pf = timed([a.mem_bin, inputs[n0]["unfragmented"][0], "--calib", a.meta,
                         "--repeat", str(a.rounds)], a.pin)
        for line in out.splitlines():
            if line.startswith("{"):
                j = json.loads(line)
                record({**j, "path": j["what"], "what": "memory_path"})
        # Peak RSS at the other sizes.
        for n in sizes[1:]:
            for v in ("unfragmented", "fragmented"):
                subprocess.run(["cat", inputs[n][v][0]], stdout=subprocess.DEVNULL, check=True)
                for tool in tools:
                    run(tool, v, n, rnd="rss")
    finally:
        if not a.keep:
            for p in made:
                for q in (p, p + ".part"):
                    if os.path.exists(q):
                        os.remove(q)
    facts["ended_loadavg"] = open("/proc/loadavg").read().split()[:3]
    write_report(a, facts, records, sizes, tools)


def best(records, tool, variant, n, what="speed"):
    rs = [r for r in records if r["what"] == what and r["tool"] == tool and r["input"] == variant
          and r["frames_in_input"] == n]
    return max(rs, key=lambda r: r["pixels_per_s"]) if rs else None


def write_report(a, facts, records, sizes, tools):
    n0 = sizes[0]
    L = []
    L.append(f"Run started {facts['started_utc']}; load average at start "
             f"{' '.join(facts['loadavg'])}, at end {' '.join(facts['ended_loadavg'])}.")
    L.append("")
    L.append(f"CPU `{facts['cpu']}`, {facts['cpus']} CPUs, {facts['mhz']} MHz; {facts['rustc']}; "
             f"ouster-sdk {facts['sdk'][0]}, numpy {facts['sdk'][1]}, CPython {facts['sdk'][2]}; "
             f"Linux {facts['kernel']}.")
    L.append("")
    gen = next(r for r in records if r["what"] == "input" and r["frames"] >= n0)
    L.append(f"Input: {gen['frames']} frames of {gen['pixels_per_column']} x "
             f"{gen['columns_per_frame']} pixels ({gen['profile']}), {gen['lidar_packets']} lidar "
             f"+ {gen['imu_packets']} IMU datagrams, {gen['span_s']:.1f} s of capture; "
             f"unfragmented {gen['out']['bytes'] / 1e6:.0f} MB, fragmented at MTU 1500 "
             f"{gen['out_fragmented']['bytes'] / 1e6:.0f} MB "
             f"({gen['out_fragmented']['fragments']} fragments).")
    L.append("")
    L.append("| input | tool | frames | points | time (s) | M pixels/s | GB/s | cycles/pixel | "
             "ringscan / ouster-sdk |")
    L.append("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for v in ("unfragmented", "fragmented"):
        sdk = best(records, "ouster-sdk", v, n0)
        for tool in tools:
            r = best(records, tool, v, n0)
            if not r:
                continue
            c = best(records, tool, v, n0, what="cycles")
            if c and "cycles" in c:
                cpp = f"{c['cycles'] / c['pixels']:.1f}"
            else:
                cpp = f"{facts['mhz'] * 1e6 * r['elapsed_s'] / r['pixels']:.1f}*"
            ratio = (f"**{r['pixels_per_s'] / sdk['pixels_per_s']:.2f}x**"
                     if tool != "ouster-sdk" and sdk else "")
            L.append(f"| {v} | {tool} | {r['frames']:,} | {r['points']:,} | {r['elapsed_s']:.3f} | "
                     f"{r['pixels_per_s'] / 1e6:.1f} | {r['gb_per_s']:.2f} | {cpp} | {ratio} |")
    L.append("")
    L.append("All rounds (M pixels/s):")
    L.append("")
    for v in ("unfragmented", "fragmented"):
        for tool in tools:
            rs = [r for r in records if r["what"] == "speed" and r["tool"] == tool
                  and r["input"] == v and r["frames_in_input"] == n0]
            L.append(f"* {v}, {tool}: " + ", ".join(f"{r['pixels_per_s'] / 1e6:.1f}" for r in rs))
    L.append("")
    mem = [r for r in records if r["what"] == "memory_path"]
    if mem:
        L.append("| ringscan, payloads in memory (unfragmented input) | frames | best time (s) | "
                 "M pixels/s |")
        L.append("|---|---:|---:|---:|")
        for path in dict.fromkeys(r["path"] for r in mem):
            r = max((r for r in mem if r["path"] == path), key=lambda r: r["pixels_per_s"])
            L.append(f"| `{path}` | {r['frames']:,} | {r['elapsed_s']:.3f} | "
                     f"{r['pixels_per_s'] / 1e6:.1f} |")
        L.append("")
    L.append("| peak RSS (MiB) | " + " | ".join(f"{n:,} frames" for n in sizes) + " |")
    L.append("|---|" + "---:|" * len(sizes))
    for v in ("unfragmented", "fragmented"):
        for tool in tools:
            cells = []
            for n in sizes:
                rs = [r for r in records if r["what"] == "speed" and r["tool"] == tool
                      and r["input"] == v and r["frames_in_input"] == n and "max_rss_kb" in r]
                cells.append(f"{max(r['max_rss_kb'] for r in rs) / 1024:.1f}" if rs else "-")
            L.append(f"| {tool}, {v} | " + " | ".join(cells) + " |")
    L.append("")
    with open(a.report, "w") as f:
        f.write("\n".join(L) + "\n")
    print("\n".join(L))


if __name__ == "__main__":
    main()
