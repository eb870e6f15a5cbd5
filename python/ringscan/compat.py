"""velodyne_decoder-compatible reading: change ``import velodyne_decoder as vd`` into
``import ringscan.compat as vd`` and ``vd.read_pcap(path, config)`` keeps its output.

Same frames (velodyne_decoder's splitting: a frame starts at the first packet's azimuth, not at
a cut angle, unless ``cut_angle`` is set; a packet more than 0.3 s after the frame's first starts
a new one), same ``(stamp, points)`` tuples: ``stamp`` a ``TimePair(host, device)`` of the
frame's last packet (first with ``timestamp_first_packet``), ``points`` an ``(N, 8)`` float32
array ``x, y, z, intensity, time, column, ring, return_type`` (time in seconds relative to the
stamp; return type 1 strongest, 2 last, 3 both; with an advanced calibration, the HDL-64E's,
``intensity`` is velodyne_decoder's focal correction of the raw one), or with
``as_pcl_structs=True`` the
PCL-compatible structured array. Decoded by ringscan's Velodyne decoder; points agree with
velodyne_decoder 3.1.0 within its azimuth quantisation (see python/tests/test_compat.py).
"""

from __future__ import annotations

import enum
import os
from collections import namedtuple
from typing import Any, Iterator, Optional, Tuple

import numpy as np

from . import _ringscan
from . import _path

__all__ = ["Config", "Model", "Calibration", "TimePair", "read_pcap", "PCL_DTYPE"]

TimePair = namedtuple("TimePair", ("host", "device"))
StampCloudTuple = namedtuple("StampCloudTuple", ("stamp", "points"))

#: velodyne_decoder's ``as_pcl_structs=True`` record.
PCL_DTYPE = np.dtype(
    {
        "names": ["x", "y", "z", "intensity", "time", "column", "ring", "return_type"],
        "formats": ["<f4", "<f4", "<f4", "<f4", "<f4", "<u2", "u1", "u1"],
        "offsets": [0, 4, 8, 12, 16, 20, 22, 23],
        "itemsize": 32,
    }
)


class Model(enum.Enum):
    """velodyne_decoder's model names, mapped to ringscan's."""

    HDL32E = "hdl32e"
    HDL64E_S2 = "hdl64e-s2"
    HDL64E_S3 = "hdl64e-s3"
    PuckHiRes = "puck-hires"
    VLP16 = "vlp16"
    VLP32C = "vlp32c"
    VLS128 = "vls128"


class Calibration:
    """A calibration file (ROS yaml or VeloView xml); ``Calibration.read(path)`` as in
    velodyne_decoder."""

    def __init__(self, path: "str | os.PathLike[str]"):
        self.path = _path(path, "calibration")

    @classmethod
    def read(cls, path: "str | os.PathLike[str]") -> "Calibration":
        return cls(path)


def _model_id(model: Any) -> Optional[str]:
    if model is None:
        return None
    if isinstance(model, Model):
        return model.value
    name = getattr(model, "name", None)  # velodyne_decoder's own Model enum
    if isinstance(name, str) and name in Model.__members__:
        return Model[name].value
    if isinstance(model, str):
        return Model[model].value if model in Model.__members__ else model
    raise TypeError(f"config.model: expected a Model or a model name, got {type(model).__name__}")


def _calib_path(calibration: Any) -> Optional[str]:
    if calibration is None:
        return None
    if isinstance(calibration, Calibration):
        return calibration.path
    if isinstance(calibration, (str, os.PathLike)):
        return os.fspath(calibration)
    raise TypeError(
        "config.calibration: expected ringscan.compat.Calibration.read(path) or a path "
        f"(velodyne_decoder's parsed Calibration objects cannot be read back), got {type(calibration).__name__}"
    )


class Config:
    """velodyne_decoder's ``Config``: ``model``, ``calibration``, ``min_range`` (m),
    ``max_range`` (m), ``min_angle`` / ``max_angle`` (degrees: the points whose firing
    azimuth is inside, as velodyne_decoder tests it), ``cut_angle`` (degrees or None), ``timestamp_first_packet``."""

    def __init__(
        self,
        *,
        model: Any = None,
        calibration: Any = None,
        min_range: float = 0.1,
        max_range: float = 200.0,
        min_angle: float = 0.0,
        max_angle: float = 360.0,
        cut_angle: Optional[float] = None,
        timestamp_first_packet: bool = False,
    ):
        self.model = model
        self.calibration = calibration
        self.min_range = min_range
        self.max_range = max_range
        self.min_angle = min_angle
        self.max_angle = max_angle
        self.cut_angle = cut_angle
        self.timestamp_first_packet = timestamp_first_packet


def read_pcap(
    pcap_file: "str | os.PathLike[str]",
    config: Any = None,
    as_pcl_structs: bool = False,
    time_range: Tuple[Optional[float], Optional[float]] = (None, None),
) -> Iterator[StampCloudTuple]:
    """Decodes and yields every frame of a Velodyne pcap as velodyne_decoder 3.1.0 does:
    ``(stamp, points)``. ``config`` is a :class:`Config` or any object with its attributes
    (velodyne_decoder's own ``Config`` works when its calibration is None or a path)."""
    config = config if config is not None else Config()
    path = _path(pcap_file, "pcap_file")
    g = lambda name, default: getattr(config, name, default)  # noqa: E731
    t0, t1 = time_range
    reader = _ringscan.CompatReader(
        path,
        _model_id(g("model", None)),
        _calib_path(g("calibration", None)),
        float(g("min_range", 0.1)),
        float(g("max_range", 200.0)),
        None if g("cut_angle", None) is None else float(g("cut_angle", None)),
        bool(g("timestamp_first_packet", False)),
        (None if t0 is None else float(t0), None if t1 is None else float(t1)),
        float(g("min_angle", 0.0)),
        float(g("max_angle", 360.0)),
    )
    try:
        while True:
            item = reader.next()
            if item is None:
                return
            host, device, buf, n = item
            arr = np.asarray(buf).reshape(n, 8)
            if as_pcl_structs:
                out = np.zeros(n, dtype=PCL_DTYPE)
                for i, name in enumerate(PCL_DTYPE.names):
                    out[name] = arr[:, i]
                arr = out
            yield StampCloudTuple(TimePair(host, device), arr)
    finally:
        reader.close()
