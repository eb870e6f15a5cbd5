"""Decoding a fleet's captures in parallel: one task per capture, on Ray Data (a laptop's local
instance or a cluster, unchanged) or on a plain ``multiprocessing`` pool.

Each task decodes one capture or bag with one decoding thread and writes, under ``out``:

* ``points/<name>.parquet`` (``parquet=True``): one row per point, columns ``sensor``,
  ``sweep``, ``timestamp_ns`` (the sweep's), ``x``, ``y``, ``z``, ``intensity``, ``t``, ``ring``,
  ``return``; one row group per sweep batch, so memory stays bounded whatever the capture's size;
* ``mcap/<name>.mcap`` (``mcap=True``): what ``ringscan decode --out`` writes, with the same
  decoding options, so it holds the Parquet's points.

``<name>`` is the capture's path relative to the listed directory or prefix (or to the
captures' common folder), folders kept: ``day1/lidar.pcap`` and ``day2/lidar.pcap`` give
``points/day1/lidar.pcap.parquet`` and ``points/day2/lidar.pcap.parquet``.

and returns one row of the summary table: the capture, ``status`` (``ok`` or ``error``), the
error's class and message (the command line's), and the ``--json`` summary's figures (sweeps,
points, packets decoded / dropped / malformed / missing, duration, sensors) of the decode with
the task's options (with neither output, a decode that writes nothing). A capture that
fails is a row with its error: never skipped silently; none of its outputs is published (they
are moved under ``out`` only once every one of them is written).

::

    from ringscan import fleet
    table = fleet.decode(["a.pcap", "b.bag"], "out/", engine="ray")      # or engine="pool"
    print(table.to_pandas())

    python -m ringscan.fleet DIR_OR_PREFIX --out OUT --engine ray --workers 8

Inputs and ``out`` may be local paths or object-store URIs that ``pyarrow.fs`` opens
(``s3://bucket/prefix``, ``gs://...``): a task copies its capture to local scratch space,
decodes it, and uploads its outputs.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from typing import Any, Dict, Iterable, List, Optional, Sequence

CAPTURE_SUFFIXES = (".pcap", ".pcapng", ".bag", ".db3", ".mcap")

#: Columns of the summary table, in order.
SUMMARY_COLUMNS = [
    "capture",
    "status",
    "error_type",
    "error",
    "sweeps",
    "points",
    "packets_decoded",
    "packets_dropped",
    "packets_malformed",
    "packets_missing",
    "duration_s",
    "sensors",
    "parquet",
    "mcap",
    "decode_s",
]

#: Rows buffered before a Parquet row group is written.
ROW_GROUP_POINTS = 1_000_000


def _is_uri(p: str) -> bool:
    return "://" in p


def list_captures(root: str) -> List[str]:
    """The captures and bags under ``root`` (a file, a directory or an object-store prefix),
    sorted; a rosbag2 directory (``metadata.yaml`` inside) is one input."""
    if _is_uri(root):
        import pyarrow.fs as pafs

        fs, base = pafs.FileSystem.from_uri(root)
        infos = fs.get_file_info(pafs.FileSelector(base, recursive=True))
        scheme = root.split("://", 1)[0]
        return sorted(
            f"{scheme}://{i.path}" for i in infos if i.is_file and i.path.endswith(CAPTURE_SUFFIXES)
        )
    if os.path.isfile(root):
        return [root]
    out: List[str] = []
    for dirpath, dirnames, filenames in os.walk(root):
        if "metadata.yaml" in filenames:
            out.append(dirpath)
            dirnames[:] = []
            continue
        out += [os.path.join(dirpath, f) for f in filenames if f.endswith(CAPTURE_SUFFIXES)]
    return sorted(out)


def _name(capture: str) -> str:
    base = capture.rstrip("/").rsplit("/", 1)[-1]
    return base if base else "capture"


def _components(path: str) -> List[str]:
    """A capture's path as folder names, its scheme first for a URI (captures of two schemes
    share no folder)."""
    if _is_uri(path):
        scheme, rest = path.split("://", 1)
        parts = [scheme + ":"] + rest.split("/")
    else:
        parts = os.path.abspath(path).split(os.sep)
    return [p for p in parts if p not in ("", ".")]


def output_names(captures: Sequence[str], root: Optional[str] = None) -> Dict[str, str]:
    """Each capture's output name (``/``-separated): its path relative to ``root`` (the listed
    directory or prefix), else to the captures' common folder, folders kept. Outputs named by
    the file name alone would overwrite each other for ``day1/lidar.pcap`` and
    ``day2/lidar.pcap``. Raises ``ValueError`` when two captures get one name (one capture
    listed twice)."""
    parts = [(c, _components(c)) for c in captures]
    if root is not None:
        common = _components(root)
    else:
        common = None
        for _c, p in parts:
            folder = p[:-1]
            if common is None:
                common = folder
            else:
                n = 0
                while n < min(len(common), len(folder)) and common[n] == folder[n]:
                    n += 1
                common = common[:n]
        common = common or []
    names: Dict[str, str] = {}
    seen: Dict[str, str] = {}
    for c, p in parts:
        # A root that is the capture itself (a single file listed) leaves its file name.
        rel = p[len(common):] if p[: len(common)] == common and len(p) > len(common) else p[-1:]
        name = "/".join(rel) or "capture"
        if name in seen:
            raise ValueError(f"{seen[name]} and {c}: both would be written as {name!r}")
        seen[name] = c
        names[c] = name
    return names


def _fetch(capture: str, scratch: str) -> str:
    """A local path of ``capture`` (object-store inputs are copied to ``scratch``)."""
    if not _is_uri(capture):
        return capture
    import pyarrow.fs as pafs

    import ringscan

    local = os.path.join(scratch, _name(capture))
    try:
        pafs.copy_files(capture, local)
    except FileNotFoundError as e:
        # The capture's own fault (a row), as a missing local file is.
        raise ringscan.InputError(f"{capture}: {e}") from e
    return local


def _make_dir_uri(uri: str) -> None:
    """Creates the folder ``uri`` where the file system has folders (local, HDFS); a no-op on
    object stores, whose "folders" are key prefixes."""
    import pyarrow.fs as pafs

    fs, path = pafs.FileSystem.from_uri(uri)
    fs.create_dir(path, recursive=True)


def _publish(local: str, out: str, dest: str) -> str:
    """Moves a finished output to ``out/dest`` (``dest`` ``/``-separated; uploads when
    ``out`` is a URI)."""
    if _is_uri(out):
        import pyarrow.fs as pafs

        uri = f"{out.rstrip('/')}/{dest}"
        _make_dir_uri(uri.rsplit("/", 1)[0])
        pafs.copy_files(local, uri)
        return uri
    path = os.path.join(out, *dest.split("/"))
    os.makedirs(os.path.dirname(path), exist_ok=True)
    shutil.move(local, path)
    return path


def _unpublish(out: str, published: str) -> None:
    try:
        if _is_uri(out):
            import pyarrow.fs as pafs

            fs, path = pafs.FileSystem.from_uri(published)
            fs.delete_file(path)
        else:
            os.remove(published)
    except OSError:
        pass


def _write_parquet(src, path: str) -> None:
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = pa.schema(
        [
            ("sensor", pa.dictionary(pa.int32(), pa.string())),
            ("sweep", pa.uint64()),
            ("timestamp_ns", pa.int64()),
            ("x", pa.float32()),
            ("y", pa.float32()),
            ("z", pa.float32()),
            ("intensity", pa.float32()),
            ("t", pa.uint32()),
            ("ring", pa.uint16()),
            ("return", pa.uint8()),
        ]
    )
    pending: List[Any] = []
    n_pending = 0

    def flush(writer) -> None:
        nonlocal pending, n_pending
        if not pending:
            return
        pts = np.concatenate([p for _, _, _, p in pending])
        # The sensor column as a dictionary: an index per point, the names once.
        names: Dict[str, int] = {}
        codes = np.concatenate([np.full(len(p), names.setdefault(s, len(names)), np.int32) for s, _, _, p in pending])
        cols = {
            "sensor": pa.DictionaryArray.from_arrays(pa.array(codes), pa.array(list(names), pa.string())),
            "sweep": pa.array(np.concatenate([np.full(len(p), i, np.uint64) for _, i, _, p in pending])),
            "timestamp_ns": pa.array(np.concatenate([np.full(len(p), t, np.int64) for _, _, t, p in pending])),
        }
        for name in ("x", "y", "z", "intensity", "t", "ring", "return"):
            cols[name] = pa.array(np.ascontiguousarray(pts[name]))
        writer.write_table(pa.table(cols, schema=schema))
        pending, n_pending = [], 0

    # Dictionary pages only for the columns that repeat: on the float and time columns Parquet
    # would hash every value, then give up past the dictionary page limit.
    dictionary = ["sensor", "sweep", "timestamp_ns", "ring", "return"]
    with pq.ParquetWriter(path, schema, compression="zstd", use_dictionary=dictionary) as writer:
        for sweep in src:
            p = sweep.points
            if p.dtype.itemsize != 24:
                p = p[list(p.dtype.names[:7])]
            pending.append((sweep.sensor, sweep.index, sweep.timestamp_ns, p))
            n_pending += len(p)
            if n_pending >= ROW_GROUP_POINTS:
                flush(writer)
        flush(writer)


def decode_one(
    capture: str,
    out: str,
    *,
    parquet: bool = True,
    mcap: bool = False,
    options: Optional[Dict[str, Any]] = None,
    name: Optional[str] = None,
) -> Dict[str, Any]:
    """Decodes one capture (one task): writes its outputs under ``out`` as ``name`` (see
    :func:`output_names`; default: the capture's file name), returns its summary row. Errors
    of the capture (unreadable, hostile, bad options) are a row with ``status="error"``;
    anything else (a full disk, a bug) is raised, so the engine retries or reports the task.
    Either way nothing of the capture is left published unless every output was written."""
    import json

    import ringscan
    from . import _ringscan

    options = dict(options or {})
    row: Dict[str, Any] = {c: None for c in SUMMARY_COLUMNS}
    row["capture"] = capture
    started = time.perf_counter()
    scratch = tempfile.mkdtemp(prefix="ringscan-fleet-")
    name = name or _name(capture)
    published: List[str] = []
    try:
        local = _fetch(capture, scratch)
        # One core per task: the capture is read on the decoding thread unless asked. The
        # Source checks the options once, for both outputs.
        src = ringscan.open(local, **{"read_ahead": False, **options})
        summary = None
        ready: List[tuple] = []
        if parquet:
            pq_local = os.path.join(scratch, "points.parquet")
            _write_parquet(src, pq_local)
            summary = src.summary
            if summary.get("no_sensor"):
                # As `ringscan decode` (and the MCAP output below): nothing decoded is an
                # error of the capture, and nothing is published.
                raise ringscan.DecodeError(f"{local}: no sensor found: {summary['no_sensor']}")
            ready.append(("parquet", pq_local, f"points/{name}.parquet"))
        if mcap or summary is None:
            # The MCAP's decode, or without any output a decode writing nothing: the Source's
            # options either way, so the row counts what the outputs would hold (`info()`
            # takes no decoding option).
            mc_local = os.path.join(scratch, "capture.mcap") if mcap else None
            decoded = json.loads(
                _ringscan.decode(local, mc_local, threads=1, read_ahead=src._read_ahead, **src._kwargs)
            )
            # With both outputs the row stays the Parquet's (the same decode, same options).
            summary = summary or decoded
            if mc_local is not None:
                ready.append(("mcap", mc_local, f"mcap/{name}.mcap"))
        for column, local_out, dest in ready:
            published.append(_publish(local_out, out, dest))
            row[column] = published[-1]
        published = []
        p = summary["packets"]
        row.update(
            status="ok",
            sweeps=summary["sweeps"],
            points=summary["points"],
            packets_decoded=p["decoded"],
            packets_dropped=p["dropped"],
            packets_malformed=p["malformed"],
            packets_missing=p["missing"],
            duration_s=summary["capture"]["duration_s"],
            sensors=len(summary["sensors"]),
        )
    except (ringscan.RingscanError, TypeError, ValueError) as e:
        row.update(status="error", error_type=type(e).__name__, error=str(e), parquet=None, mcap=None)
    finally:
        # Outputs published before a later one failed to publish (the failure is raised).
        for p in published:
            _unpublish(out, p)
        shutil.rmtree(scratch, ignore_errors=True)
    row["decode_s"] = time.perf_counter() - started
    return row


def _table(rows: Iterable[Dict[str, Any]]):
    import pyarrow as pa

    rows = sorted(rows, key=lambda r: r["capture"])
    return pa.Table.from_pylist(rows).select(SUMMARY_COLUMNS) if rows else pa.table({c: [] for c in SUMMARY_COLUMNS})


def _pool_task(args) -> Dict[str, Any]:
    capture, name, out, parquet, mcap, options = args
    return decode_one(capture, out, parquet=parquet, mcap=mcap, options=options, name=name)


def decode_pool(
    captures: Sequence[str],
    out: str,
    *,
    processes: Optional[int] = None,
    parquet: bool = True,
    mcap: bool = False,
    options: Optional[Dict[str, Any]] = None,
    names: Optional[Dict[str, str]] = None,
):
    """The fleet on one workstation: a ``multiprocessing`` pool of ``processes`` (spawned)
    processes, one capture per task. ``names``: each capture's output name (default
    :func:`output_names`). Returns the summary table (``pyarrow.Table``)."""
    import multiprocessing as mp

    names = names or output_names(captures)
    work = [(c, names[c], out, parquet, mcap, options) for c in captures]
    with mp.get_context("spawn").Pool(processes or os.cpu_count() or 1, maxtasksperchild=8) as pool:
        rows = list(pool.imap_unordered(_pool_task, work, chunksize=1))
    return _table(rows)


def decode_ray(
    captures: Sequence[str],
    out: str,
    *,
    parquet: bool = True,
    mcap: bool = False,
    options: Optional[Dict[str, Any]] = None,
    max_retries: int = 3,
    memory_per_task: Optional[int] = None,
    names: Optional[Dict[str, str]] = None,
):
    """The fleet on Ray Data: one task per capture (``num_cpus=1`` each: one decoding thread),
    as many at once as the cluster has CPUs. Connects to the running Ray instance, or starts a
    local one (``ray.init()`` first to choose). A capture's own errors come back as rows; a
    task lost to a worker crash or a node failure is retried ``max_retries`` times by Ray, then
    its error is raised. ``names``: each capture's output name (default :func:`output_names`).
    Returns the summary table (``pyarrow.Table``)."""
    import ray

    names = names or output_names(captures)
    if not ray.is_initialized():
        ray.init()
    ctx = ray.data.DataContext.get_current()
    ctx.enable_progress_bars = False
    ds = ray.data.from_items(
        [{"capture": c, "name": names[c]} for c in captures], override_num_blocks=max(1, len(captures))
    )

    def task(row: Dict[str, Any]) -> Dict[str, Any]:
        return decode_one(row["capture"], out, parquet=parquet, mcap=mcap, options=options, name=row["name"])

    remote_args: Dict[str, Any] = {"num_cpus": 1, "max_retries": max_retries}
    if memory_per_task:
        remote_args["memory"] = memory_per_task
    rows = ds.map(task, **remote_args).take_all()
    return _table(rows)


def decode(captures, out: str, *, engine: str = "pool", workers: Optional[int] = None, **kw):
    """``captures``: a list, or one directory / prefix to list. ``engine``: ``"ray"`` or
    ``"pool"``. Outputs are named by :func:`output_names` (relative to the directory listed).
    Also writes the table to ``out/summary.parquet`` (``out`` a path or a URI)."""
    import pyarrow.parquet as pq

    if isinstance(captures, (str, os.PathLike)):
        root = os.fspath(captures)
        captures = list_captures(root)
        kw.setdefault("names", output_names(captures, root))
    if engine == "ray":
        if workers:
            import ray

            if not ray.is_initialized():
                ray.init(num_cpus=workers)
        table = decode_ray(captures, out, **kw)
    elif engine == "pool":
        table = decode_pool(captures, out, processes=workers, **kw)
    else:
        raise ValueError(f"engine={engine!r}: expected 'ray' or 'pool'")
    if _is_uri(out):
        _make_dir_uri(out.rstrip("/"))
        pq.write_table(table, f"{out.rstrip('/')}/summary.parquet")
    else:
        os.makedirs(out, exist_ok=True)
        pq.write_table(table, os.path.join(out, "summary.parquet"))
    return table


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ringscan.fleet", description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="+", help="captures, bags, directories or object-store prefixes")
    ap.add_argument("--out", required=True, help="output directory or URI")
    ap.add_argument("--engine", choices=["pool", "ray"], default="pool")
    ap.add_argument("--workers", type=int, help="processes (pool) or local Ray CPUs")
    ap.add_argument("--mcap", action="store_true", help="also one MCAP per capture")
    ap.add_argument("--no-parquet", action="store_true")
    ap.add_argument("--calib", action="append", help="calibration files (as the CLI's --calib)")
    ap.add_argument("--model")
    a = ap.parse_args(argv)
    captures: List[str] = []
    for i in a.inputs:
        captures += list_captures(i)
    options = {k: v for k, v in (("calib", a.calib), ("model", a.model)) if v}
    # One input: outputs named relative to it, as decode() does; several: to their common folder.
    inputs = a.inputs[0] if len(a.inputs) == 1 else captures
    table = decode(inputs, a.out, engine=a.engine, workers=a.workers, parquet=not a.no_parquet, mcap=a.mcap, options=options)
    failed = 0
    for r in table.to_pylist():
        if r["status"] == "ok":
            print(f"ok    {r['capture']}: {r['sweeps']} sweeps, {r['points']} points")
        else:
            failed += 1
            print(f"error {r['capture']}: {r['error']}")
    print(f"{table.num_rows} captures, {failed} failed; summary: {os.path.join(a.out, 'summary.parquet')}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
