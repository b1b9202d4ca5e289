"""Helpers shared by the dataset readers: checked array access, object mesh lookup, MANO's PCA
basis, frame runs, the up direction of a group of sequences."""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dexcanvas_core.capture.up import UpEstimate, consensus_up, estimate_up
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.mano.model_file import (
    MANO_MODEL_DIR_ENV,
    MANO_MODEL_FILES,
    read_model_pickle,
    resolve_model_file,
)
from dexcanvas_core.rotations import quat_wxyz_to_matrix

logger = logging.getLogger(__name__)

MESH_NAMES: tuple[str, ...] = ("textured_simple.obj", "textured_meshlab.obj", "textured.obj")
"""File names looked up in ``<models_dir>/<object name>/`` (the YCB releases' names), in order;
then ``<models_dir>/<object name>.obj`` and ``<models_dir>/models/<object name>/…``."""

TABLE_SHARED_TOLERANCE_M = 0.01
"""A sequence whose object rests more than this [m] off its group's table plane at the rest frame
is taken to start on something else (another object): it gets the group's table height."""


def shape_str(shape: Sequence[int | None]) -> str:
    return "(" + ", ".join("T" if s is None else str(s) for s in shape) + ")"


def array(
    data: Mapping[str, Any],
    key: str,
    shape: tuple[int | None, ...],
    *,
    where: str,
    fix: str = "",
    also: tuple[tuple[int, ...], ...] = (),
) -> np.ndarray:
    """``data[key]`` as a finite float64 array of ``shape`` (``None``: any length); an array of
    one of the shapes ``also`` (same size, e.g. ``(3, 1)`` for ``(3,)``) is reshaped to it.

    Raises:
        ValidationError: the key is missing, not numeric, of another shape, or not finite; the
            message names ``where`` (the file), the key and ``fix``.
    """
    hint = f"; {fix}" if fix else ""
    if key not in data or data[key] is None:
        have = ", ".join(sorted(map(str, data))) if isinstance(data, Mapping) else "?"
        raise ValidationError(f"{where}: no key {key!r} (keys: {have}){hint}", field=key)
    try:
        a = np.asarray(data[key], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValidationError(
            f"{where}: key {key!r} is not numeric ({exc}){hint}", field=key
        ) from exc
    if a.shape in also:
        a = a.reshape(shape)
    if a.ndim != len(shape) or any(
        s is not None and s != n for s, n in zip(shape, a.shape, strict=True)
    ):
        want = " or ".join(shape_str(x) for x in (shape, *also))
        raise ValidationError(
            f"{where}: key {key!r} has shape {a.shape}, expected {want}{hint}", field=key
        )
    if not np.isfinite(a).all():
        bad = np.argwhere(~np.isfinite(a))[0].tolist()
        raise ValidationError(
            f"{where}: key {key!r} has NaN or inf (first at index {bad}){hint}", field=key
        )
    return a


def text(data: Mapping[str, Any], key: str, *, where: str, fix: str = "") -> str:
    """``data[key]`` as a non-empty string."""
    value = data.get(key)
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if not isinstance(value, str) or not value:
        hint = f"; {fix}" if fix else ""
        raise ValidationError(
            f"{where}: key {key!r} must be a non-empty string, got {value!r}{hint}", field=key
        )
    return value


def find_object_mesh(models_dir: Path | None, name: str, *, where: str, option: str) -> Path:
    """The mesh file of object ``name`` under ``models_dir`` (see ``MESH_NAMES``).

    Raises:
        ValidationError: no ``models_dir`` given, or no file found; the message lists the
            places looked at and names ``option``.
    """
    if models_dir is None:
        raise ValidationError(
            f"{where}: the object {name!r} needs its mesh: pass the folder of object models "
            f"({option}), holding {name}/{MESH_NAMES[0]} or {name}.obj",
            field="object_mesh",
        )
    root = Path(models_dir).expanduser()
    tried = [root / name / n for n in MESH_NAMES]
    tried.append(root / f"{name}.obj")
    tried += [root / "models" / name / n for n in MESH_NAMES]
    for p in tried:
        if p.is_file():
            return p
    listed = ", ".join(str(p) for p in tried[: len(MESH_NAMES) + 1])
    raise ValidationError(
        f"{where}: no mesh for object {name!r}: looked for {listed} (and under {root / 'models'}); "
        f"pass the folder that holds the object models ({option})",
        field="object_mesh",
    )


def read_mesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(V, 3)`` [file units] and triangles ``(F, 3)`` of a mesh file, vertices merged
    by position (textured files split them along UV seams).

    Raises:
        ValidationError: unreadable file or no triangles.
    """
    import trimesh

    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for a bad file
        raise ValidationError(f"object mesh {path}: cannot be read ({exc})") from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ValidationError(f"object mesh {path}: holds no triangles", field="object_mesh")
    mesh = trimesh.Trimesh(loaded.vertices, loaded.faces, process=True)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def load_mano_pca(side: str, mano_dir: Path | None, *, where: str) -> tuple[np.ndarray, np.ndarray]:
    """MANO's PCA basis of the finger pose for ``side``: ``hands_components (45, 45)`` (rows are
    components) and ``hands_mean (45,)`` [rad], read from the official model file.

    A pose in PCA space ``c (45,)`` (all components) is the axis-angle pose
    ``hands_mean + c @ hands_components`` (``manopth``'s ``use_pca=True``,
    ``flat_hand_mean=False``).

    Raises:
        ValidationError: no model folder (neither ``mano_dir`` nor ``$MANO_MODEL_DIR``), no file,
            or a file without the two keys in these shapes.
    """
    name = MANO_MODEL_FILES[side]
    need = (
        f"{where}: the hand pose is stored as MANO PCA coefficients; expanding them needs "
        f"hands_components and hands_mean from the official {name}: pass the folder that "
        f"holds it (mano_dir / --mano-dir) or set ${MANO_MODEL_DIR_ENV} "
        "(download from https://mano.is.tue.mpg.de)"
    )
    try:
        path = resolve_model_file(side, mano_dir)  # type: ignore[arg-type]
    except Exception as exc:
        raise ValidationError(f"{need}: {exc}", field="mano_dir") from exc
    if path is None:
        raise ValidationError(need, field="mano_dir")
    data = read_model_pickle(path)
    comps = array(data, "hands_components", (None, 45), where=str(path))
    mean = array(data, "hands_mean", (45,), where=str(path))
    if comps.shape[0] < 45:
        raise ValidationError(
            f"{path}: hands_components has {comps.shape[0]} components, 45 are needed",
            field="hands_components",
        )
    return comps[:45], mean


def valid_runs(valid: np.ndarray, min_frames: int = 2) -> list[tuple[int, int]]:
    """``[start, stop)`` of each run of consecutive ``True`` of at least ``min_frames``."""
    v = np.concatenate([[False], np.asarray(valid, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(v.astype(np.int8)))
    runs = list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))
    return [(a, b) for a, b in runs if b - a >= min_frames]


def parse_up(up: Any) -> np.ndarray | None:
    """A given up direction: ``None``, an axis name (``"x"``, ``"-y"``, …) or a 3-vector."""
    if up is None:
        return None
    if isinstance(up, str):
        name = up.strip().lower()
        sign = -1.0 if name.startswith("-") else 1.0
        axis = name.lstrip("+-")
        if axis not in ("x", "y", "z"):
            raise ValidationError(
                f"up_axis must be x, y, z (optionally signed) or a 3-vector, got {up!r}",
                field="up_axis",
            )
        v = np.zeros(3)
        v["xyz".index(axis)] = sign
        return v
    v = np.asarray(up, dtype=np.float64)
    if v.shape != (3,) or not np.isfinite(v).all() or np.linalg.norm(v) < 1e-9:
        raise ValidationError(f"up_axis must be a non-zero 3-vector, got {up!r}", field="up_axis")
    return v / np.linalg.norm(v)


def rest_height(s: UpInput, up: np.ndarray) -> float:
    """Height [m] along ``up`` of the object's lowest vertex at frame 0 of ``s``."""
    R0 = quat_wxyz_to_matrix(s.quat_wxyz[0])
    return float(((s.vertices @ R0.T + s.pos[0]) @ up).min())


@dataclass
class UpInput:
    """What the up estimate of one sequence needs (object in its frame, track, where)."""

    where: str
    vertices: np.ndarray
    pos: np.ndarray
    quat_wxyz: np.ndarray
    group: str


def ups_for(
    inputs: list[UpInput], *, up: np.ndarray | None, shared: bool
) -> list[tuple[np.ndarray, float, str]]:
    """``(up, table_height, note)`` of each sequence.

    With ``up`` given, each table height is taken along it. Otherwise each sequence gets its own
    :func:`estimate_up`; with ``shared``, the sequences of one ``group`` (one camera frame) get
    their :func:`consensus_up` and the median table height along it (a sequence whose object
    starts more than ``TABLE_SHARED_TOLERANCE_M`` off that plane, e.g. on another object, keeps
    the group's table). A group without a consensus falls back to per-sequence estimates.

    Raises:
        ValidationError: a sequence has no estimate (its object never moves) and no consensus
            covers it.
    """
    if up is not None:
        out = []
        for s in inputs:
            e = estimate_up(s.vertices, s.pos, s.quat_wxyz, up=up, where=s.where)
            out.append((e.up, e.table_height, e.reason))
        return out

    estimates: list[UpEstimate | None] = []
    errors: list[ValidationError | None] = []
    for s in inputs:
        try:
            estimates.append(estimate_up(s.vertices, s.pos, s.quat_wxyz, where=s.where))
            errors.append(None)
        except ValidationError as exc:
            estimates.append(None)
            errors.append(exc)

    result: list[tuple[np.ndarray, float, str] | None] = [None] * len(inputs)
    if shared:
        groups: dict[str, list[int]] = {}
        for i, s in enumerate(inputs):
            groups.setdefault(s.group, []).append(i)
        for group, idx in groups.items():
            if len(idx) < 2:
                continue
            try:
                cons = consensus_up(
                    [None if estimates[i] is None else estimates[i].up for i in idx],  # type: ignore[union-attr]
                    where=group,
                )
            except ValidationError as exc:
                logger.warning("%s; using per-sequence estimates", exc)
                continue
            heights = np.array([rest_height(inputs[i], cons.up) for i in idx])
            table = float(np.median(heights))
            logger.info(
                "%s: shared up %s from %d of %d sequences; table height %.4f m",
                group,
                np.round(cons.up, 4).tolist(),
                int(cons.supporters.sum()),
                len(idx),
                table,
            )
            for k, i in enumerate(idx):
                own = heights[k]
                off = abs(own - table) > TABLE_SHARED_TOLERANCE_M
                note = (
                    f"up shared by {int(cons.supporters.sum())} of {len(idx)} sequences of "
                    f"{group} (this one's own estimate "
                    + ("failed" if estimates[i] is None else f"{cons.angles_deg[k]:.1f}° off")
                    + ")"
                )
                if off:
                    note += (
                        f"; the object starts {(own - table) * 1000:+.0f} mm off the table plane "
                        "(on another object?): table height of the group used"
                    )
                result[i] = (cons.up, table, note)

    out: list[tuple[np.ndarray, float, str]] = []
    for i, s in enumerate(inputs):
        r = result[i]
        if r is None:
            e = estimates[i]
            if e is None:
                assert errors[i] is not None
                raise errors[i]  # type: ignore[misc]
            if e.confidence < 0.7:
                logger.warning("%s: doubtful up estimate: %s", s.where, e.reason)
            r = (e.up, e.table_height, e.reason)
        out.append(r)
    return out
