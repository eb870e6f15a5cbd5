"""The fleet (must-show 4, its correctness part; the speed is tools/bench_fleet.sh): a few small
captures and bags and corrupt ones decoded on a multiprocessing pool and on a local Ray
instance. Every capture is a row of the summary table; a corrupt one has its error (the CLI's
message), the others complete; the Parquet read back with pyarrow holds exactly the points of
the command line's MCAP (``python -m ringscan decode``); Ray and the pool give the same tables."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import ringscan
from ringscan import fleet
from conftest import CAPTURES, REPO, abspath
from test_golden import mcap_clouds

pa = pytest.importorskip("pyarrow", reason="SKIP: pyarrow is not installed")
import pyarrow.parquet as pq  # noqa: E402


def inputs(tmp_path):
    caps = [
        str(REPO / "fixtures" / "demo-vlp16.pcap"),
        str(REPO / "fixtures" / "bags" / "demo-vlp16.ros1-lz4.bag"),
        str(REPO / "fixtures" / "bags" / "demo-vlp16.sqlite3-message"),
    ]
    if CAPTURES is not None:
        caps.append(abspath("jerry73204__rust-lidar-utils/test_files/hdl32_example.pcap"))
    empty = tmp_path / "corrupt-empty.pcap"
    empty.write_bytes(b"")
    bad = tmp_path / "corrupt-magic.pcap"
    bad.write_bytes(b"\x00\x01\x02\x03" * 100)
    return caps, [str(empty), str(bad)]


def cli_error(path) -> str:
    r = subprocess.run([sys.executable, "-m", "ringscan", "info", path], capture_output=True, text=True)
    assert r.returncode == 1
    return r.stderr.strip().splitlines()[-1].removeprefix("error: ")


def check_table(table, good, corrupt):
    rows = {r["capture"]: r for r in table.to_pylist()}
    assert sorted(rows) == sorted(good + corrupt), "every capture is a row"
    for c in corrupt:
        assert rows[c]["status"] == "error"
        assert rows[c]["error_type"] == "InputError"
        assert rows[c]["error"] == cli_error(c)
        assert rows[c]["parquet"] is None
    for c in good:
        assert rows[c]["status"] == "ok", rows[c]
        assert rows[c]["points"] > 0
    return rows


def parquet_equals_cli_mcap(row, tmp_path):
    cli_out = tmp_path / "cli.mcap"
    subprocess.run([sys.executable, "-m", "ringscan", "decode", row["capture"], "--out", str(cli_out), "--threads", "1"], check=True, capture_output=True)
    clouds = mcap_clouds(cli_out)
    assert len(clouds) == 1
    ((topic, sweeps),) = clouds.items()
    t = pq.read_table(row["parquet"])
    assert t.num_rows == row["points"]
    rec = np.zeros(t.num_rows, dtype=ringscan.POINT_DTYPE)
    for name in ringscan.POINT_DTYPE.names:
        rec[name] = t.column(name).to_numpy()
    # Sweep by sweep: the Parquet rows of sweep k are the k-th PointCloud's records.
    sweep_col = t.column("sweep").to_numpy()
    ts_col = t.column("timestamp_ns").to_numpy()
    idx = np.unique(sweep_col)
    assert len(idx) == len(sweeps)
    for k, (ts, stride, data) in zip(idx, sweeps):
        sel = sweep_col == k
        assert stride == 24
        ref = np.frombuffer(data, dtype=ringscan.POINT_DTYPE)
        assert len(ref) == sel.sum() and (rec[sel] == ref).all()
        assert set(ts_col[sel]) == {ts}


def comparable(table):
    drop = {"decode_s", "parquet", "mcap"}
    return sorted((tuple((k, v) for k, v in r.items() if k not in drop) for r in table.to_pylist()))


def test_pool(tmp_path):
    good, corrupt = inputs(tmp_path)
    out = tmp_path / "out"
    table = fleet.decode(good + corrupt, str(out), engine="pool", workers=2, mcap=True)
    rows = check_table(table, good, corrupt)
    assert pq.read_table(out / "summary.parquet").num_rows == len(good) + len(corrupt)
    for c in good:
        parquet_equals_cli_mcap(rows[c], tmp_path)
        # the fleet's MCAP is the CLI's
        assert mcap_clouds(rows[c]["mcap"]) == mcap_clouds_cli(c, tmp_path)


def mcap_clouds_cli(capture, tmp_path):
    out = tmp_path / "again.mcap"
    subprocess.run([sys.executable, "-m", "ringscan", "decode", capture, "--out", str(out), "--threads", "1"], check=True, capture_output=True)
    return mcap_clouds(out)


def test_directory_listing(tmp_path):
    found = fleet.list_captures(str(REPO / "fixtures" / "bags"))
    assert str(REPO / "fixtures" / "bags" / "demo-vlp16.sqlite3-message") in found
    assert str(REPO / "fixtures" / "bags" / "demo-vlp16.ros1-bz2.bag") in found
    assert not any(f.endswith(".zstd") or f.endswith(".yaml") for f in found)


def test_ray_matches_the_pool(tmp_path):
    ray = pytest.importorskip("ray", reason="SKIP: ray is not installed (the multiprocessing pool is tested)")
    good, corrupt = inputs(tmp_path)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        t_ray = fleet.decode(good + corrupt, str(tmp_path / "ray"), engine="ray")
    finally:
        ray.shutdown()
    check_table(t_ray, good, corrupt)
    t_pool = fleet.decode(good + corrupt, str(tmp_path / "pool"), engine="pool", workers=2)
    assert comparable(t_ray) == comparable(t_pool)
    for r_ray, r_pool in zip(sorted(t_ray.to_pylist(), key=lambda r: r["capture"]), sorted(t_pool.to_pylist(), key=lambda r: r["capture"])):
        if r_ray["status"] == "ok":
            assert pq.read_table(r_ray["parquet"]).equals(pq.read_table(r_pool["parquet"]))


def test_object_store_uris(tmp_path):
    """Inputs and outputs as URIs (``file://``: the same pyarrow.fs code paths an ``s3://`` or
    ``gs://`` prefix takes): the prefix is listed, each capture copied to the task's scratch
    space, its outputs and the summary uploaded under the output URI; the points are the CLI's."""
    import shutil

    good, corrupt = inputs(tmp_path)
    bucket = tmp_path / "bucket" / "drives"
    (bucket / "day1").mkdir(parents=True)
    for c in good + corrupt:
        if c.endswith("sqlite3-message"):
            continue  # a rosbag2 directory: an object store holds its files, not a directory
        shutil.copy(c, bucket / "day1" / c.rsplit("/", 1)[-1])
    prefix = "file://" + str(bucket)
    listed = fleet.list_captures(prefix)
    assert listed and all(u.startswith("file://") for u in listed)
    out = "file://" + str(tmp_path / "bucket" / "decoded")
    table = fleet.decode(prefix, out, engine="pool", workers=2)
    rows = {r["capture"]: r for r in table.to_pylist()}
    assert sorted(rows) == listed
    for uri, r in rows.items():
        local = uri.removeprefix("file://")
        if "corrupt" in uri:
            # The message names the task's local copy; the CLI's words otherwise.
            name = local.rsplit("/", 1)[-1]
            assert (r["status"], r["error_type"], r["parquet"]) == ("error", "InputError", None)
            assert r["error"].split(name, 1)[-1] == cli_error(local).split(name, 1)[-1], r["error"]
            continue
        assert r["status"] == "ok", r
        assert r["parquet"].startswith(out + "/points/")
        parquet_equals_cli_mcap({**r, "capture": local, "parquet": r["parquet"].removeprefix("file://")}, tmp_path)
    assert pq.read_table(str(tmp_path / "bucket" / "decoded" / "summary.parquet")).num_rows == len(listed)
    # An object that is not there: the capture's error (a row), not the task's.
    gone = fleet.decode_one(prefix + "/day1/gone.pcap", out)
    assert (gone["status"], gone["error_type"]) == ("error", "InputError"), gone


def test_a_capture_with_no_sensor_is_an_error_row(tmp_path):
    """As ``ringscan decode`` exits 1 when it finds no sensor, a fleet task that decodes
    nothing is an error row (``DecodeError``, the reason given) with nothing published, whether
    it writes Parquet, MCAP, both or neither (the row alone was ``ok`` with no sensor)."""
    demo = (REPO / "fixtures" / "demo-vlp16.pcap").read_bytes()
    header_only = tmp_path / "header-only.pcap"
    header_only.write_bytes(demo[:24])
    r = subprocess.run([sys.executable, "-m", "ringscan", "decode", str(header_only)], capture_output=True, text=True)
    assert r.returncode == 1 and "no sensor found: no datagram was read" in r.stderr, r.stderr
    for parquet, mcap in [(True, False), (False, True), (True, True), (False, False)]:
        out = tmp_path / f"out-{parquet}-{mcap}"
        row = fleet.decode_one(str(header_only), str(out), parquet=parquet, mcap=mcap)
        assert (row["status"], row["error_type"]) == ("error", "DecodeError"), row
        assert "no sensor found: no datagram was read" in row["error"], row
        assert row["parquet"] is None and row["mcap"] is None
        assert not any(p.is_file() for p in out.rglob("*")) if out.exists() else True


def test_same_named_captures_in_two_folders_keep_their_own_outputs(tmp_path):
    """``day1/lidar.pcap`` and ``day2/lidar.pcap``: outputs are named by the path under the
    listed folder, so neither overwrites the other's Parquet or MCAP."""
    demo = (REPO / "fixtures" / "demo-vlp16.pcap").read_bytes()
    root = tmp_path / "drives"
    (root / "day1").mkdir(parents=True)
    (root / "day2").mkdir()
    (root / "day1" / "lidar.pcap").write_bytes(demo)
    # A different capture of the same name: the first half of the demo's records.
    recs = [pos for pos, _h, _p in records(demo)]
    (root / "day2" / "lidar.pcap").write_bytes(demo[: recs[len(recs) // 2]])
    out = tmp_path / "out"
    table = fleet.decode(str(root), str(out), engine="pool", workers=2, mcap=True)
    rows = {r["capture"]: r for r in table.to_pylist()}
    assert len(rows) == 2
    for day in ("day1", "day2"):
        r = rows[str(root / day / "lidar.pcap")]
        assert r["status"] == "ok", r
        assert r["parquet"] == str(out / "points" / day / "lidar.pcap.parquet")
        assert r["mcap"] == str(out / "mcap" / day / "lidar.pcap.mcap")
        assert pq.read_table(r["parquet"]).num_rows == r["points"]
        assert sum(len(d) // s for _t, s, d in next(iter(mcap_clouds(r["mcap"]).values()))) == r["points"]
    assert rows[str(root / "day1" / "lidar.pcap")]["points"] > rows[str(root / "day2" / "lidar.pcap")]["points"]
    # A list without a root: named under the captures' common folder; a capture listed twice
    # would overwrite itself and is refused.
    caps = [str(root / "day1" / "lidar.pcap"), str(root / "day2" / "lidar.pcap")]
    assert fleet.output_names(caps) == {caps[0]: "day1/lidar.pcap", caps[1]: "day2/lidar.pcap"}
    assert fleet.output_names(caps[:1]) == {caps[0]: "lidar.pcap"}
    with pytest.raises(ValueError, match="both would be written"):
        fleet.output_names([caps[0], caps[0]])


def records(data: bytes):
    import struct

    pos = 24
    while pos + 16 <= len(data):
        incl = struct.unpack_from("<I", data, pos + 8)[0]
        yield pos, data[pos : pos + 16], data[pos + 16 : pos + 16 + incl]
        pos += 16 + incl


def test_a_failed_mcap_publishes_no_parquet(tmp_path, monkeypatch):
    """Parquet written, then the MCAP step fails: the row is an error and nothing is
    published under ``out`` (outputs move there only once all of them are written)."""
    from ringscan import _ringscan

    def failing_decode(*args, **kwargs):
        raise ringscan.DecodeError("writing the MCAP: no space left on device")

    monkeypatch.setattr(_ringscan, "decode", failing_decode)
    out = tmp_path / "out"
    row = fleet.decode_one(str(REPO / "fixtures" / "demo-vlp16.pcap"), str(out), parquet=True, mcap=True)
    assert (row["status"], row["error_type"]) == ("error", "DecodeError"), row
    assert row["parquet"] is None and row["mcap"] is None
    assert not any(p.is_file() for p in out.rglob("*")) if out.exists() else True


def test_mcap_output_takes_every_decoding_option(tmp_path):
    """With ``min_range`` (and the other decoding options), the MCAP holds the Parquet's
    points: the options reach both decodes."""
    demo = str(REPO / "fixtures" / "demo-vlp16.pcap")
    full = fleet.decode_one(demo, str(tmp_path / "full"), parquet=True, mcap=False)
    row = fleet.decode_one(demo, str(tmp_path / "out"), parquet=True, mcap=True, options={"min_range": 5.0, "cut_angle": 90.0})
    assert row["status"] == "ok", row
    assert 0 < row["points"] < full["points"]
    assert pq.read_table(row["parquet"]).num_rows == row["points"]
    ((_topic, sweeps),) = mcap_clouds(row["mcap"]).items()
    assert sum(len(d) // s for _t, s, d in sweeps) == row["points"]
    assert len(sweeps) == row["sweeps"]
    # An option the decode refuses is the row's error, for either output.
    bad = fleet.decode_one(demo, str(tmp_path / "bad"), parquet=False, mcap=True, options={"fields": "some"})
    assert (bad["status"], bad["error_type"]) == ("error", "ValueError"), bad


def test_the_row_without_outputs_takes_the_decoding_options(tmp_path):
    """With neither Parquet nor MCAP asked, the row still counts what a decode with the task's
    options gives (``ringscan decode --json`` with the same flags): ``max_range`` cuts points.
    The row came from ``info()``, which takes no decoding option, so it counted them all."""
    demo = str(REPO / "fixtures" / "demo-vlp16.pcap")
    row = fleet.decode_one(demo, str(tmp_path / "out"), parquet=False, mcap=False, options={"max_range": 10.0, "cut_angle": 90.0})
    assert row["status"] == "ok", row
    cli = subprocess.run([sys.executable, "-m", "ringscan", "decode", demo, "--max-range", "10", "--cut-angle", "90", "--json"], check=True, capture_output=True, text=True)
    want = json.loads(cli.stdout)
    full = fleet.decode_one(demo, str(tmp_path / "full"), parquet=False, mcap=False)
    assert 0 < row["points"] == want["points"] < full["points"]
    assert (row["sweeps"], row["packets_decoded"]) == (want["sweeps"], want["packets"]["decoded"])
    assert row["points"] == sum(len(s) for s in ringscan.open(demo, max_range=10.0, cut_angle=90.0))
    assert row["parquet"] is None and row["mcap"] is None
    assert not any(p.is_file() for p in (tmp_path / "out").rglob("*"))
    # A port no packet went to finds no sensor: the row's error, as with outputs (it was `ok`
    # with every point).
    bad = fleet.decode_one(demo, str(tmp_path / "bad"), parquet=False, mcap=False, options={"port": 9})
    assert (bad["status"], bad["error_type"]) == ("error", "DecodeError") and "--port 9" in bad["error"], bad
