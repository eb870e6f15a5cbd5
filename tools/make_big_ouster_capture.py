#!/usr/bin/env python3
"""Repeat a real Ouster capture into one long, continuous capture (benchmarks).

Usage:
    python3 tools/make_big_ouster_capture.py --meta META.json [--in IN.pcap] --frames 1000 \\
        [--out BIG.pcap] [--out-fragmented BIG-frag.pcap] [--mtu 1500]

The input (default: ouster-sdk's `OS-2-128-U1_v2.3.0_1024x10.pcap`, one complete 1024-column
frame of an OS-2-128, RNG19_RFL8_SIG16_NIR16, 64 lidar + 10 LEGACY IMU packets) is repeated
until the output holds at least `--frames` sensor frames. Copy k (k = 0, 1, ...) is the input
with every clock moved by k * S and every frame id by k * F, where F = frames in the input
(last lidar frame_id - first + 1) and S = F * the frame period (1 / fps of the metadata's
`lidar_mode`, e.g. 100 ms at 1024x10). So copy k+1 starts one frame after copy k, on every
clock, and the result reads as one recording with no gap and no loss:

* lidar packets: frame_id (standard header u16 @2 modulo 2^16, FUSA header u32 @4, LEGACY: the
  u16 @10 of every column header), every column timestamp (u64 @0 of the column header);
* LEGACY IMU packets (48 bytes on the IMU port): the three timestamps (u64 @0, @8, @16);
* pcap record times;
* the lidar footer CRC-64/XZ is recomputed only if the input's packets carry valid CRCs
  (FW >= 2.5); FW 2.3 / 2.4 footers are not CRCs and are left as they are (pure Python: slow);
* IPv4: every datagram gets its own IP id (a counter modulo 2^16 over the whole output), the
  IPv4 header checksum is recomputed, and the UDP checksum too where the input's was valid
  (left as it is otherwise, e.g. 0).

Two outputs, either or both:

* `--out`: one (jumbo) frame per datagram, as the input has (the SDK's 127.0.0.1 captures);
* `--out-fragmented`: each IPv4 datagram longer than the MTU split into IPv4 fragments as a
  sender at that MTU does: at most MTU - 20 payload bytes per fragment (a multiple of 8 except
  for the last), fragment offsets in 8-byte units, MF on all but the last, the same IP id for
  all fragments of one datagram, sent in order and all stamped with the datagram's time (the
  input's times are those of whole datagrams; spreading the fragments by their wire time
  would move some past the next datagram).

Only classic little- or big-endian pcap with Ethernet link type and plain IPv4 (no options)
UDP is handled; other records are copied unchanged. Standard library only. The output is
scratch data: delete it after use (tools/bench_ouster.sh does).
"""

import argparse
import json
import os
import struct
import sys

PCAPS = "/work/shared/captures/ouster-lidar__ouster-sdk/tests/pcaps"
DEFAULT_IN = f"{PCAPS}/OS-2-128-U1_v2.3.0_1024x10.pcap"
DEFAULT_META = f"{PCAPS}/OS-2-128-U1_v2.3.0_1024x10.json"

PIXEL_BYTES = {
    "LEGACY": 12,
    "RNG19_RFL8_SIG16_NIR16": 12,
    "RNG19_RFL8_SIG16_NIR16_DUAL": 16,
    "RNG15_RFL8_NIR8": 4,
    "RNG15_RFL8_NIR8_DUAL": 8,
    "FUSA_RNG15_RFL8_NIR8_DUAL": 8,
    "FIVE_WORD_PIXEL": 20,
    "RNG15_RFL8_WIN8": 4,
}
IMU_LEGACY_BYTES = 48


def find(obj, key):
    """First value of `key` anywhere in a JSON object (flat or nested metadata layouts)."""
    if isinstance(obj, dict):
        if key in obj:
            return obj[key]
        for v in obj.values():
            r = find(v, key)
            if r is not None:
                return r
    elif isinstance(obj, list):
        for v in obj:
            r = find(v, key)
            if r is not None:
                return r
    return None


class Format:
    """What the rewriting needs to know of the sensor, from its metadata."""

    def __init__(self, meta_path):
        with open(meta_path, encoding="utf-8") as f:
            meta = json.load(f)
        self.profile = find(meta, "udp_profile_lidar") or "LEGACY"
        if self.profile not in PIXEL_BYTES:
            sys.exit(f"{meta_path}: lidar profile {self.profile} not handled")
        self.h = int(find(meta, "pixels_per_column"))
        self.cpp = int(find(meta, "columns_per_packet") or 16)
        mode = find(meta, "lidar_mode") or "1024x10"
        self.w, fps = (int(x) for x in mode.split("x"))
        self.period_ns = 1_000_000_000 // fps
        self.port_lidar = int(find(meta, "udp_port_lidar") or 7502)
        self.port_imu = int(find(meta, "udp_port_imu") or 7503)
        self.legacy = self.profile == "LEGACY"
        self.fusa = self.profile.startswith("FUSA")
        self.header = 0 if self.legacy else 32
        self.col_header = 16 if self.legacy else 12
        self.col_bytes = (
            self.col_header + self.h * PIXEL_BYTES[self.profile] + (4 if self.legacy else 0)
        )
        self.packet_bytes = 2 * self.header + self.cpp * self.col_bytes

    def frame_id(self, p):
        if self.legacy:
            return struct.unpack_from("<H", p, 10)[0], 1 << 16
        if self.fusa:
            return struct.unpack_from("<I", p, 4)[0], 1 << 32
        return struct.unpack_from("<H", p, 2)[0], 1 << 16


# ----- checksums ------------------------------------------------------------------------------


def ones_sum(b):
    """One's-complement sum of 16-bit big-endian words (odd length: zero-padded).

    2^16 = 1 (mod 0xFFFF), so the sum of the words is the whole buffer read as one big integer,
    modulo 0xFFFF; a result of 0 stands for 0xFFFF (non-zero data never sums to +0).
    """
    if len(b) % 2:
        b = bytes(b) + b"\0"
    r = int.from_bytes(b, "big") % 0xFFFF
    return r if r or not any(b) else 0xFFFF


def checksum(*parts):
    s = 0
    for p in parts:
        s += ones_sum(p)
    s = (s & 0xFFFF) + (s >> 16)
    s = (s & 0xFFFF) + (s >> 16)
    return (~s) & 0xFFFF


def udp_checksum(src, dst, udp):
    """UDP checksum of `udp` (header with its checksum field zeroed + data)."""
    pseudo = src + dst + struct.pack(">BBH", 0, 17, len(udp))
    c = checksum(pseudo, udp)
    return c or 0xFFFF


def crc64_table():
    poly = 0xC96C5795D7870F42
    t = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ poly if c & 1 else c >> 1
        t.append(c)
    return t


CRC_TABLE = crc64_table()


def crc64_xz(b):
    crc = 0xFFFFFFFFFFFFFFFF
    t = CRC_TABLE
    for x in b:
        crc = t[(crc ^ x) & 0xFF] ^ (crc >> 8)
    return crc ^ 0xFFFFFFFFFFFFFFFF


# ----- pcap -----------------------------------------------------------------------------------


def read_pcap(path):
    with open(path, "rb") as f:
        data = f.read()
    magic = data[:4]
    table = {
        b"\xd4\xc3\xb2\xa1": ("<", 1_000_000),
        b"\xa1\xb2\xc3\xd4": (">", 1_000_000),
        b"\x4d\x3c\xb2\xa1": ("<", 1_000_000_000),
        b"\xa1\xb2\x3c\x4d": (">", 1_000_000_000),
    }
    if len(data) < 24 or magic not in table:
        sys.exit(f"{path}: not a classic pcap file")
    endian, frac = table[magic]
    linktype = struct.unpack_from(endian + "I", data, 20)[0]
    records = []  # (time in ns, record bytes)
    off = 24
    while off + 16 <= len(data):
        sec, sub, caplen, _orig = struct.unpack_from(endian + "IIII", data, off)
        if off + 16 + caplen > len(data):
            break
        t = sec * 1_000_000_000 + sub * (1_000_000_000 // frac)
        records.append((t, data[off + 16 : off + 16 + caplen]))
        off += 16 + caplen
    return data[:24], endian, frac, linktype, records


class Datagram:
    """An Ethernet / IPv4 (no options, not a fragment) / UDP record, split into its parts."""

    __slots__ = ("eth", "tos", "ttl", "src", "dst", "sport", "dport", "csum_ok", "payload")

    @staticmethod
    def parse(rec, linktype):
        if linktype != 1 or len(rec) < 14 + 20 + 8 or rec[12:14] != b"\x08\x00":
            return None
        ip = rec[14:]
        vihl, tos, tot, _id, ff, ttl, proto = struct.unpack_from(">BBHHHBB", ip, 0)
        if vihl != 0x45 or proto != 17 or ff & 0x3FFF or tot > len(ip):
            return None
        udp = ip[20:tot]
        sport, dport, ulen, ucsum = struct.unpack_from(">HHHH", udp, 0)
        if ulen != len(udp):
            return None
        d = Datagram()
        d.eth, d.tos, d.ttl = rec[:14], tos, ttl
        d.src, d.dst = ip[12:16], ip[16:20]
        d.sport, d.dport = sport, dport
        zeroed = udp[:6] + b"\0\0" + udp[8:]
        d.csum_ok = ucsum != 0 and udp_checksum(d.src, d.dst, zeroed) == ucsum
        d.payload = udp[8:]
        return d


class Writer:
    def __init__(self, path, header, endian, frac):
        self.path = path
        self.f = open(path, "wb", buffering=1 << 20)
        self.f.write(header)
        self.endian = endian
        self.frac = frac
        self.bytes = len(header)
        self.records = 0

    def record(self, t_ns, body):
        sec, rem = divmod(t_ns, 1_000_000_000)
        sub = rem // (1_000_000_000 // self.frac)
        self.f.write(struct.pack(self.endian + "IIII", sec, sub, len(body), len(body)))
        self.f.write(body)
        self.bytes += 16 + len(body)
        self.records += 1

    def close(self):
        self.f.close()


def ip_header(d, total, ip_id, flags_off):
    h = struct.pack(">BBHHHBBH4s4s", 0x45, d.tos, total, ip_id, flags_off, d.ttl, 17, 0, d.src, d.dst)
    c = checksum(h)
    return h[:10] + struct.pack(">H", c) + h[12:]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--in", dest="inp", default=DEFAULT_IN, help="real Ouster capture (classic pcap)")
    ap.add_argument("--meta", default=DEFAULT_META, help="its metadata JSON")
    ap.add_argument("--frames", type=int, default=1000, help="sensor frames at least (default 1000)")
    ap.add_argument("--out", help="output: one frame per datagram")
    ap.add_argument("--out-fragmented", help="output: datagrams fragmented at --mtu")
    ap.add_argument("--mtu", type=int, default=1500, help="IPv4 MTU of --out-fragmented (default 1500)")
    a = ap.parse_args()
    if not a.out and not a.out_fragmented:
        ap.error("give --out and/or --out-fragmented")
    if a.mtu < 68:
        ap.error("--mtu must be at least 68")

    fmt = Format(a.meta)
    header, endian, frac, linktype, records = read_pcap(a.inp)
    parsed = [(t, rec, Datagram.parse(rec, linktype)) for t, rec in records]

    def is_lidar(d):
        return d is not None and d.dport == fmt.port_lidar and len(d.payload) == fmt.packet_bytes

    def is_imu(d):
        return d is not None and d.dport == fmt.port_imu and len(d.payload) == IMU_LEGACY_BYTES

    lidar = [d for _, _, d in parsed if is_lidar(d)]
    if not lidar:
        sys.exit(f"{a.inp}: no lidar packet of {fmt.packet_bytes} bytes on port {fmt.port_lidar}")
    first_fid, modulus = fmt.frame_id(lidar[0].payload)
    last_fid, _ = fmt.frame_id(lidar[-1].payload)
    frames_per_copy = (last_fid - first_fid) % modulus + 1
    copies = -(-a.frames // frames_per_copy)
    span_ns = frames_per_copy * fmt.period_ns
    p0 = lidar[0].payload
    crc_valid = not fmt.legacy and not fmt.fusa and crc64_xz(p0[:-8]) == struct.unpack_from("<Q", p0, len(p0) - 8)[0]

    writers = []
    if a.out:
        writers.append((Writer(a.out + ".part", header, endian, frac), None))
    if a.out_fragmented:
        writers.append((Writer(a.out_fragmented + ".part", header, endian, frac), a.mtu - 20))
    ip_id = 0
    n_lidar = n_imu = n_frag = 0

    for k in range(copies):
        dt = k * span_ns
        for t, rec, d in parsed:
            t_out = t + dt
            if d is None:
                for w, _ in writers:
                    w.record(t_out, rec)
                continue
            payload = d.payload
            if is_lidar(d):
                p = bytearray(payload)
                if fmt.legacy:
                    for c in range(fmt.cpp):
                        o = c * fmt.col_bytes
                        fid = struct.unpack_from("<H", p, o + 10)[0]
                        struct.pack_into("<H", p, o + 10, (fid + k * frames_per_copy) % modulus)
                elif fmt.fusa:
                    fid = struct.unpack_from("<I", p, 4)[0]
                    struct.pack_into("<I", p, 4, (fid + k * frames_per_copy) % modulus)
                else:
                    fid = struct.unpack_from("<H", p, 2)[0]
                    struct.pack_into("<H", p, 2, (fid + k * frames_per_copy) % modulus)
                for c in range(fmt.cpp):
                    o = fmt.header + c * fmt.col_bytes
                    ts = struct.unpack_from("<Q", p, o)[0]
                    if ts:
                        struct.pack_into("<Q", p, o, ts + dt)
                if crc_valid:
                    struct.pack_into("<Q", p, len(p) - 8, crc64_xz(p[:-8]))
                payload = bytes(p)
                n_lidar += 1
            elif is_imu(d):
                p = bytearray(payload)
                for o in (0, 8, 16):
                    ts = struct.unpack_from("<Q", p, o)[0]
                    if ts:
                        struct.pack_into("<Q", p, o, ts + dt)
                payload = bytes(p)
                n_imu += 1
            udp = struct.pack(">HHHH", d.sport, d.dport, 8 + len(payload), 0) + payload
            if d.csum_ok:
                udp = udp[:6] + struct.pack(">H", udp_checksum(d.src, d.dst, udp)) + udp[8:]
            for w, max_frag in writers:
                if max_frag is None or len(udp) <= max_frag:
                    w.record(t_out, d.eth + ip_header(d, 20 + len(udp), ip_id, 0) + udp)
                    continue
                step = max_frag // 8 * 8
                for off in range(0, len(udp), step):
                    chunk = udp[off : off + step]
                    more = off + step < len(udp)
                    flags_off = (0x2000 if more else 0) | (off // 8)
                    body = d.eth + ip_header(d, 20 + len(chunk), ip_id, flags_off) + chunk
                    w.record(t_out, body)
                    n_frag += 1
            ip_id = (ip_id + 1) & 0xFFFF

    summary = {
        "input": a.inp,
        "metadata": a.meta,
        "profile": fmt.profile,
        "pixels_per_column": fmt.h,
        "columns_per_frame": fmt.w,
        "frames_per_copy": frames_per_copy,
        "copies": copies,
        "frames": copies * frames_per_copy,
        "lidar_packets": n_lidar,
        "imu_packets": n_imu,
        "crc_recomputed": crc_valid,
        "span_s": copies * span_ns / 1e9,
    }
    for w, max_frag in writers:
        w.close()
        final = w.path[: -len(".part")]
        os.replace(w.path, final)
        key = "out" if max_frag is None else "out_fragmented"
        summary[key] = {"path": final, "bytes": w.bytes, "records": w.records}
    if a.out_fragmented:
        summary["out_fragmented"]["fragments"] = n_frag
        summary["out_fragmented"]["mtu"] = a.mtu
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
