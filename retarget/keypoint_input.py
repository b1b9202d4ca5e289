"""Retargeting bare 21-keypoint sequences (hand-pose estimators, teleoperation gloves).

No MANO parameters, no object: only keypoints ``(T, 21, 3)`` [m] in ``mano21`` or
``openpose21`` order. The wrist orientation is recovered from the palm: the wrist and the index,
middle and pinky MCP keypoints move rigidly with MANO's wrist frame (they are children of the
wrist joint only), so ``R_world_mano`` is the rotation that maps the rest skeleton's palm
triangle onto the observed one (Kabsch on the four points, exact for MANO-consistent input).
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dexcanvas_core.checks import check_array, check_float, check_path, check_str
from dexcanvas_core.keypoints import MANO21, ORDERS, convert_keypoints
from dexcanvas_core.mano import HandSkeleton
from dexcanvas_core.plausibility import check_fps, check_keypoint_sequence
from dexcanvas_core.rotations import matrix_to_aa
from dexcanvas_core.safe_io import atomic_write_text
from dexcanvas_core.trajectory import HandTrack, Trajectory
from retarget.errors import RetargetError
from retarget.hands import get_hand
from retarget.outputs import open_run_dir
from retarget.retargeter import Retargeter


@dataclass(frozen=True)
class KeypointsConfig:
    """``retarget keypoints``: what :func:`run_keypoints` retargets and where it writes."""

    hand: str
    input: Path
    fps: float
    out: Path
    order: str = "mano21"
    units: str = "m"
    overwrite: bool = False
    """Replace the trajectory already in ``out``; without it one is refused before any work."""

    def __post_init__(self) -> None:
        err = RetargetError
        check_str("hand", self.hand, error=err)
        check_path("input", self.input, error=err)
        check_float("fps", self.fps, positive=True, error=err)
        check_path("out", self.out, error=err)
        check_str("order", self.order, choices=tuple(ORDERS), error=err)
        check_str("units", self.units, choices=("m", "cm", "mm"), error=err)


_PALM = [MANO21.index(k) for k in ("wrist", "index1", "middle1", "pinky1", "ring1")]


def _kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Rotations ``R`` (T, 3, 3) with ``dst - mean ≈ R (src - mean)`` per frame."""
    s = src - src.mean(axis=-2, keepdims=True)
    d = dst - dst.mean(axis=-2, keepdims=True)
    H = np.einsum("...ki,...kj->...ij", s, d)
    U, _, Vt = np.linalg.svd(H)
    D = np.ones(U.shape[:-1])
    D[..., -1] = np.sign(np.linalg.det(np.einsum("...ij,...jk->...ik", U, Vt)))
    return np.einsum("...ji,...j,...kj->...ik", Vt, D, U)


def keypoints_to_trajectory(
    keypoints: np.ndarray,
    fps: float,
    order: str = "mano21",
    side: str = "right",
    uuid: str = "keypoints",
) -> Trajectory:
    """A hand-only ``Trajectory`` from a keypoint sequence, ready for ``Retargeter.retarget``.

    Args:
        keypoints: ``(T, 21, 3)`` world positions [m].
        fps: frame rate [Hz].
        order: ``"mano21"`` or ``"openpose21"``.
    """
    kp = check_array("keypoints", keypoints, (None, 21, 3), finite=False, error=RetargetError)
    if not np.all(np.isfinite(kp)):
        bad = int(np.argwhere(~np.isfinite(kp))[0, 0])
        raise RetargetError(f"keypoints contain NaN or inf (first at frame {bad}); fill gaps first")
    fps = check_float("fps", fps, positive=True, error=RetargetError)
    check_str("order", order, choices=tuple(ORDERS), error=RetargetError)
    check_fps(fps, "fps")  # 1 to 10 000 Hz (dexcanvas_core.plausibility)
    if order != "mano21":
        kp = convert_keypoints(kp, order, "mano21")
    rest = HandSkeleton.default(side).rest_keypoints
    R = _kabsch(np.broadcast_to(rest[_PALM], (kp.shape[0], len(_PALM), 3)), kp[:, _PALM])
    T = kp.shape[0]
    # wrist = J0 + transl (MANO semantics): keep the translation consistent with the skeleton.
    transl = kp[:, 0] - rest[0]
    hand = HandTrack(
        name=side,
        global_pos=transl,
        global_rot_aa=matrix_to_aa(R),
        hand_pose=np.concatenate([matrix_to_aa(R), np.zeros((T, 45))], axis=1),
        joint_pos=kp,
    )
    return Trajectory(
        uuid=uuid, timestamp=np.arange(T) / fps, fps=float(fps), hands=[hand], objects=[]
    )


def retarget_keypoints(hand, keypoints: np.ndarray, fps: float, order: str = "mano21", config=None):
    """Retarget a bare keypoint sequence onto ``hand`` (no object): a ``RobotTrajectory``.

    >>> from dexcanvas_core import load_demonstration
    >>> from retarget import get_hand
    >>> keypoints = load_demonstration("cube2/tripod").hand.joint_pos[:10]  # (T, 21, 3) [m]
    >>> retarget_keypoints(get_hand("leap"), keypoints, fps=120.0).q.shape
    (10, 22)
    """
    traj = keypoints_to_trajectory(keypoints, fps, order)
    return Retargeter(hand, None, config).retarget(traj)


def load_keypoints(path, units: str = "m") -> np.ndarray:
    """``(T, 21, 3)`` keypoints [m] from ``.npy`` (the array), ``.npz`` (key ``keypoints``) or
    ``.csv`` (one frame per row, 63 columns x0, y0, z0, x1, …; a header row is skipped)."""
    path = Path(path)
    scale = {"m": 1.0, "cm": 0.01, "mm": 0.001}.get(units)
    if scale is None:
        raise RetargetError(f"--units must be m, cm or mm, got {units!r}")
    if not path.exists():
        raise RetargetError(f"keypoint file {path} does not exist")
    try:
        if path.suffix == ".npy":
            a = np.load(path)
        elif path.suffix == ".npz":
            with np.load(path) as z:
                if "keypoints" not in z:
                    raise RetargetError(f"{path} has no 'keypoints' array (found: {list(z)})")
                a = z["keypoints"]
        elif path.suffix == ".csv":
            a = np.genfromtxt(path, delimiter=",", skip_header=0)
            if a.ndim == 2 and np.isnan(a[0]).all():
                a = a[1:]
        else:
            raise RetargetError(f"unsupported keypoint file {path.name}: use .npy, .npz or .csv")
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        reason = "the file is empty" if path.stat().st_size == 0 else str(e) or type(e).__name__
        raise RetargetError(f"cannot read keypoints from {path}: {reason}") from e
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 2 and a.shape[1] == 63:
        a = a.reshape(-1, 21, 3)
    if a.ndim != 3 or a.shape[1:] != (21, 3) or a.shape[0] < 2:
        raise RetargetError(
            f"{path}: keypoints must have shape (T >= 2, 21, 3) or (T, 63), got {a.shape}"
        )
    bad = ~np.isfinite(a).all(axis=(1, 2))
    if bad.any():
        raise RetargetError(
            f"{path}: {int(bad.sum())} frame(s) hold NaN/inf (first: frame {int(np.argmax(bad))}); "
            "interpolate or drop them first"
        )
    return a * scale


def run_keypoints(cfg) -> dict:
    """``retarget keypoints``: retarget a keypoint file; write the trajectory and metrics
    (``out`` checked, created and locked first: :func:`retarget.outputs.open_run_dir`).

    The keypoints pass the plausibility checks first (``dexcanvas_core.plausibility``: hand
    scale against ``cfg.units``, outliers, wrist speed), so a unit mistake is named as such
    instead of failing in the solver."""
    with open_run_dir(cfg.out, overwrite=cfg.overwrite) as out:
        return _run_keypoints(cfg, out)


def _run_keypoints(cfg, out: Path) -> dict:
    kp = load_keypoints(cfg.input, cfg.units)
    check_keypoint_sequence(kp, check_fps(cfg.fps), str(cfg.input), units=cfg.units)
    hand = get_hand(cfg.hand)
    robot = retarget_keypoints(hand, kp, cfg.fps, cfg.order)
    robot.save_npz(out / "robot_trajectory.npz")
    metrics = {
        "hand": hand.name,
        "input": str(cfg.input),
        "order": cfg.order,
        "frames": int(kp.shape[0]),
        "fps": cfg.fps,
        "keypoint_err_mean_m": float(robot.keypoint_err.mean()),
        "keypoint_err_max_m": float(robot.keypoint_err.max()),
        "ms_per_frame": robot.ms_per_frame,
    }
    atomic_write_text(out / "metrics.json", json.dumps(metrics, indent=2, sort_keys=True))
    err_mm = 1e3 * metrics["keypoint_err_mean_m"]
    print(
        f"{hand.name}: {kp.shape[0]} frames, keypoint error {err_mm:.1f} mm mean, "
        f"{metrics['ms_per_frame']:.2f} ms/frame → {out}/robot_trajectory.npz"
    )
    return metrics
