#!/usr/bin/env python3
"""Writes the seed corpora of the fuzz targets into tools/fuzz/corpus/<target>/ (git-ignored).

Seeds come from the repository's fixtures/ and, when present, the real captures and
calibration files in ../shared/captures (read at run time; nothing from there is committed).
Each seed is small (libFuzzer works best on inputs of a few KB): captures are cut after their
first records (a truncated tail is a valid input), and pcapng variants are written from the
classic files. Existing corpus files are kept (libFuzzer adds to the same folders).

Usage: tools/fuzz/seed_corpus.py [--captures DIR]
"""

import argparse
import hashlib
import os
import random
import struct
import zlib
import sys
from pathlib import Path

FUZZ = Path(__file__).resolve().parent
REPO = FUZZ.parent.parent
CORPUS = FUZZ / "corpus"


def put(target, data, tag=""):
    d = CORPUS / target
    d.mkdir(parents=True, exist_ok=True)
    name = (tag + "-" if tag else "") + hashlib.sha1(data).hexdigest()[:16]
    (d / name).write_bytes(data)


# ----- pcap reading / writing ----------------------------------------------------------------


def read_classic(data):
    """(endian, nanos, linktype, [(sec, frac, caplen, origlen, frame)]) of a classic pcap."""
    magic = data[:4]
    if magic in (b"\xd4\xc3\xb2\xa1", b"\x4d\x3c\xb2\xa1"):
        e = "<"
    elif magic in (b"\xa1\xb2\xc3\xd4", b"\xa1\xb2\x3c\x4d"):
        e = ">"
    else:
        return None
    nanos = magic in (b"\x4d\x3c\xb2\xa1", b"\xa1\xb2\x3c\x4d")
    linktype = struct.unpack(e + "I", data[20:24])[0] & 0xFFFF
    recs, at = [], 24
    while at + 16 <= len(data):
        sec, frac, cap, orig = struct.unpack(e + "IIII", data[at : at + 16])
        frame = data[at + 16 : at + 16 + cap]
        if len(frame) < cap:
            break
        recs.append((sec, frac, cap, orig, frame))
        at += 16 + cap
    return e, nanos, linktype, recs


def classic_bytes(e, nanos, linktype, recs, snaplen=65535):
    magic = 0xA1B23C4D if nanos else 0xA1B2C3D4
    out = bytearray(struct.pack(e + "IHHiIII", magic, 2, 4, 0, 0, snaplen, linktype))
    for sec, frac, cap, orig, frame in recs:
        out += struct.pack(e + "IIII", sec, frac, len(frame), orig) + frame
    return bytes(out)


def ng_block(e, btype, body):
    pad = (-len(body)) % 4
    total = 12 + len(body) + pad
    return struct.pack(e + "II", btype, total) + body + b"\0" * pad + struct.pack(e + "I", total)


def pcapng_bytes(e, nanos, linktype, recs, tsresol=None):
    shb = struct.pack(e + "IHHq", 0x1A2B3C4D, 1, 0, -1)
    out = bytearray(ng_block(e, 0x0A0D0D0A, shb))
    opts = b""
    res = tsresol if tsresol is not None else (9 if nanos else 6)
    if res != 6:
        opts = struct.pack(e + "HH", 9, 1) + bytes([res]) + b"\0\0\0" + struct.pack(e + "HH", 0, 0)
    out += ng_block(e, 1, struct.pack(e + "HHI", linktype, 0, 0) + opts)
    for sec, frac, cap, orig, frame in recs:
        if res == 9:
            ts = sec * 1_000_000_000 + (frac if nanos else frac * 1000)
        else:
            ts = sec * 1_000_000 + (frac // 1000 if nanos else frac)
        body = struct.pack(e + "IIIII", 0, ts >> 32, ts & 0xFFFFFFFF, len(frame), orig) + frame
        out += ng_block(e, 6, body)
    return bytes(out)


def udp_payloads(recs, linktype):
    """(src ip bytes, dst port, payload) of unfragmented IPv4 UDP in Ethernet records."""
    out = []
    for _sec, _frac, _cap, _orig, f in recs:
        if linktype != 1 or len(f) < 42 or f[12:14] != b"\x08\x00":
            continue
        ihl = (f[14] & 15) * 4
        if f[23] != 17:
            continue
        udp = 14 + ihl
        dport = struct.unpack(">H", f[udp + 2 : udp + 4])[0]
        ulen = struct.unpack(">H", f[udp + 4 : udp + 6])[0]
        out.append((f[26:30], dport, f[udp + 8 : udp + ulen]))
    return out


def head_records(recs, max_bytes):
    out, size = [], 24
    for r in recs:
        size += 16 + len(r[4])
        if size > max_bytes and out:
            break
        out.append(r)
    return out


# ----- synthetic Velodyne packets (for the stream and packet targets) ------------------------


def synth_ops(rng, n, model_sel, az0, step):
    """velodyne_stream ops of kind 1 (synthesised data packet), `n` of them."""
    out = bytearray()
    for i in range(n):
        out += bytes([1]) + struct.pack("<h", 130) + struct.pack("<H", 1327)
        out += bytes([model_sel]) + struct.pack("<HhB", (az0 + i * 12 * step) % 36000, step, rng.randrange(256))
    return bytes(out)



# ----- Ouster seeds ----------------------------------------------------------------------------

# (profile index in harness order, pixel bytes, legacy header?) as ringscan's model tables say.
OUSTER_PROFILES = [(0, 12, True), (1, 12, False), (2, 16, False), (3, 4, False), (4, 8, False),
                   (5, 8, False), (6, 20, False), (7, 4, False)]


def ouster_packet_len(pixel_bytes, legacy, h, cpp=16):
    if legacy:
        return cpp * (16 + h * pixel_bytes + 4)
    return 32 + cpp * (12 + h * pixel_bytes) + 32


def ouster_header(profile, mode, h_index, cpp_index):
    """The bytes harness::ouster_metadata reads: a valid sensor of that profile and size."""
    h = [16, 32, 64, 128][h_index]
    alt = bytes(int(170 - 85 * i / (h - 1)) for i in range(h))
    return (bytes([profile, mode, h_index, cpp_index, 0]) + alt + bytes([128]) * h
            + bytes([32]) * h + bytes([128]) + struct.pack("<HH", 0, 0xFFFF))


def ouster_header_for(n):
    for prof, pb, legacy in OUSTER_PROFILES:
        for hi, h in enumerate([16, 32, 64, 128]):
            if ouster_packet_len(pb, legacy, h) == n:
                return ouster_header(prof, 1, hi, 0)
    return None


def reassembled_udp(recs, linktype):
    """UDP payloads of Ethernet IPv4 records, fragments put back together (in capture order)."""
    out, pending = [], {}
    for _sec, _frac, _cap, _orig, f in recs:
        if linktype != 1 or len(f) < 34 or f[12:14] != b"\x08\x00" or f[23] != 17:
            continue
        ihl = (f[14] & 15) * 4
        total = struct.unpack(">H", f[16:18])[0]
        ident = struct.unpack(">H", f[18:20])[0]
        fl = struct.unpack(">H", f[20:22])[0]
        more, off = bool(fl & 0x2000), (fl & 0x1FFF) * 8
        body = f[14 + ihl : 14 + total]
        key = (f[26:30], ident)
        if off == 0 and not more:
            out.append(body[8:])
            continue
        parts = pending.setdefault(key, {})
        parts[off] = body
        if not more:
            parts["end"] = off + len(body)
        if "end" in parts:
            data, at = bytearray(), 0
            while at in parts:
                data += parts[at]
                at += len(parts[at])
            if at == parts["end"]:
                out.append(bytes(data[8:]))
                del pending[key]
    return out


def udp_eth(src_ip, dport, payload, ident):
    """An Ethernet / IPv4 / UDP frame (unfragmented, checksum 0) from src_ip to 10.5.5.1."""
    udp = struct.pack(">HHHH", 7502, dport, 8 + len(payload), 0) + payload
    ip = struct.pack(">BBHHHBBH4s4s", 0x45, 0, 20 + len(udp), ident & 0xFFFF, 0, 64, 17, 0, src_ip, b"\x0a\x05\x05\x01")
    return b"\xff" * 6 + b"\x02" * 6 + b"\x08\x00" + ip + udp

def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--captures", default=str(REPO.parent / "shared" / "captures"))
    args = ap.parse_args()
    caps = Path(args.captures)
    rng = random.Random(1)

    pcaps = sorted(REPO.glob("fixtures/**/*.pcap"))
    calibs = []
    if caps.is_dir():
        pcaps += sorted(caps.glob("**/*.pcap"))
        calibs = sorted(p for ext in ("yaml", "yml", "xml") for p in caps.glob(f"**/*.{ext}"))
    else:
        print(f"seed_corpus: {caps} absent: seeding from fixtures/ only", file=sys.stderr)
    calibs = [c for c in calibs if c.stat().st_size <= 64 * 1024 and "metadata" not in c.name]

    data_payloads, pos_payloads = [], []
    for p in pcaps:
        raw = p.read_bytes()
        parsed = read_classic(raw[: 256 * 1024])
        if parsed is None:
            put("pcap", raw[:16384], "raw")
            continue
        e, nanos, lt, recs = parsed
        for limit, tag in ((4096, "h4k"), (20000, "h20k")):
            head = head_records(recs, limit)
            put("pcap", classic_bytes(e, nanos, lt, head), tag)
        head = head_records(recs, 12000)
        put("pcap", pcapng_bytes(e, nanos, lt, head), "ng")
        put("pcap", pcapng_bytes(">", nanos, lt, head, tsresol=0x8A), "ngbe")
        put("decode_to_mcap", classic_bytes(e, nanos, lt, head_records(recs, 60000)), "h60k")
        put("decode_to_mcap", pcapng_bytes(e, nanos, lt, head_records(recs, 30000)), "ng")
        for ip, port, payload in udp_payloads(recs[:400], lt):
            if len(payload) == 1206 and len(data_payloads) < 400:
                data_payloads.append((p.name, ip, port, payload))
            elif len(payload) == 512 and len(pos_payloads) < 40:
                pos_payloads.append((p.name, ip, port, payload))

    # velodyne_packet: selector byte + one payload.
    seen = set()
    for name, _ip, _port, payload in data_payloads:
        if (name, payload[1204:1206]) in seen:
            continue
        seen.add((name, payload[1204:1206]))
        for sel in (0x00, 0x01, 0x02, 0x0B, 0x07):
            put("velodyne_packet", bytes([sel]) + payload, "data")
    for _name, _ip, _port, payload in pos_payloads[:8]:
        put("velodyne_packet", b"\x00" + payload, "pos")
    for sel in (0x20, 0x62, 0x63):
        put("velodyne_packet", bytes([sel]) + bytes(rng.randrange(256) for _ in range(1206)), "rand")

    # velodyne_stream: config (c0, cut angle, port flag, toh) then ops.
    by_file = {}
    for name, ip, port, payload in data_payloads + pos_payloads:
        by_file.setdefault(name, []).append((ip, port, payload))
    for name, items in by_file.items():
        ops = bytearray()
        for ip, port, payload in items[:24]:
            if len(payload) == 1206:
                ops += bytes([0]) + struct.pack("<h", 130) + payload
            else:
                ops += bytes([3]) + struct.pack("<h", 0) + struct.pack("<H", 512) + payload
        for c0 in (0x00, 0x10):
            put("velodyne_stream", bytes([c0]) + b"\0\0\0" + b"\0\0\0\0" + bytes(ops), "cap")
    for model_sel in range(7):
        for mode in (0, 1, 2):
            sel = model_sel | (mode << 3)
            ops = synth_ops(rng, 40, sel, 35500, 40)
            put("velodyne_stream", bytes([0x10, 0, 0, 0]) + struct.pack("<I", 3_599_990_000) + ops, "synth")
    gps = bytes([2]) + struct.pack("<h", 0) + bytes([0x41]) + struct.pack("<I", 1000) + struct.pack("<I", 79_200) + b"\x0b\x0c\x0c"
    put("velodyne_stream", bytes([0, 0, 0, 0, 0, 0, 0, 0]) + gps + synth_ops(rng, 60, 0, 0, 20), "gps")

    # decode_to_mcap: its Ouster sensor (an OS-1-16, 512x10, by the input length: RNG19,
    # RNG15 dual or LEGACY) needs datagrams of that size; a few frames of each, with IMU packets.
    for variant in range(3):
        recs = []
        t = 1_700_000_000_000_000
        for k in range(48):
            if variant == 2:
                pkt = bytearray()
                for c in range(16):
                    mid = (k * 16 + c) % 512
                    pkt += struct.pack("<QHHI", t * 1000 + c * 97_656, mid, k // 32, mid * 176)
                    pkt += bytes(rng.randrange(256) for _ in range(16 * 12))
                    pkt += b"\xff\xff\xff\xff"
            else:
                pb = 12 if variant == 0 else 8
                pkt = bytearray(struct.pack("<HH", 1, k // 32) + bytes(3) + (992210000957).to_bytes(5, "little"))
                pkt += bytes(32 - len(pkt))
                for c in range(16):
                    mid = (k * 16 + c) % 512
                    pkt += struct.pack("<QHHI", t * 1000 + c * 97_656, mid, 1, 0)[:12]
                    pkt += bytes(rng.randrange(256) for _ in range(16 * pb))
                pkt += bytes(32)
            size = len(pkt)
            recs.append((t // 1_000_000, t % 1_000_000, 0, 0, udp_eth(b"\x0a\x05\x05\x57", 7502, bytes(pkt), k)))
            if k % 4 == 0:
                imu = struct.pack("<QQQ", t * 1000, t * 1000, t * 1000) + struct.pack("<6f", 0.01, 0.0, 1.0, 0.5, -0.2, 3.0)
                recs.append((t // 1_000_000, t % 1_000_000, 0, 0, udp_eth(b"\x0a\x05\x05\x57", 7503, imu, 1000 + k)))
            t += 6250
        recs = [(a, b, len(f), len(f), f) for a, b, _c, _o, f in recs]
        data = classic_bytes("<", False, 1, recs)
        # The harness picks the Ouster profile by the input length (len % 3).
        data += bytes((variant - len(data)) % 3)
        put("decode_to_mcap", data, f"ouster{variant}-{size}")

    # pipeline_config: TOML texts (as in src/pipeline/config.rs), NUL, points; tum_poses: TUM.
    pts = b"".join(struct.pack("<hhhHB", rng.randrange(-3000, 3000), rng.randrange(-3000, 3000),
                               rng.randrange(-200, 300), rng.randrange(0, 100), rng.randrange(32))
                   for _ in range(600))
    for toml in [b"", b"[voxel]\nleaf_m = 0.2\n", b"[ground]\nmethod = \"ransac\"\niterations = 50\nseed = 7\n",
                 b"[deskew]\nmode = \"constant-velocity\"\nlinear_mps = [5.0, 0.0, 0.0]\nangular_degps = [0.0, 0.0, 30.0]\n",
                 b"[filter]\nmin_range_m = 1.0\nmax_range_m = 60.0\ncrop_box_min_m = [-2.0, -1.0, -1.0]\ncrop_box_max_m = [2.0, 1.0, 1.0]\n[cluster]\ntolerance_m = 0.5\nmin_points = 3\nmax_points = 5000\n"]:
        put("pipeline_config", toml + b"\0" + pts, "cfg")
    tum = "".join(f"{1700000000 + i * 0.1:.6f} {i * 0.5:.3f} {i * 0.01:.3f} 0.0 0.0 0.0 {0.05 * i:.4f} 1.0\n" for i in range(20))
    put("tum_poses", ("# t x y z qx qy qz qw\n" + tum).encode(), "tum")
    put("tum_poses", b"1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0.7071068 0.7071068\n", "two")

    # http_response: the replies an Ouster sensor's HTTP API gives (plain, sized, chunked, 404).
    body = b'{"sensor_info": {"prod_sn": "992109000123"}, "lidar_mode": "1024x10"}'
    put("http_response", b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\n\r\n" + body, "plain")
    put("http_response", b"HTTP/1.1 200 OK\r\nContent-Length: %d\r\n\r\n" % len(body) + body, "sized")
    put("http_response", b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n"
        + b"".join(b"%x\r\n" % len(body[i:i + 20]) + body[i:i + 20] + b"\r\n" for i in range(0, len(body), 20))
        + b"0\r\n\r\n", "chunked")
    put("http_response", b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n", "404")
    # live_view_requests: channel count, then a client's messages, one per line.
    put("live_view_requests", b"\x05" + b"\n".join([
        b'{"op":"subscribe","subscriptions":[{"id":1,"channelId":1},{"id":2,"channelId":3}]}',
        b'{"op":"subscribe","subscriptions":[{"id":1,"channelId":2},{"id":3,"channelId":3},{"id":4,"channelId":9}]}',
        b'{"op":"unsubscribe","subscriptionIds":[1,7]}',
        b'{"op":"advertise","channels":[]}',
    ]), "session")

    # calib_velodyne: the calibration files as they are.
    for c in calibs:
        put("calib_velodyne", c.read_bytes(), c.suffix[1:])
    put("calib_velodyne", b"lasers:\n- {laser_id: 0, rot_correction: 0.0, vert_correction: 0.1}\nnum_lasers: 1\n", "tiny")

    # hesai_packet: selector byte (model index in ringscan's ALL_MODELS order, option bits) +
    # the first payloads of every Hesai capture; calib_hesai: the angle corrections as they are.
    hesai_models = {1262: 0, 1198: 1, 1072: 2, 1127: 3, 568: 4, 1080: 5, 820: 6, 1118: 7, 893: 8, 861: 8}
    hesai = caps / "tier4__nebula" / "src" / "nebula_hesai"
    if hesai.is_dir():
        for p in sorted(hesai.glob("**/*.pcap")):
            parsed = read_classic(p.read_bytes()[: 64 * 1024])
            if parsed is None:
                continue
            _e, _nanos, lt, recs = parsed
            for _ip, _port, payload in udp_payloads(recs[:6], lt)[:3]:
                m = hesai_models.get(len(payload))
                if m is None:
                    continue
                for bits in (0x00, 0x30, 0x40, 0x80):
                    put("hesai_packet", bytes([m | bits]) + payload, p.stem[:8])
        for c in sorted(hesai.glob("**/calibration/*")):
            if c.stat().st_size <= 64 * 1024:
                put("calib_hesai", c.read_bytes(), c.name.replace(".", "_"))
    # An AT128 .dat of layout 1.3 (no shared file has it): fields 30/150/270°, channel offsets,
    # a few grid entries.
    v13 = bytearray(72572)
    v13[0:7] = bytes([0xEE, 0xFF, 1, 3, 128, 3, 3])
    v13[15] = 1
    struct.pack_into("<3H3H", v13, 16, 3000, 15000, 27000, 15000, 27000, 3000)
    struct.pack_into("<128h", v13, 28, *[(k % 7 - 3) * 50 for k in range(128)])
    struct.pack_into("<128h", v13, 284, *[1270 - 20 * k for k in range(128)])
    for i in range(0, 36000, 997):
        v13[540 + i] = (i * 7) % 256
        v13[36540 + i] = (i * 3) % 256
    put("calib_hesai", bytes(v13), "at128_v13")
    # The Pandar ATX (no shared capture or file): a 4.3 .dat of 8 channels and a packet of 8
    # lasers × 2 blocks with UDP sequence and signature (HesaiLidar_SDK_2.0 udp_protocol_v4_7.h).
    atx_dat = bytes([0xEE, 0xFF, 4, 3, 0, 0, 8]) + struct.pack("<H", 256)
    atx_dat += struct.pack("<8h", *[(k % 4 - 2) * 256 for k in range(8)]) * 2
    atx_dat += struct.pack("<8h", *[(6 - 2 * k) * 256 for k in range(8)])
    atx_dat += struct.pack("<70h", *[(k % 10 - 5) * 10 for k in range(70)]) + bytes(32)
    put("calib_hesai", atx_dat, "atx_v43")
    put("calib_hesai", b"Channel,Even_fire time(ns),Odd_fire time(ns)\n" + b"".join(
        b"%d,%d,%d\n" % (k + 1, 4960 + 520 * k, 7560) for k in range(8)), "atx_firetimes")
    # Its binary firetimes, as the sensor serves them over PTC (0xA9): version x.1, 8
    # channels, division 10, u16 even then odd, SHA-256.
    atx_ft = bytes([0xEE, 0xFF, 4, 1, 0, 0, 8]) + struct.pack("<H", 10)
    atx_ft += struct.pack("<8H", *[496 + 52 * k for k in range(8)]) + struct.pack("<8H", *[756] * 8)
    put("calib_hesai", atx_ft + bytes(32), "atx_firetimes_bin")
    atx = bytearray(bytes([0xEE, 0xFF, 4, 7, 0, 0, 8, 2, 1, 4, 1, 0b1001]))
    for blk in range(2):
        atx += struct.pack("<HB", (60 + blk) * 256, 0)
        atx += b"".join(struct.pack("<HBB", 2000 + 10 * k, 50, 1) for k in range(8))
    atx += bytes(4)
    tail = bytearray(32)
    tail[10] = 1
    tail[24] = 0x37
    tail[26:32] = bytes([124, 1, 2, 3, 4, 5])
    atx += tail + struct.pack("<I", 7) + bytes(12) + bytes(32)
    for bits in (0x00, 0x30, 0x40, 0x80):
        put("hesai_packet", bytes([9 | bits]) + bytes(atx), "atx")
    put("calib_hesai", b"Laser id,Elevation,Azimuth\n" + b"".join(
        b"%d,%.3f,%.3f\n" % (i + 1, 15 - i, 0.1 * i) for i in range(32)), "tiny")

    # robosense_packet: selector (model index in ringscan's ALL_MODELS order, option bits) + the
    # Helios-16P capture's first MSOP and its DIFOP; calib_robosense: its angle CSV.
    rs = caps / "tier4__nebula__pr79"
    if rs.is_dir():
        for p in sorted(rs.glob("**/*.pcap")):
            parsed = read_classic(p.read_bytes())
            if parsed is None:
                continue
            _e, _nanos, lt, recs = parsed
            payloads = [pl for _ip, _port, pl in udp_payloads(recs, lt)]
            picks = payloads[:2] + [pl for pl in payloads if pl[:2] == b"\xa5\xff"][:1]
            for i, payload in enumerate(picks):
                for bits in (0x00, 0x10, 0x40, 0x60, 0x80):
                    put("robosense_packet", bytes([4 | bits]) + payload, f"helios16p-{i}")
        for c in sorted(rs.glob("**/calibration/robosense/*.csv")):
            put("calib_robosense", c.read_bytes(), c.stem)
    put("calib_robosense", b"".join(b"%.2f,%.2f\n" % (15 - i, 0.1 * i) for i in range(32)), "tiny")
    # robosense_packet, M1 (model 6): a 1210-byte MSOP (id, counter, Unix time, 25 blocks of 5
    # points at 4 m) and a 256-byte DIFOP.
    m1 = bytearray(1210)
    m1[0:4] = b"\x55\xaa\x5a\xa5"
    m1[4:6] = struct.pack(">H", 1)
    m1[10:20] = struct.pack(">Q", 1_700_000_000)[2:] + struct.pack(">I", 1234)
    for blk in range(25):
        o = 32 + 47 * blk
        m1[o] = 6 * blk
        for c in range(5):
            m1[o + 2 + 9 * c : o + 8 + 9 * c] = struct.pack(">HHH", 800, 32768 + 100 * c, 32768 - 500 * c)
    m1d = bytearray(256)
    m1d[0:8] = b"\xa5\xff\x00\x5a\x11\x11\x55\x55"
    for i, payload in enumerate((bytes(m1), bytes(m1d))):
        for bits in (0x00, 0x20, 0x40):
            put("robosense_packet", bytes([6 | bits]) + payload, f"m1-{i}")

    # reassembly: config, then pushes of one datagram of key 2 in shuffled order, then key 0.
    for total, frag in ((1300, 400), (5000, 1480), (64000, 8000)):
        cfg = struct.pack("<HBH", 1000, 8, 20000) + struct.pack("<I", 0)
        ops = bytearray()
        pieces = list(range(0, total, frag))
        rng.shuffle(pieces)
        for off in pieces:
            ln = min(frag, total - off)
            more = off + ln < total
            op = 2 | (4 if more else 0) | 16
            ops += bytes([op, 1]) + struct.pack("<HH", off // 8, ln)
        put("reassembly", cfg + bytes(ops), "shuffled")
        data = bytes(rng.randrange(256) for _ in range(min(total, 3000)))
        ops = bytearray()
        off = 0
        while off < len(data):
            ln = min(frag, len(data) - off)
            more = off + ln < len(data)
            ops += bytes([(4 if more else 0) | 16, 0]) + struct.pack("<HH", off // 8, ln)
            ops += data[off : off + ln]
            off += ln
        put("reassembly", cfg + bytes(ops), "bytes")

    # Ouster: calib_ouster takes metadata files as they are (and generated ones: first byte
    # 0xA5); ouster_packet / ouster_stream take a generated calibration (header below) then
    # real lidar and IMU payloads whose size fits it.
    ouster = caps / "ouster-lidar__ouster-sdk"
    if ouster and ouster.is_dir():
        for m in sorted(ouster.rglob("*.json")):
            if m.stat().st_size <= 200_000:
                put("calib_ouster", m.read_bytes(), "meta")
        seen = set()
        for pc in sorted(ouster.rglob("*.pcap")):
            parsed = read_classic(pc.read_bytes()[:3_000_000])
            if not parsed:
                continue
            _e, _n, lt, recs = parsed
            for payload in reassembled_udp(recs, lt)[:400]:
                hdr = ouster_header_for(len(payload))
                if hdr is None or (len(payload), pc.name) in seen:
                    continue
                seen.add((len(payload), pc.name))
                put("ouster_packet", hdr + bytes([0]) + payload, "real")
                put("ouster_packet", hdr + bytes([1]) + payload, "realcrc")
            stream_ops = bytearray()
            hdr0 = None
            for payload in reassembled_udp(recs, lt)[:40]:
                hdr = ouster_header_for(len(payload))
                if hdr is not None and hdr0 is None:
                    hdr0 = hdr
                kind = 0 if len(payload) > 100 else 2
                stream_ops += struct.pack("<HBI", len(payload), kind, 100_000) + payload
            if hdr0 is not None:
                put("ouster_stream", hdr0 + bytes([6]) + bytes(stream_ops[:60000]), "real")
    put("calib_ouster", b"\xa5" + ouster_header(1, 1, 0, 0), "gen")
    bag_seeds()
    livox_control_seeds()
    lvx_seeds()
    for prof in range(8):
        for hi in range(4):
            put("ouster_packet", ouster_header(prof, 1, hi, 0) + b"\0" + bytes(rng.randrange(256) for _ in range(3000)), "rand")
            put("ouster_stream", ouster_header(prof, 0, hi, 0) + b"\0" + b"".join(
                struct.pack("<HBI", 600, k % 3, 50_000_000) + bytes(rng.randrange(256) for _ in range(600)) for k in range(12)), "rand")

    family_stream_seeds()

    for t in sorted(os.listdir(CORPUS)):
        print(f"{t}: {len(os.listdir(CORPUS / t))} seeds")


def family_stream_seeds():
    """family_stream builds its packets itself (simulated runs): a seed is the selector byte
    (model in the low three bits, option bits above) and ops. Each model gets an in-order run
    over its packets, and one with a reorder, a copy, a patched tail and a host-time step."""
    for sel in range(8):
        for bits in (0x00, 0x08, 0x60):
            ops = bytes([1, 255]) * 3  # three runs of 256 packets in order
            put("family_stream", bytes([sel | bits]) + ops, f"run{sel}")
        mixed = bytes([1, 40, 2, 50, 0, 2, 45, 0, 0, 2, 45, 0])  # skip, late, copy
        mixed += bytes([0x0B, 8, 0, 7, 0x4C, 3, 0, 1]) + bytes([5, 0x10, 0x27])  # patched, nudged, host +0.5 s
        mixed += bytes([6, 100, 0, 7, 10]) + bytes(10) + bytes([1, 255])
        put("family_stream", bytes([sel]) + mixed, f"mixed{sel}")


def livox_control_seeds():
    """Livox control frames of both protocols, built from the protocol documents (the CRCs pass,
    so the fuzzer starts past them)."""
    def crc16(data, poly, init, reflected):
        r = init
        for b in data:
            for i in range(8):
                bit = (b >> i) & 1 if reflected else (b >> (7 - i)) & 1
                top = r & 1 if reflected else (r >> 15) & 1
                r = (r >> 1) if reflected else ((r << 1) & 0xFFFF)
                if bit ^ top:
                    r ^= poly
        return r

    def sdk2(seq, cmd_id, cmd_type, data):
        h = struct.pack("<BBHIHBB6x", 0xAA, 0, 24 + len(data), seq, cmd_id, cmd_type, cmd_type)
        h += struct.pack("<H", crc16(h, 0x1021, 0xFFFF, False))
        return h + struct.pack("<I", zlib.crc32(data) if data else 0) + data

    def sdk1(cmd_type, seq, cmd_id, payload):
        h = struct.pack("<BBHBH", 0xAA, 1, 15 + len(payload), cmd_type, seq)
        b = h + struct.pack("<H", crc16(h, 0x8408, 0x4C49, True)) + bytes([0, cmd_id]) + payload
        return b + struct.pack("<I", zlib.crc32(b, 0x564F580A))

    kv = struct.pack("<HH", 2, 0) + struct.pack("<HH4sHH", 6, 8, bytes([127, 0, 0, 1]), 56301, 56300)
    kv += struct.pack("<HHB", 0x1A, 1, 1)
    for f in [
        sdk2(1, 0, 0, b""),
        sdk2(1, 0, 1, bytes([0, 9]) + b"47MDL9K0A1".ljust(16, b"\0") + bytes([127, 0, 0, 2]) + struct.pack("<H", 56100)),
        sdk2(2, 0x100, 0, kv),
        sdk2(2, 0x100, 1, bytes([0x22, 6, 0])),
        sdk1(2, 1, 0, b"3WEDH7600101X1".ljust(16, b"\0") + bytes([7, 0, 0])),
        sdk1(0, 2, 1, bytes([127, 0, 0, 1]) + struct.pack("<HHH", 56001, 55501, 56001)),
        sdk1(1, 2, 1, bytes([0])),
        sdk1(1, 3, 3, bytes([0, 1, 0, 0, 0, 0, 0])),
    ]:
        put("livox_control", f, "doc")


def bag_seeds():
    """Seeds of the bag targets from fixtures/bags: ROS 1 bags cut to 60 KB, the MCAP
    decompressed, metadata.yaml files, and single messages of each type (from a ROS 1 bag's
    uncompressed records where present, else synthesised)."""
    bags = REPO / "fixtures" / "bags"
    for p in sorted(bags.glob("*.bag")):
        put("bag_ros1", p.read_bytes()[:60000], p.stem)
    for p in sorted(bags.glob("*/metadata.yaml")):
        put("bag_metadata", p.read_bytes(), p.parent.name)
    try:
        import zstandard  # noqa: F401  (only when available)
    except ImportError:
        zstandard = None
    for p in sorted(bags.glob("*/*.mcap.zstd")):
        if zstandard is not None:
            raw = zstandard.ZstdDecompressor().decompressobj().decompress(p.read_bytes())
        else:
            import shutil
            import subprocess

            if not shutil.which("zstd"):
                continue
            raw = subprocess.run(["zstd", "-dc", str(p)], capture_output=True, check=True).stdout
        put("bag_mcap", raw[:60000], p.stem)
    for p in sorted(bags.glob("*/*.mcap")):
        put("bag_mcap", p.read_bytes()[:60000], p.stem)
    # CDR VelodyneScan with 2 packets, and small messages of the other types.
    scan = bytearray(b"\x00\x01\x00\x00" + struct.pack("<iI", 1, 2) + struct.pack("<I", 2) + b"v\x00\x00\x00")
    scan += struct.pack("<I", 2)
    for i in range(2):
        scan += struct.pack("<iI", 10 + i, 5) + bytes([i]) * 1206 + b"\x00\x00"
    put("bag_messages", b"\x00" + bytes(scan), "velodyne-cdr")
    put("bag_messages", b"\x01" + b"\x00\x01\x00\x00" + struct.pack("<I", 8) + bytes(8), "ouster-cdr")
    put("bag_messages", b"\x09" + struct.pack("<I", 8) + bytes(8), "ouster-ros1")
    put("bag_messages", b"\x07" + b"\x00\x01\x00\x00" + struct.pack("<I", 3) + b"{}\x00", "string-cdr")
    for sel in (2, 3, 4, 5, 6):
        put("bag_messages", bytes([sel]) + bytes(scan), f"scan-as-{sel}")
    # Livox CustomMsg (CDR: header "f", timebase aligned to 8, two points, the first padded).
    pt = lambda k: struct.pack("<IfffBBB", 100 * k, 1.0 + k, -2.0, 0.5, 7, 0x10, k % 4)
    cm = b"\x00\x01\x00\x00" + struct.pack("<iI", 1, 2) + struct.pack("<I", 2) + b"f\x00\x00\x00" \
        + struct.pack("<QIB3x", 10**18, 2, 3) + struct.pack("<I", 2) + pt(0) + b"\x00" + pt(1)
    put("bag_messages", b"\x00" + cm, "livox-custom-cdr")
    cm1 = struct.pack("<IIII", 1, 1, 2, 1) + b"f" + struct.pack("<QIB3x", 10**18, 2, 3) \
        + struct.pack("<I", 2) + pt(0) + pt(1)
    put("bag_messages", b"\x08" + cm1, "livox-custom-ros1")
    # ringscan.RawPacket (protobuf, what --raw writes to a foxglove MCAP): a message, and an MCAP
    # of its records (schema, channel, messages; no chunk, no summary).
    raw_msg = raw_packet_proto(1_700_000_000, 250_000_000, "192.168.1.201", 2368, 2368, bytes(range(40)))
    put("bag_messages", b"\x00" + raw_msg, "raw-packet")
    put("bag_mcap", raw_packet_mcap([raw_msg, raw_msg[:-3], raw_msg]), "raw-packets")


def varint(n):
    out = bytearray()
    while True:
        b, n = n & 0x7F, n >> 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)


def raw_packet_proto(sec, nanos, address, sport, dport, payload):
    """A ringscan.RawPacket by the protobuf encoding guide (field number << 3 | wire type)."""
    ts = b"\x08" + varint(sec) + b"\x10" + varint(nanos)
    addr = address.encode()
    return (b"\x0a" + varint(len(ts)) + ts + b"\x12" + varint(len(addr)) + addr
            + b"\x18" + varint(sport) + b"\x20" + varint(dport)
            + b"\x2a" + varint(len(payload)) + payload)


def raw_packet_mcap(messages):
    """An MCAP of ringscan.RawPacket messages, record by record from the MCAP specification."""
    rec = lambda op, body: bytes([op]) + struct.pack("<Q", len(body)) + body
    s = lambda b: struct.pack("<I", len(b)) + b
    out = b"\x89MCAP0\r\n" + rec(0x01, s(b"") + s(b"seed"))
    out += rec(0x03, struct.pack("<H", 1) + s(b"ringscan.RawPacket") + s(b"protobuf") + s(b""))
    out += rec(0x04, struct.pack("<HH", 1, 1) + s(b"/s/raw") + s(b"protobuf") + struct.pack("<I", 0))
    for i, m in enumerate(messages):
        t = 1_700_000_000_000_000_000 + i
        out += rec(0x05, struct.pack("<HIQQ", 1, i, t, t) + m)
    out += rec(0x0F, struct.pack("<I", 0)) + rec(0x02, bytes(20)) + b"\x89MCAP0\r\n"
    return out


def lvx_seeds():
    """Seeds of the lvx target: small .lvx2 / .lvx files from the LVX specifications, whole
    (selector 0) and as frames after the harness's own headers (selectors 1 and 2)."""

    def frames(at, frame_list):
        out = b""
        for i, pkgs in enumerate(frame_list):
            n = 24 + sum(len(p) for p in pkgs)
            out += struct.pack("<QQQ", at, at + n, i) + b"".join(pkgs)
            at += n
        return out

    def lvx2_pkg(ts, udp, records):
        data = b"".join(struct.pack("<iiiBB", k, -k, 2 * k, k & 0xFF, 0) for k in range(records))
        return struct.pack("<BIBBQHBIB4s", 0, 0, 8, 1, ts, udp, 1, len(data), 0, bytes(4)) + data

    def lvx1_pkg(ts):
        data = b"".join(struct.pack("<iiiBB", k, -k, 2 * k, k & 0xFF, 0) for k in range(96))
        return b"\x00" + struct.pack("<BBBBIBBQ", 5, 1, 1, 0, 0, 1, 2, ts) + data

    v2 = [[lvx2_pkg(10, 0, 96), lvx2_pkg(500_000, 1, 96)], [lvx2_pkg(1_000_000, 2, 96)]]
    v1 = [[lvx1_pkg(10), lvx1_pkg(400_000)]]
    head = b"livox_tech" + bytes(6)
    whole2 = head + bytes([2, 0, 0, 0]) + struct.pack("<IIB", 0xAC0EA767, 50, 1) + bytes(32) \
        + struct.pack("<IBBB", 0, 8, 9, 0) + bytes(24)
    whole1 = head + bytes([1, 1, 0, 0]) + struct.pack("<IIB", 0xAC0EA767, 50, 1) + bytes(32) \
        + bytes([0, 7, 0]) + bytes(24)
    put("lvx", b"\x00" + whole2 + frames(len(whole2), v2), "lvx2")
    put("lvx", b"\x00" + whole1 + frames(len(whole1), v1), "lvx1")
    put("lvx", b"\x01" + frames(92, v2), "lvx2-frames")
    put("lvx", b"\x02" + frames(88, v1), "lvx1-frames")


if __name__ == "__main__":
    main()
