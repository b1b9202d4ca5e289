"""The numbers of a run (``metrics.json``): object tracking, keypoint, contact and penetration
errors, and how the robot's contact forces reproduce the human's (force matching).

:func:`run_metrics` gathers them for a :class:`~retarget.pipeline.PipelineResult`; the force
scores themselves are in :mod:`retarget.force_scores`.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from dexcanvas_core.checks import check_type
from dexcanvas_core.objects.geometry import object_record
from dexcanvas_core.rotations import aa_to_matrix
from dexcanvas_core.table import table_of
from dexcanvas_core.trajectory import FORCE_GROUPS
from retarget.errors import RetargetError
from retarget.force_scores import correlation_means, finger_force_profiles, profile_band_frames
from retarget.human_forces import HUMAN_REPLAY_SEED
from retarget.pipeline import PipelineResult, RunConfig

CONTACT_OFF_TARGET_M = 0.01
"""A finger whose contacting link stays farther than this [m] from the human's contact point
(mean over its contact frames) is reported off target: the hand does not make the human's
grasp. The contact targets give way along the surface (``contact_tangent_weight``), so links a
few millimetres from the human's points still grip; beyond a centimetre they mostly do not
(``docs/method.md``, contacts)."""


def human_replay_outcome(first, second, sim_metrics: dict, fingers=None) -> dict:
    """The human replay's entry (``metrics.json``'s and the benchmark's ``human_replay``): its
    outcome (``sim_metrics``, the force pipeline's) and, when it reproduced the demonstration
    (``second``, its force-annotated trajectory; ``None`` when it did not), its forces scored
    against ``first``'s by :func:`human_replay_metrics`."""
    out = {
        "mpc_seed": HUMAN_REPLAY_SEED,
        "success": second is not None,
        "failed_at_frame": sim_metrics.get("failed_at_frame"),
        "object_pos_err_max_m": sim_metrics.get("object_pos_err_max_m"),
    }
    if second is not None:
        out.update(human_replay_metrics(first, second, fingers))
    return out


def human_replay_metrics(first, second, fingers=None) -> dict:
    """How well a second force-pipeline simulation of the same demonstration (another random
    seed of its sampling MPC) reproduces the first's per-finger forces, scored exactly as
    :func:`force_metrics` scores a robot against the first: the ceiling a robot matched to one
    simulation can be expected to reach, since the human's forces are themselves one sample.

    ``first``, ``second``: force-annotated trajectories (``Trajectory.contacts``) of the same
    demonstration; compared over their common frames (a simulation that lost the object stops
    early). ``fingers``: human fingers to score (default the five). Returns
    ``force_per_finger`` and the correlation means (the keys of :func:`force_metrics`).
    """
    fingers = tuple(FORCE_GROUPS[:5] if fingers is None else fingers)
    bad = [f for f in fingers if f not in FORCE_GROUPS[:5]]
    if bad:
        raise RetargetError(f"unknown finger(s) {bad}; choose from {FORCE_GROUPS[:5]}")
    for name, tr in (("first", first), ("second", second)):
        if tr is None or tr.contacts is None:
            raise RetargetError(
                f"human replay: the {name} trajectory has no contact forces (run it through "
                "the force pipeline first)"
            )
    T = min(first.num_frames, second.num_frames)
    if T < 3:
        raise RetargetError(f"human replay: {T} common frames, need at least 3")
    cols = [FORCE_GROUPS.index(f) for f in fingers]
    H = np.linalg.norm(first.contacts.finger_totals()[:T, cols], axis=2)
    R = np.linalg.norm(second.contacts.finger_totals()[:T, cols], axis=2)
    per = finger_force_profiles(H, R, fingers, band_frames=profile_band_frames(first.fps))
    return {"force_per_finger": per, "frames": T, **correlation_means(per)}


def force_metrics(robot, sim, human, retargeter) -> dict:
    """Force preservation of a force-matched run: per corresponding finger, the correlation of
    the human's and the re-simulated robot's contact-force magnitudes — over the frames where
    either touches (``correlation``: does the force vary alike while in contact) and over the
    whole demonstration (``profile_correlation``: the force profile, on/off timing included) —
    and their relative magnitude error; the object force error (robot fingers' summed force vs
    the human hand's) over frames where the human holds the object off the table (and, for
    reference, over all contact frames); contact precision/recall (robot finger in contact vs
    human finger in contact); the share of frames whose required force the QP could produce
    (shortfall below 10 % of it or 0.05 N).

    The correlations and the magnitude error cover the fingers the human loaded (above 0.05 N
    on more than 2 frames); a robot finger that never presses there scores 0. A finger the
    human never loaded has no profile to match (``None``): the robot pressing with it counts
    against ``contact_precision`` instead. ``*_load_bearing`` repeat the two correlation means
    over the loaded fingers carrying at least ``LOAD_BEARING_SHARE`` of the hand's force
    (``load_share`` per finger: its mean human force over the sum of the mapped fingers').

    >>> from dexcanvas_core import load_demonstration
    >>> from retarget.config import RetargetConfig
    >>> from retarget.pipeline import retarget_demonstration
    >>> human = load_demonstration("cube2/tripod").slice(230, 330)
    >>> forces = RetargetConfig.from_overrides({"force_matching": True})
    >>> r = retarget_demonstration(human, "cube2/tripod", "allegro", forces, calibrate_iterations=0)
    >>> m = force_metrics(r.robot, r.sim, r.trajectory, r.retargeter)
    >>> sorted(m["force_per_finger"]), -1 <= m["force_profile_correlation_mean"] <= 1
    (['index', 'middle', 'ring', 'thumb'], True)
    """
    H = np.linalg.norm(robot.human_force, axis=2)  # (T, F) per human finger the robot maps
    # the robot finger each human finger drives (a gripper merges index and middle)
    col = [sim.fingers.index(retargeter.hand.fingers[f]) for f in retargeter.tip_human]
    R = np.linalg.norm(sim.finger_force_world[:, col], axis=2)
    # a robot without a contact plan (a baseline's replay scored by the benchmark) has no reach
    per = finger_force_profiles(
        H, R, retargeter.tip_human, getattr(robot, "contact_err", None),
        profile_band_frames(human.fps),
    )  # fmt: skip
    human_total = human.contacts.finger_totals()[:, : len(FORCE_GROUPS)].sum(axis=1)
    robot_total = sim.finger_force_world.sum(axis=1)
    touch = np.linalg.norm(human_total, axis=1) > 0.05
    # the hand's net force on the object is only the human's to match while the hand alone
    # carries it: off the table (the table's share differs between the two simulations)
    R_o = aa_to_matrix(human.object.rot_aa.astype(np.float64))
    p_o = human.object.pos.astype(np.float64)
    low = retargeter.geometry.lowest_z(R_o, p_o)
    lifted = table_of(human).height_above(np.c_[p_o[:, :2], low]) > 0.01
    werr_all = np.linalg.norm(robot_total - human_total, axis=1)[touch]
    werr = np.linalg.norm(robot_total - human_total, axis=1)[touch & lifted]
    hc, rc = H > 0.05, R > 0.05
    need = np.linalg.norm(robot.human_force.sum(axis=1), axis=1)
    ok = robot.wrench_shortfall <= np.maximum(0.1 * need, 0.05)

    return {
        "force_per_finger": per,
        **correlation_means(per),
        "object_force_error_mean_n": float(werr.mean()) if werr.size else None,
        "object_force_error_contact_frames_mean_n": float(werr_all.mean())
        if werr_all.size
        else None,
        "contact_precision": float((hc & rc).sum() / max(rc.sum(), 1)),
        "contact_recall": float((hc & rc).sum() / max(hc.sum(), 1)),
        "wrench_feasible_fraction": float(ok[touch].mean()) if touch.any() else None,
    }


def refined_force_metrics(robot, refined, human, retargeter) -> dict | None:
    """:func:`force_metrics` of the physics refinement's simulation (``RefineResult``) over the
    frames it tracked (all of them unless it lost the object), against the same human forces
    and force plan as the re-simulation's; ``wrench_feasible_fraction`` is the force QP's, not
    the refinement's, and is left out. ``None`` when it lost the object within 3 frames."""
    Tt = refined.finger_force_world.shape[0]
    if Tt < 3:
        return None
    part = SimpleNamespace(
        human_force=robot.human_force[:Tt],
        wrench_shortfall=robot.wrench_shortfall[:Tt],
        contact_err=robot.contact_err[:Tt],
    )
    sim = SimpleNamespace(finger_force_world=refined.finger_force_world, fingers=refined.fingers)
    human_t = human if Tt == human.num_frames else human.slice(0, Tt)
    m = force_metrics(part, sim, human_t, retargeter)
    m.pop("wrench_feasible_fraction")
    return m


def contact_error_per_finger(contact_err: np.ndarray, fingers: list[str]) -> dict[str, float]:
    """``{human finger: mean contact error [m] over its contact frames}`` from the (T, F)
    per-frame errors (NaN where the finger has no contact); fingers never in contact are left
    out."""
    err = np.asarray(contact_err, dtype=np.float64)
    if err.ndim != 2 or err.shape[1] != len(fingers):
        raise RetargetError(
            f"contact errors must be (frames, {len(fingers)}) for fingers {fingers}, "
            f"got {err.shape}"
        )
    out = {}
    for k, f in enumerate(fingers):
        e = err[:, k][np.isfinite(err[:, k])]
        if e.size:
            out[f] = float(e.mean())
    return out


def run_metrics(result: PipelineResult, cfg: RunConfig) -> dict:
    """``metrics.json`` of a run: what ran (hand, pair, the options of ``result``'s retargeting
    config; ``cfg``: the dataset, time scale and ``--set`` overrides), the re-simulation's
    object tracking (``ValidationResult.metrics``), the kinematic errors, and with force
    matching the force scores, the calibration, the human replay; with a refinement its
    metrics (``refine``, ``success_refined``).

    >>> from dexcanvas_core import load_demonstration
    >>> from retarget.pipeline import RunConfig, retarget_demonstration
    >>> human = load_demonstration("cube2/tripod").slice(0, 30)
    >>> result = retarget_demonstration(human, "cube2/tripod", "shadow")
    >>> m = run_metrics(result, RunConfig(hand="shadow", pair="cube2/tripod"))
    >>> m["success"], m["frames"], m["retarget_config"]["w_contacts"]
    (True, 30, 200.0)
    """
    check_type("result", result, PipelineResult, error=RetargetError)
    check_type("cfg", cfg, RunConfig, error=RetargetError)
    robot, sim, traj, rt = result.robot, result.sim, result.trajectory, result.retargeter
    forces = rt.cfg.force_matching.enabled
    pair = result.subject
    kin_pen = (
        float(max(0.0, -np.min(robot.min_distance)))
        if np.isfinite(robot.min_distance).any()
        else 0.0
    )
    contact_err = robot.contact_err[np.isfinite(robot.contact_err)]
    per_finger = contact_error_per_finger(robot.contact_err, rt.tip_human)
    metrics = {
        "hand": rt.hand.name,
        "pair": str(pair),
        "uuid": traj.uuid,
        "dataset": str(cfg.dataset) if cfg.dataset else "built-in",
        "backend": rt.cfg.solver.backend,
        "frames": traj.num_frames,
        "fps": traj.fps,
        "time_scale": float(cfg.time_scale),
        **sim.metrics(),
        "keypoint_err_mean_m": float(robot.keypoint_err.mean()),
        "penetration_max_m": kin_pen,
        "self_penetration_max_m": robot.self_penetration_max_m,
        "sim_penetration_max_m": float(sim.penetration_max_m),
        "contact_err_mean_m": float(contact_err.mean()) if contact_err.size else None,
        "contact_frames": int(robot.contact_active.any(axis=1).sum()),
        "contact_err_per_finger_m": per_finger,
        "contacts_off_target": [f for f, e in per_finger.items() if e > CONTACT_OFF_TARGET_M],
        "ms_per_frame": robot.ms_per_frame,
        "setup_s": result.setup_s,
        "retarget_config": rt.cfg.flat(),
        "retarget_overrides": dict(cfg.overrides),
        "demonstration_of": result.substituted or str(pair),
        "object": object_record(pair.object.id),
        "approximate_object": bool(result.geometry.approximate),
        "table": table_of(traj).to_dict(),
        "forces": forces,
        "force_scale": rt.cfg.force_matching.scale if forces else None,
    }
    if forces:
        metrics.update(force_metrics(robot, sim, traj, rt))
        metrics["human_force_pipeline"] = result.human_sim
        if (rp := result.replay) is not None:
            metrics["human_replay"] = human_replay_outcome(
                traj, rp.trajectory, rp.sim_metrics, rt.tip_human
            )
    if result.calibration is not None:
        metrics["calibration"] = result.calibration.metrics()
    if (refined := result.refined) is not None:
        metrics["refine"] = refined.metrics()
        metrics["success_refined"] = refined.success
        if forces:
            metrics["refine"]["forces"] = refined_force_metrics(robot, refined, traj, rt)
    return metrics
