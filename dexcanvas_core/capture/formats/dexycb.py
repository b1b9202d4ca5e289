"""Reader of the original DexYCB release (Chao et al., CVPR 2021).

Layout (``<root>`` is the data folder of ``dex-ycb-toolkit``)::

    <root>/<subject>/<sequence>/meta.yml, pose.npz, <camera serial>/…
    <root>/calibration/mano_<id>/mano.yml               betas of the subject
    <root>/calibration/extrinsics_<id>/extrinsics.yml   cameras and the table's AprilTag
    <root>/models/<YCB name>/textured_simple.obj        object models

Conventions (facts from ``NVlabs/dex-ycb-toolkit``: ``layers/mano_layer.py``,
``layers/ycb_group_layer.py``, ``sequence_loader.py``, ``dex_ycb.py``):

* ``meta.yml``: ``num_frames``, ``mano_sides`` (one hand), ``mano_calib`` (betas id),
  ``ycb_ids`` (objects on the table, ids 1–21 of ``YCB_CLASSES``), ``ycb_grasp_ind`` (the one
  grasped), ``extrinsics`` (calibration id).
* ``pose.npz``: ``pose_m (T, 1, 51)`` = 3 global-orientation axis-angle values, 45 **PCA
  coefficients** of the finger pose (``manopth`` ``use_pca=True, ncomps=45,
  flat_hand_mean=False``: axis-angle = ``hands_mean + c @ hands_components``, from the official
  MANO model, hence ``mano_dir``), then the MANO translation (wrist = J0(β) + t); all-zero rows
  are frames without a hand. ``pose_y (T, O, 7)`` = object quaternion **(x, y, z, w)**
  (scipy order, identity ``[0, 0, 0, 1]``) and translation, per object of ``ycb_ids``.
* Everything is in the toolkit's world frame (the master camera's), metres, 30 fps.
* The table carries an AprilTag: ``extrinsics.yml``'s ``apriltag`` (3×4) is its pose in that
  frame, its +z axis pointing up from the table (the toolkit keeps the scene's points at tag
  z ∈ [-0.1, 0.7] m). It gives ``up_axis`` and ``table_height`` (the tag's height along it);
  without it the up direction is estimated from the object (shared per subject folder).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from dexcanvas_core.capture.formats._common import (
    UpInput,
    array,
    find_object_mesh,
    load_mano_pca,
    parse_up,
    read_mesh,
    ups_for,
    valid_runs,
)
from dexcanvas_core.errors import MissingDependencyError, ValidationError
from dexcanvas_core.rotations import quat_xyzw_to_wxyz

logger = logging.getLogger(__name__)

FORMAT = "dexycb"

DEXYCB_FPS = 30.0
"""DexYCB's frame rate [Hz]."""

YCB_CLASSES: dict[int, str] = {
    1: "002_master_chef_can",
    2: "003_cracker_box",
    3: "004_sugar_box",
    4: "005_tomato_soup_can",
    5: "006_mustard_bottle",
    6: "007_tuna_fish_can",
    7: "008_pudding_box",
    8: "009_gelatin_box",
    9: "010_potted_meat_can",
    10: "011_banana",
    11: "019_pitcher_base",
    12: "021_bleach_cleanser",
    13: "024_bowl",
    14: "025_mug",
    15: "035_power_drill",
    16: "036_wood_block",
    17: "037_scissors",
    18: "040_large_marker",
    19: "051_large_clamp",
    20: "052_extra_large_clamp",
    21: "061_foam_brick",
}
"""DexYCB's object ids (``meta.yml`` ``ycb_ids``) and the YCB model names."""


def _yaml(path: Path) -> dict[str, Any]:
    try:
        import yaml
    except ImportError as exc:  # pragma: no cover - present wherever the toolkit's deps are
        raise MissingDependencyError("pyyaml", "reading DexYCB's meta.yml files") from exc
    try:
        data = yaml.safe_load(path.read_text())
    except FileNotFoundError as exc:
        raise ValidationError(f"{path}: no such file") from exc
    except yaml.YAMLError as exc:
        raise ValidationError(f"{path}: not valid YAML ({exc})") from exc
    if not isinstance(data, dict):
        raise ValidationError(f"{path}: expected a mapping, got {type(data).__name__}")
    return data


def _sequence_dirs(path: Path) -> list[Path]:
    if not path.is_dir():
        raise ValidationError(
            f"{path}: a DexYCB sequence is a folder holding meta.yml and pose.npz; give it (or a "
            "subject or data folder)",
            field="path",
        )
    if (path / "meta.yml").is_file():
        return [path]
    found = sorted(p.parent for p in path.rglob("meta.yml") if (p.parent / "pose.npz").is_file())
    if not found:
        raise ValidationError(
            f"{path}: no DexYCB sequence found (expected <subject>/<sequence>/meta.yml and "
            "pose.npz below it)",
            field="path",
        )
    return found


def _calibration_dir(seq: Path, given: Path | None) -> Path:
    if given is not None:
        return Path(given).expanduser()
    for parent in seq.parents:
        if (parent / "calibration").is_dir():
            return parent / "calibration"
    raise ValidationError(
        f"{seq}: no calibration folder found above it (the data folder's calibration/); pass "
        "calibration_dir (--calibration-dir)",
        field="calibration_dir",
    )


def _table_from_tag(calib: Path, meta: dict[str, Any], where: str) -> tuple[np.ndarray, float]:
    """``(up, table height)`` from the AprilTag pose of the sequence's extrinsics."""
    path = calib / f"extrinsics_{meta.get('extrinsics')}" / "extrinsics.yml"
    ext = _yaml(path).get("extrinsics", {})
    if "apriltag" not in ext:
        raise ValidationError(f"{path}: no 'apriltag' pose", field="apriltag")
    tag = array(ext, "apriltag", (12,), where=str(path), also=((3, 4),)).reshape(3, 4)
    up = tag[:, 2] / np.linalg.norm(tag[:, 2])
    return up, float(tag[:, 3] @ up)


def read_dexycb(
    path: Path,
    *,
    models_dir: Path | None = None,
    fps: float | None = None,
    mano_dir: Path | None = None,
    calibration_dir: Path | None = None,
    up_axis: Any = "tag",
    min_frames: int = 2,
    **opts: Any,
) -> list[dict[str, Any]]:
    """Read DexYCB sequences (original release) into mano-npz dicts.

    Args:
        path: a sequence folder (``meta.yml`` + ``pose.npz``), a subject folder or the data
            folder (searched recursively; sorted by path).
        models_dir: YCB models folder; default ``<data folder>/models`` when it exists.
        fps: frame rate [Hz]; default 30.
        mano_dir: folder of the official MANO model files (the PCA basis); default
            ``$MANO_MODEL_DIR``.
        calibration_dir: DexYCB's ``calibration/`` folder; default found above the sequence.
        up_axis: ``"tag"`` (the table's AprilTag, default), ``None`` (estimated from the object,
            shared per subject folder), or an axis name / 3-vector in the world frame.
        min_frames: runs of annotated frames shorter than this are skipped.

    Returns:
        One dict per run of consecutive frames with a hand (``hand_pose`` in axis-angle,
        ``flat_hand_mean=True``, ``transl``, the grasped object's track and model,
        ``up_axis``, ``table_height``, ``hand_side``, ``source`` = ``dexycb:<folder>[#a-b]``).

    Raises:
        ValidationError: missing files or keys, wrong shapes, NaN, an unknown option or object
            id, no mesh, no MANO model (PCA poses), no calibration.
    """
    if opts:
        raise ValidationError(
            f"dexycb: unknown option(s) {sorted(opts)}; known: models_dir, fps, mano_dir, "
            "calibration_dir, up_axis, min_frames",
            field=sorted(opts)[0],
        )
    use_tag = isinstance(up_axis, str) and up_axis == "tag"
    given_up = None if use_tag else parse_up(up_axis)
    rows = []
    for seq in _sequence_dirs(Path(path)):
        where = str(seq)
        meta = _yaml(seq / "meta.yml")
        for key in ("mano_sides", "mano_calib", "ycb_ids", "ycb_grasp_ind"):
            if key not in meta:
                raise ValidationError(f"{seq / 'meta.yml'}: no key {key!r}", field=key)
        side = str(meta["mano_sides"][0])
        if side not in ("right", "left"):
            raise ValidationError(f"{seq / 'meta.yml'}: mano_sides[0] is {side!r}", field="side")
        ids = list(meta["ycb_ids"])
        k = int(meta["ycb_grasp_ind"])
        if not 0 <= k < len(ids) or ids[k] not in YCB_CLASSES:
            raise ValidationError(
                f"{seq / 'meta.yml'}: ycb_grasp_ind {k} / ycb_ids {ids} name no known object "
                f"(ids 1–21)",
                field="ycb_ids",
            )
        name = YCB_CLASSES[ids[k]]
        try:
            with np.load(seq / "pose.npz", allow_pickle=False) as z:
                pose = {key: z[key] for key in z.files}
        except FileNotFoundError as exc:
            raise ValidationError(f"{seq / 'pose.npz'}: no such file") from exc
        except (ValueError, OSError) as exc:
            raise ValidationError(f"{seq / 'pose.npz'}: cannot be read ({exc})") from exc
        pose_m = array(pose, "pose_m", (None, None, 51), where=str(seq / "pose.npz"))[:, 0]
        T = len(pose_m)
        pose_y = array(pose, "pose_y", (T, len(ids), 7), where=str(seq / "pose.npz"))[:, k]
        calib = _calibration_dir(seq, calibration_dir)
        mano_yml = calib / f"mano_{meta['mano_calib'][0]}" / "mano.yml"
        betas = array(_yaml(mano_yml), "betas", (10,), where=str(mano_yml))
        root = seq.parent.parent
        models = (
            models_dir
            if models_dir is not None
            else (root / "models" if (root / "models").is_dir() else None)
        )
        mesh = find_object_mesh(
            models, name, where=where, option="models_dir / --models-dir: the YCB models folder"
        )
        vertices, _ = read_mesh(mesh)
        # untracked frames hold the identity pose at the origin (dex-ycb-toolkit)
        obj_ok = np.any(pose_y != [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], axis=1)
        quat = np.tile([1.0, 0.0, 0.0, 0.0], (T, 1))
        quat[obj_ok] = quat_xyzw_to_wxyz(pose_y[obj_ok, :4])
        tag = _table_from_tag(calib, meta, where) if use_tag else None
        rows.append(
            (seq, side, name, mesh, vertices, pose_m, pose_y[:, 4:], quat, betas, tag, obj_ok)
        )

    inputs = []
    for r in rows:
        if r[9] is None:
            k = valid_runs(r[10], 1)[0] if r[10].any() else (0, 0)
            inputs.append(
                UpInput(str(r[0]), r[4], r[6][k[0] : k[1]], r[7][k[0] : k[1]], str(r[0].parent))
            )
    ups = iter(ups_for(inputs, up=given_up, shared=given_up is None))
    pca: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    out: list[dict[str, Any]] = []
    for seq, side, name, mesh, _, pose_m, pos, quat, betas, tag, obj_ok in rows:
        u, table, note = (tag[0], tag[1], "the table's AprilTag") if tag else next(ups)
        if side not in pca:
            pca[side] = load_mano_pca(side, mano_dir, where=str(seq))
        comps, mean = pca[side]
        hand = np.any(pose_m != 0, axis=1) & obj_ok
        runs = valid_runs(hand, min_frames)
        if not runs:
            raise ValidationError(
                f"{seq}: no {min_frames} consecutive frames with both the hand and the object"
            )
        logger.info("%s: up %s, table %.4f m (%s)", seq, np.round(u, 4).tolist(), table, note)
        for a, b in runs:
            whole = (a, b) == (0, len(hand))
            out.append(
                {
                    "fps": float(fps) if fps is not None else DEXYCB_FPS,
                    "global_orient": pose_m[a:b, :3].copy(),
                    "hand_pose": mean + pose_m[a:b, 3:48] @ comps,
                    "flat_hand_mean": True,
                    "transl": pose_m[a:b, 48:].copy(),
                    "betas": betas.copy(),
                    "object_name": name,
                    "object_pos": pos[a:b].copy(),
                    "object_quat_wxyz": quat[a:b].copy(),
                    "object_mesh": str(mesh),
                    "up_axis": np.asarray(u, dtype=np.float64).copy(),
                    "table_height": float(table),
                    "hand_side": side,
                    "source": f"{FORMAT}:{seq}" + ("" if whole else f"#{a}-{b}"),
                }
            )
    return out
