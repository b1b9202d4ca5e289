"""``dexcanvas import FORMAT PATH... --out D.lance``: captured sequences into the DexCanvas layout.

Every format's reader yields sequences as ``mano-npz`` keys (``dexcanvas_core.capture.arrays``);
each is checked, normalised (:class:`~dexcanvas_core.capture.arrays.Capture`) and converted
(:mod:`dexcanvas_core.capture.convert`). Object meshes are written next to the dataset, in
``D.lance.objects/`` with an objects manifest ``manifest.toml`` (the format of
``dexcanvas_core.objects.manifest``), which every command that opens ``D.lance`` uses.

An object's mass is, in this order: the sequence's ``object_mass_kg``; the ``--objects``
manifest's entry of that id; the catalogue's (an id the catalogue knows, e.g. ``011_banana``);
``density`` × the mesh's volume. None of them: an error naming the object and these options.

Everything is checked before anything is written; the dataset and its objects folder are
written to temporary names and renamed into place.
"""

from __future__ import annotations

import hashlib
import logging
import os
import shutil
import uuid as uuidlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dexcanvas_core.capture.arrays import capture_from_arrays
from dexcanvas_core.capture.capture import Capture
from dexcanvas_core.capture.convert import DEFAULT_FPS, capture_to_trajectory
from dexcanvas_core.capture.formats import READERS, reader_for
from dexcanvas_core.errors import UnknownNameError, ValidationError
from dexcanvas_core.io import write_dataset
from dexcanvas_core.objects.manifest import check_mass, read_manifest
from dexcanvas_core.objects.mesh import load_object_mesh
from dexcanvas_core.safe_io import check_output
from dexcanvas_core.taxonomy.object_lookup import add_objects_manifest, catalogue_spec, use_objects

log = logging.getLogger(__name__)

OBJECTS_SUFFIX = ".objects"
"""A dataset ``D.lance`` keeps its imported object meshes in ``D.lance.objects/``."""

MANIFEST_NAME = "manifest.toml"


def dataset_objects_manifest(dataset: str | os.PathLike) -> Path | None:
    """The objects manifest written with an imported dataset, or None."""
    p = Path(dataset).expanduser()
    m = p.with_name(p.name + OBJECTS_SUFFIX) / MANIFEST_NAME
    return m if m.is_file() else None


@dataclass(frozen=True)
class ImportConfig:
    """One ``dexcanvas import``."""

    format: str
    """A reader name (``dexcanvas_core.capture.formats.READERS``), e.g. ``mano-npz``."""
    paths: tuple[Path, ...]
    """Files or directories of captures."""
    out: Path
    """Output Lance dataset (its meshes go to ``<out>.objects/``)."""
    objects_manifest: Path | None = None
    """Masses, frictions and inertias of the captures' objects (``[id] mass_kg = …``)."""
    mirror_left: bool = False
    """Import left hands mirrored to right ones (the whole scene is mirrored)."""
    up: str | None = None
    """Override of the captures' up axis (``z``, ``y``, ``-y``, …)."""
    fps: float | None = DEFAULT_FPS
    """Frame rate to resample to [Hz]; None keeps each capture's."""
    density: float | None = None
    """Mass from the mesh's volume [kg/m³] for objects whose mass nothing else gives."""
    models_dir: Path | None = None
    """Object models directory for formats that name objects without meshes (``ho3d``)."""
    overwrite: bool = False
    """Replace an existing output."""


@dataclass
class ImportResult:
    """What an import wrote."""

    out: Path
    manifest: Path
    sequences: list[dict] = field(default_factory=list)
    objects: dict[str, dict] = field(default_factory=dict)


def _mesh_key(cap: Capture) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(cap.mesh_vertices, np.float64).tobytes())
    h.update(np.ascontiguousarray(cap.mesh_faces, np.int64).tobytes())
    return h.hexdigest()


def _object_id(name: str) -> str:
    """The dataset's id of a capture's object: the catalogue's id when it knows the name
    (``011_banana`` → ``banana``), else the name."""
    spec = catalogue_spec(name)
    return spec.id if spec is not None else name


def _mass(
    oid: str, caps: list[Capture], user: dict, density: float | None, volume_m3: float
) -> tuple[float, str]:
    """(mass [kg], where it came from) of one object (module docstring)."""
    given = {c.object_mass_kg for c in caps if c.object_mass_kg is not None}
    if len(given) > 1:
        raise ValidationError(
            f"object {oid!r}: the captures give different masses {sorted(given)} kg; give one "
            "(object_mass_kg) or leave them out and set it in --objects"
        )
    if given:
        return given.pop(), "capture (object_mass_kg)"
    if oid.lower() in user:
        return user[oid.lower()].mass_kg, f"objects manifest {user[oid.lower()].manifest}"
    spec = catalogue_spec(oid)
    if spec is not None:
        return spec.mass_kg, f"catalogue ({spec.id})"
    if density is not None:
        return density * volume_m3, f"density {density:g} kg/m³ × mesh volume (estimate)"
    raise ValidationError(
        f"object {oid!r} has no mass: give object_mass_kg in the capture, an --objects "
        f"manifest with [{oid}] mass_kg = ..., or --density KG_PER_M3 to estimate it from the "
        "mesh's volume"
    )


def _read_all(cfg: ImportConfig, reader: Callable) -> Iterator[tuple[str, dict, Path | None]]:
    for path in cfg.paths:
        p = Path(path).expanduser()
        if not p.exists():
            raise ValidationError(f"{p}: no such file or directory", field="path")
        yield from reader(p, models_dir=cfg.models_dir)


def read_captures(cfg: ImportConfig) -> list[Capture]:
    """Read and check every sequence of ``cfg`` (nothing is written)."""
    reader = reader_for(cfg.format)
    caps = []
    for name, arrays, base_dir in _read_all(cfg, reader):
        caps.append(
            capture_from_arrays(
                arrays, name=name, base_dir=base_dir, mirror_left=cfg.mirror_left, up=cfg.up
            )
        )
    if not caps:
        raise ValidationError(
            f"no {cfg.format} capture found in {', '.join(str(p) for p in cfg.paths)}",
            field="path",
        )
    names = [c.name for c in caps]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValidationError(f"several captures are named {dup[0]!r}; rename one", field="path")
    return caps


def _write_objects(caps: list[Capture], cfg: ImportConfig, dest: Path) -> dict[str, dict]:
    """Write each object's mesh and the manifest into ``dest`` (a fresh directory); return the
    objects' records. Checks every mesh (``load_object_mesh``) and mass first."""
    import trimesh

    user = {}
    if cfg.objects_manifest is not None:
        user = {e.id.lower(): e for e in read_manifest(cfg.objects_manifest)}
    by_obj: dict[str, list[Capture]] = {}
    for c in caps:
        by_obj.setdefault(_object_id(c.object_name), []).append(c)
    dest.mkdir(parents=True)
    lines = [
        "# Objects of an imported dataset, written by `dexcanvas import`: one mesh per object, in",
        "# the object frame of the captures' object poses (metres).",
    ]
    records = {}
    for oid, group in sorted(by_obj.items()):
        keys = {_mesh_key(c) for c in group}
        if len(keys) > 1:
            raise ValidationError(
                f"object {oid!r}: its captures carry {len(keys)} different meshes; one object "
                "id must have one mesh (rename the object in the captures that differ)"
            )
        cap = group[0]
        mesh_file = dest / f"{oid}.obj"
        tm = trimesh.Trimesh(cap.mesh_vertices, cap.mesh_faces, process=False)
        mesh_file.write_text(trimesh.exchange.obj.export_obj(tm, include_normals=False))

        try:
            checked = load_object_mesh(mesh_file)
        except ValidationError as e:
            raise ValidationError(
                f"object {oid!r} of capture {cap.name!r} ({cap.source}): {e}"
            ) from e
        mass, mass_from = _mass(oid, group, user, cfg.density, checked.volume_m3)
        mass = check_mass(mass, f"object {oid!r}", checked.volume_m3)
        entry = [f"[{_toml_key(oid)}]", f'mesh = "{mesh_file.name}"', f"mass_kg = {mass!r}"]
        u = user.get(oid.lower())
        if u is not None and u.friction is not None:
            entry.append(f"friction = {u.friction!r}")
        if u is not None and u.inertia_diag is not None:
            entry.append(f"inertia_diag = {list(u.inertia_diag)!r}")
        lines += ["", f"# mass: {mass_from}", *entry]
        records[oid] = {
            "mesh": mesh_file.name,
            "mass_kg": mass,
            "mass_from": mass_from,
            "captures": len(group),
            "extent_m": [round(float(v), 4) for v in checked.extent_m],
        }
    (dest / MANIFEST_NAME).write_text("\n".join(lines) + "\n")
    return records


def _toml_key(s: str) -> str:
    return s if all(ch.isalnum() or ch in "_-" for ch in s) else f'"{s}"'


def run_import(cfg: ImportConfig, progress: Callable[[int, int], None] | None = None):
    """Import (module docstring) and return an :class:`ImportResult`.

    Raises:
        ValidationError: a bad capture, mesh or mass (nothing is written).
        dexcanvas_core.safe_io.OutputError: the output (or its objects folder) exists and
            ``overwrite`` is not set, or cannot be written.
    """
    out = Path(cfg.out).expanduser()
    objects_dir = out.with_name(out.name + OBJECTS_SUFFIX)
    check_output(out, overwrite=cfg.overwrite, kind="dir")
    check_output(objects_dir, overwrite=cfg.overwrite, kind="dir", what="objects folder")
    if cfg.fps is not None and not (1.0 <= cfg.fps <= 2000.0):
        raise ValidationError(f"--fps must be in [1, 2000] Hz, got {cfg.fps:g}", field="fps")
    if cfg.density is not None and not (5.0 <= cfg.density <= 25_000.0):
        raise ValidationError(
            f"--density must be a solid's density in [5, 25000] kg/m³, got {cfg.density:g}",
            field="density",
        )
    caps = read_captures(cfg)
    out.parent.mkdir(parents=True, exist_ok=True)
    tag = uuidlib.uuid4().hex[:8]
    tmp_objects = objects_dir.with_name(f".{objects_dir.name}.tmp-{tag}")
    try:
        records = _write_objects(caps, cfg, tmp_objects)
        # The meshes are used from their final place; check them there via the temp copy now.
        use_objects(tmp_objects / MANIFEST_NAME)
        trajs, reports = [], []
        for i, c in enumerate(caps):
            try:
                traj, rep = capture_to_trajectory(
                    c, object_id=_object_id(c.object_name), fps=cfg.fps
                )
            except (ValidationError, UnknownNameError) as e:
                raise ValidationError(f"capture {c.name!r} ({c.source}): {e}") from e
            trajs.append(traj)
            reports.append(rep)
            if progress is not None:
                progress(i + 1, len(caps))
        write_dataset(trajs, out, mode="overwrite" if cfg.overwrite else "create")
        if objects_dir.exists():
            shutil.rmtree(objects_dir)
        os.replace(tmp_objects, objects_dir)
    finally:
        if tmp_objects.exists():
            shutil.rmtree(tmp_objects, ignore_errors=True)
    manifest = objects_dir / MANIFEST_NAME
    use_objects(manifest)
    return ImportResult(out=out, manifest=manifest, sequences=reports, objects=records)


def use_dataset_objects(dataset: str | os.PathLike | None) -> Path | None:
    """Put an imported dataset's objects manifest in use (after any ``--objects`` given),
    if it has one; return its path."""
    if dataset is None:
        return None
    m = dataset_objects_manifest(dataset)
    if m is None:
        return None

    add_objects_manifest(m)
    return m


def format_names() -> Sequence[str]:
    return tuple(READERS)
