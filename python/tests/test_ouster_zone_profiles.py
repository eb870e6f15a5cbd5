"""Ouster's zone-monitoring lidar profiles (FW 3.2: RNG19_RFL8_SIG16_NIR16_ZONE16,
RNG15_RFL8_NIR8_ZONE16, RNG19_RFL8_SIG16_ZONE16_DUAL) and colour profiles
(RNG19_RFL8_SIG16_NIR16_RGB16 and its _DUAL), of which no real capture exists here.
The packets are written by ouster-sdk 1.0.1 (``frame_to_packets``, its own packet format) from
one frame of random fields, so ringscan's layout tables and the encoder cannot share a mistake:

- every point's range, reflectivity, signal, near-IR, zone mask and colour (`fields="all"`)
  equal ouster-sdk's field values of the pixels with a return (the same multiset: each field is
  where ouster-sdk put it, and none is read as another);
- the points (x, y, z, ring, t, return) equal those of the same frame written by ouster-sdk in
  the profile without the zone mask or colour, which the real captures hold ringscan to.
"""

from __future__ import annotations

import struct
import warnings

import numpy as np
import pytest

import ringscan
from conftest import CAPTURES

core = pytest.importorskip("ouster.sdk.core", reason="SKIP: ouster-sdk is not installed")

META = "ouster-lidar__ouster-sdk/tests/pcaps/OS-0-32-U1_v2.2.0_1024x10.json"

# Each zone profile and the profile it adds the zone mask to.
PAIRS = [
    ("RNG19_RFL8_SIG16_NIR16_ZONE16", "RNG19_RFL8_SIG16_NIR16"),
    ("RNG15_RFL8_NIR8_ZONE16", "RNG15_RFL8_NIR8"),
    ("RNG19_RFL8_SIG16_ZONE16_DUAL", "RNG19_RFL8_SIG16_NIR16_DUAL"),
]

# Each colour profile and the profile without the colour channels.
RGB_PAIRS = [
    ("RNG19_RFL8_SIG16_NIR16_RGB16", "RNG19_RFL8_SIG16_NIR16"),
    ("RNG19_RFL8_SIG16_NIR16_RGB16_DUAL", "RNG19_RFL8_SIG16_NIR16_DUAL"),
]


def random_fields(h: int, w: int, seed: int) -> dict:
    """Values every profile of PAIRS can carry exactly: ranges in steps of 8 mm (15-bit
    low-data ranges), near-IR in steps of 16 (8-bit low-data near-IR); one pixel in ten
    without a return."""
    rng = np.random.default_rng(seed)

    def rnge():
        r = rng.integers(60, 12_000, (h, w), dtype=np.uint32) * 8
        r[rng.random((h, w)) < 0.1] = 0
        return r

    return {
        "RANGE": rnge(),
        "RANGE2": rnge(),
        "REFLECTIVITY": rng.integers(0, 256, (h, w), dtype=np.uint8),
        "REFLECTIVITY2": rng.integers(0, 256, (h, w), dtype=np.uint8),
        "SIGNAL": rng.integers(0, 65_536, (h, w), dtype=np.uint16),
        "SIGNAL2": rng.integers(0, 65_536, (h, w), dtype=np.uint16),
        "NEAR_IR": rng.integers(0, 256, (h, w), dtype=np.uint16) * 16,
        "ZONE_MASK": rng.integers(0, 65_536, (h, w), dtype=np.uint16),
        # ouster-sdk holds the three 16-bit colour channels as half floats; finite values
        # set bits across each channel.
        "RGB": rng.uniform(0.0, 60_000.0, (h, w, 3)).astype(np.float16),
    }


def write_pcap(path, payloads, port: int) -> None:
    """A classic pcap of UDP datagrams (Ethernet, IPv4 without options), 1 ms apart."""
    out = [struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65_535, 1)]
    for i, p in enumerate(payloads):
        udp = struct.pack(">HHHH", 7502, port, 8 + len(p), 0) + p
        ip = struct.pack(
            ">BBHHHBBH4s4s", 0x45, 0, 20 + len(udp), i & 0xFFFF, 0, 64, 17, 0,
            bytes([10, 5, 5, 86]), bytes([10, 5, 5, 1]),
        ) + udp
        frame = b"\xff" * 6 + b"\x02" * 6 + b"\x08\x00" + ip
        out.append(struct.pack("<IIII", 1_700_000_000, i * 1000, len(frame), len(frame)) + frame)
    path.write_bytes(b"".join(out))


def encode(profile: str, fields: dict, tmp) -> tuple:
    """One frame of ``fields`` as ouster-sdk writes it in ``profile``: (pcap, metadata JSON),
    and the frame's fields as ouster-sdk holds them."""
    text = (CAPTURES / META).read_text()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        info = core.SensorInfo(text)
        info.format.udp_profile_lidar = getattr(core.UDPProfileLidar, profile)
        frame = core.LidarFrame(info)
        frame.frame_id = 7
        frame.status[:] = 1
        frame.measurement_id[:] = np.arange(frame.w)
        frame.timestamp[:] = 1_000_000_000 + np.arange(frame.w, dtype=np.uint64) * 97_656
        held = {}
        for name, values in fields.items():
            if frame.has_field(name):
                frame.field(name)[:] = values
                held[name] = np.array(frame.field(name))
        packets = core.frame_to_packets(frame, core.PacketFormat(info), info.init_id, info.sn)
    pcap = tmp / f"{profile}.pcap"
    meta = tmp / f"{profile}.json"
    write_pcap(pcap, [bytes(p.buf) for p in packets], info.config.udp_port_lidar or 7502)
    meta.write_text(info.to_json_string())
    return pcap, meta, held


def decode(pcap, meta) -> np.ndarray:
    sweeps = [s.points.copy() for s in ringscan.open(str(pcap), calib=str(meta), fields="all")]
    assert len(sweeps) == 1, len(sweeps)
    return sweeps[0]


def expected_returns(held: dict) -> list:
    """(range, reflectivity, signal, near-IR, zone mask, red, green, blue) of every return of
    the frame, as ouster-sdk holds it; 0 for what the profile does not carry. The colour is
    ouster-sdk's half float, widened to float32 (exact)."""
    h, w = held["RANGE"].shape
    zeros = np.zeros((h, w), dtype=np.uint16)
    nir = held.get("NEAR_IR", zeros)
    zones = held.get("ZONE_MASK", zeros)
    rgb = held.get("RGB", np.zeros((h, w, 3), dtype=np.float16)).astype(np.float32)
    out = []
    for r, refl, sig in (("RANGE", "REFLECTIVITY", "SIGNAL"), ("RANGE2", "REFLECTIVITY2", "SIGNAL2")):
        if r not in held:
            continue
        m = held[r] > 0
        s = held[sig][m] if sig in held else np.zeros(m.sum())
        ints = zip(held[r][m].tolist(), held[refl][m].tolist(), s.tolist(), nir[m].tolist(), zones[m].tolist())
        out += [
            tuple(int(v) for v in i) + tuple(c)
            for i, c in zip(ints, rgb[m].tolist())
        ]
    return sorted(out)


@pytest.mark.skipif(CAPTURES is None, reason="SKIP: ../shared/captures is missing")
@pytest.mark.parametrize(
    "zone, base, extra",
    [(z, b, "ZONE_MASK") for z, b in PAIRS] + [(z, b, "RGB") for z, b in RGB_PAIRS],
    ids=[z for z, _ in PAIRS + RGB_PAIRS],
)
def test_zone_and_colour_profiles_decode_as_ouster_sdk_wrote_them(zone, base, extra, tmp_path):
    fields = random_fields(32, 1024, seed=len(zone))
    zpcap, zmeta, held = encode(zone, fields, tmp_path)
    assert extra in held, zone
    assert np.count_nonzero(held[extra]) > 0.9 * held[extra].size, zone
    got = decode(zpcap, zmeta)
    want = expected_returns(held)
    assert len(got) == len(want) > 25_000
    ours = sorted(
        zip(
            got["range"].tolist(),
            got["intensity"].astype(int).tolist(),
            got["signal"].tolist(),
            got["near_ir"].tolist(),
            got["zones"].tolist(),
            got["red"].tolist(),
            got["green"].tolist(),
            got["blue"].tolist(),
        )
    )
    assert ours == want
    # The values the test compares are there to be compared: masks and colours vary.
    if extra == "ZONE_MASK":
        assert len(set(got["zones"].tolist())) > 1000, zone
    else:
        assert len(set(got["red"].tolist())) > 1000, zone

    bpcap, bmeta, _ = encode(base, fields, tmp_path)
    same = decode(bpcap, bmeta)
    assert len(same) == len(got)
    for name in ("x", "y", "z", "t", "ring", "return", "range"):
        np.testing.assert_array_equal(got[name], same[name], err_msg=f"{zone} vs {base}: {name}")
