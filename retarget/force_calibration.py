"""Force calibration: force-matched servo commands corrected in the re-simulation until each
robot finger presses as hard as its human finger did.

Force matching (:mod:`retarget.force_matching`) turns the human's per-finger forces into servo
command offsets, ``Δq = K⁻¹ Jᵀ f``, planned on the kinematic solution: the finger is assumed
blocked by the object where the plan put it. Replayed open loop, the object drifts from its
planned pose, a finger meets the surface early or late, the contact is compliant, and the
forces the servos press with differ from the plan's (on the force-preservation benchmark, a
light touch pressed at 0.1–4.5 mm from the simulated object reproduces its human profile at
0.3; ``retarget.force_scores.LOAD_BEARING_SHARE``).

This stage closes that loop the way iterative learning control does: it re-simulates the
commands, measures each finger's force ``R_f(t)`` against the human's ``H_f(t)``, and adds
``g · K⁻¹ Jᵀ ((‖H_f‖ − ‖R_f‖) u_f)`` per finger and frame (``u_f`` the unit direction of the
simulated finger's force on the object, or of the human's where the robot finger presses
nothing; the error smoothed over ``smooth_s``; ``J`` the fingertip's Jacobian through the
servoed joints and the joints coupled to them). Frames after a re-simulation lost the object
are left alone. Every iterate is re-simulated; the result is the iterate that matches the
human's forces best (:func:`match_error`: magnitude and profile) among those that keep the
object (strict success), else the input commands, so calibration never turns a success into a
failure.

The defaults (10 iterates, chosen by :func:`match_error`) and the measurements behind them
are in ``docs/method.md`` (force calibration).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import mujoco
import numpy as np

from dexcanvas_core.checks import check_fields
from dexcanvas_core.sim.signal import moving_average
from retarget.errors import RetargetError
from retarget.force_matching import servo_gains, squeeze_offsets
from retarget.force_scores import correlation_means, finger_force_profiles
from retarget.limits.coupling import CouplingLimit, servo_follower_map


@dataclass(frozen=True)
class ForceCalibrationConfig:
    """Settings of the force calibration (module doc).

    >>> ForceCalibrationConfig(iterations=4).validate().iterations
    4
    """

    iterations: int = 10
    """Corrected iterates after the input commands' re-simulation (each costs one)."""
    gain: float = 0.5
    """Share ``g`` of each frame's force error corrected per iterate."""
    smooth_s: float = 0.075
    """Moving-average window [s] of the per-finger force error."""
    tolerance_n: float = 0.02
    """Force errors [N] below this are left alone."""

    def __post_init__(self) -> None:
        check_fields(self, error=RetargetError)

    def validate(self) -> ForceCalibrationConfig:
        if not (isinstance(self.iterations, int) and self.iterations >= 0):
            raise RetargetError(
                f"calibration iterations must be an int >= 0, got {self.iterations}"
            )
        for k in ("gain", "smooth_s", "tolerance_n"):
            v = getattr(self, k)
            if not (np.isfinite(v) and v >= 0):
                raise RetargetError(f"calibration {k} must be finite and >= 0, got {v}")
        if not 0 < self.gain <= 1:
            raise RetargetError(f"calibration gain must be in (0, 1], got {self.gain}")
        return self


@dataclass
class Iterate:
    """One re-simulated iterate (0: the input commands)."""

    success: bool
    first_failure_frame: int | None
    object_pos_err_max_m: float
    force_error: float | None
    """:func:`force_error` of its re-simulation against the human's forces."""
    profile_correlation: float | None = None
    """:func:`profile_correlation` of its re-simulation against the human's forces."""

    @property
    def match_error(self) -> float:
        return match_error(self.force_error, self.profile_correlation)


@dataclass
class ForceCalibrationResult:
    commands: np.ndarray
    """The chosen iterate's servo commands: (T, nq) joint targets (:func:`calibrate_forces`)
    or (T, nu) actuator targets (``refine.calibrate_refined``)."""
    sim: object
    """Its simulation (``ValidationResult``; the refinement scene's replay, or its rollout)."""
    chosen: int
    """Index of the chosen iterate in ``iterates`` (0: the input commands)."""
    iterates: list[Iterate] = field(default_factory=list)
    finger_cmd_deviation_rad: float = 0.0
    """Mean ``|Δ|`` of the fingers' commands from the input ones, over every frame."""
    compute_s: float = 0.0
    """CPU time of the re-simulations and corrections [s]."""

    @property
    def success(self) -> bool:
        return bool(self.iterates[self.chosen].success)

    def metrics(self) -> dict:
        first = self.iterates[0]
        best = self.iterates[self.chosen]
        return {
            "success": self.success,
            "chosen_iterate": self.chosen,
            "iterates": [asdict(it) for it in self.iterates],
            "force_error_before": first.force_error,
            "force_error_after": best.force_error,
            "profile_correlation_before": first.profile_correlation,
            "profile_correlation_after": best.profile_correlation,
            "match_error_before": _finite_or_none(first.match_error),
            "match_error_after": _finite_or_none(best.match_error),
            "finger_cmd_deviation_mean_rad": self.finger_cmd_deviation_rad,
            "compute_s": self.compute_s,
        }


def human_target(robot, force_scale: float = 1.0) -> np.ndarray:
    """(T, F, 3) [N]: the forces calibration presses towards, ``force_scale``
    (``RetargetConfig.force_matching.scale``) × the human's per finger (``robot.human_force``,
    set by force matching)."""
    if robot.human_force is None:
        raise RetargetError(
            "force calibration matches the human's forces: retarget with force matching "
            "(retarget run --forces) first"
        )
    return force_scale * np.asarray(robot.human_force, dtype=np.float64)


def _magnitudes(X: np.ndarray) -> np.ndarray:
    """(T, F) force magnitudes of (T, F, 3) forces; (T, F) magnitudes as they are."""
    return np.linalg.norm(X, axis=2) if np.ndim(X) == 3 else np.asarray(X)


def force_error(H: np.ndarray, R: np.ndarray) -> float | None:
    """``Σ |‖R‖ − ‖H‖| / Σ ‖H‖`` over the fingers the human loads (above 0.05 N on more than 2
    frames; ``H``, ``R``: (T, F, 3) [N] or (T, F) magnitudes); ``None`` when it loads none."""
    Hn, Rn = _magnitudes(H), _magnitudes(R)
    used = (Hn > 0.05).sum(axis=0) > 2
    if not used.any():
        return None
    return float(np.abs(Rn - Hn)[:, used].sum() / Hn[:, used].sum())


def profile_correlation(H: np.ndarray, R: np.ndarray) -> float | None:
    """The mean over the fingers the human loads of the whole-clip correlation of the robot's
    force magnitudes with the human's (``force_profile_correlation_mean`` of
    ``retarget.metrics.force_metrics``, which scores the chosen iterate; ``H``, ``R``: (T, F, 3)
    [N] or (T, F) magnitudes); ``None`` when the human loads no finger."""
    Hn, Rn = _magnitudes(H), _magnitudes(R)
    per = finger_force_profiles(Hn, Rn, [str(i) for i in range(Hn.shape[1])])
    return correlation_means(per)["force_profile_correlation_mean"]


def match_error(force_error: float | None, profile_correlation: float | None) -> float:
    """How far an iterate's forces are from the human's, the calibration's choice: the pooled
    magnitude error (:func:`force_error`) plus ``1 −`` the profile correlation
    (:func:`profile_correlation`), both 0 for a perfect match; ``inf`` when the human loads no
    finger. The force error alone is dominated by the fingers that carry the load, so a light
    touch pressing at the wrong moments barely moves it; the correlation weighs every loaded
    finger alike (``docs/method.md``, force calibration)."""
    if force_error is None:
        return np.inf
    return float(force_error + 1.0 - (profile_correlation or 0.0))


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def correction(
    model: mujoco.MjModel,
    nq: int,
    q: np.ndarray,
    tip_sites: list[str],
    target: np.ndarray,
    realized: np.ndarray,
    gain: float,
    smooth_frames: int,
    tolerance_n: float,
    frames: int | None = None,
) -> np.ndarray:
    """(T, nq) command change of one iterate (module doc): per frame ``t < frames`` and finger
    ``f``, ``g · C K⁻¹ (J_f C)ᵀ (e_f u_f)`` with ``e_f = ‖target_f‖ − ‖realized_f‖`` smoothed
    over ``smooth_frames``, ``u_f`` the unit direction of ``realized_f`` (of ``target_f`` where
    the robot finger presses below 0.05 N), ``J_f`` the Jacobian of tip site ``f`` at ``q[t]``
    and ``C`` the servoed finger joints' follower map (``servo_follower_map``; the wrist's
    columns zero). ``model``: a scene whose first ``nq`` ``qpos`` are the hand's joints.
    ``target``, ``realized``: (T, F, 3) [N] forces on the object, ``tip_sites`` order."""
    T, F = target.shape[:2]
    if realized.shape != target.shape or q.shape != (T, nq) or len(tip_sites) != F:
        raise RetargetError(
            f"force calibration: target {target.shape}, realized {realized.shape}, joints "
            f"{q.shape} and {len(tip_sites)} tip sites do not match"
        )
    frames = T if frames is None else min(frames, T)
    Hn = np.linalg.norm(target, axis=2)
    Rn = np.linalg.norm(realized, axis=2)
    e = moving_average(Hn - Rn, smooth_frames)
    u = np.where((Rn > 0.05)[..., None], realized, target)
    un = np.linalg.norm(u, axis=2, keepdims=True)
    u = np.where(un > 1e-9, u / np.maximum(un, 1e-9), 0.0)
    kp, _ = servo_gains(model, nq)
    coupling = CouplingLimit.from_mjmodel(model)
    d = mujoco.MjData(model)
    jacp = np.zeros((3, model.nv))
    sites = [model.site(s).id for s in tip_sites]
    out = np.zeros((T, nq))
    C = None
    for t in range(frames):
        todo = np.flatnonzero((np.abs(e[t]) > tolerance_n) & u[t].any(axis=1))
        if todo.size == 0:
            continue
        d.qpos[:nq] = q[t]
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)  # (the Jacobians need cdof)
        if C is None or not coupling.linear:
            C = servo_follower_map(model, q[t], nq, coupling)
            C[:, :6] = 0.0  # the wrist's servos do not press
        Js, fs = [], []
        for i in todo:
            mujoco.mj_jacSite(model, d, jacp, None, sites[i])
            Js.append(jacp[:, :nq] @ C)
            fs.append(e[t, i] * u[t, i])
        out[t] = gain * (C @ squeeze_offsets(Js, np.array(fs), kp))
    return out


def calibrate(
    simulate, step, cmd0, sim0, target, col, iterations: int, servoed, progress=None
) -> ForceCalibrationResult:
    """The calibration loop, whatever the scene (module doc).

    ``simulate(cmd)`` runs commands ``cmd`` and returns a result with ``success``,
    ``first_failure_frame``, ``object_pos_err`` and ``finger_force_world`` ((T', P, 3), T' ≤
    T frames, columns ``col`` the fingers of ``target`` (T, F, 3)); ``step(cmd, realized,
    frames)`` returns the next commands from the realized forces (T, F, 3; zero past T') and
    the frames to correct. ``sim0``: ``cmd0``'s result, if already run. ``servoed``: the
    command columns of the fingers' servos (the reported deviation). The chosen iterate is
    the successful one with the least :func:`match_error`, else 0."""
    t0 = time.process_time()
    T = target.shape[0]
    cmd, cmds, sims, its = cmd0, [], [], []
    for k in range(iterations + 1):
        if k > 0:
            prev = sims[-1]
            realized = np.zeros_like(target)
            Tp = min(T, prev.finger_force_world.shape[0])
            realized[:Tp] = prev.finger_force_world[:Tp, col]
            frames = Tp if prev.first_failure_frame is None else prev.first_failure_frame
            cmd = step(cmd, realized, min(frames, Tp))
        s = sim0 if (k == 0 and sim0 is not None) else simulate(cmd)
        Tk = min(T, s.finger_force_world.shape[0])
        cmds.append(cmd)
        sims.append(s)
        its.append(
            Iterate(
                success=bool(s.success),
                first_failure_frame=s.first_failure_frame,
                object_pos_err_max_m=float(np.max(s.object_pos_err)),
                force_error=force_error(target[:Tk], s.finger_force_world[:Tk, col]),
                profile_correlation=profile_correlation(
                    target[:Tk], s.finger_force_world[:Tk, col]
                ),
            )
        )
        if progress is not None:
            progress(k + 1, iterations + 1)
    ok = [k for k, it in enumerate(its) if it.success]
    chosen = min(ok, default=0, key=lambda k: its[k].match_error)
    dev = np.abs(cmds[chosen] - cmds[0])[:, servoed]
    return ForceCalibrationResult(
        commands=cmds[chosen],
        sim=sims[chosen],
        chosen=chosen,
        iterates=its,
        finger_cmd_deviation_rad=float(dev.mean()) if dev.size else 0.0,
        compute_s=time.process_time() - t0,
    )


def calibrate_forces(
    retargeter,
    resimulator,
    robot,
    human,
    sim=None,
    cfg: ForceCalibrationConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ForceCalibrationResult:
    """Calibrate force-matched ``robot`` (a ``RobotTrajectory`` of ``human`` made by
    ``retargeter`` with ``force_matching.enabled``) in ``resimulator``'s scene (module doc).

    ``sim``: the input commands' re-simulation, when already run (it is iterate 0).
    Returns the chosen iterate and every iterate's success and force error.

    >>> from dexcanvas_core import load_demonstration, object_geometry
    >>> from retarget import Resimulator, Retargeter, RetargetConfig, ValidateConfig, get_hand
    >>> from retarget.human_forces import human_forces
    >>> human, _ = human_forces(load_demonstration("cube2/tripod").slice(230, 330), "cube2")
    >>> hand, obj = get_hand("allegro"), object_geometry("cube2")
    >>> rt = Retargeter(hand, obj, RetargetConfig.from_overrides({"force_matching": True}))
    >>> robot = rt.retarget(human)
    >>> resim = Resimulator(hand, obj, ValidateConfig(contact_timeconst=0.02))
    >>> cal = calibrate_forces(rt, resim, robot, human, cfg=ForceCalibrationConfig(iterations=2))
    >>> len(cal.iterates), cal.commands.shape == robot.q_command.shape
    (3, True)
    """
    cfg = (cfg or ForceCalibrationConfig()).validate()
    target = human_target(robot, retargeter.cfg.force_matching.scale)
    m, nq = resimulator.model, resimulator.hand_nq
    if robot.q.shape[1] != nq:
        raise RetargetError(
            f"force calibration: trajectory has {robot.q.shape[1]} joints, the scene {nq}"
        )
    col = [resimulator.fingers.index(retargeter.hand.fingers[f]) for f in retargeter.tip_human]
    n_smooth = max(1, round(cfg.smooth_s * human.fps))

    def step(q_cmd, realized, frames):
        dq = correction(
            m, nq, robot.q, robot.tip_sites, target, realized, cfg.gain, n_smooth,
            cfg.tolerance_n, frames,
        )  # fmt: skip
        return np.stack([retargeter._within_limits(x) for x in q_cmd + dq])

    return calibrate(
        lambda q_cmd: resimulator.run(q_cmd, human), step,
        np.asarray(robot.q_command, dtype=np.float64), sim, target, col, cfg.iterations,
        np.isfinite(servo_gains(m, nq)[0]), progress,
    )  # fmt: skip
