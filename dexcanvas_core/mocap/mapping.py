"""The marker-name mapping of a real capture, and the error of an unreadable marker file.

**Mapping file** (JSON, or a two-column CSV ``capture_label,layout_name``) from the capture's
labels to layout names (``layout.MARKER_NAMES``)::

    {
      "markers": {"RHand:IndexNail": "index_nail", "Cube:M1": "obj1", ...},
      "ignore": ["LASI", "RASI"],
      "object": "cube2",
      "side": "right",
      "units": "mm",
      "up": "y"
    }

``markers`` maps capture labels (a label may be matched with or without a ``Subject:`` prefix);
``ignore`` lists labels to drop — they are reported in the stream's ``ignored_labels``, never
dropped silently. A flat JSON object ``{"capture": "layout", ...}`` is a ``markers`` mapping;
in the CSV form an empty or ``ignore`` layout name ignores the label. Without a mapping, capture
labels (prefix stripped) must be layout names. A label that is neither mapped nor ignored is an
error that lists every such label; so is a mapping onto an unknown layout name, or two labels
onto one name.
"""

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path

from dexcanvas_core.errors import DexCanvasError
from dexcanvas_core.mocap.layout import MARKER_NAMES


class MarkerFileError(DexCanvasError, ValueError):
    """A marker or mapping file that cannot be read, or whose labels do not fit the layout."""

    def __init__(self, message: str, *, path: str | None = None, labels: list[str] | None = None):
        self.path = path
        self.labels = labels or []
        super().__init__(f"{path}: {message}" if path else message)


@dataclass(frozen=True)
class MarkerMapping:
    """Capture label → layout name, plus labels to ignore and optional capture settings."""

    markers: dict[str, str] = field(default_factory=dict)
    ignore: tuple[str, ...] = ()
    object_id: str | None = None
    side: str | None = None
    units: str | None = None
    up: str | None = None
    source: str = ""

    def __post_init__(self) -> None:
        bad = sorted({v for v in self.markers.values() if v not in MARKER_NAMES})
        if bad:
            raise MarkerFileError(
                f"mapping targets {bad} are not layout marker names; valid names: "
                f"{', '.join(MARKER_NAMES)}",
                path=self.source or None,
                labels=bad,
            )
        seen: dict[str, str] = {}
        dups = []
        for k, v in self.markers.items():
            if v in seen:
                dups.append(f"{seen[v]!r} and {k!r} → {v!r}")
            seen[v] = k
        if dups:
            raise MarkerFileError(
                "two capture labels map to one layout marker: " + "; ".join(dups),
                path=self.source or None,
            )
        both = sorted(set(self.markers) & set(self.ignore))
        if both:
            raise MarkerFileError(
                f"labels both mapped and ignored: {both}", path=self.source or None, labels=both
            )

    def resolve(
        self, labels: list[str], path: str | None = None
    ) -> tuple[list[str | None], list[str]]:
        """Layout name (or ``None`` = ignored) for every capture label, and the ignored labels.

        Raises:
            MarkerFileError: labels that are neither mapped nor ignored (all listed).
        """
        out: list[str | None] = []
        ignored: list[str] = []
        unknown: list[str] = []
        for raw in labels:
            lab = raw.strip()
            short = lab.rsplit(":", 1)[-1]
            if lab in self.ignore or short in self.ignore:
                out.append(None)
                ignored.append(lab)
            elif lab in self.markers:
                out.append(self.markers[lab])
            elif short in self.markers:
                out.append(self.markers[short])
            elif not self.markers and short in MARKER_NAMES:
                out.append(short)
            elif self.markers and short in MARKER_NAMES and short not in self.markers.values():
                out.append(short)  # already a layout name
            else:
                out.append(None)
                unknown.append(lab)
        if unknown:
            how = (
                'add them to the mapping file\'s "markers" (capture label → layout name) or to '
                'its "ignore" list'
                if self.source
                else "pass a mapping file (--mapping) mapping them to layout names or ignoring them"
            )
            raise MarkerFileError(
                f"unknown marker labels {unknown}; {how}. Layout names: {', '.join(MARKER_NAMES)}",
                path=path,
                labels=unknown,
            )
        names = [n for n in out if n is not None]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise MarkerFileError(
                f"several capture labels resolve to the same layout marker(s) {dup}", path=path
            )
        return out, ignored


_MAPPING_KEYS = {"markers", "ignore", "object", "side", "units", "up"}


def load_mapping(path: str | Path) -> MarkerMapping:
    """Read a mapping file (JSON or two-column CSV; see the module docstring)."""
    p = Path(path)
    if not p.is_file():
        raise MarkerFileError("mapping file not found", path=str(p))
    text = p.read_text()
    if p.suffix.lower() == ".csv":
        markers: dict[str, str] = {}
        ignore: list[str] = []
        rows = [r for r in csv.reader(line for line in text.splitlines() if line.strip())]
        if rows and [c.strip().lower() for c in rows[0][:2]] in (
            ["capture_label", "layout_name"],
            ["label", "name"],
        ):
            rows = rows[1:]
        for i, r in enumerate(rows, start=1):
            if not r or r[0].strip().startswith("#"):
                continue
            if len(r) < 1 or len(r) > 2:
                raise MarkerFileError(
                    f"row {i}: expected 'capture_label,layout_name', got {r}", path=str(p)
                )
            lab = r[0].strip()
            tgt = r[1].strip() if len(r) == 2 else ""
            if tgt in ("", "ignore", "-"):
                ignore.append(lab)
            else:
                markers[lab] = tgt
        return MarkerMapping(markers, tuple(ignore), source=str(p))
    try:
        d = json.loads(text)
    except json.JSONDecodeError as e:
        raise MarkerFileError(f"not valid JSON ({e})", path=str(p)) from e
    if not isinstance(d, dict):
        raise MarkerFileError("a JSON mapping must be an object", path=str(p))
    if (
        "markers" not in d
        and all(isinstance(v, str) for v in d.values())
        and not (set(d) & _MAPPING_KEYS)
    ):
        d = {"markers": d}
    unknown = sorted(set(d) - _MAPPING_KEYS)
    if unknown:
        raise MarkerFileError(
            f"unknown keys {unknown}; a mapping has {', '.join(sorted(_MAPPING_KEYS))}",
            path=str(p),
        )
    markers = d.get("markers", {})
    ignore = d.get("ignore", [])
    if not isinstance(markers, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in markers.items()
    ):
        raise MarkerFileError('"markers" must map label strings to layout names', path=str(p))
    if not isinstance(ignore, list) or not all(isinstance(v, str) for v in ignore):
        raise MarkerFileError('"ignore" must be a list of labels', path=str(p))
    return MarkerMapping(
        {k.strip(): v.strip() for k, v in markers.items()},
        tuple(v.strip() for v in ignore),
        object_id=d.get("object"),
        side=d.get("side"),
        units=d.get("units"),
        up=d.get("up"),
        source=str(p),
    )
