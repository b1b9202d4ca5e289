"""Force matching: robot contact forces close to the human's that still move the object.

Kinematic retargeting puts robot fingertips where the human's were; it says nothing about how
hard they press. From the human trajectory's per-finger contact forces (the force pipeline's
output, ``dexcanvas simulate``) this module

1. chooses robot contact forces with a **contact-force distribution QP** (:func:`distribute`):
   closest to the human forces of the corresponding fingers, subject to friction cones
   (linearised, ``n_facets`` sides), non-negative normal forces and, when given, the robot's
   joint torque limits ``|Σ J_iᵀ f_i| ≤ τ_max``, while producing the object wrench the human's
   contacts produced (a heavily weighted least-squares term, so an infeasible request is met as
   closely as possible and the shortfall reported rather than failing);
2. turns them into joint position-target offsets through the servo gains,
   ``Δq = K⁻¹ Σ_i J_iᵀ f_i`` (:func:`squeeze_offsets`): a position-controlled finger blocked by
   the object then presses with ``f_i``.

Fewer robot fingers than human ones (four-finger hands, grippers): the wrench term
redistributes the missing fingers' share over the others; the shortfall says how much of the
required wrench was out of reach.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from dexcanvas_core.rotations import tangent_basis
from retarget._checks import check_range
from retarget.errors import RetargetError
from retarget.qp import QPProblem, QPSolveError, solve_qp


@dataclass(frozen=True, kw_only=True)
class ForceMatchingConfig:
    """Force matching: the human's per-finger contact forces (force pipeline output)
    distributed over the robot's contacts by the force QP (:func:`distribute`) and applied
    through the servo gains (:func:`squeeze_offsets`), in place of the grip. Needs a trajectory
    with contact records carrying forces. Chosen on the force-preservation benchmark;
    docs/method.md#2-pressing-the-grip-and-force-matching."""

    enabled: bool = False
    """Replace the grip by force matching. Default False."""
    scale: float = 1.0
    """Multiple of the human's per-finger forces asked of the force QP (the object's wrench
    stays the required one, so the extra is squeeze between the fingers). Default 1."""
    tangent_weight: float = 0.05
    """``ContactsConfig.tangent_weight`` when force matching is on. Default 0.05."""
    idle_contact_clearance: float | None = 0.001
    """A finger the captured hand touches the object with while the human's simulated finger
    does not press is commanded this far [m] off the surface where the kinematic solution
    leaves it nearer; None: its command is the kinematic solution. Default 0.001."""

    def __post_init__(self):
        check_range(self, "scale", positive=True)
        check_range(self, "tangent_weight")
        check_range(self, "idle_contact_clearance", optional=True, upper=0.02, unit="m")


def grasp_matrix(points: np.ndarray, center: np.ndarray) -> np.ndarray:
    """``(6, 3k)``: maps stacked contact forces to the wrench (force, torque about ``center``)."""
    r = np.asarray(points, dtype=np.float64).reshape(-1, 3) - center
    k = r.shape[0]
    G = np.zeros((6, k, 3))
    G[0, :, 0] = G[1, :, 1] = G[2, :, 2] = 1.0
    # torque r × f: rows [0, −r_z, r_y], [r_z, 0, −r_x], [−r_y, r_x, 0]
    G[3, :, 1], G[3, :, 2] = -r[:, 2], r[:, 1]
    G[4, :, 0], G[4, :, 2] = r[:, 2], -r[:, 0]
    G[5, :, 0], G[5, :, 1] = -r[:, 1], r[:, 0]
    return G.reshape(6, 3 * k)


@dataclass
class ForceDistribution:
    """Result of :func:`distribute` (world frame, forces on the object)."""

    forces: np.ndarray  # (k, 3) [N]
    wrench: np.ndarray  # (6,) produced [N, N·m]
    wrench_required: np.ndarray  # (6,)
    wrench_error: np.ndarray  # (6,) produced − required
    tracking_error: np.ndarray  # (k,) ‖f_i − f_desired_i‖ [N]

    @property
    def force_shortfall_n(self) -> float:
        return float(np.linalg.norm(self.wrench_error[:3]))

    @property
    def torque_shortfall_nm(self) -> float:
        return float(np.linalg.norm(self.wrench_error[3:]))


def distribute(
    points: np.ndarray,
    normals: np.ndarray,
    f_desired: np.ndarray,
    wrench_required: np.ndarray,
    center: np.ndarray,
    *,
    mu: float = 0.8,
    n_facets: int = 8,
    jacobians: list[np.ndarray] | None = None,
    tau_max: np.ndarray | None = None,
    w_wrench: float = 100.0,
    w_torque: float = 1e4,
    f_max: float = 50.0,
) -> ForceDistribution:
    """The force-distribution QP (module docstring).

    Args:
        points: ``(k, 3)`` contact points [m]; ``normals``: ``(k, 3)`` the object's outward unit
            normals there (a contact pushes along ``-n``).
        f_desired: ``(k, 3)`` the human forces of the corresponding fingers [N].
        wrench_required: ``(6,)`` force [N] and torque about ``center`` [N·m] to produce.
        mu: friction coefficient of the linearised cones (inner pyramid, conservative).
        jacobians, tau_max: optional ``(3, n)`` contact Jacobians over the robot's finger joints
            and ``(n,)`` torque limits [N·m]: ``|Σ J_iᵀ f_i| ≤ τ_max``.
        w_wrench, w_torque: weights of the force and torque parts of the wrench term (torques
            in N·m are small numbers; ``w_torque`` puts them on the forces' scale).
        f_max: bound on each force component [N] (keeps the QP bounded).
    """
    P_ = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    N_ = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    F_ = np.asarray(f_desired, dtype=np.float64).reshape(-1, 3)
    W = np.asarray(wrench_required, dtype=np.float64).reshape(6)
    k = P_.shape[0]
    if N_.shape[0] != k or F_.shape[0] != k:
        raise RetargetError(f"points, normals and f_desired must all have {k} rows")
    for name, a in (("points", P_), ("normals", N_), ("f_desired", F_), ("wrench", W)):
        if not np.isfinite(a).all():
            raise RetargetError(f"force distribution: {name} has NaN or inf")
    if k == 0:
        return ForceDistribution(np.zeros((0, 3)), np.zeros(6), W, -W, np.zeros(0))
    G = grasp_matrix(P_, np.asarray(center, dtype=np.float64))
    Wd = np.diag([w_wrench] * 3 + [w_torque] * 3)
    # ½ xᵀ P x + qᵀ x  with  ‖x − f_des‖² + (Gx − W)ᵀ Wd (Gx − W)
    P = 2.0 * (np.eye(3 * k) + G.T @ Wd @ G)
    q = -2.0 * (F_.reshape(-1) + G.T @ Wd @ W)
    angles = 2 * np.pi * np.arange(n_facets) / n_facets
    c = np.cos(np.pi / n_facets)  # inner pyramid: facets inside the true cone
    # Per contact: n_facets facet rows (cos a t₁ + sin a t₂)·f − μ cos(π/n) u·f ≤ 0 and
    # −u·f ≤ 0, with u = −n the direction the contact pushes the object.
    cone = np.empty((k, n_facets + 1, 3))
    for i in range(k):
        u = -N_[i] / np.linalg.norm(N_[i])
        t1, t2 = tangent_basis(u)
        cone[i, :n_facets] = (
            np.cos(angles)[:, None] * t1 + np.sin(angles)[:, None] * t2 - mu * c * u
        )
        cone[i, n_facets] = -u
    Gin = np.zeros((k, n_facets + 1, k, 3))
    Gin[np.arange(k), :, np.arange(k), :] = cone
    Gin = Gin.reshape(k * (n_facets + 1), 3 * k)
    hin = np.zeros(Gin.shape[0])
    if jacobians is not None and tau_max is not None:
        JT = np.concatenate([np.asarray(J, dtype=np.float64).T for J in jacobians], axis=1)
        Gin = np.concatenate([Gin, JT, -JT])
        hin = np.concatenate([hin, tau_max, tau_max])
    problem = QPProblem(
        P=P, q=q, G=Gin, h=hin, A=np.zeros((0, 3 * k)), b=np.zeros(0),
        lb=np.full(3 * k, -f_max), ub=np.full(3 * k, f_max),
    )  # fmt: skip
    try:
        x = solve_qp(problem, "daqp")
    except QPSolveError:
        raise RetargetError("force distribution QP found no solution") from None
    f = x.reshape(k, 3)
    wrench = G @ x
    return ForceDistribution(
        forces=f,
        wrench=wrench,
        wrench_required=W,
        wrench_error=wrench - W,
        tracking_error=np.linalg.norm(f - F_, axis=1),
    )


def squeeze_offsets(jacobians: list[np.ndarray], forces: np.ndarray, kp: np.ndarray) -> np.ndarray:
    """``Δq = K⁻¹ Σ_i J_iᵀ f_i``: joint-target offsets [rad] that make position servos with
    gains ``kp`` (``(n,)`` [N·m/rad], ``inf`` for joints without a servo) press with ``forces``
    (``(k, 3)``, on the object) once the object blocks the fingers."""
    tau = np.zeros(len(kp))
    for J, f in zip(jacobians, np.asarray(forces).reshape(-1, 3), strict=True):
        tau += np.asarray(J).T @ f
    with np.errstate(divide="ignore"):
        out = np.where(np.isfinite(kp) & (kp > 0), tau / np.where(kp > 0, kp, 1.0), 0.0)
    return out


def servo_gains(model: mujoco.MjModel, nq: int) -> tuple[np.ndarray, np.ndarray]:
    """``(kp, tau_max)`` per hand joint (the first ``nq`` of ``qpos``, a floating wrist's 6
    first): position-servo gain [N·m/rad or N/m] and force limit of the finger joints'
    actuators (``inf`` where none: the wrist, passive joints)."""
    kp = np.full(nq, np.inf)
    tau_max = np.full(nq, np.inf)
    for a in range(model.nu):
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
            continue
        dof = model.jnt_dofadr[model.actuator_trnid[a, 0]]
        if dof < 6 or dof >= nq:
            continue
        kp[dof] = model.actuator_gainprm[a, 0]
        if model.actuator_forcelimited[a]:
            tau_max[dof] = model.actuator_forcerange[a, 1]
    return kp, tau_max
