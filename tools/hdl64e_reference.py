#!/usr/bin/env python3
"""Compare ringscan's HDL-64E points with velodyne_decoder 3.1.0's, point by point.

Run by tools/hdl64e_reference.sh (which makes the venv, the pcap and ringscan's dump):

    python tools/hdl64e_reference.py --model hdl64e-s2 --calib 64e_s2.1-sztaki.yaml \
        --ringscan points.f32 capture.pcap

Every 1206-byte UDP payload of the pcap is decoded on its own by velodyne_decoder
(`ScanDecoder.decode([packet])`, so its `time` is the firing offset within the packet) with the
model set explicitly, the same calibration file and no range filter (min 0, max 1000 m).
ringscan's dump (tools/dump_points.rs) holds 8 float32 per point: x, y, z, raw intensity, ring,
t (us after the packet stamp), return (0 strongest/only, 1 last), corrected intensity.

Both emit points in the same order (packet, block, slot; dual: last before strongest, one point
when both returns are equal), so the comparison is row by row. Printed:

* counts, ring and return agreement (velodyne_decoder return_type 1 strongest, 2 last,
  3 both -> ringscan 0, 1, 0);
* max |dxyz|, and its split: |d r_xy| (horizontal radius) and |dz| are almost blind to the
  azimuth, d azimuth is where velodyne_decoder rounds the interpolated azimuth to 0.01 deg
  (ringscan does not: up to 0.005 deg apart, 2.6 mm at 30 m);
* max |dxyz| after rotating ringscan's point to velodyne_decoder's azimuth about z: the
  distance-formula agreement;
* firing time difference; velodyne_decoder's intensity (it outputs the corrected intensity for
  HDL-64E calibrations) against ringscan's `corrected_intensity`.

`--make-random OUT.pcap [--mode strongest|dual] [--packets N] [--seed S]` only writes a pcap of
HDL-64E packets with random raw distances over the whole u16 range (the simulated room stays
within 25.04 m; these reach the far side of the two-point correction and its edge, raw
12519 / 12520), for the same comparison.

Exit code 1 if a tolerance is exceeded: counts, rings and returns exact; formula agreement
(azimuth-aligned) 0.1 mm; |dxyz| 1 cm + r sin(0.006 deg); time 0.01 us; intensity 0.01.
"""

import argparse
import math
import sys

import dpkt
import numpy as np
import velodyne_decoder as vd

MODELS = {"hdl64e-s2": vd.Model.HDL64E_S2, "hdl64e-s3": vd.Model.HDL64E_S3}


def reference_points(pcap, model, calib_path):
    cal = vd.Calibration.read(calib_path)
    cfg = vd.Config(model=MODELS[model], calibration=cal, min_range=0.0, max_range=1000.0)
    dec = vd.ScanDecoder(cfg)
    out = []
    with open(pcap, "rb") as f:
        for ts, buf in dpkt.pcap.Reader(f):
            eth = dpkt.ethernet.Ethernet(buf)
            ip = eth.data
            if not isinstance(ip, dpkt.ip.IP) or not isinstance(ip.data, dpkt.udp.UDP):
                continue
            payload = bytes(ip.data.data)
            if len(payload) != vd.PACKET_SIZE:
                continue
            _, pts = dec.decode([vd.VelodynePacket(ts, payload)])
            out.append(np.asarray(pts, dtype=np.float32).reshape(-1, 8))
    return np.concatenate(out) if out else np.zeros((0, 8), np.float32)


def write_random_pcap(path, dual, packets, seed):
    """HDL-64E packets with random raw distances over the whole u16 range (both sides of the
    25.04 m far point, plus raw 12519 / 12520 on purpose), random reflectivities, block
    azimuths advancing at 10 Hz. Single return: blocks 2k, 2k+1 (upper, lower) share an azimuth;
    dual: blocks 4k..4k+3 do (velodyne_decoder detects dual return from az[0] == az[2]), and a
    quarter of the slots repeat the first return's distance (one point)."""
    rng = np.random.default_rng(seed)
    firing_us = 48.0
    columns = 3 if dual else 6
    per_column = 4 if dual else 2
    az = 0.0
    t_us = 0.0
    with open(path, "wb") as f:
        w = dpkt.pcap.Writer(f)
        for n in range(packets):
            body = bytearray()
            for b in range(12):
                col = b // per_column
                body += (0xEEFF if (b % per_column) % 2 == 0 else 0xDDFF).to_bytes(2, "little")
                body += (int(round((az + col * firing_us * 3.6e-3) * 100)) % 36000).to_bytes(2, "little")
                raw = rng.integers(1, 65536, 32)
                raw[rng.random(32) < 0.05] = 0
                raw[rng.random(32) < 0.02] = 12519
                raw[rng.random(32) < 0.02] = 12520
                if dual and b % 4 >= 2:
                    prev = np.frombuffer(bytes(body[(b - 2) * 100 + 4:(b - 2) * 100 + 100]), dtype=np.uint8)
                    same = rng.random(32) < 0.25
                    first = prev.reshape(32, 3)[:, 0].astype(np.uint16) | (prev.reshape(32, 3)[:, 1].astype(np.uint16) << 8)
                    raw = np.where(same, first, raw)
                refl = rng.integers(0, 256, 32)
                for d, r in zip(raw, refl):
                    body += int(d).to_bytes(2, "little") + bytes([int(r)])
            body += int(t_us).to_bytes(4, "little") + b"\x00\x00"
            udp = dpkt.udp.UDP(sport=2368, dport=2368, data=bytes(body))
            udp.ulen = len(udp)
            ip = dpkt.ip.IP(src=bytes([192, 168, 1, 201]), dst=bytes([255, 255, 255, 255]), p=17, data=udp)
            ip.len = len(ip)
            eth = dpkt.ethernet.Ethernet(src=b"\x00\x01\x02\x03\x04\x05", dst=b"\xff" * 6, type=0x0800, data=ip)
            w.writepkt(bytes(eth), ts=1714564800.0 + t_us * 1e-6)
            az = (az + columns * firing_us * 3.6e-3) % 360.0
            t_us += columns * firing_us


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", choices=sorted(MODELS))
    ap.add_argument("--calib")
    ap.add_argument("--ringscan", help="tools/dump_points output")
    ap.add_argument("--make-random", metavar="OUT.pcap", help="only write a random-packet pcap")
    ap.add_argument("--mode", default="strongest", choices=["strongest", "dual"])
    ap.add_argument("--packets", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("pcap", nargs="?")
    a = ap.parse_args()
    if a.make_random:
        write_random_pcap(a.make_random, a.mode == "dual", a.packets, a.seed)
        return 0
    if not (a.model and a.calib and a.ringscan and a.pcap):
        ap.error("--model, --calib, --ringscan and the pcap are required")

    ref = reference_points(a.pcap, a.model, a.calib).astype(np.float64)
    rs = np.fromfile(a.ringscan, dtype="<f4").reshape(-1, 8).astype(np.float64)
    ok = True
    print(f"points: velodyne_decoder {len(ref)}, ringscan {len(rs)}")
    if len(ref) != len(rs):
        print("FAIL: point counts differ")
        return 1
    if len(ref) == 0:
        print("FAIL: no points")
        return 1

    rings_equal = int(np.sum(ref[:, 6] == rs[:, 4]))
    ret_ref = np.where(ref[:, 7] == 2, 1, 0)
    returns_equal = int(np.sum(ret_ref == rs[:, 6]))
    print(f"ring equal: {rings_equal}/{len(ref)}; return equal: {returns_equal}/{len(ref)}"
          f" (velodyne_decoder types: {dict(zip(*np.unique(ref[:, 7].astype(int), return_counts=True)))})")
    ok &= rings_equal == len(ref) and returns_equal == len(ref)

    d = rs[:, :3] - ref[:, :3]
    dxyz = np.linalg.norm(d, axis=1)
    r_ref = np.hypot(ref[:, 0], ref[:, 1])
    r_rs = np.hypot(rs[:, 0], rs[:, 1])
    az_ref = np.arctan2(ref[:, 1], ref[:, 0])
    az_rs = np.arctan2(rs[:, 1], rs[:, 0])
    daz = np.degrees((az_rs - az_ref + np.pi) % (2 * np.pi) - np.pi)
    # ringscan's point turned about z onto velodyne_decoder's azimuth.
    c, s = np.cos(-np.radians(daz)), np.sin(-np.radians(daz))
    rot = np.stack([c * rs[:, 0] - s * rs[:, 1], s * rs[:, 0] + c * rs[:, 1], rs[:, 2]], axis=1)
    aligned = np.linalg.norm(rot - ref[:, :3], axis=1)
    rng = np.linalg.norm(ref[:, :3], axis=1)
    allowed = 0.01 + rng * math.sin(math.radians(0.006))
    i = int(np.argmax(dxyz))
    print(f"max |dxyz| {dxyz.max() * 1e3:.3f} mm (point {i}, range {rng[i]:.2f} m), mean {dxyz.mean() * 1e3:.3f} mm;"
          f" max |d r_xy| {np.abs(r_rs - r_ref).max() * 1e3:.4f} mm, max |dz| {np.abs(d[:, 2]).max() * 1e3:.4f} mm,"
          f" max |d azimuth| {np.abs(daz).max():.5f} deg")
    near, far = rng < 25.0, rng >= 25.0
    print(f"azimuth-aligned max |dxyz| {aligned.max() * 1e3:.4f} mm"
          f" (range < 25 m: {int(near.sum())} points, {aligned[near].max() * 1e3 if near.any() else float('nan'):.4f} mm;"
          f" >= 25 m: {int(far.sum())} points, {aligned[far].max() * 1e3 if far.any() else float('nan'):.4f} mm)")
    ok &= bool(np.all(dxyz <= allowed)) and aligned.max() <= 1e-4

    dt_us = np.abs(rs[:, 5] - ref[:, 4] * 1e6)
    print(f"max |dt| {dt_us.max():.4f} us (ringscan t = firing offset after the packet stamp, velodyne_decoder time "
          f"= the same from a one-packet scan)")
    ok &= dt_us.max() <= 0.01

    ci = rs[:, 7]
    have = ~np.isnan(ci)
    if np.any(have):
        di = np.abs(ci[have] - ref[have, 3])
        print(f"corrected intensity vs velodyne_decoder intensity: max |d| {di.max():.5f} over {int(have.sum())} points"
              f" (raw intensity differs on {int(np.sum(rs[:, 3] != ref[:, 3]))} points)")
        ok &= di.max() <= 0.01
    else:
        print("corrected intensity: not dumped (dual return)")

    print("OK" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
