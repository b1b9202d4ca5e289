"""The DexCanvas objects: the paper's table of 29 objects, read from the package's ``objects.csv``.

The catalogue is the appendix table "List of objects" of the DexCanvas paper (Xu et al. 2025,
arXiv 2510.15786), shipped as package data (``dexcanvas_core/taxonomy/objects.csv``) and read
once at import. The paper's text speaks of a "30-object set", but its table has **29 rows**:
14 geometric primitives, 8 weighted duplicates and 7 YCB-style household items. These 29 are the
catalogue; there is no 30th object.

Ids are as the paper writes them: ``cube1``, ``cube2``, ``cuboid1``–``cuboid3``,
``cylinder1``–``cylinder6``, ``sphere1``–``sphere3``; the heavy duplicates ``cube2H``,
``cuboid2H``, ``cuboid3H``, ``cylinder1H``, ``cylinder4H``, ``cylinder5H``, ``cylinder6H``,
``sphere1H``; and ``mayonnaisebottle``, ``banana``, ``bowl``, ``largeclamp``, ``pitcherbase``,
``powerdrill``, ``scissor``. Lookups ignore case and separators (``"cube2h"``, ``"Cube2H"``,
``"cube2_heavy"``, ``"mayonnaise bottle"``, ``"scissors"`` and ``"011_banana"`` all resolve), so a
dataset row whose ``index.scene`` stores ``cube2h`` finds ``cube2H``.

Every value's source is in the CSV's ``provenance`` column (``ObjectSpec.data_source``), field by
field: ``paper`` (the table) or ``estimate, <reason>`` where the table gives a dash:

* **Sizes, masses and the heavy set** are the paper's for every primitive and heavy duplicate.
* **YCB-style items have no size in the paper** (their geometry is the released object models).
  Until such a model is given, each is approximated by a built-in primitive composition
  (``dexcanvas_core.objects.geometry``; ``ObjectSpec.approximate``). Their ``size_m`` is an
  estimate: the bounding box of the DexRobot collision mesh of the item, as published in
  ``MindLab-Research/mint-vla-client-example``, ``scripts/state56_native28_geometry_contract.json``
  (``half_extents`` × 2, rounded to 1 mm, in that mesh's axes, marker mounts included); for
  ``pitcherbase`` and ``scissor``, the YCB object set's dimensions as recalled. Their masses are
  the paper's (e.g. ``powerdrill`` 0.228 kg, the printed replica, not YCB's 0.895 kg drill).
* **Placements** (how the object rests on the table at the start of a capture) are the paper's
  where it gives one (``cuboid1`` large face down, ``cuboid2`` long edge along X, ``powerdrill``
  handle along Z, bases down); elsewhere an estimate with its reason (which cylinders stand,
  which lie). ``cuboid1`` lists two placements; the first (large face down) is the object frame.

Object frame: origin at the centre of the object's bounding box, **z up as the object rests**
(``placement``). A cuboid's ``(x, y, z)`` size is laid out in that frame; a cylinder standing on an
end face has its axis along z, one lying on its side (``lying``) along x.
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Literal, get_args

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.objects.manifest import (
    check_inertia,
    check_mass,
)
from dexcanvas_core.objects.mesh import load_object_mesh

Shape = Literal["cube", "cuboid", "cylinder", "sphere", "mesh"]
Source = Literal["primitive", "ycb", "custom"]

SHAPES: tuple[Shape, ...] = get_args(Shape)

SIZE_LAYOUT: dict[str, tuple[str, ...]] = {
    "cube": ("edge",),
    "cuboid": ("x", "y", "z"),
    "cylinder": ("diameter", "height"),
    "sphere": ("diameter",),
    "mesh": ("x", "y", "z"),
}
"""Meaning of ``ObjectSpec.size_m`` per shape, all in metres (``mesh``: bounding box)."""

CATALOGUE_FILE = "objects.csv"
"""The catalogue's file inside this package (``dexcanvas_core.taxonomy``)."""

PROVENANCE_FIELDS: tuple[str, ...] = ("size", "mass", "heavy_of", "placement")
"""The fields every ``data_source`` (the CSV's ``provenance``) accounts for, in order."""

_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
_LYING = re.compile(r"\b(side down|lying|lies|axis along x)\b")
_PROVENANCE_SPLIT = re.compile(r";\s*(?=(?:" + "|".join(PROVENANCE_FIELDS) + r"):)")


@dataclass(frozen=True)
class ObjectSpec:
    """One object of the DexCanvas catalogue.

    Attributes:
        id: the object's id as the paper writes it (``index.scene`` of the release), e.g.
            ``"cube2"``, ``"cube2H"``. Letters, digits, ``_``, ``.`` and ``-``; no ``/``.
        name: human-readable name (the paper's description), e.g. ``"small cube (heavy)"``.
        shape: ``"cube"``, ``"cuboid"``, ``"cylinder"``, ``"sphere"`` or ``"mesh"`` (an item
            whose geometry is an object model; see ``approximate``).
        size_m: size [m] laid out per shape (see ``SIZE_LAYOUT``): cube ``(edge,)``, cuboid
            ``(x, y, z)`` in the object frame (z up at rest), cylinder ``(diameter, height)``,
            sphere ``(diameter,)``, mesh bounding box ``(x, y, z)``.
        mass_kg: mass [kg].
        placement: how the object rests on the table at the start of a capture (the paper's
            words where it gives them, e.g. ``"long edge along X"``); alternatives are separated
            by ``;`` and the first one defines the object frame.
        heavy: True for the weighted ``H`` duplicates.
        base_id: for a heavy duplicate, the id of the light object of the same geometry.
        source: ``"primitive"`` (geometric primitive), ``"ycb"`` (household item of the YCB
            group of the paper's table) or ``"custom"`` (a mesh object given by the user).
        ycb_id: YCB model id such as ``"011_banana"``, ``None`` for primitives and non-YCB items.
        data_source: provenance of size, mass, heavy set and placement, ``"size: …; mass: …;
            heavy_of: …; placement: …"``; ``paper`` is the paper's table, every other value
            starts with ``estimate`` and gives its reason.
        aliases: other accepted spellings; lookups also ignore case and separators.
        mesh: path of the object's mesh file (its frame is the object frame), or ``None`` for
            the built-in geometry (``dexcanvas_core.objects.geometry.object_geometry``).
        mesh_scale: metres per mesh unit.
        friction: sliding friction coefficient of the surface, or ``None`` for the scene's.
        inertia_diag: principal moments [kg·m²] about the centre of mass, or ``None``
            (computed from the shape and the mass, uniform density).
    """

    id: str
    name: str
    shape: Shape
    size_m: tuple[float, ...]
    mass_kg: float
    placement: str
    heavy: bool = False
    base_id: str | None = None
    source: Source = "primitive"
    ycb_id: str | None = None
    data_source: str = ""
    aliases: tuple[str, ...] = ()
    mesh: str | None = None
    mesh_scale: float = 1.0
    friction: float | None = None
    inertia_diag: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        where = f"object {self.id!r}"
        if not isinstance(self.id, str) or not _ID.fullmatch(self.id):
            raise ValidationError(
                f"{where}: an id is a non-empty string of letters, digits, '_', '.' or '-' "
                "starting with a letter or digit (no spaces, no '/')",
                field="id",
            )
        if self.shape not in SHAPES:
            raise ValidationError(
                f"{where}: shape {self.shape!r} is not one of {', '.join(SHAPES)}", field="shape"
            )
        size = tuple(float(v) for v in self.size_m)
        layout = SIZE_LAYOUT[self.shape]
        if len(size) != len(layout):
            raise ValidationError(
                f"{where}: a {self.shape} size is ({', '.join(layout)}) [m], "
                f"got {len(size)} values",
                field="size_m",
            )
        if not all(math.isfinite(v) and 0.0 < v < 2.0 for v in size):
            raise ValidationError(f"{where}: sizes must be in (0, 2) m, got {size}", field="size_m")
        mass = float(self.mass_kg)
        if not (math.isfinite(mass) and 0.0 < mass < 50.0):
            raise ValidationError(
                f"{where}: mass must be in (0, 50) kg, got {mass}", field="mass_kg"
            )
        if self.source not in get_args(Source):
            raise ValidationError(f"{where}: unknown source {self.source!r}", field="source")
        if self.source == "ycb" and self.shape != "mesh":
            raise ValidationError(
                f"{where}: a YCB item has shape 'mesh', got {self.shape!r}", field="shape"
            )
        if self.source == "primitive" and self.shape == "mesh":
            raise ValidationError(
                f"{where}: a primitive's shape is one of cube, cuboid, cylinder, sphere",
                field="shape",
            )
        if self.source == "custom" and (self.shape != "mesh" or self.mesh is None):
            raise ValidationError(
                f"{where}: a custom object has shape 'mesh' and a mesh file", field="mesh"
            )
        if self.ycb_id is not None and self.source != "ycb":
            raise ValidationError(f"{where}: only YCB items have a ycb_id", field="ycb_id")
        if self.heavy != (self.base_id is not None):
            raise ValidationError(
                f"{where}: a heavy variant names its light base_id, and only a heavy one does",
                field="base_id",
            )
        if not self.data_source:
            raise ValidationError(f"{where}: data_source must say where the values come from")
        object.__setattr__(self, "size_m", size)
        object.__setattr__(self, "mass_kg", mass)
        object.__setattr__(self, "aliases", tuple(self.aliases))

    @property
    def is_primitive(self) -> bool:
        return self.source == "primitive" and self.mesh is None

    @property
    def approximate(self) -> bool:
        """True when the object's geometry is the built-in primitive composition of
        ``dexcanvas_core.objects.geometry`` standing in for the real object: a YCB-style item
        whose model was not given (``--objects-dir``, a manifest)."""
        return self.source == "ycb" and self.mesh is None

    @classmethod
    def from_mesh(
        cls,
        path: str | os.PathLike,
        mass_kg: float,
        *,
        id: str | None = None,
        friction: float | None = None,
        scale: float = 1.0,
        inertia_diag: tuple[float, float, float] | None = None,
        name: str | None = None,
    ) -> ObjectSpec:
        """An object given by a mesh file (OBJ, STL, PLY, GLB) and its mass [kg].

        The mesh's frame is the object frame; ``scale`` converts its units to metres.
        ``id`` defaults to the file name's stem. The mesh is read and checked now (closed
        surface, 5 mm – 1 m across, plausible density).

        Raises:
            ValidationError: unreadable or open mesh, absurd scale, mass or inertia.
        """
        p = Path(path).expanduser().resolve()
        oid = (id if id is not None else p.stem).strip()
        where = f"object {oid!r}"
        mesh = load_object_mesh(p, scale)
        mass = check_mass(mass_kg, where, mesh.volume_m3)
        inertia = None if inertia_diag is None else check_inertia(inertia_diag, where)
        return cls._from_checked_mesh(oid, name or oid, mesh, mass, friction, scale, inertia, "")

    @classmethod
    def _from_checked_mesh(cls, oid, name, mesh, mass, friction, scale, inertia, note):
        ext = tuple(float(v) for v in mesh.extent_m)
        return cls(
            id=oid,
            name=name,
            shape="mesh",
            size_m=ext,
            mass_kg=mass,
            placement="on the table, resting as the mesh's frame stands (z up)",
            source="custom",
            data_source=f"size: mesh {mesh.source} (bounding box); mass: user-supplied{note}",
            mesh=mesh.source,
            mesh_scale=float(scale),
            friction=None if friction is None else float(friction),
            inertia_diag=inertia,
        )

    @property
    def lying(self) -> bool:
        """True for a cylinder resting on its side (``placement`` says "side down" or
        "lying"): its axis is the object frame's x. False for every other object."""
        first = self.placement.split(";")[0].lower()
        return self.shape == "cylinder" and _LYING.search(first) is not None

    @property
    def bounding_box_m(self) -> tuple[float, float, float]:
        """Axis-aligned extent (x, y, z) [m] with every cylinder axis on z (the catalogue's
        layout, not the object frame of a lying cylinder)."""
        s = self.size_m
        if self.shape in ("cube", "sphere"):
            return (s[0], s[0], s[0])
        if self.shape == "cylinder":
            return (s[0], s[0], s[1])
        return (s[0], s[1], s[2])

    @property
    def volume_m3(self) -> float | None:
        """Solid volume [m³] of a primitive; ``None`` for mesh items."""
        return _primitive_volume(self.shape, self.size_m)

    @property
    def inertia_diag_kg_m2(self) -> tuple[float, float, float] | None:
        """Principal moments of inertia ``(Ixx, Iyy, Izz)`` [kg·m²] about the centre of mass, in
        the object frame (z up at rest; a lying cylinder's axis on x), of a homogeneous solid of
        the catalogue size and mass. ``None`` for mesh items (``approximate`` ones have no true
        geometry here)."""
        m, s = self.mass_kg, self.size_m
        if self.shape in ("cube", "cuboid"):
            x, y, z = (s[0], s[0], s[0]) if self.shape == "cube" else s
            return (m * (y * y + z * z) / 12, m * (x * x + z * z) / 12, m * (x * x + y * y) / 12)
        if self.shape == "sphere":
            i = 0.4 * m * (s[0] / 2) ** 2
            return (i, i, i)
        if self.shape == "cylinder":
            r, h = s[0] / 2, s[1]
            axial = 0.5 * m * r * r
            radial = m * (3 * r * r + h * h) / 12
            return (axial, radial, radial) if self.lying else (radial, radial, axial)
        return None

    def provenance(self) -> dict[str, str]:
        """``data_source`` split by field: ``{"size": "paper", "placement": "estimate, …"}``."""
        out = {}
        for part in _PROVENANCE_SPLIT.split(self.data_source):
            key, sep, text = part.partition(":")
            if sep and key.strip() in PROVENANCE_FIELDS:
                out[key.strip()] = text.strip()
        return out

    def __str__(self) -> str:
        return self.id


def _primitive_volume(shape: str, s: tuple[float, ...]) -> float | None:
    if shape == "cube":
        return s[0] ** 3
    if shape == "cuboid":
        return s[0] * s[1] * s[2]
    if shape == "cylinder":
        return math.pi * s[0] ** 2 / 4.0 * s[1]
    if shape == "sphere":
        return math.pi * s[0] ** 3 / 6.0
    return None


# Spellings beyond the id that the release, YCB or users use (lookups also ignore case and
# separators); heavy duplicates also answer to ``<base>_heavy`` and ``<base> heavy``.
_ALIASES: dict[str, tuple[str, ...]] = {
    "cylinder2": ("flat_cylinder",),
    "mayonnaisebottle": ("mayonnaise_bottle", "mayonnaise", "bottle"),
    "largeclamp": ("large_clamp", "clamp"),
    "pitcherbase": ("pitcher_base", "pitcher"),
    "powerdrill": ("power_drill", "drill"),
    "scissor": ("scissors",),
}

# YCB model ids of the YCB-style items (the mayonnaise bottle is not a YCB object).
_YCB_IDS: dict[str, str | None] = {
    "mayonnaisebottle": None,
    "banana": "011_banana",
    "bowl": "024_bowl",
    "largeclamp": "051_large_clamp",
    "pitcherbase": "019_pitcher_base",
    "powerdrill": "035_power_drill",
    "scissor": "037_scissors",
}

CSV_COLUMNS: tuple[str, ...] = (
    "id", "description", "shape", "size_x_m", "size_y_m", "size_z_m", "diameter_m", "height_m",
    "mass_kg", "heavy_of", "placement", "provenance",
)  # fmt: skip
"""Columns of the package's ``objects.csv`` (the paper's table's, then ``provenance``)."""


def read_catalogue_rows(text: str) -> list[dict[str, str]]:
    """Rows of a catalogue CSV (``#`` lines are comments), as column → cell text.

    Raises:
        ValidationError: a missing column.
    """
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    reader = csv.DictReader(lines)
    missing = [c for c in CSV_COLUMNS if c not in (reader.fieldnames or ())]
    if missing:
        raise ValidationError(f"object catalogue: missing columns {missing}", field="columns")
    return [{k: (v or "").strip() for k, v in row.items()} for row in reader]


def _size(row: dict[str, str], shape: str) -> tuple[float, ...]:
    where = f"object catalogue row {row['id']!r}"
    names = {
        "cube": ("size_x_m", "size_y_m", "size_z_m"),
        "cuboid": ("size_x_m", "size_y_m", "size_z_m"),
        "mesh": ("size_x_m", "size_y_m", "size_z_m"),
        "cylinder": ("diameter_m", "height_m"),
        "sphere": ("diameter_m",),
    }.get(shape)
    if names is None:
        raise ValidationError(f"{where}: unknown shape {shape!r}", field="shape")
    try:
        values = tuple(float(row[n]) for n in names)
    except ValueError:
        raise ValidationError(
            f"{where}: a {shape} needs numbers in {', '.join(names)}", field="size_m"
        ) from None
    if shape == "cube":
        if len(set(values)) != 1:
            raise ValidationError(f"{where}: a cube's three sizes differ: {values}", field="size_m")
        return values[:1]
    return values


def _spec(row: dict[str, str]) -> ObjectSpec:
    oid, shape, base = row["id"], row["shape"], row["heavy_of"] or None
    where = f"object catalogue row {oid!r}"
    try:
        mass = float(row["mass_kg"])
    except ValueError:
        raise ValidationError(f"{where}: mass_kg {row['mass_kg']!r} is not a number") from None
    is_mesh = shape == "mesh"
    aliases = _ALIASES.get(base or oid, ())
    if base is not None:
        aliases = (f"{base}_heavy", f"{base} heavy", *(f"{a}H" for a in aliases))
    ycb_id = _YCB_IDS.get(oid) if is_mesh else None
    if ycb_id is not None:
        aliases = (*aliases, ycb_id, ycb_id[4:])
    return ObjectSpec(
        id=oid,
        name=row["description"],
        shape=shape,  # type: ignore[arg-type]
        size_m=_size(row, shape),
        mass_kg=mass,
        placement=row["placement"],
        heavy=base is not None,
        base_id=base,
        source="ycb" if is_mesh else "primitive",
        ycb_id=ycb_id,
        data_source=row["provenance"],
        aliases=aliases,
    )


def _load() -> dict[str, ObjectSpec]:
    text = resources.files(__package__).joinpath(CATALOGUE_FILE).read_text(encoding="utf-8")
    specs = [_spec(row) for row in read_catalogue_rows(text)]
    by_id = {s.id: s for s in specs}
    if len(by_id) != len(specs):  # pragma: no cover - a broken package file must fail loudly
        raise RuntimeError(f"duplicate ids in {CATALOGUE_FILE}")
    for s in specs:
        missing = [f for f in PROVENANCE_FIELDS if f not in s.provenance()]
        if missing:  # pragma: no cover
            raise RuntimeError(f"{CATALOGUE_FILE}: {s.id} has no provenance for {missing}")
        if s.base_id is not None:
            base = by_id.get(s.base_id)
            if base is None or base.heavy or (base.shape, base.size_m) != (s.shape, s.size_m):
                raise RuntimeError(  # pragma: no cover
                    f"{CATALOGUE_FILE}: {s.id} is not a heavy duplicate of {s.base_id}"
                )
    return by_id


OBJECTS: dict[str, ObjectSpec] = _load()
"""The 29 objects by id, in the paper's order: 14 light primitives, their 8 heavy duplicates,
then the 7 YCB-style items."""

HEAVY_BASES: tuple[str, ...] = tuple(s.base_id for s in OBJECTS.values() if s.base_id)
"""Light primitives that have a weighted ``H`` duplicate (the paper's eight)."""
