"""Size-aware reference: make the hand reference follow an object whose size was changed.

``SimConfig.object_scale`` scales the simulated object about its frame origin, but the human
reference was captured around the original object: on a 20 % larger object the fingers
penetrate it and collide at the approach, on a 20 % smaller one they close on air and the object
drops. :func:`adapt_reference_to_size` moves the hand so that every part of it that is near the
object keeps its relation to the object *surface*:

* **Contact points.** Points along the axis of every collision capsule of the simulated hand
  (both ends and the middle: 63 points on the 21 capsules), at the reference pose. A point
  ``x`` (object frame of the captured object pose) with signed distance ``d`` to the original
  surface and closest surface point ``c = x − d·n`` is mapped to ``x' = s·c + d·n``: its
  closest point is carried to the scaled surface and its signed distance is kept (exactly for
  convex surface patches). A finger pad that touched the object still touches it; one that was
  held 1 cm clear stays 1 cm clear.
* **IK.** Per frame, a damped Gauss–Newton least-squares fit of the 51 hand coordinates (wrist
  translation and rotation, 45 finger hinges) to the mapped points, each weighted by ``β``,
  which ramps from 1 (capsule surface within ``near_m`` of the object) to 0 (beyond
  ``far_m``), with its error along the surface normal weighted fully and along the surface by
  ``tangential`` only (what must be kept is the gap; a rigid palm cannot keep every point's
  closest surface point on a resized surface and may slide along it. On the mocap-fitted
  ``cylinder6/adducted_thumb`` ×1.2, a wrap grasp, the largest gap change of a contact point
  was 5.0 mm with a tangential weight of 1, 2.6 mm with 0.1 and 0.9 mm with 0.01; 0.1 is kept
  because 0.01 held fewer objects open loop on the 14 pairs that failed ``mocap_size``, 5
  against 7, in an earlier variant of this scheme). A posture term keeps each coordinate near
  the reference (cheap for the wrist, dearer for the finger flexions, dearest for abduction
  and twist).
  Jacobians come from the joint axes (exact); joint limits are bounds (a coordinate at a bound
  that the step would push out is frozen and the step solved again). Each frame starts from
  the previous frame's solution.
* **Fade-in.** The correction is applied in joint space scaled by the largest ``β`` of the
  frame: frames where the hand is far (approach, release) are exactly the captured ones, and
  the adaptation grows continuously as the hand closes on the object. (Blending each point's
  target with its old position instead pins the far points where they were, and they then
  fight the motion of the near ones: a lateral pinch on a ×0.8 cylinder jumped 0.12 rad in one
  frame at the onset that way, against 0.014 rad now.) At scale 1 every target is the
  reference's own point and the solution is the reference itself.

The keypoints (human, for the grip weights and the contact reward) are moved by the same
displacement as the simulated hand's keypoints; ``tips_object`` and ``tip_distance`` are
recomputed against the scaled geometry at the simulated object pose.

Measured on the 32-pair ``benchmarks/force_pipeline.py`` suite (seed 0, MPC tracker, one
worker), condition ``mocap_size`` (mocap-fitted demonstrations, object ×1.2 on even and ×0.8 on
odd pairs): strict success 12/32 (38 %) with the captured reference, 22/32 (69 %) adapted,
against 23/32 (72 %) at nominal size (``mocap``, unchanged: the adaptation only runs when
``object_scale != 1``). Of the 23 pairs that succeed at nominal size, 21 also succeed resized.
Cost: 0.7–1.9 s of one core per demonstration (7–8.5 s clips), against ~3 s per
demonstration-second for the MPC tracking. Contact points (capsule gap ≤ ``near_m``) keep their
gap to within 0.3–2.5 mm (per-frame worst point, median over frames) on 13 of the 14 pairs
that failed before; on the box ``cuboid3/large_diameter`` ×1.2 (a whole-hand wrap over edges)
to 4.1 mm.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS, FINGERTIPS_MANO21, MANO21
from dexcanvas_core.mano.skeleton import HandSkeleton
from dexcanvas_core.sim.hand import HAND_JOINTS, HINGE_HIGH, HINGE_LOW, add_hand
from dexcanvas_core.sim.reference import Reference

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ResizeConfig:
    """Settings of the size adaptation (module docstring)."""

    near_m: float = 0.01
    """Capsule-surface gap [m] below which a point fully follows the scaled surface."""
    far_m: float = 0.04
    """Gap [m] beyond which a point is left where the reference has it."""
    posture_wrist_pos: float = 1e-4
    """Posture weight of the wrist translation [per m²] (target errors are weighted per m²)."""
    posture_wrist_rot: float = 1e-4
    """Posture weight of the wrist rotation [per rad²]."""
    posture_flex: float = 1e-4
    """Posture weight of the finger flexion hinges [per rad²]."""
    posture_other: float = 1e-3
    """Posture weight of the abduction and twist hinges [per rad²]."""
    tangential: float = 0.1
    """Weight of a point's error along the surface relative to its error along the normal:
    the signed distance is what must be kept; rigid parts (the palm, a phalanx) cannot keep
    every point's closest surface point on a resized surface and may slide along it."""
    damping: float = 1e-6
    """Levenberg damping of each Gauss–Newton step."""
    iterations: int = 6
    """Gauss–Newton iterations per frame."""

    def validate(self) -> ResizeConfig:
        if not (0 <= self.near_m < self.far_m):
            raise ValidationError(
                f"need 0 ≤ near_m < far_m, got {self.near_m} and {self.far_m}", field="near_m"
            )
        for name in ("posture_wrist_pos", "posture_wrist_rot", "posture_flex", "posture_other"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValidationError(f"{name} must be positive, got {v}", field=name)
        if self.iterations < 1:
            raise ValidationError(f"iterations must be ≥ 1, got {self.iterations}")
        return self


@dataclass
class ResizeReport:
    """What the adaptation did, per frame.

    Attributes:
        scale: the object size factor.
        frames_adapted: ``(T,)`` bool, frames where some point was within ``far_m``.
        residual_max_m: ``(T,)`` largest distance [m] between a contact point (capsule gap
            ≤ ``near_m``, fully weighted) and its target after the IK (0 where there is none).
        gap_error_max_m: ``(T,)`` largest change [m] of a contact point's signed distance
            (to the scaled surface after vs to the original surface before).
        joint_change_max_rad: ``(T,)`` largest finger-hinge change [rad].
        wrist_shift_m: ``(T,)`` wrist translation [m].
    """

    scale: float
    frames_adapted: np.ndarray
    residual_max_m: np.ndarray
    gap_error_max_m: np.ndarray
    joint_change_max_rad: np.ndarray
    wrist_shift_m: np.ndarray

    def summary(self) -> dict:
        a = self.frames_adapted
        return {
            "scale": self.scale,
            "frames_adapted": int(a.sum()),
            "residual_max_m": float(self.residual_max_m.max(initial=0.0)),
            "residual_mean_m": float(self.residual_max_m[a].mean()) if a.any() else 0.0,
            "gap_error_max_m": float(self.gap_error_max_m.max(initial=0.0)),
            "joint_change_max_rad": float(self.joint_change_max_rad.max(initial=0.0)),
            "wrist_shift_max_m": float(self.wrist_shift_m.max(initial=0.0)),
        }


class HandKinematics:
    """Forward kinematics and point Jacobians of the simulated MANO hand alone (no object).

    Built from the same ``add_hand`` as the scene, so its coordinates are the reference's
    ``ctrl()`` (``HAND_JOINTS`` order) and its capsules are the ones that touch the object.
    """

    def __init__(self, skeleton: HandSkeleton, R_base: np.ndarray, points_per_capsule: int = 3):
        spec = mujoco.MjSpec()
        spec.compiler.degree = False
        spec.compiler.autolimits = True
        hand = add_hand(spec, skeleton, R_base=R_base)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        hand.bind(self.model)
        self.hand = hand
        m = self.model
        self.qpos_adr = hand.qpos_adr
        self.low = np.concatenate([m.jnt_range[_jnt(m, n)][None] for n in HAND_JOINTS])[:, 0]
        self.high = np.concatenate([m.jnt_range[_jnt(m, n)][None] for n in HAND_JOINTS])[:, 1]
        self.low[6:] = np.maximum(self.low[6:], HINGE_LOW)
        self.high[6:] = np.minimum(self.high[6:], HINGE_HIGH)
        geoms = sorted(hand.geom_part)
        u = np.linspace(-1.0, 1.0, points_per_capsule)
        self.geoms = np.repeat(np.array(geoms), len(u))
        self.axis_u = np.tile(u, len(geoms))
        self.radius = m.geom_size[self.geoms, 0]
        self.half = m.geom_size[self.geoms, 1]
        self.point_body = m.geom_bodyid[self.geoms]
        # (joints, bodies): does joint k move body b?
        jnt = np.array([_jnt(m, n) for n in HAND_JOINTS])
        self.jnt = jnt
        self.is_slide = m.jnt_type[jnt] == mujoco.mjtJoint.mjJNT_SLIDE
        moves = np.zeros((len(jnt), m.nbody), dtype=bool)
        for b in range(m.nbody):
            a = b
            while a > 0:
                moves[:, b] |= m.jnt_bodyid[jnt] == a
                a = m.body_parentid[a]
        self.mask = moves[:, self.point_body].T  # (P, 51)
        self.kp_bodies = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "mano_palm")] + [
            mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"mano_{n}") for n in MANO21[1:16]
        ]
        self.tip_sites = hand.tip_sites

    def forward(self, q: np.ndarray) -> None:
        self.data.qpos[self.qpos_adr] = q
        mujoco.mj_kinematics(self.model, self.data)

    def points(self) -> np.ndarray:
        """``(P, 3)`` capsule axis points [m], world (after :meth:`forward`)."""
        d = self.data
        axis = d.geom_xmat[self.geoms].reshape(-1, 3, 3)[:, :, 2]
        return d.geom_xpos[self.geoms] + (self.axis_u * self.half)[:, None] * axis

    def keypoints(self) -> np.ndarray:
        """``(21, 3)`` the simulated hand's keypoints (MANO21), world (after :meth:`forward`)."""
        d = self.data
        return np.concatenate([d.xpos[self.kp_bodies], d.site_xpos[self.tip_sites]])

    def jacobian(self, p: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """``(A, 3, 51)`` translational Jacobians of the world points ``p`` ``(A, 3)``, which
        are capsule points ``rows`` (indices or mask into :meth:`points`), after
        :meth:`forward`."""
        d = self.data
        axis = d.xaxis[self.jnt]  # (51, 3)
        anchor = d.xanchor[self.jnt]
        J = np.cross(axis[None], p[:, None, :] - anchor[None])  # (P, 51, 3)
        J[:, self.is_slide] = axis[self.is_slide][None]
        J *= self.mask[rows][..., None]
        return J.transpose(0, 2, 1)


def _jnt(m: mujoco.MjModel, name: str) -> int:
    return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)


def _posture_weights(cfg: ResizeConfig) -> np.ndarray:
    w = np.empty(len(HAND_JOINTS))
    w[:3] = cfg.posture_wrist_pos
    w[3:6] = cfg.posture_wrist_rot
    w[6:] = [
        cfg.posture_flex if n.endswith("_flex") else cfg.posture_other for n in HAND_JOINTS[6:]
    ]
    return w


def adapt_reference_to_size(
    ref: Reference,
    base,
    geometry,
    source_object_pos: np.ndarray,
    scale: float,
    cfg: ResizeConfig | None = None,
) -> tuple[Reference, ResizeReport]:
    """``ref`` adapted to the object scaled by ``scale`` (module docstring), and a report.

    Args:
        ref: the reference built against the scaled geometry; ``ref.object_pos`` is the track
            the scaled object follows (possibly lifted to keep its table clearance).
        base: the original ``ObjectGeometry`` the hand was captured with.
        geometry: ``base.scaled(scale)``.
        source_object_pos: ``(T, 3)`` the captured object positions [m] the hand relates to
            (``ref.object_pos`` before any lift); orientations are ``ref.object_quat``.
        scale: the size factor.
    """
    cfg = (ResizeConfig() if cfg is None else cfg).validate()
    T = ref.num_frames
    src = np.asarray(source_object_pos, dtype=np.float64)
    if src.shape != (T, 3) or not np.isfinite(src).all():
        raise ValidationError(
            f"source_object_pos must be finite with shape ({T}, 3), got {src.shape}",
            field="source_object_pos",
        )
    if not (np.isfinite(scale) and scale > 0):
        raise ValidationError(f"scale must be positive, got {scale}", field="scale")
    kin = HandKinematics(ref.skeleton, ref.R_base)
    q_ref = ref.ctrl()
    R_o = Rotation.from_quat(ref.object_quat, scalar_first=True).as_matrix()
    w_post = _posture_weights(cfg)
    q_out = q_ref.copy()
    kp_shift = np.zeros((T, len(MANO21), 3))
    adapted = np.zeros(T, dtype=bool)
    residual = np.zeros(T)
    gap_err = np.zeros(T)
    corr = np.zeros(len(HAND_JOINTS))  # the previous frame's correction (warm start)
    for t in range(T):
        kin.forward(q_ref[t])
        p0 = kin.points()
        x = (p0 - src[t]) @ R_o[t]  # object frame (captured pose)
        d, n = base.sdf_and_normal(x)
        gap = d - kin.radius
        beta = np.clip((cfg.far_m - gap) / (cfg.far_m - cfg.near_m), 0.0, 1.0)
        if not (beta > 0).any():
            corr[:] = 0.0
            continue
        adapted[t] = True
        kp0 = kin.keypoints()
        x_new = scale * (x - d[:, None] * n) + d[:, None] * n
        # the mapped point on the simulated object (which may be lifted or lowered to keep
        # its table clearance)
        y = ref.object_pos[t] + x_new @ R_o[t].T
        n_w = n @ R_o[t].T
        nn = n_w[:, :, None] * n_w[:, None, :]
        # square root of the point weights β (n nᵀ + w_t (I − n nᵀ)) (orthogonal projectors)
        W = np.sqrt(beta)[:, None, None] * (nn + np.sqrt(cfg.tangential) * (np.eye(3) - nn))
        q = np.clip(q_ref[t] + corr, kin.low, kin.high)
        for _ in range(cfg.iterations):
            kin.forward(q)
            p = kin.points()
            q = _gauss_newton_step(kin, q, q_ref[t], p, y, W, w_post, cfg.damping)
        q_ik = q
        # fade in over time with the closest point's weight (joint space): pinning the far
        # points to where they were instead would fight the motion of the near ones
        alpha = float(beta.max())
        q = q_ref[t] + alpha * (q_ik - q_ref[t])
        kin.forward(q)
        p = kin.points()
        full = beta >= 1.0
        if full.any():
            residual[t] = np.linalg.norm(p - y, axis=1)[full].max()
            d_new = geometry.signed_distance((p[full] - ref.object_pos[t]) @ R_o[t])
            gap_err[t] = np.abs(d_new - d[full]).max()
        kp_shift[t] = kin.keypoints() - kp0
        q_out[t] = q
        corr = q_ik - q_ref[t]
    dq = q_out - q_ref
    report = ResizeReport(
        scale=float(scale),
        frames_adapted=adapted,
        residual_max_m=residual,
        gap_error_max_m=gap_err,
        joint_change_max_rad=np.abs(dq[:, 6:]).max(axis=1),
        wrist_shift_m=np.linalg.norm(dq[:, :3], axis=1),
    )
    log.info("size adaptation ×%.3f: %s", scale, report.summary())
    return _with_pose(ref, q_out, kp_shift, geometry, R_o), report


def _gauss_newton_step(kin, q, q_ref, p, y, W, w_post, damping) -> np.ndarray:
    """One damped Gauss–Newton step of ``Σ_i ‖W_i (p_i − y_i)‖² + Σ_k w_post,k (q_k −
    q_ref,k)²`` (``W`` ``(P, 3, 3)``) within the joint bounds (coordinates at a bound the step
    pushes against are frozen)."""
    act = np.abs(W).reshape(len(W), -1).max(axis=1) > 0
    J = kin.jacobian(p[act], act)  # (A, 3, 51)
    A = np.einsum("aij,ajk->aik", W[act], J).reshape(-1, J.shape[-1])
    b = np.einsum("aij,aj->ai", W[act], y[act] - p[act]).reshape(-1)
    H = A.T @ A + np.diag(w_post + damping)
    g = A.T @ b - w_post * (q - q_ref)
    step = np.linalg.solve(H, g)
    at_low = (q <= kin.low + 1e-9) & (step < 0)
    at_high = (q >= kin.high - 1e-9) & (step > 0)
    frozen = at_low | at_high
    if frozen.any():
        free = ~frozen
        step = np.zeros_like(q)
        step[free] = np.linalg.solve(H[np.ix_(free, free)], g[free])
    return np.clip(q + step, kin.low, kin.high)


def _with_pose(ref: Reference, q: np.ndarray, kp_shift, geometry, R_o) -> Reference:
    """``ref`` with hand targets ``q`` ``(T, 51)``, its keypoints moved with the hand and the
    fingertip–object relations recomputed against ``geometry``."""
    eul = np.unwrap(q[:, 3:6], axis=0)
    R_w = np.einsum("ij,tjk->tik", ref.R_base, Rotation.from_euler("XYZ", eul).as_matrix())
    kp, tips_obj, tip_d = ref.keypoints, ref.tips_object, ref.tip_distance
    if kp is not None:
        kp = kp + kp_shift
        tips_obj = np.einsum(
            "tji,tkj->tki", R_o, kp[:, FINGERTIPS_MANO21] - ref.object_pos[:, None, :]
        )
        tip_d = geometry.signed_distance(tips_obj.reshape(-1, 3)).reshape(-1, len(FINGERS))
    return dataclasses.replace(
        ref,
        wrist_pos=q[:, :3].copy(),
        wrist_rot=R_w,
        wrist_euler=eul,
        hinges=q[:, 6:].copy(),
        keypoints=kp,
        tips_object=tips_obj,
        tip_distance=tip_d,
    )
