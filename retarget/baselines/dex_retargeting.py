"""dex-retargeting's position retargeting on our robot models: the peer baseline.

dex-retargeting (PyPI ``dex-retargeting``, the ``bench`` extra) retargets by nonlinear
least squares per frame: ``PositionOptimizer`` minimises a Huber loss between robot link
positions and target positions with NLopt's SLSQP, warm-started from the previous frame, and
reads the robot from a URDF through Pinocchio. To compare it with our QP on *the same robot*
and *the same targets*, this module

1. exports a kinematic URDF of a hand's compiled ``MjModel``
   (:func:`retarget.urdf_export.export_urdf`);
2. builds dex-retargeting's retargeting with its public API (``RetargetingConfig(type=
   "position", ...).build()``: ``PositionOptimizer`` + ``SeqRetargeting`` + its
   ``MimicJointKinematicAdaptor``) with the target links = our keypoint sites (MANO21 →
   robot site through ``hand.keypoint_map``, the order ``Retargeter`` uses) plus the wrist
   site;
3. feeds it the targets ``Retargeter.human_targets`` computes (keypoints scaled by
   ``hand.scale`` about the object's centre, the scaled wrist point), and returns the joint
   trajectory in MuJoCo ``qpos`` order, ready for ``Resimulator``.

Wrist: by default (``wrist="free"``) the six wrist joints are optimised with the fingers, as
in dex-retargeting's offline configurations (``add_dummy_free_joint: True``); its
position-only loss sees the wrist *point* but not the wrist orientation. ``wrist="fixed"``
instead pins the wrist joints to the human wrist pose (scaled wrist point, MANO wrist
rotation) frame by frame, as dex-retargeting's teleoperation users do, and optimises the
fingers alone. Both start from the hand's open posture with the wrist at the first frame's
human wrist pose (dex-retargeting's ``warm_start``), the same start our retargeter uses.

Optimizer settings are dex-retargeting's defaults: Huber ``delta`` 2 cm, ``norm_delta``
4e-3 (its step-size regulariser on ``q − q_prev``), SLSQP with ``ftol_abs`` 1e-5, joint limits
on, and no low-pass filter (``low_pass_alpha = 1``, its offline configurations' value).

Not modelled by dex-retargeting (and hence not here): the object (no contact or collision
terms), inequality tendons (Shadow's two-joint tendons that only bound a sum), and nonlinear
couplings (a polynomial joint equality of degree > 1 is refused).
"""

from __future__ import annotations

import contextlib
import io
import logging
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from dexcanvas_core.keypoints import MANO21
from retarget.config import RetargetConfig
from retarget.errors import RetargetError
from retarget.hands.base import WRIST_SITE, wrist_qpos_from_mano
from retarget.retargeter import Retargeter
from retarget.urdf_export import export_urdf, mj_name

log = logging.getLogger(__name__)

WRIST_JOINT_NAMES: tuple[str, ...] = (
    "wrist_tx",
    "wrist_ty",
    "wrist_tz",
    "wrist_rx",
    "wrist_ry",
    "wrist_rz",
)
"""The floating wrist (``retarget.hands.WRIST_JOINTS``): the first six ``qpos`` entries."""


# ------------------------------------------------------------------------------ the baseline
@dataclass(frozen=True)
class DexRetargetingConfig:
    """How dex-retargeting's position retargeting is set up (defaults: its own)."""

    wrist: Literal["free", "fixed"] = "free"
    """``free``: the 6 wrist joints are optimised (its ``add_dummy_free_joint``); ``fixed``:
    they follow the human wrist pose and only the fingers are optimised."""
    wrist_target: bool = True
    """Add the wrist site with the (scaled) human wrist point to the target links."""
    huber_delta: float = 0.02
    """Huber loss threshold [m] (dex-retargeting's ``huber_delta``)."""
    norm_delta: float = 4e-3
    """Weight of its ``‖q − q_prev‖²`` regulariser (dex-retargeting's ``normal_delta``)."""
    low_pass_alpha: float = 1.0
    """Its output low-pass filter; 1 = no filtering (its offline configurations)."""
    has_joint_limits: bool = True

    def validate(self) -> DexRetargetingConfig:
        if self.wrist not in ("free", "fixed"):
            raise RetargetError(f"wrist must be 'free' or 'fixed', got {self.wrist!r}")
        if not (self.huber_delta > 0 and self.norm_delta >= 0):
            raise RetargetError("huber_delta must be > 0 and norm_delta >= 0")
        return self


@dataclass
class BaselineTrajectory:
    """A baseline's joint trajectory and its timing."""

    method: str
    q: np.ndarray
    """(T, nq) joint positions in MuJoCo ``qpos`` order (wrist first), float64."""
    joint_names: list[str]
    solve_time_s: float
    """Time spent in the per-frame retargeting calls [s] (nothing else)."""
    solver_failures: int = 0
    """Frames on which the optimizer raised and dex-retargeting kept the previous pose."""
    meta: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return self.q.shape[0]

    @property
    def ms_per_frame(self) -> float:
        return 1e3 * self.solve_time_s / max(self.num_frames, 1)


@contextlib.contextmanager
def _tempdir(path: str):
    """Point ``tempfile`` at ``path`` for a moment: dex-retargeting's ``build()`` writes a copy of
    the URDF into a fresh ``mkdtemp()`` it never removes; this keeps it inside our own
    temporary directory (removed with it)."""
    previous = tempfile.tempdir
    tempfile.tempdir = path
    try:
        yield
    finally:
        tempfile.tempdir = previous


def _require_dex_retargeting():
    try:
        import dex_retargeting  # noqa: F401
        from dex_retargeting.retargeting_config import RetargetingConfig
    except ImportError as e:
        raise RetargetError(
            f"the dex-retargeting baseline needs the bench extra ({e}); run: "
            "pip install 'dexcanvas-retarget[bench]'"
        ) from e
    return RetargetingConfig


class DexRetargetingBaseline:
    """dex-retargeting's position retargeting on one of our hands (see the module docstring).

    Args:
        hand: a ``retarget.hands.HandModel``.
        config: its settings.
        keypoint_sites: robot sites of the keypoint targets, in the order of the ``keypoints``
            given to :meth:`retarget_targets`; default: ``hand.keypoint_map`` without the
            wrist, in map order (``Retargeter.kp_sites``).
    """

    method = "dex-retargeting"

    def __init__(self, hand, config: DexRetargetingConfig | None = None, *, keypoint_sites=None):
        RetargetingConfig = _require_dex_retargeting()
        self.hand = hand
        self.cfg = (config or DexRetargetingConfig()).validate()
        self.model = hand.compile()
        m = self.model
        kp = {k: v for k, v in hand.keypoint_map.items() if k != "wrist"}
        if keypoint_sites is None:
            self.kp_names = list(kp)
            self.keypoint_sites = list(kp.values())
        else:
            self.keypoint_sites = list(keypoint_sites)
            by_site = {v: k for k, v in kp.items()}
            self.kp_names = [by_site.get(s, s) for s in self.keypoint_sites]
        self.joint_names = [
            mj_name(m, mujoco.mjtObj.mjOBJ_JOINT, j, "joint") for j in range(m.njnt)
        ]
        if tuple(self.joint_names[:6]) != WRIST_JOINT_NAMES:
            raise RetargetError(
                f"hand {hand.name!r}: expected the floating wrist {WRIST_JOINT_NAMES} first, "
                f"got {self.joint_names[:6]}"
            )
        self._tmp = tempfile.TemporaryDirectory(prefix="dexcanvas-dexret-")
        self.urdf = export_urdf(m, Path(self._tmp.name) / f"{hand.name}.urdf", robot_name=hand.name)
        missing = [s for s in self.keypoint_sites if s not in self.urdf.site_links]
        if missing:
            raise RetargetError(f"hand {hand.name!r}: no site(s) {missing} in the model")
        self.target_links = [self.urdf.site_links[s] for s in self.keypoint_sites]
        human_idx = [MANO21.index(k) if k in MANO21 else -1 for k in self.kp_names]
        if self.cfg.wrist_target:
            self.target_links.append(self.urdf.site_links[WRIST_SITE])
            human_idx.append(MANO21.index("wrist"))
        followers = {mm.follower for mm in self.urdf.mimics}
        target_joints = [
            j
            for j in self.urdf.joint_names
            if j not in followers and (self.cfg.wrist == "free" or j not in WRIST_JOINT_NAMES)
        ]
        rc = RetargetingConfig(
            type="position",
            urdf_path=str(self.urdf.path),
            add_dummy_free_joint=False,  # the exported wrist joints are the free joint
            target_joint_names=target_joints,
            target_link_names=self.target_links,
            target_link_human_indices=np.asarray(human_idx),
            huber_delta=self.cfg.huber_delta,
            normal_delta=self.cfg.norm_delta,
            has_joint_limits=self.cfg.has_joint_limits,
            low_pass_alpha=self.cfg.low_pass_alpha,
        )
        with _tempdir(self._tmp.name):
            self.retargeting = rc.build()
        robot = self.retargeting.optimizer.robot
        pin_names = robot.dof_joint_names
        if sorted(pin_names) != sorted(self.joint_names):
            raise RetargetError(
                f"hand {hand.name!r}: URDF joints {sorted(pin_names)} differ from MuJoCo's "
                f"{sorted(self.joint_names)}"
            )
        # Index maps between Pinocchio's order (URDF tree) and MuJoCo's qpos order; the fixed
        # (not optimised, not mimic) joints: the wrist with wrist='fixed', none otherwise.
        self._pin_index_of_mj = np.array([pin_names.index(n) for n in self.joint_names])
        self._mj_index_of_pin = np.array([self.joint_names.index(n) for n in pin_names])
        fixed = self.retargeting.optimizer.fixed_joint_names
        self._fixed_mj = np.array([self.joint_names.index(n) for n in fixed], dtype=int)
        self.q_default = np.asarray(hand.default_qpos(m), dtype=np.float64)

    @property
    def optimizer(self):
        """dex-retargeting's ``PositionOptimizer``."""
        return self.retargeting.optimizer

    def retarget_targets(
        self,
        keypoints: np.ndarray,
        wrist_p: np.ndarray,
        wrist_R: np.ndarray,
        q_init: np.ndarray | None = None,
    ) -> BaselineTrajectory:
        """Retarget per-frame targets (world frame, already scaled).

        Args:
            keypoints: (T, K, 3) [m] targets of ``keypoint_sites``.
            wrist_p: (T, 3) [m] wrist point (MANO J0, scaled).
            wrist_R: (T, 3, 3) MANO wrist rotation (the robot's ``wrist`` body frame).
            q_init: (nq,) start configuration; default: the open posture with the wrist at the
                first frame's wrist pose.
        """
        kp = np.asarray(keypoints, dtype=np.float64)
        wp = np.asarray(wrist_p, dtype=np.float64)
        wR = np.asarray(wrist_R, dtype=np.float64)
        T = kp.shape[0] if kp.ndim == 3 else 0
        if kp.shape != (T, len(self.keypoint_sites), 3) or T == 0:
            raise RetargetError(
                f"keypoints must be (T, {len(self.keypoint_sites)}, 3) with T > 0, got {kp.shape}"
            )
        if wp.shape != (T, 3) or wR.shape != (T, 3, 3):
            raise RetargetError(f"wrist targets must be ({T}, 3) and ({T}, 3, 3)")
        if not (np.isfinite(kp).all() and np.isfinite(wp).all() and np.isfinite(wR).all()):
            raise RetargetError("targets contain NaN or inf")
        nq = len(self.joint_names)
        if q_init is None:
            q_init = self.q_default.copy()
            q_init[:6] = wrist_qpos_from_mano(wR[0], wp[0])
        q_init = np.asarray(q_init, dtype=np.float64)
        if q_init.shape != (nq,):
            raise RetargetError(f"q_init must be ({nq},), got {q_init.shape}")
        refs = np.concatenate([kp, wp[:, None]], axis=1) if self.cfg.wrist_target else kp
        fixed = np.zeros((T, len(self._fixed_mj)))
        if self.cfg.wrist == "fixed":
            wrist_q = np.concatenate([wp, Rotation.from_matrix(wR).as_euler("XYZ")], axis=1)
            fixed = wrist_q[:, self._fixed_mj]  # the fixed joints are the 6 wrist joints
        seq = self.retargeting
        seq.reset()
        if seq.filter is not None:
            seq.filter.reset()
        seq.set_qpos(q_init[self._mj_index_of_pin].astype(np.float32))
        out = np.zeros((T, nq))
        buf = io.StringIO()
        elapsed = 0.0
        # dex-retargeting prints an optimizer failure and keeps the previous pose: count them.
        with contextlib.redirect_stdout(buf):
            for t in range(T):
                t0 = time.perf_counter()
                q_pin = seq.retarget(refs[t], fixed_qpos=fixed[t])
                elapsed += time.perf_counter() - t0
                out[t] = q_pin[self._pin_index_of_mj]
        failures = sum(1 for line in buf.getvalue().splitlines() if line.strip())
        if failures:
            log.warning("dex-retargeting: %d of %d frames kept the previous pose", failures, T)
        return BaselineTrajectory(
            method=self.method,
            q=out,
            joint_names=list(self.joint_names),
            solve_time_s=elapsed,
            solver_failures=failures,
            meta={
                "hand": self.hand.name,
                "wrist": self.cfg.wrist,
                "target_links": list(self.target_links),
                "optimised_joints": list(self.optimizer.target_joint_names),
                "mimic_joints": [mm.follower for mm in self.urdf.mimics],
                "huber_delta": self.cfg.huber_delta,
                "norm_delta": self.cfg.norm_delta,
                "low_pass_alpha": self.cfg.low_pass_alpha,
                "solver": "nlopt LD_SLSQP, ftol_abs 1e-5 (dex-retargeting PositionOptimizer)",
            },
        )

    def retarget(self, traj, geometry=None) -> BaselineTrajectory:
        """Retarget a human trajectory with the targets our ``Retargeter`` would use.

        ``geometry`` (the object's ``ObjectGeometry``) sets the scaling centre (the object's,
        as ours); without it keypoints scale about the wrist.
        """
        rt = Retargeter(
            self.hand, geometry, RetargetConfig.from_overrides({"collision.enabled": False})
        )
        if rt.kp_sites != self.keypoint_sites:
            raise RetargetError("keypoint_sites differ from the retargeter's; pass them explicitly")
        tg = rt.human_targets(traj)
        return self.retarget_targets(tg["keypoints"], tg["wrist_p"], tg["wrist_R"])
