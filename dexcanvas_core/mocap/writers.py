"""Writing marker streams as C3D or CSV (the layouts ``readers`` reads back).

Useful to hand rendered demonstrations to other mocap tools, and for round-trip tests. Positions
are written in the stream's mocap frame and unit; missing samples as NaN (C3D: residual −1).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Literal

import numpy as np

from dexcanvas_core.errors import MissingDependencyError
from dexcanvas_core.mocap.frames import UNITS_M
from dexcanvas_core.mocap.stream import MarkerStream
from dexcanvas_core.safe_io import atomic_path


def _unit_name(unit_m: float) -> str:
    for name, v in UNITS_M.items():
        if abs(v - unit_m) < 1e-12:
            return name
    return "mm"


def write_c3d(stream: MarkerStream, path: str | Path, labels: list[str] | None = None) -> Path:
    """Write ``stream`` as a C3D file (``labels`` renames the columns, e.g. capture labels)."""
    try:
        import ezc3d
    except ImportError as e:
        raise MissingDependencyError("ezc3d", "writing C3D files") from e
    p = Path(path)
    names = list(labels) if labels is not None else list(stream.labels)
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [float(stream.fps)]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(names)
    c["parameters"]["POINT"]["UNITS"]["value"] = [_unit_name(stream.frame.unit_m)]
    T, M, _ = stream.positions.shape
    pts = np.ones((4, M, T))
    pts[:3] = np.transpose(stream.positions, (2, 1, 0))
    c["data"]["points"] = pts
    with atomic_path(p, suffix=".c3d") as tmp:
        c.write(str(tmp))
    return p


def write_csv(
    stream: MarkerStream,
    path: str | Path,
    *,
    layout: Literal["wide", "long"] = "wide",
    labels: list[str] | None = None,
) -> Path:
    """Write ``stream`` as a wide (one row per frame) or long (one row per marker sample,
    missing samples as empty cells) CSV."""
    p = Path(path)
    names = list(labels) if labels is not None else list(stream.labels)
    t = stream.times
    unit = _unit_name(stream.frame.unit_m)

    def cell(v: float) -> str:
        return "" if not np.isfinite(v) else f"{v:.6f}"

    with atomic_path(p) as tmp, tmp.open("w", newline="") as fh:
        fh.write(f"# units: {unit}\n# fps: {stream.fps:g}\n")
        w = csv.writer(fh)
        if layout == "wide":
            w.writerow(["frame", "time", *[f"{n}_{a}" for n in names for a in "xyz"]])
            for i in range(stream.num_frames):
                row = [str(i), f"{t[i]:.6f}"]
                row += [cell(v) for v in stream.positions[i].reshape(-1)]
                w.writerow(row)
        else:
            w.writerow(["frame", "time", "label", "x", "y", "z"])
            for i in range(stream.num_frames):
                for k, n in enumerate(names):
                    x = stream.positions[i, k]
                    w.writerow([i, f"{t[i]:.6f}", n, *(cell(v) for v in x)])
    return p
