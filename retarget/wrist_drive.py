"""The re-simulation's wrist driver: the arm that carries the robot hand along the command.

The robot hand hangs from a 6-DoF floating wrist (slides ``wrist_tx/ty/tz``, then hinges
``wrist_rx/ry/rz``; :mod:`retarget.hands.base`). The arm that would carry it is not modelled;
a driver stands in for it. Two are available (``ValidateConfig.wrist_driver``):

``computed_torque`` (default)
    A force-limited computed-torque controller, written into the ``ctrl`` of six motor
    actuators (gear 1) between ``mj_step1`` and ``mj_step2`` of every physics step, from that
    step's state::

        f_arm = M_ww a_ref + K_p (q_ref − q) + K_d (v_ref − v) + c_w
        f_arm ← limits(f_arm);  ctrl = f_arm − g_w

    * ``q_ref, v_ref, a_ref`` — the commanded wrist trajectory (:class:`WristReference`): a
      cubic smoothing spline through the commanded wrist joints at the data frames (each at
      the physics step where its frame ends), which passes a human wrist's motion and not a
      single frame's jump (``smoothing_hz``), sampled at every physics step; ``v_ref`` and
      ``a_ref`` are the backward and central differences of those samples over one step, the
      velocity and acceleration MuJoCo's semi-implicit integrator realises, so that a hand
      following the samples exactly needs exactly this feed-forward.
    * ``M_ww`` — the 6 × 6 wrist block of the joint-space inertia (the whole hand as one rigid
      body carried by the wrist, armature included); the fingers' own accelerations are left
      to the feedback.
    * ``K_p`` — ``WristGains.kp_slide`` [N/m] and ``kp_hinge`` [N·m/rad], the stiffness of the
      position servos this driver replaces (held under a steady load, both sag the same);
      ``K_d = 2 ζ sqrt(K_p · diag M_ww)`` per joint (``ζ = WristGains.dampratio``).
    * ``c_w`` — the bias force on the wrist joints: Coriolis, centrifugal and gravity
      (``qfrc_bias``), less the passive forces other than gravity compensation. The arm
      therefore carries the hand's weight, and the weight counts against its force limit.
      ``g_w`` — the wrist components of MuJoCo's gravity compensation (``gravcomp`` 1 on every
      hand body, kept so that the finger servos are not asked to hold their links): applied
      passively, so it is taken off the motors' ``ctrl``; the arm's total force on the wrist,
      ``actuator_force + g_w``, is ``f_arm`` after the limits.
    * limits — the force on the wrist (its three slide components, world axes) is scaled down
      to a norm of at most ``WristGains.force_slide`` [N] (direction kept); each hinge's
      torque is clipped to ± ``WristGains.torque_hinge`` [N·m] (about the hinge axes, which
      are orthogonal only at zero angles). Design values of an arm-like carrier (200 N,
      20 N·m by default), not any robot arm's specification.

    Contacts on the hand (the object, the table) are disturbances the feedback answers, with
    the stiffness of the servos: nothing about them is fed forward, and the object is moved
    by contacts only.

``servo``
    MuJoCo position servos on the six joints (``WristGains``: ``kp_slide``, ``kp_hinge``,
    critically damped, force range ± ``force_slide`` / ``torque_hinge`` per joint), the
    commands linearly interpolated within each frame: a servo trails a target moving at speed
    ``v`` by about ``2 v / ω_n`` (``ω_n = sqrt(kp / m)``).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from retarget.errors import RetargetError
from retarget.hands.base import WRIST_JOINTS, WristGains

WRIST_DRIVERS: tuple[str, ...] = ("computed_torque", "servo")
"""The re-simulation's wrist drivers (module docstring); the first is the default."""

SMOOTHING_HZ = 15.0
"""[Hz] Default frequency that the ``computed_torque`` driver's reference halves
(:meth:`WristReference.from_frames`): a human wrist's carry (2.5 m/s, 15 m/s²) passes within
a fraction of a millimetre, while a one-frame jump in retargeted commands (a few millimetres
out and back) is not fed forward as a 200 N kick."""


def check_wrist_driver(name: str) -> str:
    """``name`` if it is a wrist driver, else a :class:`RetargetError` listing them."""
    if name not in WRIST_DRIVERS:
        raise RetargetError(
            f"unknown wrist driver {name!r}; choose one of {', '.join(WRIST_DRIVERS)}"
        )
    return name


def use_wrist_motors(spec) -> None:
    """Turn the six wrist actuators of a hand's ``MjSpec`` into unlimited motors (gear 1):
    the ``computed_torque`` driver writes their forces and applies the limits itself."""
    for jn in WRIST_JOINTS:
        act = spec.actuator(f"{jn}_act")
        if act is None:
            raise RetargetError(f"the model has no wrist actuator {jn}_act")
        act.set_to_motor()
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_FALSE


def frame_steps(timestamp: np.ndarray, timestep: float) -> np.ndarray:
    """(T,) the physics step, counted from the first frame (0), at whose end each data frame is
    reached: frame ``t`` takes ``max(round((timestamp[t] − timestamp[t − 1]) / timestep), 1)``
    steps. Frames shorter than a whole number of steps are rounded each on its own (120 Hz
    data at a 2 ms timestep: 4 steps, 8 ms, per 8.33 ms frame)."""
    ts = np.asarray(timestamp, dtype=np.float64)
    n = np.maximum(np.rint(np.diff(ts) / timestep), 1).astype(np.int64)
    return np.concatenate([[0], np.cumsum(n)])


@dataclass(frozen=True)
class WristReference:
    """The commanded wrist trajectory sampled at the physics steps (module docstring).

    Row ``j`` belongs to physics step ``j`` (from the first frame, before which the wrist
    rests at the first command): ``q`` [m, rad] the reference at the step's start, ``v``
    [m/s, rad/s] its backward difference, ``a`` [m/s², rad/s²] its central second difference.
    """

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray

    @classmethod
    def from_frames(
        cls,
        q_wrist: np.ndarray,
        steps: np.ndarray,
        timestep: float,
        smoothing_hz: float | None = SMOOTHING_HZ,
    ) -> WristReference:
        """From the commanded wrist joints ``q_wrist`` (T, 6) reached at physics steps
        ``steps`` (T,) (:func:`frame_steps`) of ``timestep`` [s]: rows for steps 0 …
        ``steps[-1]``.

        The samples are those of a cubic smoothing spline through the commands (hinge angles
        unwrapped), resting at the first command before the first frame and at the last after
        the last (the commands repeated there, so the settled hand starts from rest), whose
        roughness weight ``λ = 1 / (h (2π f_c)⁴)`` (``h`` the median frame interval in
        simulated time, ``f_c = smoothing_hz``) halves a sinusoid of frequency ``f_c`` and
        passes slower motion nearly unchanged (gain ``1 / (1 + (f / f_c)⁴)``). ``None``: the
        interpolating spline (through every command).
        """
        from scipy.interpolate import make_smoothing_spline

        q = np.array(q_wrist, dtype=np.float64)
        q[:, 3:] = np.unwrap(q[:, 3:], axis=0)
        n = int(steps[-1])
        if len(q) < 2:
            samples = np.repeat(q[:1], n + 2, axis=0)
        else:
            x = np.asarray(steps, np.float64) * timestep
            h = float(np.median(np.diff(x)))
            # the rest before and after, long enough for the smoothing to settle (2 / f_c)
            k = 2 + (0 if smoothing_hz is None else int(np.ceil(2.0 / (smoothing_hz * h))))
            pad = h * np.arange(1, k + 1)
            xp = np.concatenate([x[0] - pad[::-1], x, x[-1] + pad])
            qp = np.concatenate([np.repeat(q[:1], k, 0), q, np.repeat(q[-1:], k, 0)])
            lam = 0.0 if smoothing_hz is None else 1.0 / (h * (2 * np.pi * smoothing_hz) ** 4)
            samples = make_smoothing_spline(xp, qp, lam=lam)(np.arange(-1, n + 1) * timestep)
        prev, cur = samples[:-1], samples[1:]
        nxt = np.vstack([samples[2:], samples[-1:]])  # after the last frame: held
        return cls(
            q=cur,
            v=(cur - prev) / timestep,
            a=(nxt - 2 * cur + prev) / timestep**2,
        )


class ComputedTorqueWrist:
    """The ``computed_torque`` driver of one compiled re-simulation model (module docstring).

    Call :meth:`apply` between ``mj_step1`` and ``mj_step2``. It counts the physics steps it
    drove (``steps``) and those in which the force or the torque limit bound
    (``force_saturated``, ``torque_saturated``).
    """

    def __init__(self, model: mujoco.MjModel, gains: WristGains):
        m = model
        jids = [m.joint(j).id for j in WRIST_JOINTS]
        self.dof = np.array([m.jnt_dofadr[j] for j in jids])
        self.qadr = np.array([m.jnt_qposadr[j] for j in jids])
        if not (np.array_equal(self.dof, np.arange(6)) and np.array_equal(self.qadr, self.dof)):
            raise RetargetError("the wrist joints must be the model's first six")
        self.act = np.array([m.actuator(f"{j}_act").id for j in WRIST_JOINTS])
        if np.any(m.actuator_biastype[self.act] != mujoco.mjtBias.mjBIAS_NONE):
            raise RetargetError(
                "the computed-torque wrist needs motor actuators (use_wrist_motors)"
            )
        self.force_limit = float(gains.force_slide)
        self.torque_limit = float(gains.torque_hinge)
        self.kp = np.array([gains.kp_slide] * 3 + [gains.kp_hinge] * 3, dtype=np.float64)
        self._kd_scale = 2.0 * gains.dampratio * np.sqrt(self.kp)
        self._M = np.zeros((m.nv, m.nv))
        self.reset_counts()

    def reset_counts(self) -> None:
        """Forget the step and saturation counts."""
        self.steps = self.force_saturated = self.torque_saturated = 0

    def apply(
        self,
        m: mujoco.MjModel,
        d: mujoco.MjData,
        q_ref: np.ndarray,
        v_ref: np.ndarray,
        a_ref: np.ndarray,
    ) -> None:
        """Write the wrist motors' ``ctrl`` for this step (after ``mj_step1``: the inertia,
        bias and passive forces are the current state's)."""
        mujoco.mj_fullM(m, d, self._M)
        Mww = self._M[:6, :6]
        e = q_ref - d.qpos[:6]
        de = v_ref - d.qvel[:6]
        kd = self._kd_scale * np.sqrt(np.diagonal(Mww))
        grav = d.qfrc_gravcomp[:6]
        f = Mww @ a_ref + self.kp * e + kd * de + d.qfrc_bias[:6] - d.qfrc_passive[:6] + grav
        self.steps += 1
        fn = float(np.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]))
        if fn > self.force_limit:
            f[:3] *= self.force_limit / fn
            self.force_saturated += 1
        if float(np.abs(f[3:]).max()) > self.torque_limit:
            np.clip(f[3:], -self.torque_limit, self.torque_limit, out=f[3:])
            self.torque_saturated += 1
        d.ctrl[self.act] = f - grav
