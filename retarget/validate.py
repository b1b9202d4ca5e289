"""Re-simulation: does the retargeted robot hand really move the object like the human did?

The robot hand (its own position actuators, plus the 6-DoF actuated wrist) tracks the retargeted
joint trajectory in MuJoCo; the object is a free body on a table, starting at the human's first
object pose. Success is the DexCanvas rule: no frame with object position error above 5 cm. The
loose rule of other work (mean error < 10 cm and < 0.5 rad) is reported too, with mean errors,
per-finger contact forces and the deepest hand–object penetration.

Contact forces come from ``mj_contactForce`` after each physics step (the contacts and the
constraint forces of one ``mj_step`` belong to the same forward pass), rotated out of the contact
frame into the world, signed as the force of the hand on the object, and averaged over the
physics steps of each data frame.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from dexcanvas_core.rotations import aa_to_quat_wxyz, quat_wxyz_to_aa, rotation_angle_between_aa
from dexcanvas_core.sim.forces import object_contacts
from dexcanvas_core.table import DEFAULT_TABLE, Table
from dexcanvas_core.trajectory import Trajectory
from retarget.errors import RetargetError
from retarget.hands.base import WRIST_JOINTS
from retarget.scene import OBJECT_BODY, add_object, add_table, check_table

log = logging.getLogger(__name__)


def servo_summary(m: dict) -> str | None:
    """One line of :meth:`ValidationResult.servo_metrics` (in a metrics dict ``m``) for the
    terminal and the report; None when ``m`` has none."""
    servo = m.get("finger_servo_err_mean_deg")
    if not servo:
        return None
    return (
        f"wrist {1000 * m['wrist_pos_tracking_err_mean_m']:.1f} mm / "
        f"{m['wrist_rot_tracking_err_mean_deg']:.1f}°; each finger's worst joint: "
        + ", ".join(f"{k} {v:.1f}°" for k, v in servo.items())
    )


@dataclass(frozen=True)
class ValidateConfig:
    """Re-simulation settings."""

    success_threshold_m: float = 0.05
    """DexCanvas rule: a frame with object position error above this fails the rollout [m]."""
    loose_pos_m: float = 0.10
    """Loose rule: mean position error below this [m] ..."""
    loose_rot_rad: float = 0.5
    """... and mean rotation error below this [rad]."""
    settle_s: float = 0.3
    """Time [s] the scene settles at the first frame (object resting, hand holding) first."""
    table: bool = True
    """Put the table under the object (the one given to :class:`Resimulator`)."""
    contact_timeconst: float | None = None
    """Override every contact's ``solref`` time constant [s] (force matching: the force
    pipeline's, ``retarget.run.FORCE_CONTACT_TIMECONST``)."""


@dataclass
class ValidationResult:
    """What the re-simulation measured (arrays are per data frame)."""

    success: bool
    success_loose: bool
    object_pos_err: np.ndarray
    """(T,) [m]."""
    object_rot_err: np.ndarray
    """(T,) [rad]."""
    object_pos_sim: np.ndarray
    """(T, 3) [m] simulated object position."""
    object_rot_sim: np.ndarray
    """(T, 3) [rad] simulated object orientation (axis-angle)."""
    finger_force_world: np.ndarray
    """(T, F + 1, 3) [N]: force of each robot finger (``fingers`` order) and the palm on the
    object, world frame, averaged over the physics steps of the frame."""
    fingers: list[str]
    penetration_max_m: float
    """Deepest hand–object penetration seen [m] (0 if none)."""
    first_failure_frame: int | None
    timestep: float
    meta: dict = field(default_factory=dict)
    q_sim: np.ndarray | None = None
    """(T, hand_nq) simulated hand joint positions at the end of each frame."""
    finger_servo_err: np.ndarray | None = None
    """(T, F) [rad] per robot finger (``fingers`` order), the largest ``|q_sim − q_command|``
    over its actuated joints at the end of each frame: how far its servos trail the command (a
    finger the object blocks trails it by design, by its force offset)."""
    wrist_pos_err: np.ndarray | None = None
    """(T,) [m] distance of the simulated wrist (its three slide joints) from the command."""
    wrist_rot_err: np.ndarray | None = None
    """(T,) [rad] largest ``|q_sim − q_command|`` over the wrist's three hinge joints."""

    @property
    def object_pos_err_max_m(self) -> float:
        return float(self.object_pos_err.max())

    @property
    def object_pos_err_mean_m(self) -> float:
        return float(self.object_pos_err.mean())

    @property
    def object_rot_err_mean_rad(self) -> float:
        return float(self.object_rot_err.mean())

    def servo_metrics(self) -> dict:
        """Mean servo tracking errors (empty when the rollout did not record them)."""
        if self.finger_servo_err is None or self.wrist_pos_err is None:
            return {}
        return {
            "finger_servo_err_mean_deg": {
                f: float(np.degrees(self.finger_servo_err[:, i].mean()))
                for i, f in enumerate(self.fingers)
            },
            "wrist_pos_tracking_err_mean_m": float(self.wrist_pos_err.mean()),
            "wrist_rot_tracking_err_mean_deg": float(np.degrees(self.wrist_rot_err.mean())),
        }

    def metrics(self) -> dict:
        return {
            "success": bool(self.success),
            "success_loose": bool(self.success_loose),
            "object_pos_err_max_m": self.object_pos_err_max_m,
            "object_pos_err_mean_m": self.object_pos_err_mean_m,
            "object_rot_err_mean_rad": self.object_rot_err_mean_rad,
            "penetration_max_m": float(self.penetration_max_m),
            "first_failure_frame": self.first_failure_frame,
            "finger_force_mean_n": {
                f: float(np.linalg.norm(self.finger_force_world[:, i], axis=1).mean())
                for i, f in enumerate([*self.fingers, "palm"])
            },
            **self.servo_metrics(),
        }


def build_sim_scene(
    hand, geometry, *, table: Table | None = DEFAULT_TABLE, contact_timeconst: float | None = None
) -> mujoco.MjModel:
    """Hand with its actuators + the object as a free body (+ ``table``; ``None``: none)."""
    spec = hand.build_spec()
    if table is not None:
        add_table(spec, table)
    add_object(spec, geometry, mocap=False)
    if contact_timeconst is not None:
        spec.option.enableflags |= mujoco.mjtEnableBit.mjENBL_OVERRIDE
        spec.option.o_solref = [contact_timeconst, 1.0]
        spec.option.o_margin = 0.0
    return spec.compile()


class Resimulator:
    """Re-simulate retargeted trajectories of one hand with one object on one table.

    ``table``: the table of the trajectories it will run (``dexcanvas_core.table.table_of``;
    default the default table); :meth:`run` refuses a trajectory on another table.
    """

    def __init__(
        self, hand, geometry, config: ValidateConfig | None = None, table: Table | None = None
    ):
        self.hand = hand
        self.geometry = geometry
        self.cfg = config or ValidateConfig()
        self.table = DEFAULT_TABLE if table is None else table
        self.model = build_sim_scene(
            hand,
            geometry,
            table=self.table if self.cfg.table else None,
            contact_timeconst=self.cfg.contact_timeconst,
        )
        m = self.model
        self.object_body = m.body(OBJECT_BODY).id
        jnt = m.body_jntadr[self.object_body]
        self.obj_qadr = int(m.jnt_qposadr[jnt])
        self.obj_vadr = int(m.jnt_dofadr[jnt])
        self.hand_nq = self.obj_qadr  # the hand's joints come first, the object's free joint last
        # Actuator → hand qpos index of the joint it drives.
        self.act_q = np.array([m.jnt_qposadr[m.actuator_trnid[a, 0]] for a in range(m.nu)])
        parts = hand.hand_parts(m)
        self.fingers = [f for f in hand.robot_fingers]
        body_part = np.full(m.nbody, -1)
        for i, f in enumerate([*self.fingers, "palm"]):
            for bname in parts.get(f, []):
                body_part[m.body(bname).id] = i
        self.body_part = body_part
        # Per actuator: the finger (index into ``fingers``) its joint moves, -1 for the wrist
        # and the palm; the wrist's slide and hinge joints (qpos indices).
        jb = m.jnt_bodyid[[m.actuator_trnid[a, 0] for a in range(m.nu)]]
        self.act_finger = np.where(body_part[jb] < len(self.fingers), body_part[jb], -1)
        wq = [int(m.jnt_qposadr[m.joint(j).id]) for j in WRIST_JOINTS]
        self.wrist_slide_q, self.wrist_hinge_q = np.array(wq[:3]), np.array(wq[3:])

    def run(
        self,
        q: np.ndarray,
        human: Trajectory,
        progress: Callable[[int, int], None] | None = None,
    ) -> ValidationResult:
        """Track ``q`` (T, hand_nq) at the human trajectory's timestamps (module docstring)."""
        m = self.model
        q = np.asarray(q, dtype=np.float64)
        T = human.num_frames
        if q.shape != (T, self.hand_nq):
            raise RetargetError(
                f"joint trajectory has shape {q.shape}, expected ({T}, {self.hand_nq})"
            )
        if not np.all(np.isfinite(q)):
            raise RetargetError("joint trajectory contains NaN or inf")
        if self.cfg.table:
            check_table(self.table, human, "Resimulator")
        d = mujoco.MjData(m)
        p_obj = human.object.pos.astype(np.float64)
        r_obj = human.object.rot_aa.astype(np.float64)
        d.qpos[: self.hand_nq] = q[0]
        d.qpos[self.obj_qadr : self.obj_qadr + 3] = p_obj[0]
        d.qpos[self.obj_qadr + 3 : self.obj_qadr + 7] = aa_to_quat_wxyz(r_obj[0])
        d.ctrl[:] = q[0][self.act_q]
        mujoco.mj_forward(m, d)
        for _ in range(round(self.cfg.settle_s / m.opt.timestep)):
            mujoco.mj_step(m, d)
        F = len(self.fingers) + 1
        forces = np.zeros((T, F, 3))
        pos_sim = np.zeros((T, 3))
        q_sim = np.zeros((T, self.hand_nq))
        rot_sim = np.zeros((T, 3))
        pen = 0.0
        ts = human.timestamp
        for t in range(T):
            dt = (ts[t] - ts[t - 1]) if t > 0 else 0.0
            n_sub = max(round(dt / m.opt.timestep), 0 if t == 0 else 1)
            acc = np.zeros((F, 3))
            n_read = 0
            for k in range(n_sub):
                a = (k + 1) / n_sub
                d.ctrl[:] = ((1 - a) * q[t - 1] + a * q[t])[self.act_q]
                mujoco.mj_step(m, d)
                f, p = self._contact_forces(d)
                acc += f
                pen = max(pen, p)
                n_read += 1
            if n_read == 0:
                mujoco.mj_forward(m, d)
                f, p = self._contact_forces(d)
                acc, n_read, pen = f, 1, max(pen, p)
            forces[t] = acc / n_read
            pos_sim[t] = d.qpos[self.obj_qadr : self.obj_qadr + 3]
            q_sim[t] = d.qpos[: self.hand_nq]
            rot_sim[t] = quat_wxyz_to_aa(d.qpos[self.obj_qadr + 3 : self.obj_qadr + 7])
            if progress is not None:
                progress(t + 1, T)
            if not np.all(np.isfinite(d.qpos)):
                raise RetargetError(f"simulation diverged at frame {t} (non-finite state)")
        pos_err = np.linalg.norm(pos_sim - p_obj, axis=1)
        dq = np.abs(q_sim - q)
        act_err = dq[:, self.act_q]
        finger_servo = np.zeros((T, len(self.fingers)))
        for i in range(len(self.fingers)):
            cols = self.act_finger == i
            if cols.any():
                finger_servo[:, i] = act_err[:, cols].max(axis=1)
        rot_err = rotation_angle_between_aa(rot_sim, r_obj)
        over = np.flatnonzero(pos_err > self.cfg.success_threshold_m)
        return ValidationResult(
            success=over.size == 0,
            success_loose=bool(
                pos_err.mean() < self.cfg.loose_pos_m and rot_err.mean() < self.cfg.loose_rot_rad
            ),
            object_pos_err=pos_err,
            object_rot_err=rot_err,
            object_pos_sim=pos_sim,
            object_rot_sim=rot_sim,
            finger_force_world=forces,
            fingers=list(self.fingers),
            penetration_max_m=pen,
            first_failure_frame=int(over[0]) if over.size else None,
            timestep=float(m.opt.timestep),
            q_sim=q_sim,
            finger_servo_err=finger_servo,
            wrist_pos_err=np.linalg.norm(
                q_sim[:, self.wrist_slide_q] - q[:, self.wrist_slide_q], axis=1
            ),
            wrist_rot_err=dq[:, self.wrist_hinge_q].max(axis=1),
            meta={
                "integrator": "implicitfast",
                "cone": "elliptic",
                "impratio": float(m.opt.impratio),
                "timestep": float(m.opt.timestep),
            },
        )

    def _contact_forces(self, d: mujoco.MjData) -> tuple[np.ndarray, float]:
        """(F+1, 3) hand-part forces on the object [N] and the deepest penetration [m]."""
        out = np.zeros((len(self.fingers) + 1, 3))
        pen = 0.0
        for c in object_contacts(self.model, d, self.object_body):
            part = self.body_part[c.other_body]
            if part < 0:
                continue  # the table
            out[part] += c.force
            pen = max(pen, -c.dist)
        return out, pen
