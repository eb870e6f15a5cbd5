"""ringscan: LiDAR packets (Velodyne, Ouster, Hesai, RoboSense, Livox) to NumPy point clouds.

Reads pcap / pcapng captures and ROS bags (ROS 1, rosbag2 sqlite3 and MCAP) with the same
decoder as the ``ringscan`` command line::

    import ringscan

    with ringscan.open("drive.pcap") as src:
        print(src.info()["sensors"][0]["model"])
        for sweep in src:
            pts = sweep.points            # NumPy structured array, no copy
            xyz = sweep.xyz               # (N, 3) float32
            print(sweep.sensor, sweep.timestamp, len(pts), sweep.missing_packets)

``python -m ringscan ...`` runs the command line itself (``decode``, ``info``, ``listen``...).
"""

from __future__ import annotations

import json
import os
from typing import Any, Dict, Iterator, List, Optional, Sequence, Union

import numpy as np

from ._ringscan import (
    CalibrationError,
    DecodeError,
    InputError,
    RingscanError,
    UsageError,
)
from . import _ringscan

__all__ = [
    "compat",
    "open",
    "Source",
    "Sweep",
    "POINT_DTYPE",
    "EXTENDED_DTYPE",
    "RingscanError",
    "UsageError",
    "InputError",
    "CalibrationError",
    "DecodeError",
    "info",
    "Decoder",
    "listen",
    "Listener",
    "voxel_downsample",
    "segment_ground",
    "cluster",
    "deskew",
    "Odometry",
    "McapWriter",
    "fleet",
    "__version__",
]

__version__: str = _ringscan.version()

#: One point as the decoder emits it (24 bytes, the MCAP ``foxglove.PointCloud`` record):
#: metres in the sensor frame (x forward, y left, z up), the raw intensity, ``t`` in ns since the
#: sweep's timestamp, ``ring`` (0 = lowest beam) and ``return`` (0 strongest / first, 1 last).
POINT_DTYPE = np.dtype(
    {
        "names": ["x", "y", "z", "intensity", "t", "ring", "return"],
        "formats": ["<f4", "<f4", "<f4", "<f4", "<u4", "<u2", "u1"],
        "offsets": [0, 4, 8, 12, 16, 20, 22],
        "itemsize": 24,
    }
)

#: ``fields="all"`` (Ouster): the point, then range (mm), signal and near-IR photons, the zone
#: mask (ZONE16 profiles) and red, green, blue (RGB16 profiles); 0 where the sensor sends none.
EXTENDED_DTYPE = np.dtype(
    {
        "names": POINT_DTYPE.names
        + ("range", "signal", "near_ir", "zones", "red", "green", "blue"),
        "formats": [
            "<f4", "<f4", "<f4", "<f4", "<u4", "<u2", "u1",
            "<u4", "<u2", "<u2", "<u2", "<f4", "<f4", "<f4",
        ],
        "offsets": [0, 4, 8, 12, 16, 20, 22, 24, 28, 30, 32, 36, 40, 44],
        "itemsize": 48,
    }
)

PathLike = Union[str, "os.PathLike[str]"]


def _path(value: Any, what: str) -> str:
    if isinstance(value, (str, os.PathLike)):
        return os.fspath(value)
    raise TypeError(f"{what}: expected a path (str or os.PathLike), got {type(value).__name__}")


def _paths(value: Any, what: str) -> List[str]:
    if value is None:
        return []
    if isinstance(value, (str, os.PathLike)):
        return [os.fspath(value)]
    if isinstance(value, Sequence):
        return [_path(v, what) for v in value]
    raise TypeError(f"{what}: expected a path or a list of paths, got {type(value).__name__}")


def _strings(value: Any, what: str) -> List[str]:
    if value is None:
        return []
    if isinstance(value, str):
        return [value]
    if isinstance(value, Sequence) and all(isinstance(v, str) for v in value):
        return list(value)
    raise TypeError(f"{what}: expected a string or a list of strings, got {type(value).__name__}")


def _number(value: Any, what: str) -> Optional[float]:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{what}: expected a number, got {type(value).__name__}")
    return float(value)


class Sweep:
    """One sweep (a turn of a spinning sensor, one frame of a solid-state one).

    ``points`` is a NumPy structured array (:data:`POINT_DTYPE`, or :data:`EXTENDED_DTYPE` with
    ``fields="all"``) viewing the decoder's own buffer: no copy is made.
    """

    __slots__ = ("_raw", "_points")

    def __init__(self, raw: "_ringscan.RawSweep"):
        self._raw = raw
        self._points: Optional[np.ndarray] = None

    @property
    def points(self) -> np.ndarray:
        """The points, a structured array (x, y, z, intensity, t, ring, return [, range, signal, near_ir, zones, red, green, blue])."""
        if self._points is None:
            dtype = EXTENDED_DTYPE if self._raw.extended else POINT_DTYPE
            self._points = np.asarray(self._raw.points).view(dtype)
        return self._points

    @property
    def xyz(self) -> np.ndarray:
        """``(N, 3)`` float32 coordinates (a copy)."""
        p = self.points
        return np.stack([p["x"], p["y"], p["z"]], axis=1)

    @property
    def timestamp(self) -> float:
        """The sweep's first firing, seconds since the Unix epoch (clock: :attr:`clock`)."""
        return self._raw.timestamp_ns * 1e-9

    @property
    def timestamp_ns(self) -> int:
        """The sweep's first firing, ns since the Unix epoch."""
        return self._raw.timestamp_ns

    @property
    def clock(self) -> str:
        """Where :attr:`timestamp` comes from (e.g. ``host``, ``gps``, ``ptp``)."""
        return self._raw.clock

    @property
    def sensor(self) -> str:
        """The sensor's name, as ``ringscan decode`` names it (its topic prefix)."""
        return self._raw.sensor

    @property
    def sensor_index(self) -> int:
        """The sensor's index in the capture (order of first appearance)."""
        return self._raw.sensor_index

    @property
    def family(self) -> str:
        """The sensor family: ``velodyne``, ``ouster``, ``hesai``, ``robosense`` or ``livox``."""
        return self._raw.family

    @property
    def address(self) -> str:
        """The sensor's IPv4 address."""
        return self._raw.address

    @property
    def index(self) -> int:
        """The sweep's number within its sensor's stream."""
        return self._raw.index

    @property
    def packets(self) -> int:
        """Data packets in the sweep."""
        return self._raw.packets

    @property
    def missing_packets(self) -> int:
        """Packets lost inside or just before the sweep (sequence or timing gaps)."""
        return self._raw.missing_packets

    @property
    def missing_columns(self) -> int:
        """Columns lost (Ouster)."""
        return self._raw.missing_columns

    @property
    def frame_id(self) -> int:
        """The sensor's frame counter (Ouster), else 0."""
        return self._raw.frame_id

    @property
    def device_time_ns(self) -> int:
        """The sensor's own clock at the sweep's first firing, ns."""
        return self._raw.device_time_ns

    @property
    def host_time_ns(self) -> "tuple[int, int]":
        """Receive (capture) times of the sweep's first and last packets, ns."""
        return (self._raw.first_host_ns, self._raw.last_host_ns)

    def __len__(self) -> int:
        return len(self._raw.points)

    def __repr__(self) -> str:
        return (
            f"<ringscan.Sweep {self.sensor!r} #{self.index}: {len(self)} points, "
            f"t={self.timestamp:.6f} ({self.clock}), missing_packets={self.missing_packets}>"
        )

    def image(self, field: str = "range", ret: int = 0, fill: Any = 0) -> np.ndarray:
        """An organised image (channel x column) of one field, for sensors whose points keep
        their firing column (Velodyne, Ouster, RoboSense).

        ``field`` is a field of :attr:`points` or ``"range"`` (metres, from x, y, z when the
        sweep has no range field); ``ret`` picks the return (0 or 1); cells without a point hold
        ``fill``. Row 0 is the lowest beam.
        """
        cols_buf = self._raw.columns
        rows = self._raw.channels
        if cols_buf is None or rows is None:
            raise ValueError(
                f"sensor {self.sensor!r}: this sweep has no firing columns (not an organised sensor)"
            )
        p = self.points
        if field == "range" and "range" not in p.dtype.names:
            values = np.sqrt(p["x"].astype(np.float64) ** 2 + p["y"] ** 2 + p["z"] ** 2).astype(np.float32)
        elif field in p.dtype.names:
            values = p[field]
        else:
            raise ValueError(f"image({field!r}): expected one of {', '.join(p.dtype.names)} or 'range'")
        columns = np.asarray(cols_buf)
        ncols = int(columns.max()) + 1 if len(columns) else 0
        img = np.full((rows, ncols), fill, dtype=values.dtype)
        sel = (p["return"] == ret) & (p["ring"] < rows)
        img[p["ring"][sel], columns[sel]] = values[sel]
        return img

    def to_pandas(self):
        """The points as a ``pandas.DataFrame`` (needs pandas)."""
        try:
            import pandas as pd
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("Sweep.to_pandas() needs pandas: pip install pandas") from e
        p = self.points
        return pd.DataFrame({name: p[name] for name in p.dtype.names})

    def to_open3d(self):
        """The points as an ``open3d.geometry.PointCloud`` (needs open3d); intensity / 255 as
        grey colours."""
        try:
            import open3d as o3d
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("Sweep.to_open3d() needs open3d: pip install open3d") from e
        pc = o3d.geometry.PointCloud()
        pc.points = o3d.utility.Vector3dVector(self.xyz.astype(np.float64))
        grey = np.clip(self.points["intensity"].astype(np.float64) / 255.0, 0.0, 1.0)
        pc.colors = o3d.utility.Vector3dVector(np.repeat(grey[:, None], 3, axis=1))
        return pc


class Source:
    """A capture (pcap, pcapng) or bag (ROS 1, rosbag2 directory, ``.db3``, ``.mcap``) to read
    sweep by sweep. Made by :func:`open`; iterate it for :class:`Sweep` objects (each iteration
    reads the file again from the start).

    Decoding runs on a thread of its own without the GIL; at most a few sweeps wait in memory.
    With ``read_ahead`` (the default) a capture's bytes are read on one more thread, a few
    MiB ahead of the decoding, so a machine with a spare core overlaps the two (a fleet task
    that should keep to one core passes ``read_ahead=False``).
    """

    def __init__(
        self,
        path: PathLike,
        calib: Union[None, PathLike, Sequence[PathLike]] = None,
        model: Optional[str] = None,
        topics: Union[None, str, Sequence[str]] = None,
        *,
        start: Optional[float] = None,
        end: Optional[float] = None,
        port: Optional[int] = None,
        cut_angle: float = 0.0,
        min_range: Optional[float] = None,
        max_range: Optional[float] = None,
        fields: str = "default",
        crc: Optional[bool] = None,
        dual_return_threshold: Optional[float] = None,
        fov: Optional["tuple[float, float]"] = None,
        integration_ms: Optional[float] = None,
        read_ahead: bool = True,
    ):
        self.path = _path(path, "path")
        if not isinstance(read_ahead, bool):
            raise TypeError(f"read_ahead: expected True or False, got {type(read_ahead).__name__}")
        if model is not None and not isinstance(model, str):
            raise TypeError(f"model: expected a string such as 'vlp16', got {type(model).__name__}")
        if fields not in ("default", "all"):
            raise ValueError(f"fields={fields!r}: expected 'default' or 'all'")
        if port is not None and (isinstance(port, bool) or not isinstance(port, int) or not 0 < port < 65536):
            raise ValueError(f"port={port!r}: expected a UDP port number 1 ... 65535")
        if crc is not None and not isinstance(crc, bool):
            raise TypeError(f"crc: expected True, False or None, got {type(crc).__name__}")
        if fov is not None:
            if not (isinstance(fov, Sequence) and len(fov) == 2):
                raise TypeError("fov: expected (start_deg, end_deg)")
            fov = (_number(fov[0], "fov"), _number(fov[1], "fov"))
        self._kwargs: Dict[str, Any] = dict(
            model=model,
            calib=_paths(calib, "calib"),
            topics=_strings(topics, "topics"),
            start=_number(start, "start"),
            end=_number(end, "end"),
            port=port,
            cut_angle=_number(cut_angle, "cut_angle"),
            min_range=_number(min_range, "min_range"),
            max_range=_number(max_range, "max_range"),
            fields_all=fields == "all",
            crc=crc,
            dual_return_threshold=_number(dual_return_threshold, "dual_return_threshold"),
            fov=fov,
            integration_ms=_number(integration_ms, "integration_ms"),
        )
        # `ringscan info` has no flag for these (it reports the capture as read, every point,
        # every port): info() refuses them rather than report a decode they did not shape.
        self._not_info = [
            f"{name}={value!r}"
            for name, value, default in (
                ("port", port, None),
                ("cut_angle", cut_angle, 0.0),
                ("min_range", min_range, None),
                ("max_range", max_range, None),
                ("fields", fields, "default"),
                ("crc", crc, None),
                ("dual_return_threshold", dual_return_threshold, None),
                ("fov", fov, None),
                ("integration_ms", integration_ms, None),
            )
            if value != default
        ]
        self._read_ahead = read_ahead
        self._readers: List[Any] = []
        self._summary: Optional[dict] = None

    def __iter__(self) -> Iterator[Sweep]:
        reader = _ringscan.Reader(self.path, read_ahead=self._read_ahead, **self._kwargs)
        self._readers.append(reader)
        try:
            while True:
                raw = reader.next()
                if raw is None:
                    break
                yield Sweep(raw)
            s = reader.summary()
            # None when close() ended the iteration early: the last complete one's stays.
            if s is not None:
                self._summary = json.loads(s)
        finally:
            reader.close()
            self._readers.remove(reader)

    def info(self) -> dict:
        """What ``ringscan info --json`` says of the input (a full decode without output):
        sensors, models, return modes, ports, duration, sweeps, packet loss.

        Takes the options ``ringscan info`` has flags for (``model``, ``calib``, ``topics``,
        ``start``, ``end``); a Source opened with any other decoding option (``max_range``,
        ``port``, ``cut_angle``...) raises ``TypeError``: iterate it and read :attr:`summary`
        for the counts with them (``ringscan decode --json``'s)."""
        if self._not_info:
            raise TypeError(
                f"info() takes no {', '.join(self._not_info)}: `ringscan info` has no such flag "
                "(only --model, --calib, --topic, --start, --end); for the counts of a decode "
                "with them, iterate ringscan.open(...) and read its .summary"
            )
        k = self._kwargs
        return json.loads(
            _ringscan.info(self.path, k["model"], k["calib"], k["topics"], k["start"], k["end"])
        )

    @property
    def summary(self) -> Optional[dict]:
        """The ``--json`` summary of the last complete iteration (``None`` before one)."""
        return self._summary

    def close(self) -> None:
        """Stops any iteration in progress, from any thread, without waiting: an iteration
        waiting for a sweep ends (as at the end of the capture) within 100 ms."""
        for r in list(self._readers):
            r.close()

    def __enter__(self) -> "Source":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<ringscan.Source {self.path!r}>"


def open(path: PathLike, calib=None, model=None, topics=None, **options: Any) -> Source:  # noqa: A001
    """Opens a capture or bag: ``path`` (pcap, pcapng, ROS 1 bag, rosbag2 directory or file).

    ``calib``: calibration / metadata files (``[ADDR=]FILE`` as the CLI's ``--calib``; Ouster
    pcaps need their metadata JSON), ``model``: force a model (``vlp16``, ``hdl32e``...),
    ``topics``: bag topics to read. Other options are the CLI's flags: ``start``, ``end``
    (bags, seconds), ``port``, ``cut_angle``, ``min_range``, ``max_range``, ``fields``
    (``"default"`` or ``"all"``), ``crc``, ``dual_return_threshold``, ``fov``,
    ``integration_ms``; and ``read_ahead`` (default ``True``: the capture is read on a thread
    of its own, ahead of the decoding).
    """
    return Source(path, calib=calib, model=model, topics=topics, **options)


def info(path: PathLike, calib=None, model=None, topics=None, **options: Any) -> dict:
    """``ringscan info --json`` as a dict: shorthand for ``open(...).info()``, so with the
    options of ``ringscan info`` only (``start``, ``end`` besides these); any other decoding
    option raises ``TypeError``, as the CLI refuses the flag. (``read_ahead``, which changes no
    count, is taken and unused: info reads the input on its decoding thread.)"""
    return Source(path, calib=calib, model=model, topics=topics, **options).info()



def _sweeps(raws) -> List[Sweep]:
    return [Sweep(r) for r in raws]


class Decoder:
    """Decodes datagrams the caller receives itself (its own socket, a message queue, a
    custom file format), as ``decode`` decodes a capture: sensor detection, calibrations,
    sweep cutting, loss counting.

    ::

        dec = ringscan.Decoder()
        for payload, (ip, port), t in my_datagrams:
            for sweep in dec.push(payload, f"{ip}:{port}", 2368, t):
                ...
        last = dec.finish()

    ``push`` holds the GIL (a datagram decodes in microseconds); decoding whole files is
    :func:`open`'s job.
    """

    def __init__(self, calib=None, model: Optional[str] = None, *, port: Optional[int] = None,
                 cut_angle: float = 0.0, min_range: Optional[float] = None,
                 max_range: Optional[float] = None, fields: str = "default"):
        if model is not None and not isinstance(model, str):
            raise TypeError(f"model: expected a string such as 'vlp16', got {type(model).__name__}")
        if fields not in ("default", "all"):
            raise ValueError(f"fields={fields!r}: expected 'default' or 'all'")
        self._native = _ringscan.Decoder(
            model, _paths(calib, "calib"), port, _number(cut_angle, "cut_angle"),
            _number(min_range, "min_range"), _number(max_range, "max_range"), fields == "all",
        )

    def push(self, payload: bytes, src: str, port: int, time_ns: int = 0) -> List[Sweep]:
        """One UDP payload from ``src`` (``"IP:PORT"``) to ``port`` received at ``time_ns`` (ns
        since the epoch): the sweeps it completed."""
        if not isinstance(payload, (bytes, bytearray, memoryview)):
            raise TypeError(f"payload: expected bytes, got {type(payload).__name__}")
        return _sweeps(self._native.push(bytes(payload), src, port, time_ns))

    def finish(self) -> List[Sweep]:
        """Ends every stream: the last sweeps."""
        return _sweeps(self._native.finish())

    def summary(self) -> dict:
        """Sweeps, points, packets (decoded, dropped, malformed, missing) and sensors so far."""
        return json.loads(self._native.summary())


class Listener:
    """Live sensors (``ringscan listen``): sockets on their own thread, a bounded queue of
    datagrams and one of sweeps, each dropping and counting when full. Iterate it for
    sweeps; ``stop()`` (or leaving a ``with`` block, Ctrl-C in the loop, or ``duration``)
    ends it, then ``summary`` is ``listen --json``'s (``receive.queue_dropped``,
    ``receive.sweeps_dropped``...). Iterate from one thread at a time; ``stop()`` may come
    from any thread."""

    def __init__(self, native):
        self._native = native
        self.summary: Optional[dict] = None

    def __iter__(self) -> Iterator[Sweep]:
        while True:
            raw = self._native.next()
            if raw is None:
                self._take_summary()
                return
            yield Sweep(raw)

    def _take_summary(self) -> None:
        s = self._native.summary()
        self.summary = json.loads(s) if s else None

    def stop(self) -> None:
        """Stops listening and returns once the listening thread has ended: the ``out`` MCAP
        file is complete and ``summary`` set. Raises the thread's error (e.g. the file could
        not be written) unless the iteration already did. Sweeps still queued can be iterated."""
        try:
            self._native.stop()
        finally:
            self._take_summary()

    def __enter__(self) -> "Listener":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()


def listen(sensors: Union[str, Sequence[str]], calib=None, model: Optional[str] = None, *,
           duration: Optional[float] = None, multicast: Optional[str] = None,
           interface: str = "0.0.0.0", recv_buffer: Optional[int] = None, api_port: int = 80,
           queue: int = 16, out: Optional[PathLike] = None) -> Listener:
    """Receives and decodes live sensors: ``sensors`` as the CLI's ``--sensor IP[:PORT]``.
    ``out``: also record to this MCAP file (complete once :meth:`Listener.stop` returned, or
    the ``with`` block or the iteration ended). ``queue``: sweeps held for a slow consumer
    (at most 65536: the queue's slots are allocated up front); ``duration``: seconds."""
    return Listener(_ringscan.Listener(
        _strings(sensors, "sensors"), model, _paths(calib, "calib"), _number(duration, "duration"),
        multicast, interface, recv_buffer, api_port, queue,
        None if out is None else _path(out, "out"),
    ))


def _records(points: Any) -> bytes:
    """24-byte point records from a structured array (any of POINT_DTYPE's fields) or an
    (N, >=3) array of x, y, z."""
    a = np.asarray(points)
    if a.dtype == POINT_DTYPE:
        return np.ascontiguousarray(a).tobytes()
    out = np.zeros(len(a), dtype=POINT_DTYPE)
    if a.dtype.names:
        missing = {"x", "y", "z"} - set(a.dtype.names)
        if missing:
            raise ValueError(f"points: no field {', '.join(sorted(missing))}")
        for name in POINT_DTYPE.names:
            if name in a.dtype.names:
                out[name] = a[name]
    elif a.ndim == 2 and a.shape[1] >= 3:
        out["x"], out["y"], out["z"] = a[:, 0], a[:, 1], a[:, 2]
    else:
        raise ValueError(f"points: expected a structured array or an (N, 3) array, got shape {a.shape}")
    return out.tobytes()


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float, np.integer, np.floating)):
        return repr(float(v)) if isinstance(v, (float, np.floating)) else str(int(v))
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"{v!r}: expected a number, string, bool or list")


def _toml(section: str, keys: Dict[str, Any]) -> str:
    return f"[{section}]\n" + "".join(f"{k} = {_toml_value(v)}\n" for k, v in keys.items())


def _points(buf) -> np.ndarray:
    return np.asarray(buf).view(POINT_DTYPE)


def voxel_downsample(points, leaf_m: float = 0.2) -> np.ndarray:
    """One point per voxel (the pipeline's ``[voxel] leaf_m``)."""
    return _points(_ringscan.voxel_downsample(_records(points), _toml("voxel", {"leaf_m": leaf_m})))


def segment_ground(points, **ground) -> np.ndarray:
    """A boolean mask, True for ground points. Keys: the pipeline's ``[ground]`` ones
    (``method="grid"|"ransac"``, ``distance_threshold_m``, ``sectors``, ``sensor_height_m``...)."""
    return np.frombuffer(_ringscan.segment_ground(_records(points), _toml("ground", ground)), dtype=bool)


def cluster(points, **keys):
    """Euclidean clusters (the pipeline's ``[cluster]``: ``tolerance_m``, ``min_points``,
    ``max_points``): each point's cluster index (-1 for none, int64) and a list of dicts
    (``points``, ``centroid``, ``min``, ``max``)."""
    labels, clusters = _ringscan.cluster(_records(points), _toml("cluster", keys))
    lab = np.asarray(labels).astype(np.int64)
    lab[lab == 0xFFFFFFFF] = -1
    return lab, [dict(points=n, centroid=c, min=lo, max=hi) for n, c, lo, hi in clusters]


def deskew(points, linear_mps=(0.0, 0.0, 0.0), angular_degps=(0.0, 0.0, 0.0), reference: str = "start") -> np.ndarray:
    """Constant-velocity deskew (the pipeline's ``[deskew]``): each point moved by the motion
    between its firing (``t``, ns) and the sweep's ``reference`` (``start`` or ``end``)."""
    keys = {"mode": "constant-velocity", "reference": reference, "linear_mps": list(linear_mps), "angular_degps": list(angular_degps)}
    return _points(_ringscan.deskew(_records(points), _toml("deskew", keys)))


class Odometry:
    """LiDAR odometry (``decode --odometry``): ``method`` (``point-to-plane``,
    ``point-to-point``, ``continuous-time``), ``voxel`` (m), ``max_range`` (m)."""

    def __init__(self, method: str = "point-to-plane", voxel: Optional[float] = None, max_range: float = 100.0):
        self._native = _ringscan.Odometry(method, _number(voxel, "voxel"), float(max_range))

    def register(self, points, stamp_ns: int = 0) -> dict:
        """Registers one sweep (a :class:`Sweep` or its points + ``stamp_ns``): the pose
        ``world_from_sensor`` (4 x 4), ``status``, and the ICP figures."""
        if isinstance(points, Sweep):
            points, stamp_ns = points.points, points.timestamp_ns
        r = self._native.register(_records(points), int(stamp_ns))
        r["world_from_sensor"] = np.array(r["world_from_sensor"]).reshape(4, 4)
        return r

    def reset(self) -> None:
        self._native.reset()


class McapWriter:
    """MCAP files as ``ringscan decode`` writes them (the same schemas: ``foxglove.PointCloud``
    or ROS 2 ``sensor_msgs/PointCloud2``, diagnostics channels)::

        with ringscan.McapWriter("out.mcap") as w:
            lidar = w.add_sensor("front")
            for sweep in ringscan.open("drive.pcap"):
                w.write_sweep(lidar, sweep)
    """

    def __init__(self, path: PathLike, format: str = "foxglove", compression: str = "zstd", threads: int = 1):
        self._native = _ringscan.McapWriter(_path(path, "path"), format, compression, threads)
        self.summary: Optional[dict] = None

    def add_sensor(self, name: str, topic_prefix: str = "", metadata: Optional[Dict[str, str]] = None) -> int:
        return self._native.add_sensor(name, topic_prefix, metadata)

    def write_sweep(self, sensor: int, sweep_or_points, timestamp_ns: Optional[int] = None, log_time_ns: Optional[int] = None) -> None:
        if isinstance(sweep_or_points, Sweep):
            sw = sweep_or_points
            points = sw.points if sw.points.dtype == POINT_DTYPE else sw.points[list(POINT_DTYPE.names)]
            ts = sw.timestamp_ns if timestamp_ns is None else timestamp_ns
            log = sw.host_time_ns[1] if log_time_ns is None else log_time_ns
        else:
            if timestamp_ns is None:
                raise TypeError("write_sweep(sensor, points, timestamp_ns): timestamp_ns is needed with bare points")
            points, ts, log = sweep_or_points, timestamp_ns, log_time_ns
        self._native.write_sweep(sensor, _records(points), max(0, int(ts)), None if log is None else max(0, int(log)))

    def close(self) -> dict:
        self.summary = json.loads(self._native.close())
        return self.summary

    def __enter__(self) -> "McapWriter":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


from . import compat  # noqa: E402  (needs the helpers above)
from . import fleet  # noqa: E402
