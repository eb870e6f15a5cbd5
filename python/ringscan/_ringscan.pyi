"""Type stubs of the native module (python/src/*.rs); the public API is ringscan's."""

from typing import Dict, List, Optional, Sequence, Tuple

class RingscanError(Exception): ...
class UsageError(RingscanError): ...
class InputError(RingscanError): ...
class CalibrationError(RingscanError): ...
class DecodeError(RingscanError): ...

class Buffer:
    @property
    def __array_interface__(self) -> dict: ...
    def __len__(self) -> int: ...

class RawSweep:
    index: int
    timestamp_ns: int
    clock: str
    device_time_ns: int
    first_host_ns: int
    last_host_ns: int
    packets: int
    missing_packets: int
    missing_columns: int
    frame_id: int
    columns_count: int
    first_azimuth_cdeg: int
    sensor: str
    sensor_index: int
    family: str
    address: str
    channels: Optional[int]
    points: Buffer
    extended: bool
    columns: Optional[Buffer]

class Reader:
    def __init__(
        self,
        path: str,
        model: Optional[str] = None,
        calib: Sequence[str] = ...,
        topics: Sequence[str] = ...,
        start: Optional[float] = None,
        end: Optional[float] = None,
        port: Optional[int] = None,
        cut_angle: float = 0.0,
        min_range: Optional[float] = None,
        max_range: Optional[float] = None,
        fields_all: bool = False,
        crc: Optional[bool] = None,
        dual_return_threshold: Optional[float] = None,
        fov: Optional[Tuple[float, float]] = None,
        integration_ms: Optional[float] = None,
        keep_columns: bool = True,
        read_ahead: bool = False,
    ) -> None: ...
    def next(self) -> Optional[RawSweep]: ...
    def summary(self) -> Optional[str]: ...
    def close(self) -> None: ...

class CompatReader:
    def __init__(
        self,
        path: str,
        model: Optional[str] = None,
        calibration: Optional[str] = None,
        min_range: float = 0.1,
        max_range: float = 200.0,
        cut_angle: Optional[float] = None,
        timestamp_first_packet: bool = False,
        time_range: Tuple[Optional[float], Optional[float]] = (None, None),
        min_angle: float = 0.0,
        max_angle: float = 360.0,
    ) -> None: ...
    def next(self) -> Optional[Tuple[float, float, Buffer, int]]: ...
    def close(self) -> None: ...

class Decoder:
    def __init__(
        self,
        model: Optional[str] = None,
        calib: Sequence[str] = ...,
        port: Optional[int] = None,
        cut_angle: float = 0.0,
        min_range: Optional[float] = None,
        max_range: Optional[float] = None,
        fields_all: bool = False,
        keep_columns: bool = True,
    ) -> None: ...
    def push(self, payload: bytes, src: str, port: int, time_ns: int = 0) -> List[RawSweep]: ...
    def finish(self) -> List[RawSweep]: ...
    def summary(self) -> str: ...

class Listener:
    def __init__(
        self,
        sensors: Sequence[str],
        model: Optional[str] = None,
        calib: Sequence[str] = ...,
        duration: Optional[float] = None,
        multicast: Optional[str] = None,
        interface: str = "0.0.0.0",
        recv_buffer: Optional[int] = None,
        api_port: int = 80,
        queue: int = 16,
        out: Optional[str] = None,
    ) -> None: ...
    def next(self) -> Optional[RawSweep]: ...
    def stop(self) -> None: ...
    def summary(self) -> Optional[str]: ...

class Odometry:
    def __init__(self, method: str = "point-to-plane", voxel: Optional[float] = None, max_range: float = 100.0) -> None: ...
    def register(self, points: bytes, stamp_ns: int) -> dict: ...
    def reset(self) -> None: ...

class McapWriter:
    def __init__(self, path: str, format: str = "foxglove", compression: str = "zstd", threads: int = 1) -> None: ...
    def add_sensor(self, name: str, topic_prefix: str = "", metadata: Optional[Dict[str, str]] = None) -> int: ...
    def write_sweep(self, sensor: int, points: bytes, timestamp_ns: int, log_time_ns: Optional[int] = None) -> None: ...
    def close(self) -> str: ...

def info(
    path: str,
    model: Optional[str] = None,
    calib: Sequence[str] = ...,
    topics: Sequence[str] = ...,
    start: Optional[float] = None,
    end: Optional[float] = None,
) -> str: ...
def decode(
    path: str,
    out: Optional[str] = None,
    model: Optional[str] = None,
    calib: Sequence[str] = ...,
    topics: Sequence[str] = ...,
    threads: int = 1,
    start: Optional[float] = None,
    end: Optional[float] = None,
    port: Optional[int] = None,
    cut_angle: float = 0.0,
    min_range: Optional[float] = None,
    max_range: Optional[float] = None,
    fields_all: bool = False,
    crc: Optional[bool] = None,
    dual_return_threshold: Optional[float] = None,
    fov: Optional[Tuple[float, float]] = None,
    integration_ms: Optional[float] = None,
    read_ahead: bool = False,
) -> str: ...
def cli_main(argv: List[str]) -> int: ...
def version() -> str: ...
def voxel_downsample(points: bytes, toml: str) -> Buffer: ...
def segment_ground(points: bytes, toml: str) -> bytes: ...
def cluster(points: bytes, toml: str) -> Tuple[Buffer, List[Tuple[int, List[float], List[float], List[float]]]]: ...
def deskew(points: bytes, toml: str) -> Buffer: ...
