#!/usr/bin/env python3
"""Repeat a real Velodyne capture into one large, plausible, continuous capture (benchmarks).

Usage:
    python3 tools/make_big_capture.py [--in IN.pcap] --out OUT.pcap (--mb 200 | --copies N)

Copy k of the input (k = 0, 1, ...) is written unchanged except for its clocks, all moved by
k * S, where S = the capture's device-time span (top-of-hour stamp of the last data packet minus
that of the first) + one packet period (the median difference of consecutive data-packet
stamps), in whole microseconds. So copy k+1 starts one packet period after copy k ends, on both
clocks, and the result reads as one drive with no gap and no packet loss:

* pcap record timestamps (classic pcap, microsecond or nanosecond, either byte order);
* Velodyne data packets (1206-byte UDP payloads): the top-of-hour microseconds at payload bytes
  1200..1204 (little-endian u32), modulo one hour (3.6e9 us);
* Velodyne position packets (512-byte UDP payloads): the top-of-hour microseconds at payload
  offset 0xC6, and the `$..RMC` sentence at 0xCE (time of day and date moved by the same whole
  seconds as the packet's own stamp, checksum recomputed), so GPS time completion stays
  consistent;
* the UDP checksum of every rewritten datagram is recomputed (left 0 where it was 0).

Anything else (other payloads, non-UDP records, IPv4 fragments) is copied as it is.
Standard library only. The output is scratch data: delete it after use (tools/bench_velodyne.sh
does).
"""

import argparse
import datetime as dt
import os
import statistics
import struct
import sys

DEFAULT_IN = "/work/shared/captures/Kitware__VeloView/Testing/Data/monterey-first-100-packets.pcap"
HOUR_US = 3_600_000_000
DATA_LEN = 1206
POS_LEN = 512
POS_TOH = 0xC6
POS_NMEA = 0xCE
POS_NMEA_LEN = 128


def read_pcap(path):
    with open(path, "rb") as f:
        data = f.read()
    if len(data) < 24:
        sys.exit(f"{path}: too short for a pcap file")
    magic = data[:4]
    table = {
        b"\xd4\xc3\xb2\xa1": ("<", 1_000_000),
        b"\xa1\xb2\xc3\xd4": (">", 1_000_000),
        b"\x4d\x3c\xb2\xa1": ("<", 1_000_000_000),
        b"\xa1\xb2\x3c\x4d": (">", 1_000_000_000),
    }
    if magic not in table:
        sys.exit(f"{path}: not a classic pcap file (pcapng is not supported here)")
    endian, frac = table[magic]
    linktype = struct.unpack_from(endian + "I", data, 20)[0]
    records = []  # (offset of the record header, caplen)
    off = 24
    while off + 16 <= len(data):
        caplen = struct.unpack_from(endian + "I", data, off + 8)[0]
        if off + 16 + caplen > len(data):
            break  # truncated tail: dropped
        records.append((off, caplen))
        off += 16 + caplen
    return data, endian, frac, linktype, records


def udp_of(data, rec_off, caplen, linktype):
    """(offset of the IPv4 header, offset of the UDP header, payload offset, payload length) or None."""
    p = rec_off + 16
    end = p + caplen
    if linktype == 1:  # Ethernet
        if caplen < 14:
            return None
        etype = struct.unpack_from(">H", data, p + 12)[0]
        q = p + 14
        while etype in (0x8100, 0x88A8) and q + 4 <= end:
            etype = struct.unpack_from(">H", data, q + 2)[0]
            q += 4
        if etype != 0x0800:
            return None
        ip = q
    elif linktype in (101, 228):  # raw IPv4
        ip = p
    elif linktype == 113:  # Linux cooked (SLL)
        if caplen < 16 or struct.unpack_from(">H", data, p + 14)[0] != 0x0800:
            return None
        ip = p + 16
    else:
        return None
    if ip + 20 > end or data[ip] >> 4 != 4:
        return None
    ihl = (data[ip] & 0x0F) * 4
    if data[ip + 9] != 17:
        return None
    frag = struct.unpack_from(">H", data, ip + 6)[0]
    if frag & 0x3FFF:  # fragment (MF set or offset != 0)
        return None
    udp = ip + ihl
    if udp + 8 > end:
        return None
    ulen = struct.unpack_from(">H", data, udp + 4)[0]
    plen = min(ulen - 8, end - udp - 8)
    if plen < 0:
        return None
    return ip, udp, udp + 8, plen


def udp_checksum(buf, ip, udp, ulen):
    """UDP checksum over the IPv4 pseudo-header and the datagram in buf (checksum field as 0)."""
    pseudo = bytes(buf[ip + 12 : ip + 20]) + struct.pack(">BBH", 0, 17, ulen)
    seg = bytearray(buf[udp : udp + ulen])
    seg[6:8] = b"\0\0"
    blob = pseudo + bytes(seg)
    if len(blob) % 2:
        blob += b"\0"
    n = int.from_bytes(blob, "big")
    s = n % 0xFFFF  # one's complement sum of the 16-bit words (2^16 = 1 mod 0xFFFF)
    if s == 0 and n != 0:
        s = 0xFFFF
    c = ~s & 0xFFFF
    return c if c else 0xFFFF


def nmea_checksum(body):
    c = 0
    for ch in body:
        c ^= ch
    return c


def parse_rmc(sentence):
    """(fields, tail, has_checksum, rest after the checksum, UTC datetime) of a $..RMC sentence, or None."""
    try:
        s = sentence.decode("ascii")
    except UnicodeDecodeError:
        return None
    stripped = s.rstrip("\r\n")
    tail = s[len(stripped) :]
    if not stripped.startswith("$"):
        return None
    body, star, cs = stripped[1:].partition("*")
    f = body.split(",")
    if len(f) < 10 or not f[0].endswith("RMC") or len(f[1]) < 6 or len(f[9]) != 6:
        return None
    try:
        hh, mm, ss = int(f[1][0:2]), int(f[1][2:4]), int(f[1][4:6])
        day, mon, yy = int(f[9][0:2]), int(f[9][2:4]), int(f[9][4:6])
        t = dt.datetime(2000 + yy if yy < 80 else 1900 + yy, mon, day, hh, mm, ss)
    except ValueError:
        return None
    return f, tail, star, cs, t


def shift_rmc(sentence, seconds):
    """Moves the time and date of a $..RMC sentence by whole seconds; None if not an RMC."""
    r = parse_rmc(sentence)
    if r is None:
        return None
    f, tail, star, cs, t = r
    t += dt.timedelta(seconds=seconds)
    f[1] = t.strftime("%H%M%S") + f[1][6:]
    f[9] = t.strftime("%d%m%y")
    body = ",".join(f)
    out = "$" + body
    if star:
        out += "*%02X" % nmea_checksum(body.encode("ascii")) + cs[2:]
    return (out + tail).encode("ascii")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--in", dest="inp", default=DEFAULT_IN, help="input capture (classic pcap)")
    ap.add_argument("--out", required=True, help="output pcap")
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--mb", type=float, help="target size in MB (10^6 bytes); copies = ceil(target / input)")
    g.add_argument("--copies", type=int, help="number of copies")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args()

    data, endian, frac, linktype, records = read_pcap(args.inp)
    scale = frac // 1_000_000  # pcap sub-second units per microsecond
    hdr = endian + "IIII"

    # Classify the records once.
    plan = []  # (rec_off, caplen, kind, ip, udp, payload_off, ulen)
    data_toh = []
    for rec_off, caplen in records:
        u = udp_of(data, rec_off, caplen, linktype)
        kind = None
        if u is not None:
            ip, udp, pay, plen = u
            ulen = struct.unpack_from(">H", data, udp + 4)[0]
            if plen == DATA_LEN and ulen == DATA_LEN + 8:
                kind = "data"
                data_toh.append(struct.unpack_from("<I", data, pay + 1200)[0])
            elif plen == POS_LEN and ulen == POS_LEN + 8:
                kind = "pos"
        if kind is None:
            plan.append((rec_off, caplen, None, 0, 0, 0, 0))
        else:
            plan.append((rec_off, caplen, kind, ip, udp, pay, ulen))
    # Phase of the GPS second on the top-of-hour clock: the stamp of the first position packet
    # whose RMC second differs from the previous one's (the sentence's second changes there).
    # The RMC of a packet moved by d then says its second + floor((toh - c + d) / 1 s) -
    # floor((toh - c) / 1 s), which is what a continuous drive would have said.
    rmc_phase = None
    prev_rmc = None
    for rec_off, caplen, kind, ip, udp, pay, ulen in plan:
        if kind != "pos":
            continue
        toh = struct.unpack_from("<I", data, pay + POS_TOH)[0]
        r = parse_rmc(data[pay + POS_NMEA : pay + POS_NMEA + POS_NMEA_LEN].split(b"\0", 1)[0])
        if r is None:
            continue
        if rmc_phase is None:
            rmc_phase = toh  # fallback: no change seen, all packets within one second of this
        if prev_rmc is not None and r[4] != prev_rmc:
            rmc_phase = toh
            break
        prev_rmc = r[4]
    if rmc_phase is None:
        rmc_phase = 0
    if len(data_toh) < 2:
        sys.exit(f"{args.inp}: fewer than 2 Velodyne data packets")
    diffs = [(b - a) % HOUR_US for a, b in zip(data_toh, data_toh[1:])]
    period_us = int(round(statistics.median(diffs)))
    span_us = (data_toh[-1] - data_toh[0]) % HOUR_US
    shift_us = span_us + period_us

    in_size = len(data)
    if args.copies is not None:
        copies = max(1, args.copies)
    else:
        copies = max(1, -(-int(args.mb * 1_000_000 - 24) // (in_size - 24)))

    tmp = args.out + ".part"
    with open(tmp, "wb", buffering=16 << 20) as out:
        out.write(data[:24])
        for k in range(copies):
            d_us = k * shift_us
            buf = bytearray(data)
            for rec_off, caplen, kind, ip, udp, pay, ulen in plan:
                sec, sub, _, _ = struct.unpack_from(hdr, buf, rec_off)
                t = (sec * frac + sub) + d_us * scale
                struct.pack_into(endian + "II", buf, rec_off, t // frac, t % frac)
                if kind is None or k == 0:
                    continue
                if kind == "data":
                    o = pay + 1200
                    toh = struct.unpack_from("<I", buf, o)[0]
                    struct.pack_into("<I", buf, o, (toh + d_us) % HOUR_US)
                else:
                    o = pay + POS_TOH
                    toh = struct.unpack_from("<I", buf, o)[0]
                    struct.pack_into("<I", buf, o, (toh + d_us) % HOUR_US)
                    # Whole seconds the packet's stamp moved past, as the GPS second counts them.
                    secs = (toh - rmc_phase + d_us) // 1_000_000 - (toh - rmc_phase) // 1_000_000
                    field = bytes(buf[pay + POS_NMEA : pay + POS_NMEA + POS_NMEA_LEN])
                    sentence = field.split(b"\0", 1)[0]
                    new = shift_rmc(sentence, secs) if sentence else None
                    if new is not None and len(new) <= POS_NMEA_LEN:
                        nf = new + b"\0" * (POS_NMEA_LEN - len(new))
                        buf[pay + POS_NMEA : pay + POS_NMEA + POS_NMEA_LEN] = nf
                if struct.unpack_from(">H", buf, udp + 6)[0] != 0:
                    struct.pack_into(">H", buf, udp + 6, udp_checksum(buf, ip, udp, ulen))
            out.write(memoryview(buf)[24:])
    os.replace(tmp, args.out)
    if not args.quiet:
        size = os.path.getsize(args.out)
        print(
            f"{args.out}: {copies} copies of {args.inp} ({in_size} bytes, {len(data_toh)} data packets), "
            f"{size} bytes, {copies * len(data_toh)} data packets, "
            f"{copies * shift_us / 1e6:.3f} s of capture (copy shift {shift_us} us, packet period {period_us} us)"
        )


if __name__ == "__main__":
    main()
