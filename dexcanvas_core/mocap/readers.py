"""Reading real captures: C3D and CSV marker files.

**C3D** (read with ``ezc3d``, an optional dependency: ``pip install ezc3d``): the ``POINT``
group's ``LABELS`` (and ``LABELS2``…), ``RATE`` [Hz] and ``UNITS`` (``mm`` when empty); samples
that the file marks invalid (negative residual) arrive as NaN.

**CSV**, one of two layouts (detected from the header; ``#`` lines before it are comments, and
``# units: mm`` / ``# fps: 120`` comment lines set the unit and rate):

* *wide*: one row per frame, columns ``<label>_x, <label>_y, <label>_z`` per marker, plus an
  optional ``frame`` and an optional ``time`` [s] column::

      frame,time,mc2_head_x,mc2_head_y,mc2_head_z,...
      0,0.0,512.3,88.1,-20.4,...

* *long*: one row per marker sample, columns ``frame, label, x, y, z`` (optional ``time``)::

      frame,time,label,x,y,z
      0,0.0,mc2_head,512.3,88.1,-20.4

Empty cells, ``nan`` and ``NaN`` are missing samples. Coordinates are in the file's unit
(millimetres unless declared otherwise) in the mocap frame.

Labels are mapped to layout names by a mapping file (:mod:`.mapping`).
"""

import csv
import logging
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from dexcanvas_core.errors import MissingDependencyError, ValidationError
from dexcanvas_core.mocap.frames import UNITS_M, MocapFrame
from dexcanvas_core.mocap.mapping import MarkerFileError, MarkerMapping, load_mapping
from dexcanvas_core.mocap.stream import MarkerStream
from dexcanvas_core.plausibility import ImplausibleDataError, report

log = logging.getLogger(__name__)

log = logging.getLogger(__name__)

FORMATS: tuple[str, ...] = ("c3d", "csv")


def _assemble(
    labels: list[str],
    positions: np.ndarray,
    fps: float,
    timestamp: np.ndarray | None,
    unit_m: float,
    mapping: MarkerMapping | None,
    path: str,
    *,
    up: str,
    origin_m: Any,
    object_id: str | None,
    side: str | None,
) -> MarkerStream:
    mapping = mapping or MarkerMapping()
    names, ignored = mapping.resolve(labels, path)
    keep = [i for i, n in enumerate(names) if n is not None]
    if not keep:
        raise MarkerFileError("no marker of the file maps to the layout", path=path)
    up = mapping.up or up
    if up not in ("y", "z"):
        raise ValidationError(f"up must be 'y' or 'z', got {up!r}", field="up")
    maker = MocapFrame.y_up if up == "y" else MocapFrame.z_up
    base = maker("mm", origin_m)
    frame = MocapFrame(base.R_world_mocap, base.t_world_mocap_m, unit_m, name=f"{up}_up")
    if ignored:
        log.info("%s: ignoring %d labels listed in the mapping: %s", path, len(ignored), ignored)
    return MarkerStream(
        labels=tuple(names[i] for i in keep),  # type: ignore[misc]
        positions=positions[:, keep],
        fps=fps,
        frame=frame,
        timestamp=timestamp,
        object_id=object_id or mapping.object_id,
        side=side or mapping.side or "right",
        source=path,
        ignored_labels=tuple(ignored),
    )


def _unit_m(unit: str | None, path: str) -> float:
    key = (unit or "mm").strip().lower()
    if key not in UNITS_M:
        raise MarkerFileError(
            f"unknown length unit {unit!r}; expected one of {', '.join(UNITS_M)}", path=path
        )
    return UNITS_M[key]


def read_c3d(
    path: str | Path,
    mapping: MarkerMapping | None = None,
    *,
    fps: float | None = None,
    units: str | None = None,
    up: str = "y",
    origin_m: Any = (0.0, 0.0, 0.0),
    object_id: str | None = None,
    side: str | None = None,
) -> MarkerStream:
    """Read a C3D file's labelled points into a :class:`MarkerStream`."""
    try:
        import ezc3d
    except ImportError as e:
        raise MissingDependencyError("ezc3d", "reading C3D files") from e
    p = Path(path)
    if not p.is_file():
        raise MarkerFileError("file not found", path=str(p))
    try:
        c = ezc3d.c3d(str(p))
    except Exception as e:  # ezc3d raises plain RuntimeError/IOError subclasses
        raise MarkerFileError(f"cannot read C3D ({e})", path=str(p)) from e
    point = c["parameters"]["POINT"]
    labels: list[str] = list(point["LABELS"]["value"])
    k = 2
    while f"LABELS{k}" in point:
        labels.extend(point[f"LABELS{k}"]["value"])
        k += 1
    pts = np.asarray(c["data"]["points"], dtype=np.float64)  # (4, M, T)
    labels = labels[: pts.shape[1]]
    if len(labels) < pts.shape[1]:
        raise MarkerFileError(
            f"{pts.shape[1]} points but only {len(labels)} labels in POINT:LABELS", path=str(p)
        )
    _check_c3d_frame_count(p, pts.shape[2])
    positions = np.transpose(pts[:3], (2, 1, 0)).copy()  # (T, M, 3)
    rate = float(np.asarray(point["RATE"]["value"]).reshape(-1)[0]) if "RATE" in point else 0.0
    rate = float(fps) if fps else rate
    if not (math.isfinite(rate) and rate > 0):
        raise MarkerFileError("C3D has no POINT:RATE; pass fps", path=str(p))
    unit_vals = list(point["UNITS"]["value"]) if "UNITS" in point else []
    file_unit = units or (mapping and mapping.units) or (unit_vals[0] if unit_vals else "") or "mm"
    return _assemble(
        labels,
        positions,
        rate,
        None,
        _unit_m(str(file_unit), str(p)),
        mapping,
        str(p),
        up=up,
        origin_m=origin_m,
        object_id=object_id,
        side=side,
    )


def c3d_header_frames(path: Path) -> int | None:
    """The frame count a C3D file's header announces (``last - first + 1``, header words 4
    and 5), or ``None`` when the header cannot say: not a C3D header, or a file longer than
    the header's 16-bit frame numbers (last frame 65535)."""
    with open(path, "rb") as fh:
        head = fh.read(512)
        if len(head) < 12 or head[1] != 0x50 or head[0] < 2:
            return None
        fh.seek((head[0] - 1) * 512 + 3)
        processor = fh.read(1)
    # Parameter-section processor type: 84 Intel, 85 DEC (both little-endian), 86 MIPS (big).
    order = "big" if processor == bytes([86]) else "little"
    first = int.from_bytes(head[6:8], order)
    last = int.from_bytes(head[8:10], order)
    if last == 0xFFFF or last < first:
        return None
    return last - first + 1


def _check_c3d_frame_count(path: Path, frames_read: int) -> None:
    """Refuse a C3D file holding fewer (or more) frames than its header announces: a file cut
    short by a copy or a crashed export (ezc3d reads what is there without a word)."""
    announced = c3d_header_frames(path)
    if announced is None or announced == frames_read:
        return
    report(
        ImplausibleDataError(
            f"{path}: the C3D header announces {announced} frames but the file holds "
            f"{frames_read}"
            + (
                f" (frames {frames_read}..{announced - 1} missing: truncated?)"
                if frames_read < announced
                else ""
            ),
            field="C3D frames",
            frame=frames_read,
            fix="copy or export the file again",
        )
    )


_META = re.compile(r"#\s*(units?|fps|rate)\s*[:=]\s*(\S+)", re.IGNORECASE)


def _parse_float(cell: str, row: int, col: str, path: str) -> float:
    s = cell.strip()
    if s == "" or s.lower() == "nan":
        return math.nan
    try:
        return float(s)
    except ValueError:
        raise MarkerFileError(
            f"row {row}, column {col!r}: {cell!r} is not a number", path=path
        ) from None


def read_csv(
    path: str | Path,
    mapping: MarkerMapping | None = None,
    *,
    fps: float | None = None,
    units: str | None = None,
    up: str = "y",
    origin_m: Any = (0.0, 0.0, 0.0),
    object_id: str | None = None,
    side: str | None = None,
) -> MarkerStream:
    """Read a wide or long marker CSV (see the module docstring) into a :class:`MarkerStream`."""
    p = Path(path)
    if not p.is_file():
        raise MarkerFileError("file not found", path=str(p))
    lines = p.read_text().splitlines()
    meta: dict[str, str] = {}
    body = []
    for line in lines:
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            m = _META.match(s)
            if m:
                key = m.group(1).lower()
                meta["unit" if key.startswith("unit") else key] = m.group(2)
            continue
        body.append(line)
    if not body:
        raise MarkerFileError("no header row", path=str(p))
    rows = list(csv.reader(body))
    header = [h.strip() for h in rows[0]]
    data = rows[1:]
    low = [h.lower() for h in header]
    file_unit = units or (mapping.units if mapping else None) or meta.get("unit") or "mm"
    rate = (
        fps
        or (float(meta["fps"]) if "fps" in meta else None)
        or (float(meta["rate"]) if "rate" in meta else None)
    )
    if "label" in low or "marker" in low:
        labels, pos, t = _csv_long(header, data, str(p))
    else:
        labels, pos, t = _csv_wide(header, data, str(p))
    if t is not None and np.isfinite(t).all() and len(t) > 1:
        if np.any(np.diff(t) <= 0):
            raise MarkerFileError("the time column is not strictly increasing", path=str(p))
        if rate is None:
            rate = 1.0 / float(np.median(np.diff(t)))
    else:
        t = None
    if not rate:
        raise MarkerFileError(
            "the frame rate is unknown: add a time column or a '# fps: N' line, or pass fps",
            path=str(p),
        )
    return _assemble(
        labels,
        pos,
        float(rate),
        t,
        _unit_m(file_unit, str(p)),
        mapping,
        str(p),
        up=up,
        origin_m=origin_m,
        object_id=object_id,
        side=side,
    )


def _csv_wide(header: list[str], data: list[list[str]], path: str):
    low = [h.lower() for h in header]
    time_col = low.index("time") if "time" in low else None
    frame_col = low.index("frame") if "frame" in low else None
    labels: list[str] = []
    cols: list[tuple[int, int, int]] = []
    by_label: dict[str, dict[str, int]] = {}
    order: list[str] = []
    for i, h in enumerate(header):
        if i in (time_col, frame_col):
            continue
        m = re.match(r"^(.*?)[_.:]?([xyzXYZ])$", h)
        if not m or not m.group(1):
            raise MarkerFileError(
                f"column {h!r} is neither frame/time nor '<label>_x|_y|_z'; for a long CSV use "
                "columns frame,label,x,y,z",
                path=path,
            )
        lab, ax = m.group(1).rstrip("_.:"), m.group(2).lower()
        if lab not in by_label:
            by_label[lab] = {}
            order.append(lab)
        if ax in by_label[lab]:
            raise MarkerFileError(f"column {h!r} repeats {lab}_{ax}", path=path)
        by_label[lab][ax] = i
    for lab in order:
        axes = by_label[lab]
        if set(axes) != {"x", "y", "z"}:
            raise MarkerFileError(
                f"marker {lab!r} lacks column(s) {sorted({'x', 'y', 'z'} - set(axes))}", path=path
            )
        labels.append(lab)
        cols.append((axes["x"], axes["y"], axes["z"]))
    T = len(data)
    pos = np.full((T, len(labels), 3), np.nan)
    t = np.full(T, np.nan) if time_col is not None else None
    for r, row in enumerate(data):
        if len(row) != len(header):
            raise MarkerFileError(
                f"row {r + 2} has {len(row)} cells, the header has {len(header)}", path=path
            )
        for k, (cx, cy, cz) in enumerate(cols):
            for d, c in enumerate((cx, cy, cz)):
                pos[r, k, d] = _parse_float(row[c], r + 2, header[c], path)
        if t is not None:
            t[r] = _parse_float(row[time_col], r + 2, "time", path)
    if frame_col is not None and T:
        frames = [_parse_float(row[frame_col], i + 2, "frame", path) for i, row in enumerate(data)]
        if any(np.diff(frames) <= 0):
            raise MarkerFileError("the frame column is not strictly increasing", path=path)
    if T == 0:
        raise MarkerFileError("no data rows", path=path)
    return labels, pos, t


def _csv_long(header: list[str], data: list[list[str]], path: str):
    low = [h.lower() for h in header]
    lab_col = low.index("label") if "label" in low else low.index("marker")
    need = [c for c in ("frame", "x", "y", "z") if c not in low]
    if need:
        raise MarkerFileError(f"long CSV lacks column(s) {need}", path=path)
    fc, xc, yc, zc = (low.index(c) for c in ("frame", "x", "y", "z"))
    tc = low.index("time") if "time" in low else None
    frames: list[int] = []
    labs: list[str] = []
    vals: list[tuple[float, float, float]] = []
    times: dict[int, float] = {}
    for r, row in enumerate(data):
        if len(row) != len(header):
            raise MarkerFileError(
                f"row {r + 2} has {len(row)} cells, the header has {len(header)}", path=path
            )
        f = _parse_float(row[fc], r + 2, "frame", path)
        if not math.isfinite(f) or f != int(f) or f < 0:
            raise MarkerFileError(f"row {r + 2}: frame {row[fc]!r} is not an index", path=path)
        frames.append(int(f))
        labs.append(row[lab_col].strip())
        vals.append(tuple(_parse_float(row[c], r + 2, header[c], path) for c in (xc, yc, zc)))
        if tc is not None:
            times[int(f)] = _parse_float(row[tc], r + 2, "time", path)
    if not frames:
        raise MarkerFileError("no data rows", path=path)
    labels = list(dict.fromkeys(labs))
    f0 = min(frames)
    T = max(frames) - f0 + 1
    pos = np.full((T, len(labels), 3), np.nan)
    li = {lab: i for i, lab in enumerate(labels)}
    seen = set()
    for f, lab, v in zip(frames, labs, vals, strict=True):
        key = (f, lab)
        if key in seen:
            raise MarkerFileError(f"frame {f} lists marker {lab!r} twice", path=path)
        seen.add(key)
        pos[f - f0, li[lab]] = v
    t = None
    if tc is not None:
        t = np.full(T, np.nan)
        for f, v in times.items():
            t[f - f0] = v
    return labels, pos, t


def detect_format(path: str | Path) -> str:
    """``'c3d'`` or ``'csv'`` from the file extension."""
    ext = Path(path).suffix.lower().lstrip(".")
    if ext in FORMATS:
        return ext
    raise MarkerFileError(
        f"cannot tell the format from the extension {ext!r}; pass format='c3d' or 'csv'",
        path=str(path),
    )


def read_markers(
    path: str | Path,
    *,
    format: str = "auto",
    mapping: str | Path | MarkerMapping | None = None,
    **kwargs: Any,
) -> MarkerStream:
    """Read a C3D or CSV marker file (``format="auto"``: from the extension).

    Keyword arguments (``fps``, ``units``, ``up``, ``origin_m``, ``object_id``, ``side``) override
    what the file and the mapping say.
    """
    fmt = detect_format(path) if format == "auto" else format
    if fmt not in FORMATS:
        raise MarkerFileError(f"unknown format {fmt!r}; expected auto, {', '.join(FORMATS)}")
    m = load_mapping(mapping) if isinstance(mapping, str | Path) else mapping
    reader = read_c3d if fmt == "c3d" else read_csv
    return reader(path, m, **kwargs)
