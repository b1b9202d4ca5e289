"""Re-simulation: does the retargeted robot hand really move the object like the human did?

The robot hand (its own position actuators, plus the 6-DoF actuated wrist) tracks the retargeted
joint trajectory in MuJoCo; the object is a free body on a table, starting at the human's first
object pose. Success is the DexCanvas rule: no frame with object position error above 5 cm. The
loose rule of other work (mean error < 10 cm and < 0.5 rad) is reported too, with mean errors,
per-finger contact forces and the deepest hand–object penetration.

The wrist is driven by ``ValidateConfig.wrist_driver`` (:mod:`retarget.wrist_drive`: by default
a force-limited computed-torque controller that follows the commanded wrist trajectory with its
velocity and acceleration fed forward; ``servo``: plain position servos); the finger actuators
track their commands, linearly interpolated within each frame of
:func:`retarget.wrist_drive.frame_steps` physics steps.

Contact forces come from ``mj_contactForce`` after each physics step (the contacts and the
constraint forces of one ``mj_step`` belong to the same forward pass), rotated out of the contact
frame into the world, signed as the force of the hand on the object, and averaged over the
physics steps of each data frame.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from dexcanvas_core.checks import check_fields
from dexcanvas_core.rotations import aa_to_quat_wxyz, quat_wxyz_to_aa, rotation_angle_between_aa
from dexcanvas_core.sim import mujoco_log  # noqa: F401 (MuJoCo's warnings to logging, not a file)
from dexcanvas_core.sim.forces import object_contacts
from dexcanvas_core.sim.mj_warnings import WarningCounter
from dexcanvas_core.sim.scene import OBJECT_ANCHOR, OBJECT_HOLD, add_object_hold
from dexcanvas_core.sim.support import hold_until_frame
from dexcanvas_core.table import DEFAULT_TABLE, Table
from dexcanvas_core.trajectory import Trajectory
from retarget.errors import RetargetError
from retarget.hands.base import WRIST_JOINTS
from retarget.scene import OBJECT_BODY, add_object, add_table, check_table
from retarget.validation_result import ValidationResult
from retarget.wrist_drive import (
    SMOOTHING_HZ,
    WRIST_DRIVERS,
    ComputedTorqueWrist,
    WristReference,
    check_wrist_driver,
    frame_steps,
    use_wrist_motors,
)

log = logging.getLogger(__name__)

FORCE_CONTACT_TIMECONST = 0.02
"""Contact solref time constant [s] of force-matching re-simulations
(``ValidateConfig.contact_timeconst`` in ``retarget run --forces``): the force pipeline's own
(``dexcanvas_core.sim.scene.PhysicsSettings.solref``), so the robot presses the object through
the contact model the human's forces were measured with. Soft contacts give a little: a finger
pressing ``K⁻¹Jᵀf`` into them presses 60–90 % of ``f``, and the force calibration
(:mod:`retarget.force_calibration`) makes up the rest (``docs/method.md``, force matching).
Every hand's and object's collision geoms already carry this ``solref``, so the override's one
remaining effect is zero contact margin. Pinned to the pipeline's by a test."""


def servo_summary(m: dict) -> str | None:
    """One line of :meth:`~retarget.validation_result.ValidationResult.servo_metrics` (in a
    metrics dict ``m``) for the terminal and the report; None when ``m`` has none."""
    servo = m.get("finger_servo_err_mean_deg")
    if not servo:
        return None
    sat = [m.get(f"wrist_{k}_saturation_fraction") or 0.0 for k in ("force", "torque")]
    limits = (
        f" (at its force / torque limit in {100 * sat[0]:.1f} / {100 * sat[1]:.1f} % of the steps)"
        if any(sat)
        else ""
    )
    driver = " (servo driver)" if m.get("wrist_driver") == "servo" else ""
    return (
        f"wrist{driver} {1000 * m['wrist_pos_tracking_err_mean_m']:.1f} mm / "
        f"{m['wrist_rot_tracking_err_mean_deg']:.1f}°{limits}; each finger's worst joint: "
        + ", ".join(f"{k} {v:.1f}°" for k, v in servo.items())
    )


@dataclass(frozen=True)
class ValidateConfig:
    """Re-simulation settings.

    >>> ValidateConfig(contact_timeconst=FORCE_CONTACT_TIMECONST).contact_timeconst
    0.02
    """

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
    pipeline's, ``retarget.validate.FORCE_CONTACT_TIMECONST``)."""
    wrist_driver: str = WRIST_DRIVERS[0]
    """What carries the wrist along its command (:mod:`retarget.wrist_drive`):
    ``computed_torque`` (force-limited, velocity and acceleration fed forward) or ``servo``
    (MuJoCo position servos, the earlier driver)."""
    wrist_smoothing_hz: float | None = SMOOTHING_HZ
    """``computed_torque``: the frequency [Hz] its reference halves (motion well below it
    passes; :meth:`retarget.wrist_drive.WristReference.from_frames`); ``None``: the reference
    goes through every command."""

    def __post_init__(self) -> None:
        check_fields(self, error=RetargetError)
        check_wrist_driver(self.wrist_driver)
        hz = self.wrist_smoothing_hz
        if hz is not None and not (np.isfinite(hz) and hz > 0):
            raise RetargetError(f"wrist_smoothing_hz must be > 0 or None, got {hz}")


def build_sim_spec(
    hand,
    geometry,
    *,
    table: Table | None = DEFAULT_TABLE,
    contact_timeconst: float | None = None,
    wrist_driver: str = WRIST_DRIVERS[0],
) -> mujoco.MjSpec:
    """The ``mujoco.MjSpec`` of :func:`build_sim_scene` (not compiled), for writers of the scene
    (``retarget export --format mujoco``)."""
    spec = hand.build_spec()
    if check_wrist_driver(wrist_driver) == "computed_torque":
        use_wrist_motors(spec)
    if table is not None:
        add_table(spec, table)
    add_object(spec, geometry, mocap=False)
    add_object_hold(spec)
    if contact_timeconst is not None:
        spec.option.enableflags |= mujoco.mjtEnableBit.mjENBL_OVERRIDE
        spec.option.o_solref = [contact_timeconst, 1.0]
        spec.option.o_margin = 0.0
    return spec


def build_sim_scene(
    hand,
    geometry,
    *,
    table: Table | None = DEFAULT_TABLE,
    contact_timeconst: float | None = None,
    wrist_driver: str = WRIST_DRIVERS[0],
) -> mujoco.MjModel:
    """Hand with its actuators + the object as a free body (+ ``table``; ``None``: none).

    ``wrist_driver`` ``computed_torque``: the six wrist actuators are motors
    (:func:`retarget.wrist_drive.use_wrist_motors`); ``servo``: the hand's position servos."""
    return build_sim_spec(
        hand,
        geometry,
        table=table,
        contact_timeconst=contact_timeconst,
        wrist_driver=wrist_driver,
    ).compile()


class Resimulator:
    """Re-simulate retargeted trajectories of one hand with one object on one table.

    ``table``: the table of the trajectories it will run (``dexcanvas_core.table.table_of``;
    default the default table); :meth:`run` refuses a trajectory on another table.

    >>> from dexcanvas_core import load_demonstration, object_geometry
    >>> from retarget import Retargeter, get_hand
    >>> human = load_demonstration("cube2/tripod").slice(0, 30)
    >>> hand, obj = get_hand("shadow"), object_geometry("cube2")
    >>> robot = Retargeter(hand, obj).retarget(human)
    >>> sim = Resimulator(hand, obj).run(robot.q_command, human)
    >>> sim.success, sim.q_sim.shape
    (True, (30, 30))
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
            wrist_driver=self.cfg.wrist_driver,
        )
        m = self.model
        self.object_body = m.body(OBJECT_BODY).id
        jnt = m.body_jntadr[self.object_body]
        self.obj_qadr = int(m.jnt_qposadr[jnt])
        self.obj_vadr = int(m.jnt_dofadr[jnt])
        self.hand_nq = self.obj_qadr  # the hand's joints come first, the object's free joint last
        self.hold_eq = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, OBJECT_HOLD)
        self.anchor_mocap = int(m.body_mocapid[m.body(OBJECT_ANCHOR).id])
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
        self.wrist_act = np.array([m.actuator(f"{j}_act").id for j in WRIST_JOINTS])
        gains = hand.wrist_gains
        self.wrist_force_limit = float(gains.force_slide)
        self.wrist_torque_limit = float(gains.torque_hinge)

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
        # an object that does not rest by itself at its first pose (it leaned on something not
        # captured) is held there until the demonstration moves it
        held_until = (
            hold_until_frame(self.geometry, human, self.table.top_z_m) if self.cfg.table else 0
        )
        self._hold(d, p_obj[0], r_obj[0], held_until > 0)
        mujoco.mj_forward(m, d)
        ts = human.timestamp
        steps = frame_steps(ts, m.opt.timestep)
        wq = np.r_[self.wrist_slide_q, self.wrist_hinge_q]
        wrist = self._wrist_stepper(q[:, wq], steps)
        # the computed-torque driver's reference starts from rest at (nearly) the first command
        q_hold = wrist.reference.q[0] if wrist.driver is not None else q[0, wq]
        hold = (q_hold, np.zeros(6), np.zeros(6))
        for _ in range(round(self.cfg.settle_s / m.opt.timestep)):
            wrist.reset_peaks()  # frame 0 (no steps of its own) gets the settling's last
            wrist.step(d, *hold)
        wrist.reset_counts()
        warnings = WarningCounter()
        warnings.update(d, 0)  # the settling counts as frame 0
        F = len(self.fingers) + 1
        forces = np.zeros((T, F, 3))
        pos_sim = np.zeros((T, 3))
        q_sim = np.zeros((T, self.hand_nq))
        rot_sim = np.zeros((T, 3))
        force_peak = np.zeros(T)
        torque_peak = np.zeros(T)
        pen = 0.0
        ref = wrist.reference
        for t in range(T):
            if t == held_until:
                self._hold(d, p_obj[0], r_obj[0], False)
            n_sub = int(steps[t] - steps[t - 1]) if t > 0 else 0
            acc = np.zeros((F, 3))
            n_read = 0
            if n_sub:
                wrist.reset_peaks()
            for k in range(n_sub):
                a = (k + 1) / n_sub
                d.ctrl[:] = ((1 - a) * q[t - 1] + a * q[t])[self.act_q]
                j = steps[t - 1] + k
                wrist.step(d, ref.q[j], ref.v[j], ref.a[j])
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
            force_peak[t], torque_peak[t] = wrist.force_peak, wrist.torque_peak
            warnings.update(d, t)
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
            success=over.size == 0 and not warnings.blew_up,
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
            wrist_rot_err=_euler_angle_between(
                q_sim[:, self.wrist_hinge_q], q[:, self.wrist_hinge_q]
            ),
            wrist_force_peak=force_peak,
            wrist_torque_peak=torque_peak,
            object_held_until_frame=held_until if held_until < T else T,
            mujoco_warnings=warnings.to_dict(),
            meta={
                "integrator": "implicitfast",
                "cone": "elliptic",
                "impratio": float(m.opt.impratio),
                "timestep": float(m.opt.timestep),
                "wrist_driver": self.cfg.wrist_driver,
                "wrist_force_limit_n": self.wrist_force_limit,
                "wrist_torque_limit_nm": self.wrist_torque_limit,
                "wrist_force_saturation_fraction": wrist.force_saturated / max(wrist.steps, 1),
                "wrist_torque_saturation_fraction": wrist.torque_saturated / max(wrist.steps, 1),
            },
        )

    def _wrist_stepper(self, q_wrist: np.ndarray, steps: np.ndarray) -> _WristStepper:
        m = self.model
        if self.cfg.wrist_driver == "computed_torque":
            ref = WristReference.from_frames(
                q_wrist, steps, m.opt.timestep, self.cfg.wrist_smoothing_hz
            )
            driver = ComputedTorqueWrist(m, self.hand.wrist_gains)
        else:
            n = int(steps[-1]) + 1  # the servos take the interpolated commands from ``ctrl``
            ref = WristReference(q=np.zeros((n, 6)), v=np.zeros((n, 6)), a=np.zeros((n, 6)))
            driver = None
        return _WristStepper(self, driver, ref)

    def _hold(self, d: mujoco.MjData, pos: np.ndarray, rot_aa: np.ndarray, on: bool) -> None:
        """Weld the object to its pose ``(pos, rot_aa)`` (``on``), or let it go."""
        if on:
            d.mocap_pos[self.anchor_mocap] = pos
            d.mocap_quat[self.anchor_mocap] = aa_to_quat_wxyz(rot_aa)
        d.eq_active[self.hold_eq] = int(on)

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


def _euler_angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(T,) [rad] rotation angle between the wrist orientations of hinge angles ``a`` and
    ``b`` (T, 3) (intrinsic X-Y-Z, ``retarget.hands.base``)."""
    ra = Rotation.from_euler("XYZ", a)
    rb = Rotation.from_euler("XYZ", b)
    return (ra.inv() * rb).magnitude()


class _WristStepper:
    """One physics step of a re-simulation with its wrist driver, and the arm's force on the
    wrist measured after it (module :mod:`retarget.wrist_drive`).

    The measured force is the wrist actuators' plus their gravity compensation, per step;
    ``force_peak`` [N] (norm over the slides) and ``torque_peak`` [N·m] (largest hinge) since
    :meth:`reset_peaks`; ``steps`` and the saturated steps since :meth:`reset_counts` (the
    ``computed_torque`` driver's limits, or a servo at its force range).
    """

    def __init__(self, sim: Resimulator, driver: ComputedTorqueWrist | None, ref: WristReference):
        self.m = sim.model
        self.driver = driver
        self.reference = ref
        self.act = sim.wrist_act
        self.range = self.m.actuator_forcerange[self.act, 1] * (1 - 1e-9)
        self.limited = self.m.actuator_forcelimited[self.act].astype(bool)
        self.reset_counts()
        self.reset_peaks()

    def reset_peaks(self) -> None:
        self.force_peak = self.torque_peak = 0.0

    def reset_counts(self) -> None:
        self.steps = self.force_saturated = self.torque_saturated = 0
        if self.driver is not None:
            self.driver.reset_counts()

    def step(self, d: mujoco.MjData, q_ref, v_ref, a_ref) -> None:
        m = self.m
        if self.driver is None:
            mujoco.mj_step(m, d)
            f = np.abs(d.actuator_force[self.act])
            at = self.limited & (f >= self.range)
            self.force_saturated += bool(at[:3].any())
            self.torque_saturated += bool(at[3:].any())
            self.steps += 1
        else:
            mujoco.mj_step1(m, d)
            self.driver.apply(m, d, q_ref, v_ref, a_ref)
            mujoco.mj_step2(m, d)
            self.force_saturated = self.driver.force_saturated
            self.torque_saturated = self.driver.torque_saturated
            self.steps = self.driver.steps
        f = d.actuator_force[self.act] + d.qfrc_gravcomp[:6]
        self.force_peak = max(self.force_peak, float(np.sqrt(f[:3] @ f[:3])))
        self.torque_peak = max(self.torque_peak, float(np.abs(f[3:]).max()))
