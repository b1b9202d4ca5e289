"""Reader of HO-3D-style sequences: a folder ``meta/`` of per-frame pickles ``0000.pkl, …``.

Two producers write this layout; ``layout="auto"`` tells them apart by the keys (the DexYCB
exporter adds ``order``, ``side`` and ``frame``):

**HO-3D** (v2, v3; ``train/<SEQ>/meta/NNNN.pkl``; Hampali et al., CVPR 2020). Right hands. Keys
``handPose (48,)`` — the full MANO axis-angle pose, global orientation first — with
``flat_hand_mean=True``; ``handTrans (3,)`` the MANO translation (wrist = J0(β) + handTrans);
``handBeta (10,)``; ``objRot`` (a rotation vector, ``(3,)`` or ``(3, 1)``); ``objTrans (3,)``;
``objName`` (a YCB name); ``handJoints3D (21, 3)`` in MANO21 order (16 MANO joints, then the
thumb, index, middle, ring, pinky tips at mesh vertices 744, 333, 444, 555, 672). Frames
without an annotation hold ``None``. Camera frame, OpenGL axes, metres. Source: the dataset's
reference code (``shreyashampali/ho3d``: ``vis_HO3D.py`` poses MANO with
``load_model(flat_hand_mean=True)``, ``fullpose = handPose``, ``trans = handTrans``;
``setup_mano.py`` appends those five tip vertices to the joints). HO-3D documents no frame
rate: 30 fps is assumed; pass ``fps`` when known.

**DexYCB exported to this layout** (``<side>/<subject>/<sequence>/meta/NNNN.pkl``, written by a
public DexYCB-to-HO-3D exporter from DexYCB's ``pose.npz``). Master-camera frame, OpenCV axes,
metres; 30 fps (DexYCB's capture rate). Conventions found, with the numbers that show them
(``benchmarks/capture_conventions.py`` on the 499 left-hand sequences; hand checks on every 10th
sequence with ``ManoLayer(side="left")``'s built-in skeleton):

* ``handPose[3:]`` holds DexYCB's **45 PCA coefficients**, not axis-angles (the exporter copies
  ``pose_m[:, :48]``, which DexYCB poses with ``manopth`` ``use_pca=True, ncomps=45,
  flat_hand_mean=False``): axis-angle = ``hands_mean + c @ hands_components`` of the official
  MANO model, so these files need ``mano_dir`` (or ``$MANO_MODEL_DIR``). Read as axis-angles,
  the keypoints miss ``handJoints3D`` by 23 mm on average (MCP joints 3.7 mm, fingertips
  48 mm); the coefficients' spread falls from 0.4–0.6 rad (first six) to 0.07–0.17 (last six),
  as PCA coefficients do; a zero pose gives MANO's mean pose (4.8 mm from ``handJoints3D``),
  not the flat hand (30.5 mm). ``handPose[:3]`` is the global orientation (axis-angle).
* ``handTrans`` is MANO's translation: wrist = J0(β) + handTrans, 3.1 mm mean error against
  ``handJoints3D[:, 0]`` (93.5 mm for wrist = handTrans).
* ``handJoints3D`` is in MANO21 order (23 mm mean error of the unexpanded pose vs 65 mm in the
  OpenPose order; the exporter reorders ``manopth``'s OpenPose-like output to HO-3D's order).
* ``objRot`` is **wrong as stored**: the exporter read DexYCB's quaternion ``(x, y, z, w)``
  (scipy order, identity ``[0, 0, 0, 1]``) as ``(w, x, y, z)``; the reader undoes the swap.
  With the swap undone, the up directions estimated per sequence agree with their subject's
  (one camera setup's) consensus within 3.4° (median over 498 sequences) and the objects'
  lowest points at the first frame lie on that table plane within 1.9 mm (median; 14 objects
  start 1–14 cm higher, on other objects); as stored, the estimates scatter by 34° (median).
* Frames before the hand is annotated hold zeros (``handPose``, ``handTrans``): they are dropped
  (the object track of all frames is still used for the up direction).

Each sequence's up direction comes from :func:`dexcanvas_core.capture.up.estimate_up` (the object
rests at the first frame, then is lifted). With ``shared_up`` (default for DexYCB exports), the
sequences of one folder (one DexYCB subject, one camera setup) share a consensus up and table
height, which also covers sequences whose object starts on another object or never moves.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from dexcanvas_core.capture.formats._common import (
    UpInput,
    array,
    find_object_mesh,
    load_mano_pca,
    parse_up,
    read_mesh,
    text,
    ups_for,
    valid_runs,
)
from dexcanvas_core.capture.formats.dexycb import DEXYCB_FPS
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import convert_keypoints
from dexcanvas_core.rotations import aa_to_quat_wxyz
from dexcanvas_core.safe_pickle import load_pickle

logger = logging.getLogger(__name__)

FORMAT = "ho3d"

HO3D_FPS = 30.0
"""Frame rate assumed for HO-3D sequences [Hz] (the release states none)."""

LAYOUTS = ("auto", "ho3d", "dexycb-export")

MODELS_OPTION = "models_dir / --models-dir: the YCB models folder"


@dataclass
class _Sequence:
    """The frames of one sequence folder, as read (all frames, before trimming)."""

    folder: Path
    layout: str
    side: str
    object_name: str
    mesh_path: Path
    vertices: np.ndarray
    pose48: np.ndarray  # (T, 48) as stored
    trans: np.ndarray  # (T, 3)
    betas: np.ndarray  # (10,)
    joints: np.ndarray  # (T, 21, 3)
    obj_pos: np.ndarray  # (T, 3)
    obj_quat: np.ndarray  # (T, 4) wxyz, corrected
    hand_ok: np.ndarray  # (T,) bool
    obj_ok: np.ndarray  # (T,) bool


def dexycb_export_rotation(obj_rot: np.ndarray) -> np.ndarray:
    """The true object orientation ``(T, 4)`` (w, x, y, z) of the DexYCB exporter's ``objRot``.

    The exporter turned DexYCB's quaternion ``q = (x, y, z, w)`` into a rotation vector reading
    it as ``(w', x', y', z') = (x, y, z, w)``. Reading the stored rotation vector back as a
    quaternion ``(w', x', y', z')`` (either sign) gives ``q`` as ``(x, y, z, w) = (w', x', y',
    z')``.
    """
    q = Rotation.from_rotvec(np.asarray(obj_rot, dtype=np.float64).reshape(-1, 3)).as_quat()
    xp, yp, zp, wp = q.T  # scipy's (x', y', z', w') of the stored rotation
    true_xyzw = np.stack([wp, xp, yp, zp], axis=1)
    return Rotation.from_quat(true_xyzw).as_quat(scalar_first=True, canonical=True)


def _sequence_dirs(path: Path) -> list[Path]:
    if path.is_file():
        raise ValidationError(
            f"{path}: an HO-3D sequence is a folder holding meta/0000.pkl, …; give that folder "
            "(or a folder of sequences)",
            field="path",
        )
    if not path.is_dir():
        raise ValidationError(f"{path}: no such folder", field="path")
    if (path / "meta").is_dir():
        return [path]
    if path.name == "meta" and any(path.glob("*.pkl")):
        return [path.parent]
    found = sorted({m.parent for m in path.rglob("meta") if m.is_dir() and any(m.glob("*.pkl"))})
    if not found:
        raise ValidationError(
            f"{path}: no HO-3D sequence found (expected <sequence>/meta/0000.pkl, … below it)",
            field="path",
        )
    return found


def _frame_files(folder: Path) -> list[Path]:
    files = list((folder / "meta").glob("*.pkl"))
    bad = [f.name for f in files if not f.stem.isdigit()]
    if bad:
        raise ValidationError(
            f"{folder / 'meta'}: file names must be frame numbers (0000.pkl, …), got {bad[:3]}",
            field="path",
        )
    files.sort(key=lambda f: int(f.stem))
    numbers = [int(f.stem) for f in files]
    if numbers != list(range(numbers[0], numbers[0] + len(numbers))):
        missing = sorted(set(range(numbers[0], numbers[-1] + 1)) - set(numbers))
        raise ValidationError(
            f"{folder / 'meta'}: frames {missing[:5]} are missing (frames must be consecutive)",
            field="path",
        )
    return files


def _is_none(frame: dict[str, Any], key: str) -> bool:
    return key not in frame or frame[key] is None


def _read_sequence(folder: Path, layout: str, models_dir: Path | None) -> _Sequence:
    files = _frame_files(folder)
    frames = []
    for f in files:
        d = load_pickle(f, what="HO-3D meta file")
        if not isinstance(d, dict):
            raise ValidationError(f"{f}: holds a {type(d).__name__}, expected a dict of arrays")
        frames.append(d)
    first = frames[0]
    if layout == "auto":
        layout = "dexycb-export" if "order" in first else "ho3d"
    T = len(frames)
    pose48 = np.zeros((T, 48))
    trans = np.zeros((T, 3))
    joints = np.zeros((T, 21, 3))
    obj_pos = np.zeros((T, 3))
    obj_rot = np.zeros((T, 3))
    hand_ok = np.zeros(T, dtype=bool)
    obj_ok = np.zeros(T, dtype=bool)
    names: set[str] = set()
    betas = []
    for i, (f, d) in enumerate(zip(files, frames, strict=True)):
        where = str(f)
        if "handJoints3D" in d and np.asarray(d["handJoints3D"]).shape == (3,):
            raise ValidationError(
                f"{where}: handJoints3D holds the root joint only and there is no hand pose "
                "(HO-3D's evaluation split); only annotated (train) sequences can be imported",
                field="handPose",
            )
        if not (_is_none(d, "objRot") or _is_none(d, "objTrans")):
            obj_rot[i] = array(d, "objRot", (3,), where=where, also=((3, 1), (1, 3)))
            obj_pos[i] = array(d, "objTrans", (3,), where=where)
            names.add(text(d, "objName", where=where))
            obj_ok[i] = True
        if not (_is_none(d, "handPose") or _is_none(d, "handTrans")):
            p = array(d, "handPose", (48,), where=where, fix="48 = 3 global + 45 finger values")
            t = array(d, "handTrans", (3,), where=where)
            if np.any(p != 0) or np.any(t != 0):
                pose48[i], trans[i] = p, t
                joints[i] = array(d, "handJoints3D", (21, 3), where=where)
                betas.append(array(d, "handBeta", (10,), where=where))
                hand_ok[i] = True
    if not names:
        raise ValidationError(f"{folder}: no frame has an object pose (objRot, objTrans)")
    if len(names) > 1:
        raise ValidationError(
            f"{folder}: the frames name several objects {sorted(names)}; one object per sequence"
        )
    if not betas:
        raise ValidationError(f"{folder}: no frame has a hand annotation (handPose, handTrans)")
    b = np.array(betas)
    if np.ptp(b, axis=0).max() > 1e-4:
        logger.warning("%s: handBeta varies over frames; using the median", folder)
    side = "right"
    if layout == "dexycb-export":
        side = text(first, "side", where=str(files[0]))
        if side not in ("right", "left"):
            raise ValidationError(
                f"{files[0]}: key 'side' must be 'right' or 'left', got {side!r}", field="side"
            )
        quat = dexycb_export_rotation(obj_rot)
    else:
        quat = aa_to_quat_wxyz(obj_rot)
    name = names.pop()
    mesh_path = find_object_mesh(models_dir, name, where=str(folder), option=MODELS_OPTION)
    vertices, _ = read_mesh(mesh_path)
    return _Sequence(
        folder=folder,
        layout=layout,
        side=side,
        object_name=name,
        mesh_path=mesh_path,
        vertices=vertices,
        pose48=pose48,
        trans=trans,
        betas=np.median(b, axis=0),
        joints=joints,
        obj_pos=obj_pos,
        obj_quat=quat,
        hand_ok=hand_ok,
        obj_ok=obj_ok,
    )


def read_ho3d(
    path: Path,
    *,
    models_dir: Path | None = None,
    fps: float | None = None,
    layout: str = "auto",
    mano_dir: Path | None = None,
    up_axis: Any = None,
    shared_up: bool | None = None,
    min_frames: int = 2,
    **opts: Any,
) -> list[dict[str, Any]]:
    """Read HO-3D-style sequences into mano-npz dicts (one per run of annotated frames).

    Args:
        path: a sequence folder (holding ``meta/``), its ``meta/`` folder, or a folder of
            sequences (searched recursively; returned sorted by path).
        models_dir: folder of the YCB object models (``<name>/textured_simple.obj``,
            ``<name>/textured_meshlab.obj`` or ``<name>.obj``); required.
        fps: frame rate [Hz]; default 30 (DexYCB's rate; HO-3D states none).
        layout: ``"auto"`` (by the keys), ``"ho3d"`` or ``"dexycb-export"`` (see the module
            docstring for what differs).
        mano_dir: folder of the official MANO model files, needed by DexYCB exports (PCA
            poses); default ``$MANO_MODEL_DIR``.
        up_axis: the up direction if known (``"z"``, ``"-y"``, a 3-vector in the source frame); by
            default estimated from the object (see :mod:`dexcanvas_core.capture.up`).
        shared_up: the sequences of one folder share one camera frame, so one consensus up and
            table height (default: ``True`` for DexYCB exports, ``False`` for HO-3D).
        min_frames: runs of annotated frames shorter than this are skipped.

    Returns:
        One dict per run of consecutive frames with both hand and object annotations, with
        the mano-npz keys (``hand_pose`` in axis-angle, ``flat_hand_mean=True``, ``transl``,
        ``keypoints`` in OpenPose order, ``object_mesh`` the model file, ``up_axis`` a unit
        vector, ``table_height``, ``hand_side``, ``source`` = ``ho3d:<folder>[#a-b]``). A DexYCB
        export without the MANO model for its PCA poses gives keypoints and no pose (the import
        fits the pose to them).

    Raises:
        ValidationError: a missing key, a wrong shape, NaN, an unknown option, no mesh, or no
            up direction (an object that never moves,
            without ``up`` or a shared estimate).
    """
    if opts:
        raise ValidationError(
            f"ho3d: unknown option(s) {sorted(opts)}; known: models_dir, fps, layout, mano_dir, "
            "up_axis, shared_up, min_frames",
            field=sorted(opts)[0],
        )
    if layout not in LAYOUTS:
        raise ValidationError(f"ho3d: layout must be one of {LAYOUTS}, got {layout!r}")
    given_up = parse_up(up_axis)
    seqs = [_read_sequence(d, layout, models_dir) for d in _sequence_dirs(Path(path))]

    inputs = []
    for s in seqs:
        k = np.flatnonzero(s.obj_ok)
        if not np.all(np.diff(k) == 1):  # the object track must be one run for the estimate
            k = k[: int(np.argmax(np.diff(k) != 1)) + 1]
        inputs.append(
            UpInput(
                where=str(s.folder),
                vertices=s.vertices,
                pos=s.obj_pos[k],
                quat_wxyz=s.obj_quat[k],
                group=str(s.folder.parent),
            )
        )
    share = shared_up if shared_up is not None else all(s.layout == "dexycb-export" for s in seqs)
    ups = ups_for(inputs, up=given_up, shared=share)

    pca: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    out: list[dict[str, Any]] = []
    for s, (u, table, note) in zip(seqs, ups, strict=True):
        fingers = s.pose48[:, 3:]
        if s.layout == "dexycb-export":
            if s.side not in pca:
                try:
                    pca[s.side] = load_mano_pca(s.side, mano_dir, where=str(s.folder))
                except ValidationError as e:  # no licensed model: fit the pose to the joints
                    logger.warning("%s; the hand pose is fitted to handJoints3D instead", e)
                    pca[s.side] = None
            if pca[s.side] is None:
                fingers = None
            else:
                comps, mean = pca[s.side]
                fingers = mean + fingers @ comps
        rate = float(fps) if fps is not None else (DEXYCB_FPS if s.layout != "ho3d" else HO3D_FPS)
        runs = valid_runs(s.hand_ok & s.obj_ok, min_frames)
        if not runs:
            raise ValidationError(
                f"{s.folder}: no {min_frames} consecutive frames have both hand and object "
                "annotations"
            )
        logger.info("%s: up %s, table %.4f m (%s)", s.folder, np.round(u, 4).tolist(), table, note)
        for a, b in runs:
            whole = (a, b) == (0, len(s.hand_ok))
            pose = (
                {}
                if fingers is None
                else {
                    "global_orient": s.pose48[a:b, :3].copy(),
                    "hand_pose": fingers[a:b].copy(),
                    "flat_hand_mean": True,
                    "transl": s.trans[a:b].copy(),
                }
            )
            out.append(
                {
                    "fps": rate,
                    **pose,
                    "betas": s.betas.copy(),
                    "keypoints": convert_keypoints(s.joints[a:b], "mano21", "openpose21"),
                    "object_name": s.object_name,
                    "object_pos": s.obj_pos[a:b].copy(),
                    "object_quat_wxyz": s.obj_quat[a:b].copy(),
                    "object_mesh": str(s.mesh_path),
                    "up_axis": np.asarray(u, dtype=np.float64).copy(),
                    "table_height": float(table),
                    "hand_side": s.side,
                    "source": f"{FORMAT}:{s.folder}" + ("" if whole else f"#{a}-{b}"),
                }
            )
    return out
