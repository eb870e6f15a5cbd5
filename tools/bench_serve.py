#!/usr/bin/env python3
"""What `--serve` costs the run it is attached to, side by side in one run.

1. `ringscan decode BIG.pcap --out X.mcap --serve-rate max`: process wall time without `--serve`,
   with `--serve` and no client, with one client that reads every /points message, and with one
   client that subscribes and never reads (best of ROUNDS each, interleaved).
2. `ringscan listen` fed by `ringscan replay BIG.pcap --rate R`: receive-side drops and what a
   reading and a never-reading client got, at R times real time.

Usage (from tools/bench_serve.sh): bench_serve.py --bin BIN --pcap BIG.pcap --tmp DIR
"""

import argparse
import os
import signal
import statistics
import subprocess
import threading
import time

from serve_client import Client, Run, free_udp_port, open_ws


def decode_run(a, mode, out):
    args = [a.bin, "decode", a.pcap, "--out", out, "--json"]
    if mode != "no --serve":
        args += ["--serve", "127.0.0.1:0", "--serve-rate", "max"]
    t0 = time.perf_counter()
    run = Run(args, False, wait_addr=mode != "no --serve")
    got = []
    ws = None
    if mode in ("--serve, reading client", "--serve, client never reads"):
        ws = open_ws(run.addr)
        c = Client(ws)
        ch = c.wait_channel("/points")
        c.subscribe(1, ch["id"])
        if mode == "--serve, reading client":
            th = threading.Thread(target=lambda: got.extend(c.receive_all()))
            th.start()
    summary = run.finish()
    wall = time.perf_counter() - t0
    if ws is not None:
        if mode == "--serve, reading client":
            th.join(timeout=30)
        ws.close()
    return wall, summary, len(got)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", required=True)
    ap.add_argument("--pcap", required=True)
    ap.add_argument("--tmp", required=True)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--rate", default="10")
    a = ap.parse_args()
    out = os.path.join(a.tmp, "bench.mcap")
    modes = ["no --serve", "--serve, no client", "--serve, reading client", "--serve, client never reads"]
    walls = {m: [] for m in modes}
    last = {}
    for _ in range(a.rounds):
        for m in modes:
            w, s, got = decode_run(a, m, out)
            walls[m].append(w)
            last[m] = (s, got)
    base = min(walls["no --serve"])
    print(f"decode --serve-rate max, {a.pcap} ({os.path.getsize(a.pcap) / 1e6:.1f} MB), best of {a.rounds}:")
    print("| run | wall (s), best | median | / no --serve | sweeps sent to the client | dropped for it |")
    print("|---|---:|---:|---:|---:|---:|")
    for m in modes:
        s, got = last[m]
        serve = (s or {}).get("serve") or {}
        sent = serve.get("messages_sent", "")
        print(
            f"| {m} | {min(walls[m]):.3f} | {statistics.median(walls[m]):.3f} | {min(walls[m]) / base:.2f} | "
            f"{sent} | {serve.get('messages_dropped', '')} |"
        )
    sweeps = (last["no --serve"][0] or {}).get("sweeps")

    # listen, fed at R times real time.
    port = free_udp_port()
    out = os.path.join(a.tmp, "listen.mcap")
    run = Run([a.bin, "listen", "--sensor", f"127.0.0.1:{port}", "--out", out, "--serve", "127.0.0.1:0", "--json"], True)
    with open_ws(run.addr) as w1, open_ws(run.addr) as w2:
        reader, stalled = Client(w1), Client(w2)
        rp = subprocess.Popen(
            [a.bin, "replay", a.pcap, "--to", "127.0.0.1", "--port-offset", str(port - 2368), "--rate", a.rate],
            stdout=subprocess.DEVNULL,
        )
        ch = reader.wait_channel("/points")
        reader.subscribe(1, ch["id"])
        stalled.wait_channel("/points")
        stalled.subscribe(1, ch["id"])
        got = []
        th = threading.Thread(target=lambda: got.extend(reader.receive_all()))
        th.start()
        rp.wait()
        time.sleep(0.5)
        s = run.finish(signal.SIGINT)
        th.join(timeout=30)
    r = s["receive"]
    clients = s["serve"]["clients"]
    print()
    print(f"listen --serve fed by replay --rate {a.rate}: {s['sweeps']} sweeps, {r['datagrams']} datagrams;"
          f" receive queue dropped {r['queue_dropped']}, kernel dropped {r['kernel_dropped']}, missing packets {s['packets']['missing']};"
          f" reading client got {len(got)} sweeps; per client (sent, dropped): {[(c['sent'], c['dropped']) for c in clients]}")


if __name__ == "__main__":
    main()
