"""Must-show 1: every capture of ../shared/captures read through ``ringscan.open`` gives the
points the command line writes. The truth is the CLI's MCAP (``python -m ringscan decode``,
read back with the official ``mcap`` reader and protobuf): each ``foxglove.PointCloud``'s data
is the sweep's records byte for byte, so the comparison is exact; and the ``--json`` summary's
totals equal the Python source's summary."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import defaultdict

import numpy as np
import pytest

import ringscan
from conftest import CAPTURES, abspath, capture_cases

CASES = capture_cases()


def cli_decode(case: dict, out) -> dict:
    args = [sys.executable, "-m", "ringscan", "decode", abspath(case["path"]), "--out", str(out)]
    args += ["--json", "--threads", "1"]
    if case["model"]:
        args += ["--model", case["model"]]
    for c in case["calib"]:
        args += ["--calib", abspath(c)]
    r = subprocess.run(args, capture_output=True, text=True, timeout=300)
    if r.returncode == 1 and "no sensor found: " in r.stderr:
        # Nothing decoded (an empty capture, packets of no family): an error, nothing written;
        # --json gives the error as an object, with the reason stderr has.
        assert not out.exists()
        err = json.loads(r.stdout)
        assert err["kind"] == "no_sensor" and err["exit_code"] == 1, err
        assert r.stderr == f"error: {err['error']}\n"
        assert err["error"].endswith(f"no sensor found: {err['no_sensor']}; nothing written")
        return {"no_sensor": err["no_sensor"]}
    assert r.returncode == 0, f"{' '.join(args)}: {r.stderr}"
    return json.loads(r.stdout)


def mcap_clouds(path) -> dict:
    """topic -> [(timestamp_ns, point_stride, data bytes)] of every foxglove.PointCloud."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    clouds = defaultdict(list)
    factory = DecoderFactory()
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, msg in reader.iter_messages():
            if schema.name != "foxglove.PointCloud" or not channel.topic.endswith("/points"):
                continue
            pc = factory.decoder_for(channel.message_encoding, schema)(msg.data)
            ts = pc.timestamp.seconds * 10**9 + pc.timestamp.nanos
            clouds[channel.topic].append((ts, pc.point_stride, bytes(pc.data)))
    return clouds


@pytest.mark.skipif(CAPTURES is None, reason="SKIP: ../shared/captures is missing")
@pytest.mark.parametrize("case", CASES, ids=[c["path"].rsplit("/", 1)[-1] for c in CASES])
def test_open_gives_the_cli_points(case, tmp_path):
    out = tmp_path / "cli.mcap"
    summary = cli_decode(case, out)
    if "no_sensor" in summary:
        # The command line found no sensor: neither does the Python source, for the same reason.
        src = ringscan.open(abspath(case["path"]), calib=[abspath(c) for c in case["calib"]], model=case["model"])
        assert list(src) == []
        assert src.summary["no_sensor"] == summary["no_sensor"]
        return
    cli = mcap_clouds(out)
    topic_of = {s["name"]: s["topic"] for s in summary["sensors"] if s.get("name")}

    src = ringscan.open(abspath(case["path"]), calib=[abspath(c) for c in case["calib"]], model=case["model"])
    py = defaultdict(list)
    for sweep in src:
        p = sweep.points
        assert p.dtype == ringscan.POINT_DTYPE
        # Zero-copy: the array views the native buffer, it does not own its memory.
        assert not p.flags.owndata
        py[topic_of[sweep.sensor]].append((sweep.timestamp_ns, p.dtype.itemsize, p.tobytes()))

    assert sorted(py) == sorted(cli), "not the same sensors"
    for topic in cli:
        assert len(py[topic]) == len(cli[topic]), f"{topic}: sweep counts"
        for i, (a, b) in enumerate(zip(py[topic], cli[topic])):
            assert a[0] == b[0], f"{topic} sweep {i}: timestamp {a[0]} != {b[0]}"
            assert a[1] == b[1], f"{topic} sweep {i}: stride"
            assert a[2] == b[2], f"{topic} sweep {i}: points differ"
    for key in ("sweeps", "points", "imu_samples", "packets"):
        assert src.summary[key] == summary[key], key


@pytest.mark.skipif(CAPTURES is None, reason="SKIP: ../shared/captures is missing")
def test_the_captures_hold_points():
    """The comparison above is not vacuous: most captures decode to points, every family with
    a golden among them."""
    assert len(CASES) >= 40
    total = 0
    for case in CASES:
        if "velodyne_example" in case["path"] or "OS-1-32-G" in case["path"]:
            src = ringscan.open(abspath(case["path"]), calib=[abspath(c) for c in case["calib"]], model=case["model"])
            total += sum(len(s) for s in src)
    assert total == 31630 + 27310  # the goldens' points (velodyne_decoder, ouster-sdk)


@pytest.mark.skipif(CAPTURES is None, reason="SKIP: ../shared/captures is missing")
def test_info_is_the_cli_info(captures):
    rel = "ouster-lidar__ouster-sdk/tests/bags/512x10_raw.bag"
    r = subprocess.run([sys.executable, "-m", "ringscan", "info", "--json", abspath(rel)], capture_output=True, text=True, check=True)
    cli = json.loads(r.stdout)
    py = ringscan.open(abspath(rel)).info()
    for d in (cli, py):
        d.pop("elapsed_s")
    assert py == cli
    assert py["capture"]["bag"]["kind"] and py["sensors"][0]["kind"] == "ouster"


@pytest.mark.skipif(CAPTURES is None, reason="SKIP: ../shared/captures is missing")
def test_info_refuses_the_options_the_cli_info_has_no_flag_for(captures):
    """``ringscan info`` has no ``--max-range``, ``--port``... (exit 2), and ``max_range`` does
    change the counts (``decode --json --max-range 5`` has fewer points than ``info``): so
    ``info(..., max_range=5)`` raises, as does ``open(..., max_range=5).info()``. They returned
    the capture's full counts, as if the option had not been given."""
    path = abspath("jerry73204__rust-lidar-utils/test_files/hdl32_example.pcap")

    def cli(*args, check=True):
        r = subprocess.run([sys.executable, "-m", "ringscan", *args], capture_output=True, text=True, check=check)
        return r if not check else json.loads(r.stdout)

    for flags in (["--max-range", "5"], ["--port", "2368"], ["--cut-angle", "90"]):
        r = cli("info", "--json", path, *flags, check=False)
        assert r.returncode == 2 and "unexpected argument" in r.stderr, (flags, r.stderr)
    full = cli("info", "--json", path)
    cut = cli("decode", "--json", "--max-range", "5", path)
    assert 0 < cut["points"] < full["points"] == 252057
    refused = [
        {"max_range": 5.0}, {"min_range": 1.0}, {"port": 2368}, {"cut_angle": 90.0},
        {"fields": "all"}, {"crc": True}, {"dual_return_threshold": 0.1}, {"fov": (30, 150)},
        {"integration_ms": 50.0}, {"max_range": 5.0, "port": 9},
    ]
    for opts in refused:
        for call in (lambda: ringscan.info(path, **opts), lambda: ringscan.open(path, **opts).info()):
            with pytest.raises(TypeError, match=r"info\(\) takes no ") as e:
                call()
            assert all(f"{k}=" in str(e.value) for k in opts), e.value
    # info's own options still apply, as on the CLI; a decoding option at its default changes
    # nothing and is taken.
    want = cli("info", "--json", "--model", "hdl32e", path)
    for got in (ringscan.info(path, model="hdl32e"), ringscan.info(path, model="hdl32e", cut_angle=0.0, read_ahead=False)):
        for d in (want, got):
            d.pop("elapsed_s", None)
        assert got == want
