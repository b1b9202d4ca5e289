"""One captured sequence as arrays: the ``mano-npz`` keys, checked, and the :class:`Capture` they
become (right hand, world frame with z up, metres, MANO's flat-hand pose convention).

The ``mano-npz`` format (one sequence per ``.npz`` file, SI units) is also the in-memory form every
other format's reader produces (``dexcanvas_core.capture.formats``), so one set of checks guards
every import. Keys (``T`` frames):

* ``fps`` () [Hz].
* ``global_orient`` (T, 3): wrist orientation, axis-angle [rad], in the file's world frame.
* ``hand_pose`` (T, 45): finger joints, axis-angle [rad] relative to the parent joint, MANO joint
  order (index1–3, middle1–3, pinky1–3, ring1–3, thumb1–3).
* ``flat_hand_mean`` () bool, default true: a zero ``hand_pose`` is the flat hand; false: MANO's
  mean pose is added to it (as in ``smplx(flat_hand_mean=False)``).
* ``wrist_pos`` (T, 3): the wrist joint J0 in the world [m]; or instead ``transl`` (T, 3), MANO's
  translation (wrist = J0(betas) + transl).
* ``betas`` (10,), optional: MANO shape.
* ``keypoints`` (T, 21, 3), optional, OpenPose/MediaPipe order (wrist, then thumb, index, middle,
  ring, pinky, base to tip) [m]: the subject's bone lengths are measured from them. A sequence
  with keypoints and no ``global_orient``/``hand_pose`` gets a pose fitted to its keypoints
  (``dexcanvas_core.capture.fit``).
* ``object_name`` (): the object's id (a catalogue id or any name; letters, digits, ``_.-``).
* ``object_pos`` (T, 3) [m] and ``object_quat_wxyz`` (T, 4): the object frame in the world.
* ``object_mesh`` (): the object's mesh in that frame, a path relative to the file (OBJ, STL,
  PLY, GLB, metres); or inline ``object_vertices`` (V, 3) [m] + ``object_faces`` (F, 3).
* ``object_mass_kg`` (), optional (else the objects manifest, the catalogue, or the YCB table).
* ``up_axis`` (), optional: ``'z'`` (default) or ``'y'`` (also ``'-y'``, ``'x'``, … or a unit
  3-vector): the world direction against gravity.
* ``table_height`` (), optional: the table top's height along the up axis [m]; absent: no table.
* ``contact_window`` (2,), optional: first and last frame of the interaction.
* ``manipulation_type`` (), optional: a DexCanvas manipulation type name (default ``unknown``).
* ``hand_side`` (), optional: ``'right'`` (default) or ``'left'`` (imported only with
  ``mirror_left``: the whole scene is mirrored across the world's x = 0 plane).

Readers of other formats also set ``source`` (where the sequence came from). Other keys are
ignored (and listed in the import report).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dexcanvas_core.capture.capture import Capture
from dexcanvas_core.capture.fit import fit_pose_to_keypoints
from dexcanvas_core.capture.world import mirror_capture, to_z_up, up_vector
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import convert_keypoints
from dexcanvas_core.mano import ManoLayer
from dexcanvas_core.mano.pose import MANO_HANDS_MEAN_RIGHT, mirror_axis_angle

KEYS: tuple[str, ...] = (
    "fps", "global_orient", "hand_pose", "flat_hand_mean", "wrist_pos", "transl", "betas",
    "keypoints", "object_name", "object_pos", "object_quat_wxyz", "object_mesh",
    "object_vertices", "object_faces", "object_mass_kg", "up_axis", "table_height",
    "contact_window", "manipulation_type", "hand_side", "source",
)  # fmt: skip
"""Every key a sequence may carry (module docstring)."""

REQUIRED: tuple[str, ...] = (
    "fps", "global_orient", "hand_pose", "object_name", "object_pos", "object_quat_wxyz",
)  # fmt: skip

MAX_POSITION_M = 20.0
"""Positions beyond this distance from the origin [m] are taken for another unit (mm, cm)."""

_NAME = re.compile(r"[A-Za-z0-9_.\-]+")


# -- reading the keys -------------------------------------------------------------------------


def _scalar(arrays: Mapping[str, Any], key: str, where: str) -> Any:
    v = arrays[key]
    a = np.asarray(v)
    if a.shape not in ((), (1,)):
        raise ValidationError(f"{where}: {key} must be a scalar, got shape {a.shape}", field=key)
    return a.reshape(()).item()


def _string(arrays: Mapping[str, Any], key: str, where: str) -> str:
    v = _scalar(arrays, key, where)
    if isinstance(v, bytes):
        v = v.decode()
    if not isinstance(v, str) or not v.strip():
        raise ValidationError(f"{where}: {key} must be a non-empty string, got {v!r}", field=key)
    return v.strip()


def _array(
    arrays: Mapping[str, Any], key: str, shape: tuple[int | None, ...], where: str
) -> np.ndarray:
    """``arrays[key]`` as float64 with ``shape`` (``None``: any length), finite."""
    try:
        a = np.asarray(arrays[key], dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValidationError(f"{where}: {key} is not numeric ({e})", field=key) from e
    ok = a.ndim == len(shape) and all(
        s is None or s == n for s, n in zip(shape, a.shape, strict=False)
    )
    if not ok:
        want = "(" + ", ".join("T" if s is None else str(s) for s in shape) + ")"
        raise ValidationError(f"{where}: {key} must have shape {want}, got {a.shape}", field=key)
    bad = ~np.isfinite(a)
    if bad.any():
        rows = np.unique(np.nonzero(bad)[0]) if a.ndim else np.array([0])
        first = ", ".join(str(r) for r in rows[:5])
        raise ValidationError(
            f"{where}: {key} has NaN or inf ({int(bad.sum())} values; first rows {first}); "
            "fill or cut those frames before importing",
            field=key,
        )
    return a


def _bool(arrays: Mapping[str, Any], key: str, default: bool, where: str) -> bool:
    if key not in arrays:
        return default
    v = _scalar(arrays, key, where)
    if isinstance(v, bool | np.bool_) or v in (0, 1):
        return bool(v)
    raise ValidationError(f"{where}: {key} must be true or false, got {v!r}", field=key)


def _mesh(arrays: Mapping[str, Any], base_dir: Path | None, where: str):
    """(vertices (V, 3), faces (F, 3), file or None) of the object's mesh."""
    has_inline = "object_vertices" in arrays or "object_faces" in arrays
    if "object_mesh" in arrays and has_inline:
        raise ValidationError(
            f"{where}: give the object's mesh once: object_mesh (a file) or object_vertices + "
            "object_faces, not both",
            field="object_mesh",
        )
    if "object_mesh" in arrays:
        import trimesh

        rel = Path(_string(arrays, "object_mesh", where)).expanduser()
        path = rel if rel.is_absolute() or base_dir is None else base_dir / rel
        if not path.is_file():
            raise ValidationError(
                f"{where}: object_mesh {str(rel)!r}: no such file (looked at {path}); the path "
                "is relative to the capture file",
                field="object_mesh",
            )
        try:
            mesh = trimesh.load(str(path), force="mesh", process=False)
        except Exception as e:  # trimesh raises many types for unreadable files
            raise ValidationError(
                f"{where}: object_mesh {path} cannot be read as a mesh ({e})", field="object_mesh"
            ) from e
        return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64), path
    if not has_inline:
        raise ValidationError(
            f"{where}: the object's mesh is missing: give object_mesh (a file path relative to "
            "the capture) or object_vertices (V, 3) + object_faces (F, 3)",
            field="object_mesh",
        )
    for key in ("object_vertices", "object_faces"):
        if key not in arrays:
            raise ValidationError(
                f"{where}: {key} is missing (inline meshes need object_vertices and object_faces)",
                field=key,
            )
    v = _array(arrays, "object_vertices", (None, 3), where)
    f = np.asarray(arrays["object_faces"])
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise ValidationError(
            f"{where}: object_faces must be integer (F, 3), got {f.dtype} {f.shape}",
            field="object_faces",
        )
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValidationError(
            f"{where}: object_faces index vertices 0..{len(v) - 1}, found {f.min()}..{f.max()}",
            field="object_faces",
        )
    return v, f.astype(np.int64), None


def _check_units(name: str, a: np.ndarray, where: str) -> None:
    far = float(np.abs(a).max()) if a.size else 0.0
    if far > MAX_POSITION_M:
        raise ValidationError(
            f"{where}: {name} reaches {far:.4g} from the origin: positions must be metres (a "
            "capture in millimetres: divide by 1000)",
            field=name,
        )


def capture_from_arrays(
    arrays: Mapping[str, Any],
    *,
    name: str,
    where: str | None = None,
    base_dir: Path | None = None,
    mirror_left: bool = False,
    up: Any = None,
) -> Capture:
    """Check a sequence given as ``mano-npz`` keys and normalise it (module docstring).

    Args:
        arrays: the keys (an ``np.load`` result or a reader's dict).
        name: the sequence's name.
        where: how messages name the sequence (default ``name``).
        base_dir: directory ``object_mesh`` paths are relative to.
        mirror_left: import a left hand by mirroring the scene across the world's x = 0 plane.
        up: override of the file's ``up_axis`` (an axis name or a 3-vector).

    Raises:
        ValidationError: a missing key, a wrong shape, NaN, a unit off by 1000, a left hand
            without ``mirror_left``, a missing mesh, an up axis that stands the table on its
            side; the message names the key and the fix.
    """
    where = where or name
    fitted = None
    if "global_orient" not in arrays and "hand_pose" not in arrays and "keypoints" in arrays:
        arrays, fitted = _pose_from_keypoints(arrays, where)
    missing = [k for k in REQUIRED if k not in arrays]
    if missing:
        hint = (
            "; or give only keypoints and the pose is fitted to them"
            if {"global_orient", "hand_pose"} & set(missing)
            else ""
        )
        raise ValidationError(
            f"{where}: missing key(s) {', '.join(missing)} (the mano-npz keys are documented in "
            f"the README and dexcanvas_core.capture.arrays){hint}",
            field=missing[0],
        )
    fps = _scalar(arrays, "fps", where)
    if isinstance(fps, bool) or not isinstance(fps, int | float) or not 1.0 <= fps <= 2000.0:
        raise ValidationError(f"{where}: fps must be a number in [1, 2000] Hz, got {fps!r}")
    go = _array(arrays, "global_orient", (None, 3), where)
    T = go.shape[0]
    if T < 2:
        raise ValidationError(f"{where}: a sequence needs at least 2 frames, got {T}")
    hp = _array(arrays, "hand_pose", (T, None), where)
    if hp.shape[1] == 48:
        raise ValidationError(
            f"{where}: hand_pose has 48 columns; mano-npz takes the 45 finger values (put the "
            "first 3, the global orientation, in global_orient)",
            field="hand_pose",
        )
    if hp.shape[1] != 45:
        raise ValidationError(
            f"{where}: hand_pose must have shape (T, 45) (15 joints × axis-angle), got "
            f"{hp.shape}; PCA coefficients must be expanded first",
            field="hand_pose",
        )
    for key, a, limit in (("global_orient", go, 2 * math.pi), ("hand_pose", hp, math.pi)):
        norms = np.linalg.norm(a.reshape(T, -1, 3), axis=-1)
        if norms.max() > limit + 1e-3:
            raise ValidationError(
                f"{where}: {key} has rotations of {norms.max():.4g} rad (over {limit:.3g}): "
                "axis-angles must be radians, not degrees",
                field=key,
            )
    flat = _bool(arrays, "flat_hand_mean", True, where)
    if ("wrist_pos" in arrays) == ("transl" in arrays):
        raise ValidationError(
            f"{where}: give exactly one of wrist_pos (world wrist joint) and transl (MANO "
            "translation)",
            field="wrist_pos",
        )
    pos_key = "wrist_pos" if "wrist_pos" in arrays else "transl"
    hand_pos = _array(arrays, pos_key, (T, 3), where)
    _check_units(pos_key, hand_pos, where)
    betas = _array(arrays, "betas", (10,), where) if "betas" in arrays else np.zeros(10)
    keypoints = None
    if "keypoints" in arrays:
        kp = _array(arrays, "keypoints", (T, 21, 3), where)
        _check_units("keypoints", kp, where)
        keypoints = convert_keypoints(kp, "openpose21", "mano21")
        span = np.median(np.linalg.norm(keypoints[:, 18] - keypoints[:, 0], axis=-1))
        if not 0.08 <= span <= 0.35:
            raise ValidationError(
                f"{where}: keypoints put the middle fingertip {span:.4g} m from the wrist (a hand "
                "is 0.12-0.25 m): keypoints must be metres in OpenPose/MediaPipe order",
                field="keypoints",
            )
    obj_name = _string(arrays, "object_name", where)
    if not _NAME.fullmatch(obj_name):
        raise ValidationError(
            f"{where}: object_name {obj_name!r} may hold letters, digits, '_', '.' and '-' only",
            field="object_name",
        )
    opos = _array(arrays, "object_pos", (T, 3), where)
    _check_units("object_pos", opos, where)
    oq = _array(arrays, "object_quat_wxyz", (T, 4), where)
    qn = np.linalg.norm(oq, axis=1)
    if np.abs(qn - 1.0).max() > 1e-2:
        i = int(np.argmax(np.abs(qn - 1.0)))
        raise ValidationError(
            f"{where}: object_quat_wxyz must be unit quaternions (w, x, y, z); frame {i} has norm "
            f"{qn[i]:.4g}",
            field="object_quat_wxyz",
        )
    oq = oq / qn[:, None]
    verts, faces, mesh_file = _mesh(arrays, base_dir, where)
    mass = None
    if "object_mass_kg" in arrays:
        mass = _scalar(arrays, "object_mass_kg", where)
        if isinstance(mass, bool) or not isinstance(mass, int | float) or not 0 < mass < 50:
            raise ValidationError(
                f"{where}: object_mass_kg must be in (0, 50) kg, got {mass!r}",
                field="object_mass_kg",
            )
        mass = float(mass)
    window = None
    if "contact_window" in arrays:
        w = np.asarray(arrays["contact_window"]).reshape(-1)
        if w.shape != (2,) or not np.issubdtype(w.dtype, np.number):
            raise ValidationError(
                f"{where}: contact_window must be (2,) frames (first, last)",
                field="contact_window",
            )
        a, b = int(w[0]), int(w[1])
        if not 0 <= a <= b < T:
            raise ValidationError(
                f"{where}: contact_window ({a}, {b}) must satisfy 0 <= first <= last < {T}",
                field="contact_window",
            )
        window = (a, b)
    mtype = _string(arrays, "manipulation_type", where) if "manipulation_type" in arrays else None
    side = _string(arrays, "hand_side", where).lower() if "hand_side" in arrays else "right"
    if side not in ("right", "left"):
        raise ValidationError(
            f"{where}: hand_side must be 'right' or 'left', got {side!r}", field="hand_side"
        )
    if side == "left" and not mirror_left:
        raise ValidationError(
            f"{where}: a left hand; this toolkit retargets right hands: pass --mirror-left "
            "(mirror_left=True) to mirror the whole scene (hand, object, mesh) across x = 0",
            field="hand_side",
        )
    up_raw = up if up is not None else arrays.get("up_axis", "z")
    up_v = up_vector(up_raw, where)
    table = None
    if "table_height" in arrays:
        table = _scalar(arrays, "table_height", where)
        if (
            isinstance(table, bool)
            or not isinstance(table, int | float)
            or not math.isfinite(table)
        ):
            raise ValidationError(
                f"{where}: table_height must be a number [m], got {table!r}", field="table_height"
            )
        table = float(table)
    source = _string(arrays, "source", where) if "source" in arrays else where
    if not flat:
        mean = (
            MANO_HANDS_MEAN_RIGHT if side == "right" else mirror_axis_angle(MANO_HANDS_MEAN_RIGHT)
        )
        hp = hp + mean
    cap = Capture(
        name=name,
        source=source,
        fps=float(fps),
        global_orient=go,
        hand_pose=hp,
        wrist_pos=hand_pos if pos_key == "wrist_pos" else hand_pos + _rest_wrist(betas, side),
        betas=betas,
        keypoints=keypoints,
        object_name=obj_name,
        object_pos=opos,
        object_quat_wxyz=oq,
        mesh_vertices=verts,
        mesh_faces=faces,
        mesh_file=mesh_file,
        object_mass_kg=mass,
        table_height=table,
        contact_window=window,
        manipulation_type=mtype or "unknown",
        up=up_v,
        ignored_keys=tuple(sorted(str(k) for k in arrays if k not in KEYS)),
        pose_fit_mm=fitted,
    )
    if side == "left":
        cap = mirror_capture(cap)
    return to_z_up(cap, where)


def _pose_from_keypoints(arrays: Mapping[str, Any], where: str) -> tuple[dict, float]:
    """``arrays`` with ``global_orient``, ``hand_pose`` and ``wrist_pos`` fitted to its
    ``keypoints`` (a left hand's are mirrored for the fit and the result mirrored back), and the
    fit's mean keypoint distance [mm]."""
    kp = _array(arrays, "keypoints", (None, 21, 3), where)
    _check_units("keypoints", kp, where)
    if "wrist_pos" in arrays or "transl" in arrays:
        raise ValidationError(
            f"{where}: wrist_pos/transl without global_orient and hand_pose; give the whole "
            "pose, or only keypoints (the pose is then fitted to them)",
            field="global_orient",
        )
    side = _string(arrays, "hand_side", where).lower() if "hand_side" in arrays else "right"
    sign = np.array([-1.0, 1.0, 1.0]) if side == "left" else np.ones(3)
    mano = convert_keypoints(kp, "openpose21", "mano21") * sign
    fit = fit_pose_to_keypoints(mano)
    out = dict(arrays)
    if side == "left":
        out["global_orient"] = mirror_axis_angle(fit["global_orient"])
        out["hand_pose"] = mirror_axis_angle(fit["hand_pose"])
    else:
        out["global_orient"], out["hand_pose"] = fit["global_orient"], fit["hand_pose"]
    out["wrist_pos"] = fit["wrist_pos"] * sign
    out["flat_hand_mean"] = np.bool_(True)
    return out, float(np.mean(fit["residual_mm"]))


def _rest_wrist(betas: np.ndarray, side: str) -> np.ndarray:
    """(3,) MANO's wrist joint J0 [m] at rest for ``betas`` (the exact model when
    ``$MANO_MODEL_DIR`` holds it, else the built-in skeleton's mean J0)."""
    out = ManoLayer(side).forward_numpy(betas=betas[None], hand_pose=np.zeros((1, 45)))
    return out.keypoints[0, 0]
