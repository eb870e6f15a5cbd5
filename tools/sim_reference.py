#!/usr/bin/env python3
"""Reference decoders on the simulator's pcaps: velodyne_decoder 3.1.0 (Velodyne) and ouster-sdk
1.0.1 (Ouster) against ringscan, point by point, and both against the simulator's truth.

Run by tools/sim_reference.sh, which makes the venvs, the pcaps (a moving sensor, 15 m/s with
60 deg/s yaw, in the urban scene), ringscan's dumps (tools/dump_points.rs) and the truth files
(tools/simulate.rs --truth, format in src/sim/truth.rs).

    python tools/sim_reference.py velodyne --model vlp16 --calib VLP16db.yaml \
        --ringscan points.f32 --truth sim.truth capture.pcap
    python tools/sim_reference.py ouster --metadata meta.json \
        --ringscan points.f32 --truth sim.truth capture.pcap

Velodyne: every 1206-byte payload is decoded on its own by velodyne_decoder
(`ScanDecoder.decode([packet])`), model explicit, the same calibration file, no range filter;
ringscan's dump (8 x f32: x, y, z, intensity, ring, t us, return, corrected intensity) and the
truth file list the same measurements in the same order (packet, block, slot), so rows are
compared one to one: counts, rings and returns exact; |dxyz| <= 1 mm + r sin(0.01 deg)
(velodyne_decoder rounds its interpolated azimuth to 0.01 deg); firing time within 0.01 us.

Ouster: `ouster.sdk.pcap.PcapFrameSetSource(pcap, meta=[json])` frames, xyz from
`core.XYZLut(info, use_extrinsics=False)` on RANGE / RANGE2; ringscan's dump (10 x f32: x, y,
z, reflectivity, return, row, column, frame id, range mm, signal) is matched by (frame, return,
row, column) as tests/ouster_golden.rs does: points per frame equal, range, reflectivity and
signal exact, xyz within 1 mm.

Against the truth (the scene point the simulator's ray hit, sensor frame at its firing time):
max |dxyz| of both decoders is printed with the allowance 1 cm + r sin(0.005 deg) (ringscan)
and 1 cm + r sin(0.01 deg) (velodyne_decoder's azimuth rounding); exceeding it fails.
Exit code 0 when every tolerance holds, 1 otherwise.
"""

import argparse
import math
import sys

import numpy as np

TRUTH_DTYPE = np.dtype([("sensor", "<f4", 3), ("world", "<f4", 3), ("time_ns", "<i8"),
                        ("label", "<u4"), ("channel", "<u2"), ("ring", "u1"), ("ret", "u1")])


def read_truth(path):
    with open(path, "rb") as f:
        head = f.read(16)
        if head[:8] != b"RSTRUTH1" or int.from_bytes(head[8:12], "little") != 40:
            raise SystemExit(f"{path}: not a ringscan truth file")
        return np.frombuffer(f.read(), dtype=TRUTH_DTYPE)


def udp_payloads(pcap_path, size):
    import dpkt
    with open(pcap_path, "rb") as f:
        for ts, buf in dpkt.pcap.Reader(f):
            eth = dpkt.ethernet.Ethernet(buf)
            ip = eth.data
            if not isinstance(ip, dpkt.ip.IP) or not isinstance(ip.data, dpkt.udp.UDP):
                continue
            payload = bytes(ip.data.data)
            if len(payload) == size:
                yield ts, payload


def against_truth(name, xyz, truth, sin_deg):
    t = truth["sensor"].astype(np.float64)
    d = np.linalg.norm(xyz - t, axis=1)
    r = np.linalg.norm(t, axis=1)
    allowed = 0.01 + r * math.sin(math.radians(sin_deg))
    i = int(np.argmax(d))
    ok = bool(np.all(d <= allowed))
    print(f"{name} vs truth: max |dxyz| {d.max() * 1e3:.3f} mm (range {r[i]:.2f} m), mean {d.mean() * 1e3:.3f} mm,"
          f" worst excess over 1 cm + r sin({sin_deg} deg): {(d - allowed).max() * 1e3:.3f} mm"
          f" [{'ok' if ok else 'FAIL'}]")
    return ok


def velodyne(a):
    import velodyne_decoder as vd
    models = {"vlp16": vd.Model.VLP16, "hdl32e": vd.Model.HDL32E, "vlp32c": vd.Model.VLP32C,
              "hdl64e-s2": vd.Model.HDL64E_S2, "hdl64e-s3": vd.Model.HDL64E_S3}
    cal = vd.Calibration.read(a.calib)
    cfg = vd.Config(model=models[a.model], calibration=cal, min_range=0.0, max_range=1000.0)
    dec = vd.ScanDecoder(cfg)
    out = []
    for ts, payload in udp_payloads(a.pcap, vd.PACKET_SIZE):
        _, pts = dec.decode([vd.VelodynePacket(ts, payload)])
        out.append(np.asarray(pts, dtype=np.float32).reshape(-1, 8))
    ref = (np.concatenate(out) if out else np.zeros((0, 8), np.float32)).astype(np.float64)
    rs = np.fromfile(a.ringscan, dtype="<f4").reshape(-1, 8).astype(np.float64)
    truth = read_truth(a.truth) if a.truth else None
    print(f"points: velodyne_decoder {len(ref)}, ringscan {len(rs)}"
          + (f", truth {len(truth)}" if truth is not None else ""))
    if len(ref) != len(rs) or len(ref) == 0 or (truth is not None and len(truth) != len(rs)):
        print("FAIL: point counts differ (or no points)")
        return 1
    ok = True
    rings = int(np.sum(ref[:, 6] == rs[:, 4]))
    rets = int(np.sum(np.where(ref[:, 7] == 2, 1, 0) == rs[:, 6]))
    print(f"ring equal {rings}/{len(ref)}, return equal {rets}/{len(ref)}")
    ok &= rings == len(ref) and rets == len(ref)
    dxyz = np.linalg.norm(rs[:, :3] - ref[:, :3], axis=1)
    rng = np.linalg.norm(ref[:, :3], axis=1)
    allowed = 0.001 + rng * math.sin(math.radians(0.01))
    i = int(np.argmax(dxyz))
    print(f"ringscan vs velodyne_decoder: max |dxyz| {dxyz.max() * 1e3:.3f} mm (range {rng[i]:.2f} m),"
          f" mean {dxyz.mean() * 1e3:.4f} mm, worst excess over 1 mm + r sin(0.01 deg)"
          f" {(dxyz - allowed).max() * 1e3:.3f} mm")
    ok &= bool(np.all(dxyz <= allowed))
    dt = np.abs(rs[:, 5] - ref[:, 4] * 1e6)
    print(f"max |dt| {dt.max():.4f} us")
    ok &= dt.max() <= 0.01
    if truth is not None:
        ok &= bool(np.all(truth["ring"] == rs[:, 4]))
        ok &= against_truth("ringscan", rs[:, :3], truth, 0.005)
        ok &= against_truth("velodyne_decoder", ref[:, :3], truth, 0.01)
    print("OK" if ok else "FAIL")
    return 0 if ok else 1


def ouster(a):
    from ouster.sdk import core, pcap
    src = pcap.PcapFrameSetSource(a.pcap, meta=[a.metadata])
    info = src.sensor_info[0]
    lut = core.XYZLut(info, use_extrinsics=False)
    dual = info.format.udp_profile_lidar in (core.UDPProfileLidar.RNG19_RFL8_SIG16_NIR16_DUAL,
                                             core.UDPProfileLidar.RNG15_RFL8_NIR8_DUAL,
                                             core.UDPProfileLidar.FUSA_RNG15_RFL8_NIR8_DUAL)
    rs = np.fromfile(a.ringscan, dtype="<f4").reshape(-1, 10).astype(np.float64)
    truth = read_truth(a.truth) if a.truth else None
    ok = True
    frames = 0
    compared = 0
    max_dxyz = 0.0
    int_mismatch = 0
    sdk_xyz_rows = np.full((len(rs), 3), np.nan)
    # ringscan rows by (frame, ret, row, col)
    key = (rs[:, 7].astype(np.int64) * 2 + rs[:, 4].astype(np.int64)) * (1 << 32) \
        + rs[:, 5].astype(np.int64) * (1 << 16) + rs[:, 6].astype(np.int64)
    order = np.argsort(key)
    skey = key[order]
    for frame_set in src:
        for fr in frame_set:
            if fr is None:
                continue
            fid = int(fr.frame_id)
            returns = [(0, core.ChanField.RANGE, core.ChanField.REFLECTIVITY, core.ChanField.SIGNAL)]
            if dual:
                returns.append((1, core.ChanField.RANGE2, core.ChanField.REFLECTIVITY2, core.ChanField.SIGNAL2))
            for ret, fr_, fl_, fs_ in returns:
                rng = fr.field(fr_).astype(np.int64)
                refl = fr.field(fl_).astype(np.int64)
                sig = fr.field(fs_).astype(np.int64) if fs_ in fr.fields else None
                xyz = lut(fr.field(fr_))
                rows, cols = np.nonzero(rng)
                k = (fid * 2 + ret) * (1 << 32) + rows * (1 << 16) + cols
                lo = np.searchsorted(skey, (fid * 2 + ret) * (1 << 32))
                hi = np.searchsorted(skey, (fid * 2 + ret + 1) * (1 << 32))
                if hi - lo != len(k):
                    print(f"FAIL: frame {fid} return {ret}: ouster-sdk {len(k)} points, ringscan {hi - lo}")
                    ok = False
                    continue
                idx = np.searchsorted(skey, k)
                if len(k) and not np.all(skey[np.minimum(idx, len(skey) - 1)] == k):
                    print(f"FAIL: frame {fid} return {ret}: pixels differ")
                    ok = False
                    continue
                rows_rs = order[idx]
                p = rs[rows_rs]
                int_mismatch += int(np.sum(p[:, 8] != rng[rows, cols]) + np.sum(p[:, 3] != refl[rows, cols]))
                if sig is not None:
                    int_mismatch += int(np.sum(p[:, 9] != sig[rows, cols]))
                d = np.linalg.norm(p[:, :3] - xyz[rows, cols], axis=1)
                if len(d):
                    max_dxyz = max(max_dxyz, float(d.max()))
                sdk_xyz_rows[rows_rs] = xyz[rows, cols]
                compared += len(k)
            frames += 1
    src.close()
    print(f"frames {frames}; points compared {compared} of ringscan's {len(rs)} (frames ouster-sdk emits);"
          f" integer mismatches (range, reflectivity, signal) {int_mismatch}; max |dxyz| ringscan vs ouster-sdk"
          f" {max_dxyz * 1e3:.4f} mm")
    ok &= compared > 0 and int_mismatch == 0 and max_dxyz <= 0.001
    if truth is not None:
        if len(truth) != len(rs):
            print(f"FAIL: truth {len(truth)} returns, ringscan {len(rs)} points")
            return 1
        ok &= against_truth("ringscan", rs[:, :3], truth, 0.005)
        have = ~np.isnan(sdk_xyz_rows[:, 0])
        ok &= against_truth("ouster-sdk", sdk_xyz_rows[have], truth[have], 0.005)
    print("OK" if ok else "FAIL")
    return 0 if ok else 1


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("kind", choices=["velodyne", "ouster"])
    ap.add_argument("--model")
    ap.add_argument("--calib")
    ap.add_argument("--metadata")
    ap.add_argument("--ringscan", required=True)
    ap.add_argument("--truth")
    ap.add_argument("pcap")
    a = ap.parse_args()
    return velodyne(a) if a.kind == "velodyne" else ouster(a)


if __name__ == "__main__":
    sys.exit(main())
