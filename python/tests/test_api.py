"""The rest of the API, each against a truth of its own:

* ``Decoder``: every datagram of a capture pushed by hand gives ``ringscan.open``'s sweeps
  (themselves the CLI's, test_golden.py);
* ``listen``: the CLI's ``replay`` of a capture over loopback gives the capture's points;
* ``McapWriter``: sweeps written from Python read back with the official reader as the CLI's
  own MCAP (same schemas, channels, point bytes);
* the pipeline stages on hand-built clouds whose answer is known (voxel centroids, a plane
  and boxes, two blobs, a known motion), and the odometry on a sweep moved by a known offset.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import struct
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import ringscan
from conftest import REPO
from test_golden import mcap_clouds

DEMO = REPO / "fixtures" / "demo-vlp16.pcap"


def datagrams(path):
    """(time_ns, src "ip:port", dst port, payload) of a classic pcap of Ethernet/IPv4/UDP."""
    data = path.read_bytes()
    magic = struct.unpack_from("<I", data, 0)[0]
    scale = 1000 if magic == 0xA1B2C3D4 else 1
    pos = 24
    while pos + 16 <= len(data):
        sec, frac, incl = struct.unpack_from("<III", data, pos)
        rec = data[pos + 16 : pos + 16 + incl]
        pos += 16 + incl
        ip = rec[14:34]
        src = ".".join(str(b) for b in ip[12:16])
        sport, dport = struct.unpack_from(">HH", rec, 34)
        yield sec * 10**9 + frac * scale, f"{src}:{sport}", dport, rec[42:]


def test_decoder_equals_open():
    dec = ringscan.Decoder()
    pushed = []
    for t, src, port, payload in datagrams(DEMO):
        pushed += dec.push(payload, src, port, t)
    pushed += dec.finish()
    opened = list(ringscan.open(DEMO))
    assert len(pushed) == len(opened) > 5
    for a, b in zip(pushed, opened):
        assert a.timestamp_ns == b.timestamp_ns and a.sensor == b.sensor
        assert a.points.tobytes() == b.points.tobytes()
    assert dec.summary()["points"] == sum(len(s) for s in opened)
    with pytest.raises(ringscan.UsageError, match="IPv4:PORT"):
        dec.push(b"x", "nowhere", 2368)
    with pytest.raises(TypeError):
        dec.push("text", "1.2.3.4:5", 2368)


def free_port_offset() -> int:
    for off in range(20000, 40000, 97):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            s.bind(("127.0.0.1", 2368 + off))
            return off
        except OSError:
            continue
        finally:
            s.close()
    raise RuntimeError("no free port")


def test_listen_over_loopback_gives_the_capture_points():
    off = free_port_offset()
    opened = list(ringscan.open(DEMO))
    live = ringscan.listen([f"127.0.0.1:{2368 + off}"], queue=64)
    got = []
    reader = threading.Thread(target=lambda: got.extend(live))
    reader.start()
    time.sleep(0.5)
    subprocess.run([sys.executable, "-m", "ringscan", "replay", str(DEMO), "--to", "127.0.0.1", "--port-offset", str(off), "--rate", "1", "--per-source-loopback"], check=True, capture_output=True)
    time.sleep(0.5)
    live.stop()
    reader.join(timeout=30)
    assert not reader.is_alive()
    s = live.summary
    assert s["stop"] == "stopped by the caller"
    assert s["receive"]["queue_dropped"] == 0 and s["receive"]["sweeps_dropped"] == 0
    assert s["sweeps"] == len(opened) == len(got)
    for a, b in zip(got, opened):
        assert a.points.tobytes() == b.points.tobytes()


def test_listen_bad_sensor_is_a_usage_error():
    with pytest.raises(ringscan.UsageError, match="IPv4"):
        ringscan.listen(["not-an-ip"])


def test_mcap_writer_writes_the_cli_schemas(tmp_path):
    cli = tmp_path / "cli.mcap"
    subprocess.run([sys.executable, "-m", "ringscan", "decode", str(DEMO), "--out", str(cli), "--threads", "1"], check=True, capture_output=True)
    ours = tmp_path / "py.mcap"
    with ringscan.McapWriter(ours) as w:
        sid = w.add_sensor("vlp16-201")
        for sweep in ringscan.open(DEMO):
            w.write_sweep(sid, sweep)
    assert w.summary["topics"]["/points"] == len(list(ringscan.open(DEMO)))
    assert mcap_clouds(ours) == mcap_clouds(cli)

    from mcap.reader import make_reader

    def schemas(p):
        with open(p, "rb") as f:
            s = make_reader(f).get_summary()
        return {(c.topic, s.schemas[c.schema_id].name) for c in s.channels.values()}

    assert ("/points", "foxglove.PointCloud") in schemas(ours)
    assert schemas(ours) <= schemas(cli)
    with pytest.raises(ringscan.UsageError, match="format"):
        ringscan.McapWriter(tmp_path / "x.mcap", format="pcd")


def cloud(xyz, t=None):
    p = np.zeros(len(xyz), dtype=ringscan.POINT_DTYPE)
    p["x"], p["y"], p["z"] = np.asarray(xyz, dtype=np.float32).T
    if t is not None:
        p["t"] = t
    return p


def test_voxel_downsample_gives_centroids():
    # Two voxels of 1 m: 8 corners of a 0.5 m cube in each.
    corners = np.array([[x, y, z] for x in (0.1, 0.6) for y in (0.1, 0.6) for z in (0.1, 0.6)])
    pts = cloud(np.vstack([corners, corners + [5.0, 0, 0]]))
    out = ringscan.voxel_downsample(pts, leaf_m=1.0)
    got = sorted(map(tuple, np.round(np.stack([out["x"], out["y"], out["z"]], 1), 4)))
    assert got == [(0.35, 0.35, 0.35), (5.35, 0.35, 0.35)]
    with pytest.raises(ringscan.UsageError, match="voxel.leaf_m"):
        ringscan.voxel_downsample(pts, leaf_m=-1.0)


def test_ground_plane_and_boxes():
    rng = np.random.default_rng(1)
    ground = np.column_stack([rng.uniform(-20, 20, 4000), rng.uniform(-20, 20, 4000), np.full(4000, -1.8)])
    box = np.column_stack([rng.uniform(5, 6, 500), rng.uniform(-0.5, 0.5, 500), rng.uniform(-1.0, 0.5, 500)])
    mask = ringscan.segment_ground(cloud(np.vstack([ground, box])), method="ransac", distance_threshold_m=0.1)
    assert mask[:4000].mean() > 0.99 and mask[4000:].mean() < 0.01


def test_cluster_two_blobs():
    rng = np.random.default_rng(2)
    a = rng.normal([10, 0, 0], 0.1, (300, 3))
    b = rng.normal([0, 10, 0], 0.1, (200, 3))
    labels, clusters = ringscan.cluster(cloud(np.vstack([a, b])), tolerance_m=0.5, min_points=5)
    assert sorted(c["points"] for c in clusters) == [200, 300]
    assert len(set(labels[:300])) == 1 and len(set(labels[300:])) == 1 and labels[0] != labels[300]
    big = [c for c in clusters if c["points"] == 300][0]
    assert abs(big["centroid"][0] - 10) < 0.05


def test_deskew_known_motion():
    # Moving forward at 10 m/s: a point fired 0.1 s after the sweep start is 1 m farther
    # forward in the start frame than where it was measured.
    pts = cloud([[5.0, 0.0, 0.0], [5.0, 0.0, 0.0]], t=[0, 100_000_000])
    out = ringscan.deskew(pts, linear_mps=(10.0, 0.0, 0.0))
    assert abs(out["x"][0] - 5.0) < 1e-5 and abs(out["x"][1] - 6.0) < 1e-4


def test_odometry_recovers_a_known_shift():
    sweeps = list(ringscan.open(DEMO))
    s = sweeps[2].points.copy()
    s["t"] = 0
    odo = ringscan.Odometry(voxel=0.5, max_range=50.0)
    assert odo.register(s, 0)["status"] == "Initialized"
    moved = s.copy()
    moved["x"] -= 0.3  # the sensor moved 0.3 m forward
    r = odo.register(moved, 100_000_000)
    assert r["status"] == "Converged"
    assert abs(r["world_from_sensor"][0, 3] - 0.3) < 0.02
    assert np.abs(r["world_from_sensor"][1:3, 3]).max() < 0.02
    with pytest.raises(ringscan.UsageError, match="method"):
        ringscan.Odometry(method="magic")
    with pytest.raises(ringscan.UsageError, match="odometry-max-range"):
        ringscan.Odometry(max_range=-1)


def test_arrays_kept_alive_are_never_reused_and_reading_ahead_changes_nothing():
    # The arrays of every sweep kept alive at once (the decoding thread must not get their
    # memory back for later sweeps), against sweeps copied and dropped one by one (their
    # memory is reused) and against the capture read without the read-ahead thread.
    kept = [(s.points, s.image("intensity")) for s in ringscan.open(DEMO)]
    copied = [(s.points.copy(), s.image("intensity").copy()) for s in ringscan.open(DEMO)]
    plain = [s.points.copy() for s in ringscan.open(DEMO, read_ahead=False)]
    assert len(kept) == len(copied) == len(plain) > 5
    for (a, ia), (b, ib), c in zip(kept, copied, plain):
        # Field by field: numpy's copy of a structured array leaves the padding byte unset.
        for f in a.dtype.names:
            assert np.array_equal(a[f], b[f]) and np.array_equal(a[f], c[f]), f
        assert np.array_equal(ia, ib)
    with pytest.raises(TypeError, match="read_ahead"):
        ringscan.open(DEMO, read_ahead="yes")


def test_image_is_channel_by_column():
    sweep = list(ringscan.open(DEMO))[3]
    img = sweep.image("intensity")
    assert img.shape[0] == 16 and img.shape[1] > 800
    p = sweep.points
    # every point lands in the cell of its ring and column
    assert (img > 0).sum() == (p["intensity"] > 0).sum()


def test_pandas_and_numpy_views():
    sweep = next(iter(ringscan.open(DEMO)))
    assert sweep.xyz.shape == (len(sweep), 3)
    pd = pytest.importorskip("pandas", reason="SKIP: pandas is not installed")
    df = sweep.to_pandas()
    assert list(df.columns) == list(ringscan.POINT_DTYPE.names) and len(df) == len(sweep)


def run_child(code: str, timeout: float = 60) -> str:
    """Runs ``code`` in a child interpreter: a hang there (a deadlock) is a timeout, not a
    stuck test run."""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_close_from_another_thread_ends_a_waiting_iteration(tmp_path):
    """A ``Source`` waiting for its first sweep (its calibration a FIFO nobody writes yet) is
    closed from the main thread: ``close()`` returns at once and the iteration ends.
    ``next()`` holds the reader's lock while it waits without the GIL, so a ``close()`` that
    waited for the lock with the GIL held hung both threads."""
    fifo = tmp_path / "calib.yaml"
    os.mkfifo(fifo)
    code = f"""
import os, threading, time, ringscan
src = ringscan.open({str(DEMO)!r}, calib={str(fifo)!r})
got = []
t = threading.Thread(target=lambda: got.extend(src), daemon=True)
t.start()
time.sleep(0.5)
t0 = time.monotonic()
src.close()
closed = time.monotonic() - t0
t.join(timeout=2)
print(closed < 1, not t.is_alive(), got == [], src.summary is None)
# The decoding thread's read of the FIFO returns (empty), so it ends too.
os.close(os.open({str(fifo)!r}, os.O_WRONLY))
"""
    assert run_child(code, timeout=30).split() == ["True"] * 4


def test_listener_used_from_two_threads():
    """A second ``next()`` while one waits is an error (not a hang), and ``stop()`` from
    another thread ends the waiting iteration."""
    off = free_port_offset()
    code = f"""
import threading, time, ringscan
live = ringscan.listen(["127.0.0.1:{2368 + off}"])
got = []
t = threading.Thread(target=lambda: got.extend(live), daemon=True)
t.start()
time.sleep(0.5)
try:
    live._native.next()
    print("no-error")
except RuntimeError as e:
    print("another-thread" if "another thread" in str(e) else repr(e))
t0 = time.monotonic()
live.stop()
t.join(timeout=2)
print(time.monotonic() - t0 < 2, not t.is_alive(), live.summary["stop"] == "stopped by the caller")
"""
    assert run_child(code, timeout=30).split() == ["another-thread", "True", "True", "True"]


def test_leaving_the_with_block_finishes_the_recording(tmp_path):
    """``stop()`` (and the end of a ``with`` block) returns once the listening thread has ended:
    the MCAP file has its footer and summary, and ``summary`` is set, even when the loop is
    left after the first sweep."""
    from mcap.reader import make_reader

    off = free_port_offset()
    out = tmp_path / "live.mcap"
    replay = subprocess.Popen([sys.executable, "-m", "ringscan", "replay", str(DEMO), "--to", "127.0.0.1", "--port-offset", str(off), "--rate", "1", "--per-source-loopback"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with ringscan.listen([f"127.0.0.1:{2368 + off}"], out=out, duration=30) as live:
            for sweep in live:
                assert len(sweep) > 0
                break
        assert live.summary is not None and live.summary["stop"] == "stopped by the caller"
        assert live.summary["sweeps"] >= 1
        with open(out, "rb") as f:
            summary = make_reader(f).get_summary()
        assert summary is not None
        assert sum(summary.statistics.channel_message_counts.values()) >= 1
    finally:
        replay.kill()
        replay.wait()
    # Nothing received: no file (as `listen`), no temporary file left, the summary still set.
    quiet = tmp_path / "quiet"
    quiet.mkdir()
    with ringscan.listen([f"127.0.0.1:{2368 + off}"], out=quiet / "none.mcap") as live:
        pass
    assert live.summary is not None and list(quiet.iterdir()) == []


@pytest.mark.parametrize("kwargs", [dict(duration=1e20), dict(duration=float("nan")), dict(duration=float("inf")), dict(duration=0), dict(duration=-1), dict(queue=10**9)])
def test_listen_bad_duration_or_queue_is_a_usage_error(kwargs):
    with pytest.raises(ringscan.UsageError, match="duration|queue"):
        ringscan.listen(["127.0.0.1:1"], **kwargs)


def test_a_duration_past_the_clock_is_no_limit():
    """``duration=1e19`` fits a ``Duration``, so it is taken, but not the clock: the deadline's
    ``Instant + Duration`` panicked on the listening thread (``stop()`` raised RuntimeError).
    It is no deadline, as ``1e9`` already is in effect."""
    off = free_port_offset()
    with ringscan.listen([f"127.0.0.1:{2368 + off}"], duration=1e19) as live:
        time.sleep(0.3)
    assert live.summary["stop"] == "stopped by the caller"


def test_a_listening_thread_that_panics_raises(monkeypatch):
    """A listening thread that ends without a result (it panicked: a bug) raises
    ``RuntimeError`` with the panic's message, from the iteration or from ``stop()``, once; it
    must not end as a normal stop would. The panic is a seam of debug builds (the CI's)."""
    var = getattr(ringscan._ringscan, "_test_listen_panic", None)
    if var is None:
        pytest.skip("SKIP: a release build: the listening thread's panic seam is in debug builds only")
    monkeypatch.setenv(var, "1")
    off = free_port_offset()
    why = f"stopped without a result \\({var} is set\\)"
    live = ringscan.listen([f"127.0.0.1:{2368 + off}"])
    with pytest.raises(RuntimeError, match=why):
        list(live)
    live.stop()
    assert live.summary is None
    live = ringscan.listen([f"127.0.0.1:{2368 + off}"])
    with pytest.raises(RuntimeError, match=why):
        live.stop()
    assert list(live) == [] and live.summary is None


def test_ctrl_c_ends_the_command_line(tmp_path):
    """``python -m ringscan`` runs the command line without the GIL: Python's own SIGINT
    handler would only set a flag nobody reads, so Ctrl-C must end it as it ends ``ringscan``;
    ``listen`` still catches it and finishes its run."""
    off = free_port_offset()

    def interrupt(p, timeout):
        time.sleep(1.5)
        p.send_signal(signal.SIGINT)
        try:
            return p.communicate(timeout=timeout)[0]
        except subprocess.TimeoutExpired:
            p.kill()
            p.communicate()
            pytest.fail(f"{p.args[3]} did not stop on SIGINT")

    lst = subprocess.Popen([sys.executable, "-m", "ringscan", "listen", "--sensor", f"127.0.0.1:{2368 + off}", "--json"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    # A replay that would take minutes (a tenth of real time, looped).
    rep = subprocess.Popen([sys.executable, "-m", "ringscan", "replay", str(DEMO), "--to", "127.0.0.1", "--port-offset", str(off), "--rate", "0.1", "--loop", "100"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        out = interrupt(lst, 10)
        assert lst.returncode == 0 and json.loads(out)["stop"] == "SIGINT"
    finally:
        interrupt(rep, 5)
    assert rep.returncode != 0


def counted_during(call) -> "tuple[float, float]":
    """Runs ``call()`` while another Python thread counts in a loop: the call's wall time, and
    how far the counter got during it as a fraction of how far it gets in the same wall time
    while this thread sleeps (the GIL free). Near 1 when the call releases the GIL; near 0
    when it holds it, the counter moving only at the call's two ends, for about a switch
    interval each. A ratio, so a slow or loaded machine slows both sides alike."""
    count = [0]
    running = [True]

    def spin():
        while running[0]:
            count[0] += 1

    t = threading.Thread(target=spin, daemon=True)
    t.start()
    try:
        while count[0] == 0:
            time.sleep(0.001)
        c0, t0 = count[0], time.perf_counter()
        call()
        took = time.perf_counter() - t0
        during = count[0] - c0
        c0 = count[0]
        time.sleep(took)
        alone = count[0] - c0
    finally:
        running[0] = False
        t.join()
    return took, during / max(alone, 1)


def assert_releases_the_gil(calls) -> None:
    """``calls``: ever larger versions of one call. The first lasting 40 switch intervals
    decides: the counter must reach a fifth of its pace without the call. (A call holding the
    GIL lets it move for about two switch intervals, a twentieth of that call: 3 to 8 % seen.)"""
    for call in calls:
        took, fraction = counted_during(call)
        if took >= 40 * sys.getswitchinterval():
            break
    else:
        pytest.fail(f"the largest call took {took:.3f} s: too short to tell a held GIL")
    # A burst of load may starve the counting thread once; a held GIL stops it every time.
    for _retry in range(2):
        if fraction >= 0.2:
            break
        took, fraction = counted_during(call)
    assert fraction >= 0.2, f"another thread counted {fraction:.0%} of its pace during the {took:.3f} s call: the GIL was held"


def test_odometry_register_releases_the_gil():
    """A Python thread runs while ``Odometry.register`` aligns a large cloud (every sweep of
    the demo, tiled by small turns to make more of it)."""
    base = np.concatenate([s.points for s in ringscan.open(DEMO)])
    base["t"] = 0

    def call(copies):
        parts = []
        for k in range(copies):
            c, s = np.cos(np.radians(0.5 * k)), np.sin(np.radians(0.5 * k))
            p = base.copy()
            p["x"], p["y"] = c * base["x"] - s * base["y"], s * base["x"] + c * base["y"]
            parts.append(p)
        cloud = np.concatenate(parts)
        moved = cloud.copy()
        moved["x"] -= 0.3
        odo = ringscan.Odometry(voxel=0.1)
        odo.register(cloud, 0)
        # The native call alone: numpy's copies in the wrapper release the GIL themselves.
        records = ringscan._records(moved)
        return lambda: odo._native.register(records, 100_000_000)

    assert_releases_the_gil(call(k) for k in (1, 2, 4))


def test_mcap_writer_write_sweep_releases_the_gil(tmp_path):
    """A Python thread runs while ``McapWriter.write_sweep`` encodes and compresses a large
    sweep (copies of the demo's sweeps, one writing thread)."""
    base = np.concatenate([s.points for s in ringscan.open(DEMO)])

    def call(copies):
        records = ringscan._records(np.concatenate([base] * copies))
        w = ringscan.McapWriter(tmp_path / f"big{copies}.mcap", threads=1)
        writers.append(w)
        sid = w.add_sensor("big")
        # The native call alone: numpy's copies in the wrapper release the GIL themselves.
        return lambda: w._native.write_sweep(sid, records, 1, None)

    writers = []
    try:
        assert_releases_the_gil(call(k) for k in (8, 16, 32))
    finally:
        for w in writers:
            w.close()


def test_mcap_writer_close_releases_the_gil(tmp_path):
    """A Python thread runs while ``McapWriter.close`` compresses the chunk still open (the
    demo's sweeps written again and again, under one 4 MiB chunk, at zstd's slowest level,
    one writing thread) and writes the file's summary."""
    sweeps = [ringscan._records(s.points) for s in ringscan.open(DEMO)]
    writers = []

    class CloseNext:
        """``close()`` of the next of three writers filled beforehand: a writer closes once,
        and the helper may call again."""

        def __init__(self, mib):
            self.ready = []
            for k in range(3):
                w = ringscan.McapWriter(tmp_path / f"close{mib}-{k}.mcap", compression="zstd:19", threads=1)
                writers.append(w)
                sid = w.add_sensor("big")
                written, i = 0, 0
                while written < mib * 2**20:
                    records = sweeps[i % len(sweeps)]
                    w._native.write_sweep(sid, records, 1_000_000 * (i + 1), None)
                    written, i = written + len(records), i + 1
                self.ready.append(w)

        def __call__(self):
            # The native call alone, as for the other calls.
            self.ready.pop()._native.close()

    try:
        assert_releases_the_gil(CloseNext(mib) for mib in (0.5, 1, 2, 3))
    finally:
        for w in writers:
            w.close()
