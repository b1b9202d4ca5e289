"""Reader of TACO clips as released with GeneOH-Diffusion (``data/taco/source_data/<clip>.pkl``
with ``<clip>.obj`` beside it).

TACO (Liu et al., CVPR 2024) is captured with an optical motion-capture system and 12
allocentric cameras; the clips hold one hand and one object. Keys and the conventions found,
with the numbers that show them (clips ``20231104_010`` and ``20231104_017``):

* ``hand_pose (T, 48)``: MANO axis-angle, global orientation first, ``flat_hand_mean=True``
  (fingertips of our skeleton vs the tip vertices of ``hand_verts``: 13.0 mm mean with the flat
  hand, 64.4 mm with MANO's mean pose added).
* ``hand_trans (T, 3)``: the **wrist joint position** (J0), not MANO's translation: TACO poses
  MANO centred on J0 (``manopth`` ``ManoLayer(center_idx=0)``, then ``+ hand_trans``, in
  TACO-Instructions ``hand_pose_loader.py``). Checked: the centroid of the mesh's wrist opening
  (its 16 boundary vertices) stays fixed relative to ``hand_trans`` in the hand frame (std
  0.05 mm over a clip); tips 13 mm off with wrist = ``hand_trans`` vs 97 mm with
  wrist = J0 + ``hand_trans``. Given as ``wrist_pos``.
* ``hand_shape (10,)``: MANO betas. ``hand_verts (T, 778, 3)``, ``hand_faces``: the posed MANO
  mesh (used to tell the side).
* Side: the released clips are **left** hands (tips 13 mm off with the left skeleton, 206 mm with
  the right); ``side="auto"`` decides from ``hand_verts`` the same way.
* ``obj_pose (T, 4, 4)``: object-to-world transforms; ``obj_verts (T, 1000, 3)`` = ``obj_pose``
  applied to the vertices of ``<clip>.obj`` (max difference 1e-4 mm), ``obj_faces`` = its
  triangles. The ``.obj`` is therefore the mesh in the object frame; without it, the mesh is
  recovered from frame 0 (``obj_pose[0]⁻¹ · obj_verts[0]``).
* World frame: the mocap frame, metres, **+z up**: the object rests at z = 0.551 / 0.549 m at the
  first frame and is put back within 0.4 mm of it at the last; the hand never goes lower than
  6 mm below that; estimated from the object's lift, up is 1.0° / 2.8° from +z.
* Frame rate: 30 fps (TACO's videos are decoded at 30 fps, TACO-Instructions README).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from dexcanvas_core.capture.formats._common import UpInput, array, parse_up, read_mesh, ups_for
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.mano.layer import MANO_TIP_VERTEX_IDS, ManoLayer
from dexcanvas_core.rotations import matrix_to_quat_wxyz
from dexcanvas_core.safe_pickle import load_pickle

logger = logging.getLogger(__name__)

FORMAT = "taco"

TACO_FPS = 30.0
"""TACO's frame rate [Hz]."""

MESH_MATCH_TOLERANCE_M = 0.001
"""Largest difference [m] between ``obj_verts`` and ``obj_pose`` applied to the ``.obj`` file."""

SIDE_MAX_TIP_ERROR_M = 0.04
"""Largest mean fingertip error [m] of the side chosen by ``side="auto"`` (built-in skeleton vs
``hand_verts``; 13 mm on the released clips, the other side 206 mm)."""


def _files(path: Path) -> list[Path]:
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise ValidationError(f"{path}: no such file or folder", field="path")
    found = sorted(path.rglob("*.pkl"))
    if not found:
        raise ValidationError(f"{path}: no TACO clip (*.pkl) found below it", field="path")
    return found


def tip_error(side: str, pose48: np.ndarray, wrist: np.ndarray, verts: np.ndarray) -> float:
    """Mean distance [m] between the skeleton's fingertips (pose ``pose48``, wrist at ``wrist``)
    and the fingertip vertices of the MANO mesh ``verts`` (every 4th frame)."""
    k = slice(None, None, 4)
    layer = ManoLayer(side=side, flat_hand_mean=True)  # type: ignore[arg-type]
    out = layer.forward_numpy(hand_pose=pose48[k])
    tips = out.keypoints[:, 16:] - out.joints[:, :1] + wrist[k, None]
    ref = verts[k][:, [MANO_TIP_VERTEX_IDS[f] for f in FINGERS]]
    return float(np.linalg.norm(tips - ref, axis=-1).mean())


def _side(
    side: str, data: dict[str, Any], pose48: np.ndarray, wrist: np.ndarray, where: str
) -> str:
    if side in ("right", "left"):
        return side
    if side != "auto":
        raise ValidationError(f"taco: side must be 'auto', 'right' or 'left', got {side!r}")
    if "hand_verts" not in data:
        raise ValidationError(
            f"{where}: no 'hand_verts' to tell the hand side from; pass side='left' or "
            "side='right' (--side)",
            field="side",
        )
    verts = array(data, "hand_verts", (len(pose48), 778, 3), where=where)
    err = {s: tip_error(s, pose48, wrist, verts) for s in ("left", "right")}
    best = min(err, key=err.__getitem__)
    other = "right" if best == "left" else "left"
    if err[best] > SIDE_MAX_TIP_ERROR_M or err[best] > 0.5 * err[other]:
        raise ValidationError(
            f"{where}: cannot tell the hand side: fingertips of hand_pose miss hand_verts by "
            f"{err['left'] * 1000:.0f} mm (left) and {err['right'] * 1000:.0f} mm (right); "
            "pass side= (--side)",
            field="side",
        )
    logger.info(
        "%s: %s hand (fingertips %.1f mm vs %.1f mm for the %s)",
        where,
        best,
        err[best] * 1000,
        err[other] * 1000,
        other,
    )
    return best


def _mesh(
    f: Path, data: dict[str, Any], pose: np.ndarray, models_dir: Path | None
) -> tuple[dict[str, Any], np.ndarray]:
    """The object mesh entry (``object_mesh`` path or vertices/faces) and its vertices."""
    where = str(f)
    candidates = [f.with_suffix(".obj")]
    if models_dir is not None:
        candidates.append(Path(models_dir).expanduser() / f"{f.stem}.obj")
    path = next((p for p in candidates if p.is_file()), None)
    R, t = pose[:, :3, :3], pose[:, :3, 3]
    posed = None
    if "obj_verts" in data:
        posed = array(data, "obj_verts", (len(pose), None, 3), where=where)
    if path is not None:
        V, _ = read_mesh(path)
        if posed is not None and len(V) == posed.shape[1]:
            dev = np.abs(np.einsum("tij,vj->tvi", R, V) + t[:, None] - posed).max()
            if dev > MESH_MATCH_TOLERANCE_M:
                raise ValidationError(
                    f"{where}: obj_verts differ from obj_pose applied to {path} by up to "
                    f"{dev * 1000:.1f} mm: the .obj is not this clip's object in its own frame",
                    field="object_mesh",
                )
        return {"object_mesh": str(path)}, V
    if posed is None or "obj_faces" not in data:
        raise ValidationError(
            f"{where}: no object mesh: looked for {', '.join(map(str, candidates))} and the "
            "clip has no obj_verts/obj_faces; put the clip's .obj beside it or pass "
            "models_dir (--models-dir)",
            field="object_mesh",
        )
    faces = np.asarray(data["obj_faces"])
    if faces.ndim == 3:  # some releases store one face array per frame
        faces = faces[0]
    faces = array({"obj_faces": faces}, "obj_faces", (None, 3), where=where).astype(np.int64)
    if faces.min() < 0 or faces.max() >= posed.shape[1]:
        raise ValidationError(f"{where}: obj_faces index outside obj_verts", field="obj_faces")
    V = (posed[0] - t[0]) @ R[0]  # R0ᵀ (x - t0), row-vector form
    logger.info("%s: no .obj beside the clip; object mesh recovered from frame 0", where)
    return {"object_vertices": V, "object_faces": faces}, V


def read_taco(
    path: Path,
    *,
    models_dir: Path | None = None,
    fps: float | None = None,
    side: str = "auto",
    up_axis: Any = "z",
    **opts: Any,
) -> list[dict[str, Any]]:
    """Read TACO clips (GeneOH-Diffusion release) into mano-npz dicts, one per clip.

    Args:
        path: a clip ``.pkl``, or a folder searched recursively for them (sorted by path).
        models_dir: another folder to look for ``<clip>.obj`` in (default: beside the clip).
        fps: frame rate [Hz]; default 30.
        side: ``"auto"`` (from ``hand_verts``), ``"left"`` or ``"right"``.
        up_axis: the up direction: ``"z"`` (TACO's world, default), another axis or 3-vector, or
            ``None`` to estimate it from the object's lift.

    Returns:
        Dicts with ``global_orient``, ``hand_pose`` (axis-angle, ``flat_hand_mean=True``),
        ``wrist_pos`` (= ``hand_trans``), ``betas``, the object track and mesh (``object_mesh``
        or ``object_vertices``/``object_faces``), ``up_axis``, ``table_height``, ``hand_side``
        and ``source`` = ``taco:<file>``.

    Raises:
        ValidationError: a missing key, a wrong shape, NaN, an unknown option, a non-rigid
            ``obj_pose``, no mesh, or an undecidable side.
    """
    if opts:
        raise ValidationError(
            f"taco: unknown option(s) {sorted(opts)}; known: models_dir, fps, side, up_axis",
            field=sorted(opts)[0],
        )
    given_up = parse_up(up_axis)
    out: list[dict[str, Any]] = []
    inputs: list[UpInput] = []
    for f in _files(Path(path)):
        where = str(f)
        data = load_pickle(f, what="TACO clip")
        if not isinstance(data, dict):
            raise ValidationError(f"{where}: holds a {type(data).__name__}, expected a dict")
        pose48 = array(data, "hand_pose", (None, 48), where=where, fix="3 global + 45 fingers")
        T = len(pose48)
        wrist = array(data, "hand_trans", (T, 3), where=where)
        betas = array(data, "hand_shape", (10,), where=where, also=((1, 10),))
        pose = array(data, "obj_pose", (T, 4, 4), where=where)
        R = pose[:, :3, :3]
        err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max()
        if err > 1e-3 or np.any(np.linalg.det(R) < 0):
            raise ValidationError(
                f"{where}: obj_pose is not a rigid transform (R Rᵀ off identity by {err:.2g})",
                field="obj_pose",
            )
        hand_side = _side(side, data, pose48, wrist, where)
        mesh, V = _mesh(f, data, pose, models_dir)
        quat = matrix_to_quat_wxyz(R)
        inputs.append(
            UpInput(where=where, vertices=V, pos=pose[:, :3, 3], quat_wxyz=quat, group=where)
        )
        out.append(
            {
                "fps": float(fps) if fps is not None else TACO_FPS,
                "global_orient": pose48[:, :3].copy(),
                "hand_pose": pose48[:, 3:].copy(),
                "flat_hand_mean": True,
                "wrist_pos": wrist,
                "betas": betas,
                "object_name": f.stem,
                "object_pos": pose[:, :3, 3].copy(),
                "object_quat_wxyz": quat,
                **mesh,
                "hand_side": hand_side,
                "source": f"{FORMAT}:{f}",
            }
        )
    for d, (u, table, note) in zip(out, ups_for(inputs, up=given_up, shared=False), strict=True):
        d["up_axis"] = np.asarray(u, dtype=np.float64).copy() if given_up is None else _axis(u)
        d["table_height"] = float(table)
        logger.info("%s: up %s, table %.4f m (%s)", d["source"], d["up_axis"], table, note)
    return out


def _axis(u: np.ndarray) -> Any:
    """``"z"``/``"y"`` for the axes the mano-npz names, else the unit vector."""
    for name, i in (("z", 2), ("y", 1)):
        e = np.zeros(3)
        e[i] = 1.0
        if np.allclose(u, e):
            return name
    return np.asarray(u, dtype=np.float64).copy()
