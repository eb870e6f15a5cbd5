#!/usr/bin/env python3
"""Load benchmark of `ringscan listen` on loopback (run by hand; tools/bench_listen.sh).

Usage:
    python3 tools/bench_listen.py --bin target/release/ringscan --hdl64 HDL64.pcap \\
        --hdl64-calib CALIB.yaml --ouster BIG.pcap --ouster-meta META.json \\
        [--seconds 60] [--ramp-seconds 10] [--report /tmp/bench_listen.md]

Each scenario starts `ringscan listen --json --duration T+2` under `/usr/bin/time -v` (CPU
time and peak RSS of the listener alone), then `ringscan replay --rate R --loop N` of the input
for about T seconds, and reads: datagrams sent (replay's summary) and received, queue and
kernel drops (listen's summary), CPU % of the listener (user + system over its wall time) and
its peak RSS. Scenarios:

* count only (no --out), 10x the real packet rate, T = --seconds: the HDL-64E S3 input and the
  OS-2-128 RNG19 input (same packet format as an OS-1-128 RNG19 stream);
* with --out: 1x and 5x of each input, T = --seconds (`--threads N` is passed on to listen;
  the MCAP chunks its compression threads could not take in time are reported, written
  uncompressed by listen, never dropped);
* ramp (count only, T = --ramp-seconds each): HDL-64E at 10, 15, 20, 30, 40x and max, to find
  where loss begins; the same with --out (zstd MCAP) at 5, 10, 12, 15, 20, 30x and max;
* garbage flood (count only, T = --ramp-seconds): random datagrams of random sizes (1 to 65507
  bytes) as fast as one Python sender can, half from the sensor's address (queued, then ignored
  by the decoder) and half from another loopback address (filtered); peak RSS shows whether
  memory stays bounded.

The load average before and after each scenario is recorded (the machine is shared). Standard
library only. Prints a Markdown table and writes it to --report.
"""

import argparse
import json
import os
import random
import re
import socket
import subprocess
import sys
import tempfile
import threading
import time

LOADAVG = "/proc/loadavg"


def loadavg():
    with open(LOADAVG) as f:
        return f.read().split()[0]


def capture_rate(bin_, pcap, extra):
    """Datagrams and duration of a capture, from `ringscan info --json`."""
    out = subprocess.run([bin_, "info", pcap, "--json", *extra], check=True,
                         capture_output=True, text=True).stdout
    j = json.loads(out)
    return j["capture"]["datagrams"], j["capture"]["duration_s"]


def free_port_base(ports):
    for _ in range(200):
        off = random.randint(1000, 20000)
        ok = True
        for p in ports:
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                s.bind(("0.0.0.0", p + off))
            except OSError:
                ok = False
            finally:
                s.close()
        if ok:
            return off
    raise SystemExit("no free ports")


def parse_time_v(text):
    def grab(name):
        m = re.search(rf"{re.escape(name)}: ([0-9.:]+)", text)
        return m.group(1) if m else None
    user = float(grab("User time (seconds)") or 0)
    sys_ = float(grab("System time (seconds)") or 0)
    rss_kb = int(grab("Maximum resident set size (kbytes)") or 0)
    wall = grab("Elapsed (wall clock) time (h:mm:ss or m:ss)") or "0:0"
    parts = [float(x) for x in wall.split(":")]
    secs = 0.0
    for p in parts:
        secs = secs * 60 + p
    return user, sys_, rss_kb, secs


def flood(port, seconds, sensor="127.0.0.1", other="127.0.0.2"):
    socks = []
    for addr in (sensor, other):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind((addr, 0))
        socks.append(s)
    end = time.monotonic() + seconds
    sent = 0
    blob = os.urandom(65507)
    while time.monotonic() < end:
        for s in socks:
            n = random.randint(1, 65507)
            start = random.randint(0, 65507 - n)
            try:
                s.sendto(blob[start:start + n], ("127.0.0.1", port))
                sent += 1
            except OSError:
                pass
    return sent


def scenario(args, name, pcap, ports, calib, rate, seconds, out=False, garbage=False,
             loop=True):
    off = free_port_base(ports)
    tmp = tempfile.mkdtemp(prefix="bench-listen-")
    listen = [args.bin, "listen", "--json", "--duration", str(seconds + 2)]
    for p in ports:
        listen += ["--sensor", f"127.0.0.1:{p + off}"]
    for c in calib:
        listen += ["--calib", c]
    if out:
        listen += ["--out", os.path.join(tmp, "out.mcap")]
        if args.threads:
            listen += ["--threads", str(args.threads)]
    la0 = loadavg()
    proc = subprocess.Popen(["/usr/bin/time", "-v", *listen], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    time.sleep(1.0)
    sent = 0
    replay_rate = None
    send_s = seconds
    if garbage:
        sent = flood(ports[0] + off, seconds)
    else:
        loops = 1
        if loop:
            datagrams, duration = capture_rate(args.bin, pcap, [x for c in calib for x in ("--calib", c)])
            per_loop = duration / (rate if rate != "max" else 50)
            loops = int(seconds / max(per_loop, 1e-3)) + 2  # --duration stops it
        r = subprocess.run([args.bin, "replay", pcap, "--to", "127.0.0.1", "--port-offset",
                            str(off), "--rate", str(rate), "--loop", str(loops), "--duration",
                            str(seconds), "--json"],
                           capture_output=True, text=True, check=True)
        rj = json.loads(r.stdout)
        sent = rj["sent"]
        replay_rate = rj["datagrams_per_s"]
        send_s = rj["elapsed_s"]
    stdout, stderr = proc.communicate()
    la1 = loadavg()
    try:
        j = json.loads(stdout)
    except json.JSONDecodeError:
        print(stderr, file=sys.stderr)
        raise
    user, sys_, rss_kb, wall = parse_time_v(stderr)
    rcv = j["receive"]
    row = {
        "scenario": name,
        "rate": rate,
        "out": out,
        "sent": sent,
        "send_rate_pps": replay_rate,
        "send_s": send_s,
        "received": rcv["datagrams"] + rcv["other_source"],
        "queue_dropped": rcv["queue_dropped"],
        "kernel_dropped": rcv["kernel_dropped"],
        "other_source": rcv["other_source"],
        "queue_peak_mib": rcv["queue_peak_bytes"] / 2**20,
        "sweeps": j["sweeps"],
        "points": j["points"],
        "missing": j["packets"]["missing"],
        "ignored": j["packets"]["ignored"],
        "cpu_pct": 100.0 * (user + sys_) / max(wall, 1e-3),
        "rss_mib": rss_kb / 1024,
        "wall_s": wall,
        "load_before": la0,
        "load_after": la1,
        "out_mib": (os.path.getsize(os.path.join(tmp, "out.mcap")) / 2**20) if out else None,
        "chunks": j["output"]["chunks"] if out else None,
        "chunks_uncompressed": j["output"]["chunks_uncompressed"] if out else None,
        "threads": j["output"]["threads"] if out else None,
    }
    if out:
        os.remove(os.path.join(tmp, "out.mcap"))
    os.rmdir(tmp)
    print(json.dumps(row), flush=True)
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin", required=True)
    ap.add_argument("--hdl64", required=True)
    ap.add_argument("--hdl64-calib", required=True)
    ap.add_argument("--ouster", required=True)
    ap.add_argument("--ouster-meta", required=True)
    ap.add_argument("--seconds", type=float, default=60)
    ap.add_argument("--ramp-seconds", type=float, default=10)
    ap.add_argument("--only", default="", help="comma-separated scenario names")
    ap.add_argument("--report", default="/tmp/bench_listen.md")
    ap.add_argument("--threads", type=int, default=None,
                    help="listen --threads with --out (default: listen's, the machine's cores)")
    a = ap.parse_args()
    a.bin = os.path.abspath(a.bin)
    # Velodyne inputs loop (the stream only sees its clock jump back: a discontinuity); the
    # Ouster input is sent once, never looped (repeated frame ids would be late or duplicate
    # packets, not load), so its scenarios last as long as its frames at that rate.
    H = (a.hdl64, [2368], [a.hdl64_calib], True)
    O = (a.ouster, [7502, 7503], [a.ouster_meta], False)
    plan = [
        ("hdl64e-10x-count", H, 10, a.seconds, False, False),
        ("os-rng19-10x-count", O, 10, a.seconds, False, False),
        ("hdl64e-1x-out", H, 1, a.seconds, True, False),
        ("hdl64e-5x-out", H, 5, a.seconds, True, False),
        ("os-rng19-1x-out", O, 1, a.seconds, True, False),
        ("os-rng19-5x-out", O, 5, a.seconds, True, False),
    ]
    for r in (15, 20, 30, 40, "max"):
        plan.append((f"hdl64e-{r}x-count", H, r, a.ramp_seconds, False, False))
    for r in (20, 40, "max"):
        plan.append((f"os-rng19-{r}x-count", O, r, a.ramp_seconds, False, False))
    for r in (5, 10, 12, 15, 20, 30, "max"):
        plan.append((f"hdl64e-{r}x-out-ramp", H, r, a.ramp_seconds, True, False))
    plan.append(("garbage-flood", H, 1, a.ramp_seconds, False, True))
    only = [x for x in a.only.split(",") if x]
    rows = []
    for name, (pcap, ports, calib, loop), rate, secs, out, garbage in plan:
        if only and name not in only:
            continue
        rows.append(scenario(a, name, pcap, ports, calib, rate, secs, out, garbage, loop))
    lines = [
        "| scenario | send rate (datagrams/s) | sent for (s) | sent | received | queue drops | kernel drops | "
        "sweeps | points | listen CPU % | peak RSS MiB | queue peak MiB | MCAP chunks (uncompressed) | load avg before/after |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | --- |",
    ]
    for r in rows:
        rate = f"{r['send_rate_pps']:.0f}" if r["send_rate_pps"] else "flood"
        lines.append(
            f"| {r['scenario']} | {rate} | {r['send_s']:.1f} | {r['sent']} | {r['received']} | {r['queue_dropped']} | "
            f"{r['kernel_dropped']} | {r['sweeps']} | {r['points']} | {r['cpu_pct']:.0f} | "
            f"{r['rss_mib']:.0f} | {r['queue_peak_mib']:.1f} | "
            + (f"{r['chunks']} ({r['chunks_uncompressed']}), {r['threads']} threads" if r["out"] else "")
            + f" | {r['load_before']} / {r['load_after']} |"
        )
    text = "\n".join(lines) + "\n"
    with open(a.report, "w") as f:
        f.write(text)
    with open(os.path.splitext(a.report)[0] + ".jsonl", "w") as f:
        for r in rows:
            f.write(json.dumps(r) + "\n")
    print(text)


if __name__ == "__main__":
    main()
