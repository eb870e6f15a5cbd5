"""Must-show 5: bad input from Python raises exceptions with clear messages, never crashes the
interpreter. Hostile captures are the hardening suite's (tests/cli_bad_input.rs, built here the
same way from the demo capture; fixtures/regressions, the fuzzers' finds; fixtures/bags):
each goes through ``ringscan.open`` in a child interpreter (a crash there cannot hide behind
pytest), and its exception's message is the command line's ``error: ...`` line, word for word."""

from __future__ import annotations

import json
import os
import random
import struct
import subprocess
import sys
from pathlib import Path

import pytest

import ringscan
from conftest import CAPTURES, REPO

DEMO = REPO / "fixtures" / "demo-vlp16.pcap"


def records(data: bytes):
    """(offset, header, payload) of every record of a classic pcap."""
    pos = 24
    while pos + 16 <= len(data):
        incl = struct.unpack_from("<I", data, pos + 8)[0]
        yield pos, data[pos : pos + 16], data[pos + 16 : pos + 16 + incl]
        pos += 16 + incl


def hostile_inputs(tmp: Path) -> dict:
    demo = DEMO.read_bytes()
    recs = list(records(demo))
    out = {}

    def put(name, data):
        p = tmp / name
        p.write_bytes(data)
        out[name] = p

    put("empty.pcap", b"")
    put("wrong-magic.pcap", b"\x0a\x0d\x0d\x0b" * 6 + demo[24:200])
    put("header-only.pcap", demo[:24])
    put("truncated-last-record.pcap", demo[: recs[49][0] + 16 + 100])
    big = bytearray(demo)
    off = recs[3][0]
    big[off + 8 : off + 12] = struct.pack("<I", 1_000_000_000)
    big[off + 12 : off + 16] = struct.pack("<I", 1_000_000_000)
    put("gigabyte-record.pcap", bytes(big))
    snap = bytearray(demo)
    snap[16:20] = struct.pack("<I", 1000)
    put("record-longer-than-snaplen.pcap", bytes(snap))
    bad = bytearray(demo)
    for i, (pos, _h, payload) in enumerate(recs[:60]):
        p = pos + 16 + 42
        if i % 15 == 1:
            bad[p : p + 2] = b"\x00\x00"  # a block flag
        if i % 15 == 7:
            bad[p + 302 : p + 304] = struct.pack("<H", 40_000)  # azimuth out of range
    put("bad-flags-and-azimuths.pcap", bytes(bad))
    rng = random.Random(23)
    for k in range(8):
        put(f"random-{k}.pcap", demo[:24] + bytes(rng.getrandbits(8) for _ in range(rng.randrange(16, 20_000))))
    # Random byte flips all over a valid capture.
    for k in range(4):
        b = bytearray(demo)
        for _ in range(200):
            b[rng.randrange(len(b))] = rng.getrandbits(8)
        put(f"flipped-{k}.pcap", bytes(b))
    for f in sorted((REPO / "fixtures" / "regressions").glob("*.bin")):
        out["regression-" + f.name] = f
    for f in sorted((REPO / "fixtures" / "bags").iterdir()):
        if f.name != "README.md":
            out["bag-" + f.name] = f
    # A bag cut in half.
    put("half.bag", (REPO / "fixtures" / "bags" / "demo-vlp16.ros1-lz4.bag").read_bytes()[:20_000])
    return out


CHILD = r"""
import json, sys, ringscan
try:
    n = sum(len(s) for s in ringscan.open(sys.argv[1]))
    print(json.dumps({"ok": n}))
except ringscan.RingscanError as e:
    print(json.dumps({"error": type(e).__name__, "message": str(e)}))
"""


def test_hostile_captures_raise_clear_errors(tmp_path):
    inputs = hostile_inputs(tmp_path)
    assert len(inputs) >= 30
    outcomes = {}
    for name, path in inputs.items():
        r = subprocess.run([sys.executable, "-c", CHILD, str(path)], capture_output=True, text=True, timeout=120)
        # Exit 0 and one JSON line: no crash, no uncaught exception, no panic text.
        assert r.returncode == 0, f"{name}: exit {r.returncode}: {r.stderr[-2000:]}"
        assert "panicked" not in r.stderr, f"{name}: {r.stderr}"
        got = json.loads(r.stdout)
        outcomes[name] = got
        cli = subprocess.run([sys.executable, "-m", "ringscan", "info", str(path)], capture_output=True, text=True, timeout=120)
        if "error" in got:
            # The CLI's message, word for word, and a message that names the input.
            assert cli.returncode in (1, 2), f"{name}: the CLI accepted what Python refused"
            assert cli.stderr.strip().splitlines()[-1] == "error: " + got["message"], name
            assert got["message"].strip(), name
        else:
            assert cli.returncode == 0, f"{name}: {cli.stderr}"
    errors = {k: v for k, v in outcomes.items() if "error" in v}
    # The suite exercises both outcomes: refused inputs and decoded-with-counted-losses ones.
    assert "empty.pcap" in errors and "empty" in errors["empty.pcap"]["message"].lower()
    assert "magic" in errors["wrong-magic.pcap"]["message"]
    assert "gigabyte-record.pcap" in errors
    assert outcomes["truncated-last-record.pcap"].get("ok", 0) > 0
    assert outcomes["bad-flags-and-azimuths.pcap"].get("ok", 0) > 0


def test_truncated_and_damaged_captures_count_their_losses(tmp_path):
    inputs = hostile_inputs(tmp_path)
    src = ringscan.open(inputs["bad-flags-and-azimuths.pcap"])
    list(src)
    # 8 packets damaged by hand (4 block flags, 4 azimuths): 8 counted, the rest decoded.
    assert src.summary["packets"]["malformed"] == 8
    data_packets = sum(1 for _pos, _h, payload in records(DEMO.read_bytes()) if len(payload) == 42 + 1206)
    assert src.summary["packets"]["decoded"] == data_packets - 8
    src = ringscan.open(inputs["truncated-last-record.pcap"])
    list(src)
    assert src.summary["capture"]["truncated_tail_offset"] is not None


def test_missing_file(tmp_path):
    missing = tmp_path / "nope.pcap"
    with pytest.raises(ringscan.InputError, match="nope.pcap"):
        list(ringscan.open(missing))
    with pytest.raises(ringscan.InputError, match="nope.pcap"):
        ringscan.open(missing).info()


@pytest.mark.parametrize(
    "kwargs,exc,pattern",
    [
        (dict(path=3), TypeError, "path: expected a path"),
        (dict(path=None), TypeError, "path: expected a path"),
        (dict(calib=7), TypeError, "calib"),
        (dict(model=16), TypeError, "model"),
        (dict(topics=[1, 2]), TypeError, "topics"),
        (dict(min_range="near"), TypeError, "min_range"),
        (dict(fields="most"), ValueError, "fields"),
        (dict(port=70000), ValueError, "port"),
        (dict(crc="yes"), TypeError, "crc"),
    ],
)
def test_wrong_types_are_type_errors(kwargs, exc, pattern):
    kwargs.setdefault("path", DEMO)
    with pytest.raises(exc, match=pattern):
        ringscan.open(**kwargs)


@pytest.mark.parametrize(
    "kwargs,pattern",
    [
        (dict(model="vlp17"), r"--model vlp17: expected one of"),
        (dict(cut_angle=400.0), r"--cut-angle 400: expected \[0, 360\)"),
        (dict(min_range=5.0, max_range=1.0), r"empty range"),
        (dict(topics=["/x"]), r"is not a bag"),
    ],
)
def test_bad_options_are_usage_errors_with_the_cli_message(kwargs, pattern):
    with pytest.raises(ringscan.UsageError, match=pattern):
        list(ringscan.open(DEMO, **kwargs))
    assert issubclass(ringscan.UsageError, ringscan.RingscanError)


def test_bad_calibration_file(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("lasers: [ {laser_id: 0, rot_correction: nope} ]\n")
    with pytest.raises(ringscan.CalibrationError, match="bad.yaml"):
        list(ringscan.open(DEMO, calib=bad))


@pytest.mark.skipif(CAPTURES is None, reason="SKIP: ../shared/captures is missing")
def test_a_sensor_without_its_calibration_is_a_decode_error_info_still_reads_it():
    """As on the command line: a Hesai capture without its angle correction decodes nothing,
    so iterating raises (the CLI's message); ``info()`` still names the model."""
    xt32 = CAPTURES / (
        "tier4__nebula/src/nebula_hesai/nebula_hesai/test_resources/decoder_ground_truth/"
        "xt32/1673400677802009732/1673400677802009732_0.pcap"
    )
    with pytest.raises(ringscan.DecodeError, match="the PandarXT32 has no built-in calibration"):
        list(ringscan.open(xt32))
    info = ringscan.open(xt32).info()
    assert info["sensors"][0]["model"] == "PandarXT32"


def test_stopping_early_and_reiterating():
    src = ringscan.open(DEMO)
    it = iter(src)
    first = next(it)
    it.close()  # the decoding thread stops; nothing hangs
    again = next(iter(src))
    assert first.timestamp_ns == again.timestamp_ns and len(first) == len(again)
    assert src.summary is None  # no iteration ran to the end
    n = sum(1 for _ in src)
    assert src.summary["sweeps"] == n > 0
