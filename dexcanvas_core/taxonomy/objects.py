"""The 30 DexCanvas objects: geometric primitives, their heavy variants, and YCB-style items.

Ids are the lowercase strings the release stores in ``index.scene`` and
``trajectory_metadata.object_names``: ``cube1``, ``cube2``, ``cuboid1``–``cuboid3``,
``cylinder1``–``cylinder6``, ``sphere1``–``sphere3``, the heavy variants ``<id>h`` (the paper
writes ``cube2H``; lookups ignore case) and ``banana``, ``bowl``, ``largeclamp``,
``mayonnaisebottle``, ``pitcherbase``, ``powerdrill``, ``scissor`` (the release's spellings;
``"mayonnaise bottle"``, ``"scissors"``, ``"011_banana"`` … are accepted too).

Provenance, field by field, is in every entry's ``data_source``. In short:

* **The paper's object table was not reachable** (only the abstract of arXiv 2510.15786 is in
  the stored copies searched), so no value below is quoted from it.
* **Sizes** of cube1, cube2, cylinder3, cylinder4, banana, bowl, largeclamp, mayonnaisebottle
  and powerdrill are the axis-aligned bounding boxes of the DexRobot collision meshes of these
  objects, as published in ``MindLab-Research/mint-vla-client-example``,
  ``scripts/state56_native28_geometry_contract.json`` (``half_extents`` × 2, rounded to 1 mm).
  Convex-decomposition hulls and marker mounts make them a few mm larger than the bare object.
* **Other primitive sizes** are estimates from the proportions of the object renders on the
  project page (``dexCanvas/dexcanvas.github.io``, ``assets/images/objects``); ``cylinder5`` is
  not pictured there and is a pure guess.
* **Primitive masses** are size × density estimates: 600 kg/m³ for the (3-D printed) light
  objects, 2000 kg/m³ for the weighted ``H`` variants.
* **Which nine primitives have heavy variants** was not found; the set below is a guess that
  keeps the catalogue at the paper's 30 objects.
* **YCB masses** are the Yale–CMU–Berkeley object set values (Calli et al. 2015);
  ``scissor`` and ``pitcherbase`` sizes are that paper's dimensions as recalled (estimates).
  The mayonnaise bottle is not a YCB object: its mass is YCB 006_mustard_bottle's (similar
  size), an estimate.
* **Placements** (how the object rests on the table at the start of a capture) are estimates.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, get_args

from dexcanvas_core.errors import UnknownNameError, ValidationError
from dexcanvas_core.objects.manifest import (
    MANIFEST_ENV,
    OBJECTS_DIR_ENV,
    check_inertia,
    check_mass,
    objects_dir_meshes,
    read_manifest,
)
from dexcanvas_core.objects.mesh import load_object_mesh
from dexcanvas_core.taxonomy._lookup import build_index, lookup

Shape = Literal["cube", "cuboid", "cylinder", "sphere", "ycb", "mesh"]
Source = Literal["primitive", "ycb", "custom"]

SHAPES: tuple[Shape, ...] = get_args(Shape)

SIZE_LAYOUT: dict[str, tuple[str, ...]] = {
    "cube": ("edge",),
    "cuboid": ("x", "y", "z"),
    "cylinder": ("diameter", "height"),
    "sphere": ("diameter",),
    "ycb": ("x", "y", "z"),
    "mesh": ("x", "y", "z"),
}
"""Meaning of ``ObjectSpec.size_m`` per shape, all in metres (``ycb``: bounding box)."""

LIGHT_DENSITY_KG_M3 = 600.0
"""Estimated effective density of the light primitives (FDM-printed plastic with infill)."""

HEAVY_DENSITY_KG_M3 = 2000.0
"""Estimated effective density of the weighted ``H`` variants."""


@dataclass(frozen=True)
class ObjectSpec:
    """One object of the DexCanvas catalogue.

    Attributes:
        id: the release's object id (``index.scene``), lowercase, e.g. ``"cube2"``, ``"cube2h"``.
        name: human-readable name, e.g. ``"Cube 2 (heavy)"``.
        shape: ``"cube"``, ``"cuboid"``, ``"cylinder"``, ``"sphere"`` or ``"ycb"`` (a household
            item modelled by a mesh or a primitive composition).
        size_m: size [m] laid out per shape (see ``SIZE_LAYOUT``): cube ``(edge,)``, cuboid
            ``(x, y, z)``, cylinder ``(diameter, height)``, sphere ``(diameter,)``, ycb bounding
            box ``(x, y, z)``.
        mass_kg: mass [kg].
        placement: how the object rests on the table at the start of a capture.
        heavy: True for the weighted ``H`` variants.
        base_id: for a heavy variant, the id of the light object of the same size.
        source: ``"primitive"`` (geometric primitive) or ``"ycb"`` (household item of the YCB
            group of the paper's table).
        ycb_id: YCB model id such as ``"011_banana"``, ``None`` for primitives and non-YCB items.
        data_source: provenance of size, mass and placement; every value not taken from a
            measurement or a published table starts with ``estimate``.
        aliases: other accepted spellings; lookups also ignore case and separators.
        mesh: path of the object's mesh file (its frame is the object frame), or ``None`` for
            the built-in geometry (``dexcanvas_core.demos.object_geometry``).
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
        if not isinstance(self.id, str) or not self.id or self.id != self.id.lower():
            raise ValidationError(f"{where}: id must be a non-empty lowercase string", field="id")
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
        if self.shape == "ycb" and self.source != "ycb":
            raise ValidationError(f"{where}: shape 'ycb' goes with source 'ycb'", field="source")
        if self.source == "custom" and self.mesh is None:
            raise ValidationError(f"{where}: a custom object needs a mesh", field="mesh")
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
        """The geometry stands in for the real object: a YCB-style item built from primitives
        because no model of it was given (``--objects-dir``, a manifest)."""
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
            id=oid.lower(),
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
    def bounding_box_m(self) -> tuple[float, float, float]:
        """Axis-aligned extent (x, y, z) [m] in the object frame (cylinder axis along z)."""
        s = self.size_m
        if self.shape in ("cube", "sphere"):
            return (s[0], s[0], s[0])
        if self.shape == "cylinder":
            return (s[0], s[0], s[1])
        return (s[0], s[1], s[2])

    @property
    def volume_m3(self) -> float | None:
        """Solid volume [m³] of a primitive; ``None`` for YCB items."""
        return _primitive_volume(self.shape, self.size_m)

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


# --- provenance strings -------------------------------------------------------------------------
_AABB = (
    "derived: DexRobot collision-mesh bounding box {dims} mm (public copy "
    "MindLab-Research/mint-vla-client-example, scripts/state56_native28_geometry_contract.json)"
)
_RENDER = "estimate: proportions of the project-page render (dexCanvas/dexcanvas.github.io)"
_UNPICTURED = "estimate: not pictured or listed anywhere found; a guess"
_CALLI = "Calli et al. 2015, YCB object set table"
# YCB masses checked against public copies of that table (e.g. 035_power_drill 0.895 kg,
# 051_large_clamp 0.125 kg, 019_pitcher_base 0.178 kg).
_PLACEMENT = "placement: estimate"


def _mass_note(density: float) -> str:
    return f"mass: estimate, volume × {density:.0f} kg/m³"


_PRIMITIVE_FACES = "on the table, resting on a face"
_STANDING = "on the table, standing on an end face"
_LYING = "on the table, lying on its side"

# (id, name, shape, size_m, placement, size provenance, aliases)
# fmt: off
_PRIMITIVES: tuple[tuple[str, str, Shape, tuple[float, ...], str, str, tuple[str, ...]], ...] = (
    ("cube1", "Cube 1", "cube", (0.085,), _PRIMITIVE_FACES,
     _AABB.format(dims="86.7 × 87.3 × 81.2") + ", edge = mean extent", ()),
    ("cube2", "Cube 2", "cube", (0.052,), _PRIMITIVE_FACES,
     _AABB.format(dims="52.6 × 52.2 × 51.4") + ", edge = mean extent", ()),
    ("cuboid1", "Cuboid 1 (plate)", "cuboid", (0.10, 0.10, 0.025),
     "on the table, lying flat on its largest face", _RENDER + " (twice cube2's face)", ()),
    ("cuboid2", "Cuboid 2 (bar)", "cuboid", (0.16, 0.04, 0.04),
     "on the table, lying along its long axis", _RENDER, ()),
    ("cuboid3", "Cuboid 3 (box)", "cuboid", (0.07, 0.05, 0.09), _PRIMITIVE_FACES, _RENDER, ()),
    ("cylinder1", "Cylinder 1", "cylinder", (0.05, 0.12), _STANDING, _RENDER, ()),
    ("cylinder2", "Cylinder 2 (disc)", "cylinder", (0.09, 0.03),
     "on the table, lying flat on an end face", _RENDER, ("flat_cylinder",)),
    ("cylinder3", "Cylinder 3", "cylinder", (0.034, 0.103), _STANDING,
     _AABB.format(dims="34.1 × 34.8 × 103.1"), ()),
    ("cylinder4", "Cylinder 4 (rod)", "cylinder", (0.013, 0.152), _LYING,
     _AABB.format(dims="12.5 × 14.0 × 151.9"), ()),
    ("cylinder5", "Cylinder 5", "cylinder", (0.03, 0.20), _LYING, _UNPICTURED, ()),
    ("cylinder6", "Cylinder 6", "cylinder", (0.06, 0.09), _STANDING, _RENDER, ()),
    ("sphere1", "Sphere 1", "sphere", (0.08,), "on the table, free to roll", _RENDER, ()),
    ("sphere2", "Sphere 2", "sphere", (0.065,), "on the table, free to roll", _RENDER, ()),
    ("sphere3", "Sphere 3", "sphere", (0.048,), "on the table, free to roll",
     _RENDER + " (0.73 × sphere2, same camera)", ()),
)

HEAVY_BASES: tuple[str, ...] = (
    "cube1", "cube2", "cuboid1", "cuboid3", "cylinder1", "cylinder3", "cylinder6", "sphere1",
    "sphere2",
)
"""Light primitives that have a weighted ``H`` variant (estimate: the paper's list was not
found; nine are needed for 14 primitives + 7 YCB items + 9 heavy = 30 objects)."""
# fmt: on


def _primitive(
    oid: str,
    name: str,
    shape: Shape,
    size: tuple[float, ...],
    placement: str,
    size_note: str,
    aliases: tuple[str, ...],
    *,
    heavy: bool,
) -> ObjectSpec:
    density = HEAVY_DENSITY_KG_M3 if heavy else LIGHT_DENSITY_KG_M3
    volume = _primitive_volume(shape, size)
    if volume is None:  # pragma: no cover - _PRIMITIVES holds primitives only
        raise RuntimeError(f"{oid} is not a primitive")
    mass = round(volume * density, 3)
    notes = [f"size: {size_note}", _mass_note(density), _PLACEMENT]
    if heavy:
        notes.append("heavy variant: estimate (which primitives have one was not found)")
        return ObjectSpec(
            f"{oid}h",
            f"{name} (heavy)",
            shape,
            size,
            mass,
            placement,
            heavy=True,
            base_id=oid,
            data_source="; ".join(notes),
            aliases=(f"{oid}_heavy", f"{oid} heavy", *(f"{a}h" for a in aliases)),
        )
    return ObjectSpec(
        oid, name, shape, size, mass, placement, data_source="; ".join(notes), aliases=aliases
    )


# (id, name, ycb_id, bounding box [m], mass [kg], placement, provenance, aliases)
# fmt: off
_YCB: tuple[tuple[str, str, str | None, tuple[float, float, float], float, str, str,
                  tuple[str, ...]], ...] = (
    ("mayonnaisebottle", "Mayonnaise bottle", None, (0.101, 0.062, 0.194), 0.603,
     "on the table, standing upright",
     f"size: {_AABB.format(dims='101.5 × 62.4 × 194.2')}; mass: estimate, YCB "
     f"006_mustard_bottle's 0.603 kg ({_CALLI}), a bottle of similar size; not a YCB object",
     ("mayonnaise_bottle", "mayonnaise", "bottle")),
    ("banana", "Banana", "011_banana", (0.095, 0.069, 0.220), 0.066,
     "on the table, lying on its side",
     f"size: {_AABB.format(dims='94.9 × 68.8 × 219.9')}; mass: {_CALLI}", ()),
    ("bowl", "Bowl", "024_bowl", (0.169, 0.170, 0.071), 0.147,
     "on the table, upright (opening up)",
     f"size: {_AABB.format(dims='169.1 × 170.3 × 71.2')}; mass: {_CALLI}", ()),
    ("largeclamp", "Large clamp", "051_large_clamp", (0.134, 0.053, 0.185), 0.125,
     "on the table, lying flat",
     f"size: {_AABB.format(dims='134.2 × 53.4 × 185.1')}; mass: {_CALLI}",
     ("large_clamp", "clamp")),
    ("pitcherbase", "Pitcher base", "019_pitcher_base", (0.108, 0.108, 0.235), 0.178,
     "on the table, standing upright",
     f"size: estimate, {_CALLI} as recalled (body 108 mm diameter × 235 mm; the handle adds "
     "width); "
     f"mass: {_CALLI}",
     ("pitcher_base", "pitcher")),
    ("powerdrill", "Power drill", "035_power_drill", (0.190, 0.067, 0.197), 0.895,
     "on the table, standing on its battery base",
     f"size: {_AABB.format(dims='189.5 × 67.4 × 197.5')}; mass: {_CALLI}",
     ("power_drill", "drill")),
    ("scissor", "Scissors", "037_scissors", (0.087, 0.200, 0.014), 0.082,
     "on the table, lying flat",
     f"size: estimate, {_CALLI} as recalled (87 × 200 × 14 mm); mass: {_CALLI}",
     ("scissors",)),
)
# fmt: on


def _build() -> dict[str, ObjectSpec]:
    specs: list[ObjectSpec] = []
    for row in _PRIMITIVES:
        specs.append(_primitive(*row, heavy=False))
    for row in _PRIMITIVES:
        if row[0] in HEAVY_BASES:
            specs.append(_primitive(*row, heavy=True))
    for oid, name, ycb_id, box, mass, placement, note, aliases in _YCB:
        specs.append(
            ObjectSpec(
                oid,
                name,
                "ycb",
                box,
                mass,
                placement,
                source="ycb",
                ycb_id=ycb_id,
                data_source=f"{note}; {_PLACEMENT}",
                aliases=(*aliases, *((ycb_id, ycb_id[4:]) if ycb_id else ())),
            )
        )
    return {s.id: s for s in specs}


OBJECTS: dict[str, ObjectSpec] = _build()
"""The 30 objects by id: 14 light primitives, their 9 heavy variants, then the 7 YCB items."""

_BY_SPELLING = build_index(((s, (s.id, *s.aliases)) for s in OBJECTS.values()), "object")


def object_spec(object_id: str | ObjectSpec) -> ObjectSpec:
    """Look an object up by id or alias, ignoring case and separators.

    ``"cube2"``, ``"Cube 2"``, ``"cube2H"`` (heavy variant), ``"mayonnaise_bottle"``,
    ``"scissors"`` and ``"011_banana"`` all resolve. An :class:`ObjectSpec` is returned as is.

    Raises:
        UnknownNameError: unknown object; the message suggests close matches.
        ValidationError: ``object_id`` is not a string.
    """
    if isinstance(object_id, ObjectSpec):
        return object_id
    if not isinstance(object_id, str):
        raise ValidationError(
            f"an object is given by its id (str), got {type(object_id).__name__} {object_id!r}"
        )
    custom = _custom_index()
    found = lookup(custom, object_id) or lookup(_BY_SPELLING, object_id)
    if found is None:
        raise UnknownNameError(
            "object",
            object_id.strip().lower(),
            [*OBJECTS, *(s.id for s in custom.values())],
            hint=(
                "; an object outside the catalogue is given with --objects MANIFEST (a TOML "
                "file: [<id>] mesh = 'path.obj', mass_kg = ...) or ObjectSpec.from_mesh"
            ),
        )
    return found


# -- objects from meshes: a manifest and an objects directory --------------------------------------

_custom_state: dict = {"key": None, "index": {}}


def _custom_index() -> dict[str, ObjectSpec]:
    """The lookup index of the objects given by ``DEXCANVAS_OBJECTS`` (a manifest) and
    ``DEXCANVAS_OBJECTS_DIR`` (models of catalogue objects), rebuilt when either changes."""
    key = (os.environ.get(MANIFEST_ENV) or None, os.environ.get(OBJECTS_DIR_ENV) or None)
    if key != _custom_state["key"]:
        specs = _custom_specs(*key)
        index = build_index(((s, (s.id, *s.aliases)) for s in specs.values()), "object")
        _custom_state.update(key=key, index=index, specs=specs)
    return _custom_state["index"]


def _custom_specs(manifest: str | None, objects_dir: str | None) -> dict[str, ObjectSpec]:
    out: dict[str, ObjectSpec] = {}
    if objects_dir:
        files = objects_dir_meshes(objects_dir)
        for spec in OBJECTS.values():
            f = files.get(spec.id.lower()) or (
                files.get(spec.base_id.lower()) if spec.base_id else None
            )
            if f is None:
                continue
            mesh = load_object_mesh(f)
            check_mass(spec.mass_kg, f"object {spec.id!r} with the model {f}", mesh.volume_m3)
            out[spec.id] = dataclasses.replace(
                spec,
                size_m=tuple(float(v) for v in mesh.extent_m) if spec.shape in ("ycb", "mesh")
                else spec.size_m,
                mesh=mesh.source,
                data_source=f"shape: model {f} (objects directory); {spec.data_source}",
            )  # fmt: skip
    if manifest:
        for e in read_manifest(manifest):
            base = lookup(_BY_SPELLING, e.id)
            note = f" (objects manifest {e.manifest})"
            if base is None:
                spec = ObjectSpec._from_checked_mesh(
                    e.id, e.name, e.mesh, e.mass_kg, e.friction, e.scale, e.inertia_diag, note
                )
            else:  # a catalogue object given a model: the mesh replaces its built-in shape
                spec = dataclasses.replace(
                    base,
                    mass_kg=e.mass_kg,
                    mesh=e.mesh.source,
                    mesh_scale=e.scale,
                    friction=e.friction,
                    inertia_diag=e.inertia_diag,
                    data_source=f"shape and mass: {e.mesh.source}{note}; {base.data_source}",
                )
            out[spec.id] = spec
    return out


def custom_objects() -> dict[str, ObjectSpec]:
    """Objects given by the current manifest and objects directory, by id (see
    :func:`use_objects`); a catalogue id here overrides the built-in shape."""
    _custom_index()
    return dict(_custom_state.get("specs", {}))


def use_objects(
    manifest: str | os.PathLike | None = None, objects_dir: str | os.PathLike | None = None
) -> dict[str, ObjectSpec]:
    """Use an objects manifest and/or a directory of object models in every lookup of this
    process and of the processes it starts (through ``DEXCANVAS_OBJECTS`` /
    ``DEXCANVAS_OBJECTS_DIR``). ``None`` leaves that source unchanged.

    Everything is read and checked now, so a bad entry stops before any work.

    Returns:
        the objects given by the manifest and the directory, by id.

    Raises:
        ValidationError: a bad manifest entry, model file or directory.
    """
    previous = {k: os.environ.get(k) for k in (MANIFEST_ENV, OBJECTS_DIR_ENV)}
    for env, value in ((MANIFEST_ENV, manifest), (OBJECTS_DIR_ENV, objects_dir)):
        if value is not None:
            os.environ[env] = str(Path(value).expanduser().resolve())
    try:
        return custom_objects()
    except Exception:
        for k, v in previous.items():  # leave the process as it was
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        raise


def clear_objects() -> None:
    """Forget the manifest and objects directory (back to the built-in catalogue)."""
    os.environ.pop(MANIFEST_ENV, None)
    os.environ.pop(OBJECTS_DIR_ENV, None)


def heavy_variant(object_id: str | ObjectSpec) -> ObjectSpec | None:
    """The weighted ``H`` variant of a light object, or ``None`` if it has none."""
    base = object_spec(object_id)
    heavy = next((s for s in OBJECTS.values() if s.base_id == base.id), None)
    return None if heavy is None else object_spec(heavy.id)
