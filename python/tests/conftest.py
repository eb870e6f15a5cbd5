"""Shared fixtures of the Python package's tests: where the real captures are, and the
per-capture options the goldens were made with (../shared/captures/golden/index.json)."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def captures_dir() -> Path | None:
    """``$RINGSCAN_CAPTURES``, else ``../shared/captures`` beside the repository."""
    env = os.environ.get("RINGSCAN_CAPTURES")
    p = Path(env) if env else REPO.parent / "shared" / "captures"
    return p if p.is_dir() else None


CAPTURES = captures_dir()
if CAPTURES is None:
    print(
        "SKIP: ../shared/captures (or $RINGSCAN_CAPTURES) is missing: "
        "the tests on real captures are skipped",
        file=sys.stderr,
    )

# The models the goldens name, as the command line spells them.
MODELS = {"VLP16": "vlp16", "HDL32E": "hdl32e", "VLP32C": "vlp32c"}

CAPTURE_SUFFIXES = (".pcap", ".pcapng", ".bag", ".db3", ".mcap")

# Captures without a golden that still need a file to decode (no built-in calibration).
_HESAI = "tier4__nebula/src/nebula_hesai/nebula_hesai_decoders/calibration/"
EXTRA_CALIB = {
    "vls128/": "tier4__nebula/src/nebula_velodyne/nebula_velodyne_decoders/calibration/VLS128.yaml",
    # nebula's Hesai captures and the angle correction of each (NEBULA.md).
    "decoder_ground_truth/40p/": _HESAI + "Pandar40P.csv",
    "decoder_ground_truth/64/": _HESAI + "Pandar64.csv",
    "decoder_ground_truth/qt64/": _HESAI + "PandarQT64.csv",
    "decoder_ground_truth/qt128/": _HESAI + "PandarQT128.csv",
    "decoder_ground_truth/xt32/": _HESAI + "PandarXT32.csv",
    "decoder_ground_truth/xt32m/": _HESAI + "PandarXT32M.csv",
}


def capture_cases() -> list[dict]:
    """Every capture file under the shared folder, with the options (model, calibrations) its
    golden was made with, or none."""
    if CAPTURES is None:
        return []
    index = json.loads((CAPTURES / "golden" / "index.json").read_text())
    known: dict[str, dict] = {}
    for g in index["goldens"]:
        case = {"path": g["capture"], "model": None, "calib": []}
        if g["reference"] == "velodyne_decoder":
            cfg = json.loads((CAPTURES / "golden" / g["golden"]).read_text())["config"]
            case["model"] = MODELS[cfg["model"]]
            case["calib"] = [cfg["calibration"]]
        else:
            case["calib"] = [s["metadata"] for s in g.get("sensors", []) if s.get("metadata")]
        known[g["capture"]] = case
    cases = []
    for p in sorted(CAPTURES.rglob("*")):
        rel = p.relative_to(CAPTURES).as_posix()
        if rel.startswith("golden/") or p.suffix not in CAPTURE_SUFFIXES or not p.is_file():
            continue
        case = known.get(rel, {"path": rel, "model": None, "calib": []})
        for part, calib in EXTRA_CALIB.items():
            if part in rel:
                case["calib"] = [calib]
        cases.append(case)
    return cases


def abspath(rel: str) -> str:
    assert CAPTURES is not None
    return str(CAPTURES / rel)


@pytest.fixture
def captures() -> Path:
    if CAPTURES is None:
        pytest.skip("SKIP: ../shared/captures is missing")
    return CAPTURES
