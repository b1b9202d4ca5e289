"""Objects manifests: a TOML file that maps object ids to meshes, masses and frictions.

A dataset whose objects are not in the DexCanvas catalogue (or a user who has the real object
models) describes them in a manifest and passes it with ``--objects MANIFEST`` (or the
``DEXCANVAS_OBJECTS`` environment variable), one table per object::

    [mug]                        # the object id, as the dataset's rows name it
    mesh = "meshes/mug.obj"      # OBJ, STL, PLY or GLB; relative paths are from the manifest
    mass_kg = 0.31
    friction = 0.8               # optional: sliding friction coefficient (default: the scene's)
    scale = 0.001                # optional: metres per mesh unit (a mesh in mm)
    inertia_diag = [4.1e-4, 4.1e-4, 2.9e-4]  # optional [kg·m²] about the centre of mass
    name = "Coffee mug"          # optional

    [cube2]                      # a catalogue id: this mesh replaces the built-in shape
    mesh = "cube_5cm.obj"
    mass_kg = 0.037

The tables may also sit under one ``[objects]`` table (``[objects.mug]``). Every entry is checked
when the manifest is read, before any work: unknown keys, a missing or unreadable mesh, an open
surface, an absurd scale or mass stop with a message naming the entry and the fix.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.objects.mesh import MESH_SUFFIXES, ObjectMesh, load_object_mesh

try:  # Python ≥ 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

MANIFEST_ENV = "DEXCANVAS_OBJECTS"
"""Environment variable holding an objects manifest's path (what ``--objects`` sets)."""

OBJECTS_DIR_ENV = "DEXCANVAS_OBJECTS_DIR"
"""Environment variable holding a directory of ``<id>.<ext>`` object models (``--objects-dir``)."""

_KEYS = ("mesh", "mass_kg", "friction", "scale", "inertia_diag", "name")


@dataclass(frozen=True)
class MeshObjectEntry:
    """One object of a manifest, checked.

    Attributes:
        id: object id as the data names it (lookups ignore case).
        mesh: the checked mesh (object frame = the mesh's frame, metres).
        mass_kg: mass [kg].
        friction: sliding friction coefficient, or ``None`` for the scene's default.
        scale: metres per mesh unit the mesh was read with.
        inertia_diag: principal moments [kg·m²] about the centre of mass, or ``None``.
        name: a readable name.
        manifest: the manifest it came from.
    """

    id: str
    mesh: ObjectMesh
    mass_kg: float
    friction: float | None
    scale: float
    inertia_diag: tuple[float, float, float] | None
    name: str
    manifest: str


def check_mass(mass_kg, where: str, volume_m3: float | None = None) -> float:
    """``mass_kg`` as a float after checking it is a plausible object mass [kg] (0–50 kg and,
    given the volume, a mean density of 5–25,000 kg/m³: outside it, size or mass is in the
    wrong unit)."""
    if isinstance(mass_kg, bool) or not isinstance(mass_kg, int | float):
        raise ValidationError(f"{where}: mass_kg must be a number [kg], got {mass_kg!r}")
    m = float(mass_kg)
    if not (math.isfinite(m) and 0.0 < m < 50.0):
        raise ValidationError(f"{where}: mass_kg must be in (0, 50) kg, got {m:g}")
    if volume_m3 is not None and volume_m3 > 0:
        rho = m / volume_m3
        if not 5.0 <= rho <= 25_000.0:
            raise ValidationError(
                f"{where}: {m:g} kg in {volume_m3 * 1e6:.4g} cm³ is a density of {rho:.4g} "
                "kg/m³, no solid object's; check the mass (kg, not g) and the mesh's scale"
            )
    return m


def read_manifest(path: str | os.PathLike) -> list[MeshObjectEntry]:
    """Read and check every entry of an objects manifest (see the module docstring).

    Raises:
        ValidationError: the file is missing or not TOML, an entry has unknown or missing keys,
            bad values, or a mesh that cannot be used; the message names the entry.
    """
    p = Path(path).expanduser()
    if not p.is_file():
        raise ValidationError(
            f"objects manifest {str(p)!r}: no such file (give a TOML file mapping object ids "
            "to meshes, see `dexcanvas_core.objects.manifest`)",
            field="objects",
        )
    try:
        doc = tomllib.loads(p.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ValidationError(f"objects manifest {str(p)!r} is not valid TOML: {e}") from e
    tables = doc.get("objects", doc) if isinstance(doc.get("objects"), dict) else doc
    if not tables:
        raise ValidationError(f"objects manifest {str(p)!r} lists no object")
    out = []
    for oid, entry in tables.items():
        where = f"objects manifest {p.name}, object {oid!r}"
        if not isinstance(entry, dict):
            raise ValidationError(
                f"{where}: expected a table ([{oid}] with mesh = ..., mass_kg = ...), got "
                f"{type(entry).__name__}"
            )
        unknown = sorted(set(entry) - set(_KEYS))
        if unknown:
            raise ValidationError(f"{where}: unknown keys {unknown}; valid: {', '.join(_KEYS)}")
        for key in ("mesh", "mass_kg"):
            if key not in entry:
                raise ValidationError(f"{where}: {key} is missing")
        if not isinstance(entry["mesh"], str):
            raise ValidationError(f"{where}: mesh must be a path string")
        mesh_path = Path(entry["mesh"]).expanduser()
        if not mesh_path.is_absolute():
            mesh_path = (p.parent / mesh_path).resolve()
        scale = entry.get("scale", 1.0)
        if isinstance(scale, bool) or not isinstance(scale, int | float):
            raise ValidationError(f"{where}: scale must be a number, got {scale!r}")
        try:
            mesh = load_object_mesh(mesh_path, float(scale))
        except ValidationError as e:
            raise ValidationError(f"{where}: {e}") from e
        mass = check_mass(entry["mass_kg"], where, mesh.volume_m3)
        friction = entry.get("friction")
        if friction is not None and (
            isinstance(friction, bool)
            or not isinstance(friction, int | float)
            or not 0.0 < float(friction) <= 5.0
        ):
            raise ValidationError(f"{where}: friction must be a number in (0, 5], got {friction!r}")
        inertia = entry.get("inertia_diag")
        if inertia is not None:
            inertia = check_inertia(inertia, where)
        name = entry.get("name", oid)
        out.append(
            MeshObjectEntry(
                id=str(oid),
                mesh=mesh,
                mass_kg=mass,
                friction=None if friction is None else float(friction),
                scale=float(scale),
                inertia_diag=inertia,
                name=str(name),
                manifest=str(p.resolve()),
            )
        )
    return out


def check_inertia(inertia, where: str) -> tuple[float, float, float]:
    """Three positive principal moments [kg·m²] that satisfy the triangle inequality."""
    try:
        vals = tuple(float(v) for v in inertia)
    except (TypeError, ValueError) as e:
        raise ValidationError(f"{where}: inertia_diag must be 3 numbers [kg·m²]") from e
    if len(vals) != 3 or not all(math.isfinite(v) and v > 0 for v in vals):
        raise ValidationError(f"{where}: inertia_diag must be 3 positive numbers [kg·m²]")
    a, b, c = sorted(vals)
    if a + b < c * (1 - 1e-9):
        raise ValidationError(
            f"{where}: inertia_diag {vals} breaks the triangle inequality (no rigid body has it)"
        )
    return vals


def objects_dir_meshes(directory: str | os.PathLike) -> dict[str, Path]:
    """``<id>.<ext>`` model files in ``directory`` by lowercase id (the first suffix of
    ``MESH_SUFFIXES`` wins when an id has several)."""
    d = Path(directory).expanduser()
    if not d.is_dir():
        raise ValidationError(
            f"objects directory {str(d)!r} does not exist (give a directory holding <id>.obj, "
            "<id>.stl, ... object models)",
            field="objects_dir",
        )
    found: dict[str, Path] = {}
    for suffix in MESH_SUFFIXES:
        for f in sorted(d.iterdir()):
            if f.suffix.lower() == suffix and f.is_file():
                found.setdefault(f.stem.lower(), f)
    return found
