#!/usr/bin/env python3
"""Peak memory of `ringscan decode` on hostile captures (issue: hardening, memory bounds).

Writes three captures into a scratch directory, runs `ringscan decode FILE --json` (and with
`--out` to an MCAP) under `/usr/bin/time -v`, prints the peak resident set size of each run as
a Markdown table, and deletes the captures:

1. random:    a valid pcap header followed by 1 GB of random bytes (records of random lengths);
2. fragments: 10^6 lone first IPv4 fragments (MF set, offset 0, distinct IP ids, 1480-byte
              payloads: 1.5 GB) that never complete;
3. flood:     20,000 maximum-size UDP datagrams (65,507-byte payloads, unfragmented jumbo
              frames) from 1,000 source addresses to the Velodyne port.

Usage: tools/memory_bounds.py [--bin target/release/ringscan] [--dir DIR] [--scale 1.0]
"""
import argparse
import os
import random
import re
import shutil
import struct
import subprocess
import sys
import tempfile


def pcap_header(snaplen=262144):
    return struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, snaplen, 1)


def record(ts_us, frame):
    return struct.pack("<IIII", ts_us // 1_000_000, ts_us % 1_000_000, len(frame), len(frame)) + frame


def ipv4(src, dst, ident, flags_off, payload, proto=17):
    total = 20 + len(payload)
    hdr = struct.pack("!BBHHHBBH4s4s", 0x45, 0, total, ident, flags_off, 64, proto, 0, src, dst)
    return b"\x00\x01\x02\x03\x04\x05\x06\x07\x08\x09\x0a\x0b\x08\x00" + hdr + payload


def write_random(path, size):
    rnd = random.Random(7)
    with open(path, "wb") as f:
        f.write(pcap_header())
        left = size
        chunk = 1 << 20
        while left > 0:
            n = min(chunk, left)
            f.write(rnd.randbytes(n))
            left -= n


def write_fragments(path, count):
    with open(path, "wb") as f:
        f.write(pcap_header())
        body = bytes(1480)
        for i in range(count):
            src = bytes([10, (i >> 16) & 255, (i >> 8) & 255, i & 255])
            udp = struct.pack("!HHHH", 7502, 7502, 8 + 20000, 0) + body[8:]
            frame = ipv4(src, b"\x0a\x00\x00\x01", i & 0xFFFF, 0x2000, udp)
            f.write(record(1_700_000_000_000_000 + i * 10, frame))


def write_flood(path, count):
    with open(path, "wb") as f:
        f.write(pcap_header())
        payload = bytes(65507)
        for i in range(count):
            src = bytes([192, 168, (i % 1000) >> 8, (i % 1000) & 255])
            udp = struct.pack("!HHHH", 2368, 2368, 8 + len(payload), 0) + payload
            frame = ipv4(src, b"\xff\xff\xff\xff", i & 0xFFFF, 0x4000, udp)
            f.write(record(1_700_000_000_000_000 + i * 100, frame))


def peak_rss_kb(cmd):
    r = subprocess.run(["/usr/bin/time", "-v"] + cmd, capture_output=True, text=True)
    m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", r.stderr)
    return (int(m.group(1)) if m else -1), r.returncode


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/ringscan")
    ap.add_argument("--dir", default=None)
    ap.add_argument("--scale", type=float, default=1.0)
    a = ap.parse_args()
    if not os.path.exists("/usr/bin/time"):
        sys.exit("needs /usr/bin/time (apt-get install time)")
    d = a.dir or tempfile.mkdtemp(prefix="ringscan-mem-")
    os.makedirs(d, exist_ok=True)
    cases = [
        ("1 GB of random bytes after a pcap header", "random.pcap", lambda p: write_random(p, int(1e9 * a.scale))),
        ("10^6 lone first fragments (1.5 GB)", "fragments.pcap", lambda p: write_fragments(p, int(1e6 * a.scale))),
        ("20,000 max-size datagrams from 1,000 sources (1.3 GB)", "flood.pcap", lambda p: write_flood(p, int(20000 * a.scale))),
    ]
    print("| input | file size | peak RSS, decode (no output) | peak RSS, decode --out | exit codes |")
    print("|---|---:|---:|---:|---|")
    try:
        for label, name, make in cases:
            p = os.path.join(d, name)
            make(p)
            size = os.path.getsize(p)
            rss1, rc1 = peak_rss_kb([a.bin, "decode", p, "--json"])
            out = os.path.join(d, "out.mcap")
            rss2, rc2 = peak_rss_kb([a.bin, "decode", p, "--json", "--out", out])
            print(f"| {label} | {size / 1e6:.0f} MB | {rss1 / 1024:.1f} MiB | {rss2 / 1024:.1f} MiB | {rc1}, {rc2} |", flush=True)
            os.remove(p)
            if os.path.exists(out):
                os.remove(out)
    finally:
        if a.dir is None:
            shutil.rmtree(d, ignore_errors=True)


if __name__ == "__main__":
    main()
