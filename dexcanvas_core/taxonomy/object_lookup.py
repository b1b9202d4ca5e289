"""Looking objects up by name: the catalogue's (``object_spec``, any spelling) and those given as
meshes by an objects manifest or an objects directory (``use_objects``, ``--objects``,
``--objects-dir``), which take precedence; a catalogue id given a model keeps its table mass.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

from dexcanvas_core.errors import UnknownNameError, ValidationError
from dexcanvas_core.objects.manifest import (
    MANIFEST_ENV,
    OBJECTS_DIR_ENV,
    check_mass,
    objects_dir_meshes,
    read_manifest,
)
from dexcanvas_core.objects.mesh import load_object_mesh
from dexcanvas_core.taxonomy._lookup import build_index, lookup
from dexcanvas_core.taxonomy.objects import OBJECTS, ObjectSpec

_BY_SPELLING = build_index(((s, (s.id, *s.aliases)) for s in OBJECTS.values()), "object")


def object_spec(object_id: str | ObjectSpec) -> ObjectSpec:
    """Look an object up by id or alias, ignoring case and separators.

    ``"cube2"``, ``"Cube 2"``, ``"cube2H"``, ``"cube2h"`` (heavy duplicate),
    ``"mayonnaise_bottle"``, ``"scissors"`` and ``"011_banana"`` all resolve. An
    :class:`ObjectSpec` is returned as is.

    Raises:
        UnknownNameError: unknown object; the message suggests close matches.
        ValidationError: ``object_id`` is not a string.

    >>> from dexcanvas_core import object_spec
    >>> spec = object_spec("Cube 2")
    >>> spec.id, spec.size_m, spec.mass_kg
    ('cube2', (0.05,), 0.037)
    >>> object_spec("cube2h").mass_kg  # the heavy duplicate
    0.123
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


def catalogue_spec(name: str) -> ObjectSpec | None:
    """The catalogue's object of any spelling of ``name`` (manifests aside), or None."""
    return lookup(_BY_SPELLING, name)


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
                size_m=tuple(float(v) for v in mesh.extent_m) if spec.shape == "mesh"
                else spec.size_m,
                mesh=mesh.source,
                data_source=f"shape: model {f} (objects directory); {spec.data_source}",
            )  # fmt: skip
    for one in (manifest or "").split(os.pathsep):
        if not one:
            continue
        for e in read_manifest(one):
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


def add_objects_manifest(manifest: str | os.PathLike) -> dict[str, ObjectSpec]:
    """Use one more objects manifest, after those in use (its entries win over theirs), e.g.
    the one written with an imported dataset; a manifest already in use is not added twice.

    Raises:
        ValidationError: a bad manifest entry (nothing changes then).
    """
    path = str(Path(manifest).expanduser().resolve())
    current = [m for m in (os.environ.get(MANIFEST_ENV) or "").split(os.pathsep) if m]
    if path in current:
        return custom_objects()
    previous = os.environ.get(MANIFEST_ENV)
    os.environ[MANIFEST_ENV] = os.pathsep.join([*current, path])
    try:
        return custom_objects()
    except Exception:
        if previous is None:
            os.environ.pop(MANIFEST_ENV, None)
        else:
            os.environ[MANIFEST_ENV] = previous
        raise


def clear_objects() -> None:
    """Forget the manifest and objects directory (back to the built-in catalogue)."""
    os.environ.pop(MANIFEST_ENV, None)
    os.environ.pop(OBJECTS_DIR_ENV, None)


def heavy_variant(object_id: str | ObjectSpec) -> ObjectSpec | None:
    """The weighted ``H`` duplicate of a light object, or ``None`` if it has none."""
    base = object_spec(object_id)
    heavy = next((s for s in OBJECTS.values() if s.base_id == base.id), None)
    return None if heavy is None else object_spec(heavy.id)
