"""Force preservation: do retargeted robot hands move the object like the human, pressing alike?

Demonstrations: ``--n-pairs`` (default 20) generated pairs of the built-in demonstrations, spread
evenly over the four groups (power, intermediate, precision, in-hand) exactly as
``benchmarks/retarget_speed_quality.py`` picks them (``_common.load_demonstrations``), cropped to
``--max-frames`` if given. Light and heavy: a pair whose object has a weighted ``H`` variant in
the catalogue (``taxonomy.heavy_variant``: cube2 → cube2h) is also run as a heavy version of the
same demonstration: the human is simulated with ``SimConfig(object_id=<heavy id>)`` and every
robot variant retargeted and re-simulated with the heavy object's geometry (same shape, its
mass). ``--no-heavy`` leaves them out.

Human forces: every (pair, object) goes once through the force pipeline
(``dexcanvas_core.sim.pipeline.simulate``; sampling MPC, or ``--human-tracker open_loop`` for
speed). Where it does not reproduce the demonstration (DexCanvas rule) there are no human forces
to match: variant (d) is skipped for it (counted and listed) and the force columns of the other
variants stay empty.

Human replay (``--no-human-replay`` to skip; ``mpc`` only): every (pair, object) the force
pipeline reproduced is simulated a second time with another seed of its sampling MPC
(``HUMAN_REPLAY_SEED``), and the replay's per-finger forces are scored against the first
simulation's exactly as a robot's are (``retarget.run.human_replay_metrics``). The human's
forces are one sample of a stochastic tracker: a robot matched to that sample cannot be
expected to correlate with it better than another equally valid sample does, so the replay
is the force correlation's ceiling, reported on the same runs and fingers as each variant's
(``replay_ceiling``), and the replay's success on light and heavy objects is the heavy/light
parity the human hand model itself reaches (``human_heavy_vs_light``). It doubles the force
pipeline's CPU time (cached with ``--human-cache`` like the first simulations).

Per hand (``--hands``, default every registered hand; a hand skips pairs it cannot perform,
``retarget.run.check_pair``) and per (pair, object), five variants side by side:

* **(a) dex-retargeting** — its position retargeting (``retarget.baselines``, free wrist unless
  ``--dex-wrist fixed``) on the same scaled keypoint targets, re-simulated on its ``q``;
* **(b) keypoints** — ``Retargeter`` with ``use_contacts=False, squeeze_depth=0``;
* **(c) + contacts** — default ``RetargetConfig`` (contact preservation, the 10 mm grip squeeze),
  re-simulated on ``q_command``; contacts inferred from the demonstration's geometry, as the
  kinematic product does without the force pipeline;
* **(d) + forces** — ``force_matching=True`` on the force-annotated demonstration (contacts
  inferred from its geometry as in (c), the human's per-finger forces from its records →
  force-distribution QP → ``K⁻¹Jᵀf`` offsets),
  re-simulated on ``q_command`` with the force pipeline's contacts
  (``retarget.run.FORCE_CONTACT_TIMECONST``, 20 ms: the default contacts (a)–(c) have too),
  then force-calibrated as ``retarget run --forces`` does (``retarget.force_calibration``,
  ``--calibrate-iterations``, default 10; 0: the planned commands): the row is the chosen
  iterate's, with the planned commands' success in ``planned_success``;
* **(e) + refinement** — (d), and where (d)'s replay fails, ``retarget.refine.refine``: the
  force pipeline's sampling MPC on the robot hand (its contacts as (d)'s), starting from (d)'s
  commands; success and object errors are the refined rollout's (no force columns: the
  refinement reports no per-finger forces), plus how far the commands moved.

Measured per run (``Resimulator``: the hand's own position servos, object free on a table):

* strict success (no frame with object position error > 5 cm) and mean-error success (mean
  < 10 cm and < 0.5 rad); mean object position [cm] and rotation [°] errors;
* force correlation — ``retarget.run.force_metrics``: per corresponding finger, the correlation
  of the human's and the re-simulated robot's contact-force magnitudes, averaged over fingers
  (runs with human forces only; the human side is (d)'s ``human_force``), two ways: over the
  whole demonstration (the force *profile*, on/off timing included) and over only the frames
  where either finger touches (how the force varies while in contact); over the fingers the
  human loaded (> 0.05 N on more than 2 frames), a robot finger that never presses there
  scoring 0; and the whole-demonstration one over the load-bearing fingers only (those
  carrying at least ``retarget.run.LOAD_BEARING_SHARE`` of the hand's mean force: the
  breakdown that separates the grip from light touches; the target is checked on all);
* object force error — mean over frames where the human touches of ‖Σ robot contact forces −
  Σ human contact forces‖ [N] (the force part of the hand's wrench on the object; the
  re-simulation reports no contact points, so no torque), also as % of the object's weight m·g;
* contact precision / recall, and for (d) the share of frames whose required force the force QP
  could produce (``wrench_feasible_fraction``);
* penetration — deepest kinematic hand–object penetration of the solution ``q`` [mm] and the
  deepest one seen in the re-simulation;
* ms/frame — the per-frame retargeting loop (ours: QP solve + squeeze or force QP; dex-
  retargeting: its per-frame call), divided by the frame count. The force pipeline's time is
  reported per simulation, apart.

Aggregates (errors count as failures; skipped (d) runs are not runs): per hand and over the
five-finger hands (five distinct robot fingers), per variant; heavy vs light per variant (all
runs, and the same (hand, pair) with both objects). The "target met?" table checks the issue's
targets on the five-finger hands (on every hand run when none was): (d) strict success ≥ 85 %
(and (e)'s: the issue asks for it "with (d) or (e)") and ≥ 2× (a)'s on the same runs; mean
force correlation ≥ 0.8 (both ways) and object force error ≤ 15 % of the weight on (d)'s
successful runs; heavy variants succeed as often as their light ones ((d), and (e)).

Writes JSON (default ``benchmarks/results/force_preservation.json``, atomically) and a PNG of
strict success by variant and hand (grouped bars, next to the JSON unless ``--plot``). Work runs
on ``--workers`` spawned processes, one thread each::

    python benchmarks/force_preservation.py                      # 20 pairs, every hand, MPC
    python benchmarks/force_preservation.py --hands allegro --n-pairs 2 \\
        --human-tracker open_loop --workers 1 --out /tmp/fp7.json   # smoke run

Ablations of the retargeting: ``--variants`` runs a subset (the others' rows are marked
skipped; (e) brings (d)), ``--set NAME=VALUE`` changes a ``RetargetConfig`` field of our
variants (each variant's defining fields win), and ``--human-cache DIR`` stores each human
simulation (pickle, written atomically) keyed by the demonstration's data, the object, the
tracker's ``SimConfig`` and the force pipeline's source (``dexcanvas_core.sim``, ``.mano``), so
a second run reads them back instead of running the force pipeline again (five hands, (d)
only: 516 s with an empty cache, 196 s with a full one)::

    python benchmarks/force_preservation.py --hands shadow ability inspire svh leap \\
        --variants d --human-cache ~/.cache/dexcanvas-retarget/human-sims \\
        --set contact_tangent_weight=0.2 --out /tmp/ablation.json
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import logging
import multiprocessing
import os
import sys
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from _common import (
    atomic_write_json,
    config_overrides,
    git_commit,
    load_demonstrations,
    machine_info,
    parse_override,
    progress_bar,
    resim_result,
    sim_metrics,
    table_penetration,
    versions,
)
from force_pipeline import _init_worker, _one_thread_env

from dexcanvas_core.sim.signal import CAPTURE_SMOOTH_S
from retarget.run import FORCE_CONTACT_TIMECONST, HUMAN_REPLAY_SEED, RunConfig, human_sim_config

DEFAULT_OUT = Path(__file__).parent / "results" / "force_preservation.json"
NOT_REQUESTED = "not requested (--variants)"
TRACKERS = ("mpc", "open_loop")
VERSION_DISTS = (
    "dexcanvas-retarget",
    "dex-retargeting",
    "mujoco",
    "pin",
    "numpy",
    "qpsolvers",
    "daqp",
    "matplotlib",
)

VARIANTS = ("a", "b", "c", "d", "e")
LABELS = {
    "a": "(a) dex-retargeting",
    "b": "(b) ours: keypoints",
    "c": "(c) + contacts",
    "d": "(d) + forces",
    "e": "(e) + refinement",
}
NOT_IMPLEMENTED: dict[str, str] = {}
"""Variants the library cannot run yet: a row in every table, no numbers."""
RUN_VARIANTS = tuple(v for v in VARIANTS if v not in NOT_IMPLEMENTED)
HUMAN_METRICS = ("success", "success_loose", "failed_at_frame", "frames", "frames_tracked",
                 "object_pos_err_max_m", "object_pos_err_mean_m", "mass_kg", "compute_s",
                 "compute_s_per_demo_s", "hold_weight_ratio", "contact_frames")  # fmt: skip
"""Force-pipeline metrics kept per human simulation (``SimResult.metrics``)."""
FIVE_FINGER = "five-finger hands"
ALL_HANDS = "all hands"

# The issue's targets (reported against, not enforced).
TARGET_SUCCESS = 0.85
TARGET_RATIO = 2.0
TARGET_CORRELATION = 0.8
TARGET_FORCE_PCT_WEIGHT = 0.15


@dataclass(frozen=True)
class BenchConfig:
    """One benchmark run."""

    hands: tuple[str, ...] | None = None
    """Hands to run; ``None``: every registered hand."""
    n_pairs: int = 20
    """Demonstration pairs (light objects as generated), spread over the four groups."""
    max_frames: int | None = None
    """Crop each demonstration to this many frames (around the start of the object motion)."""
    human_tracker: str = "mpc"
    """Force pipeline tracker: ``mpc`` (sampling MPC) or ``open_loop`` (fast, less successful)."""
    heavy: bool = True
    """Also run pairs whose object has a heavy variant with that variant."""
    workers: int = 2
    """Worker processes (one thread each)."""
    out: Path = DEFAULT_OUT
    """JSON output."""
    plot: Path | None = None
    """PNG of strict success by variant and hand; ``None``: the JSON path with ``.png``."""
    operator: str = "operator1"
    seed: int = 0
    dex_wrist: str = "free"
    """dex-retargeting's wrist: ``free`` (optimised) or ``fixed`` (the human wrist pose)."""
    variants: tuple[str, ...] = ("a", "b", "c", "d", "e")
    """Variants to run; the others' rows are marked skipped ("not requested"). (e) refines
    (d)'s output, so asking for (e) runs (d) too."""
    overrides: dict = field(default_factory=dict)
    """``RetargetConfig`` fields changed for our variants (b)–(e) (``--set NAME=VALUE``); each
    variant's defining fields win (b: no contacts, no squeeze; d: force matching)."""
    refine_overrides: dict = field(default_factory=dict)
    """``RefineConfig`` fields changed for variant (e)'s refinement (``--refine-set
    NAME=VALUE``)."""
    calibrate_iterations: int = RunConfig.calibrate_iterations
    """Variant (d)'s force calibration (``retarget.force_calibration``,
    ``ForceCalibrationConfig.iterations``, as ``retarget run --forces``): 0 re-simulates the
    planned commands only."""
    human_cache: Path | None = None
    """Directory of cached human simulations (``--human-cache``): a (demonstration, object,
    tracker) simulated once is read back on later runs instead of simulated again."""
    human_replay: bool = True
    """Simulate every (pair, object) a second time with another seed of the force pipeline's
    sampling MPC (``HUMAN_REPLAY_SEED``) and score its per-finger forces against the first's as the
    robots' are (``retarget.run.human_replay_metrics``): the ceiling of the force correlation
    (``--no-human-replay``: skip; never with the deterministic ``open_loop`` tracker)."""

    def replays(self) -> bool:
        """Whether this run simulates the human replays (``mpc`` only)."""
        return self.human_replay and self.human_tracker == "mpc"

    def validate(self) -> BenchConfig:
        from retarget.hands import available_hands

        if self.n_pairs < 1:
            raise SystemExit(f"--n-pairs must be >= 1, got {self.n_pairs}")
        if self.max_frames is not None and self.max_frames < 2:
            raise SystemExit(f"--max-frames must be >= 2, got {self.max_frames}")
        if self.human_tracker not in TRACKERS:
            raise SystemExit(
                f"unknown --human-tracker {self.human_tracker!r}; available: {', '.join(TRACKERS)}"
            )
        if self.workers < 1:
            raise SystemExit(f"--workers must be >= 1, got {self.workers}")
        if self.calibrate_iterations < 0:
            raise SystemExit(
                f"--calibrate-iterations must be >= 0, got {self.calibrate_iterations}"
            )
        if self.dex_wrist not in ("free", "fixed"):
            raise SystemExit(f"--dex-wrist must be free or fixed, got {self.dex_wrist!r}")
        bad_v = [v for v in self.variants if v not in RUN_VARIANTS]
        if bad_v or not self.variants:
            raise SystemExit(
                f"--variants: unknown or none {', '.join(bad_v)}; choose from "
                f"{' '.join(RUN_VARIANTS)}"
            )
        bad = [h for h in self.hands or () if h not in available_hands()]
        if bad:
            raise SystemExit(
                f"unknown hand(s) {', '.join(bad)}; available: {', '.join(available_hands())}"
            )
        return self

    def plot_path(self) -> Path:
        return Path(self.plot) if self.plot is not None else Path(self.out).with_suffix(".png")

    def computed_variants(self) -> tuple[str, ...]:
        """The requested variants plus what they need: (e) needs (d)."""
        want = set(self.variants) | ({"d"} if "e" in self.variants else set())
        return tuple(v for v in RUN_VARIANTS if v in want)


def is_five_finger(hand) -> bool:
    """Five distinct robot fingers (Shadow, SVH, Ability, Inspire)."""
    return len(set(hand.robot_fingers)) == 5


def object_plan(pair, heavy: bool) -> list[dict]:
    """The objects a pair is run with: the demonstration's own, then its heavy variant."""
    from dexcanvas_core.taxonomy import heavy_variant

    spec = pair.object
    out = [
        {
            "object_id": spec.id,
            "object_variant": "heavy" if spec.heavy else "light",
            "heavy_version_of": None,
        }
    ]
    h = heavy_variant(spec.id) if heavy and not spec.heavy else None
    if h is not None:
        out.append({"object_id": h.id, "object_variant": "heavy", "heavy_version_of": spec.id})
    return out


# ------------------------------------------------------------------------------------ workers
def _error(e: BaseException) -> dict:
    return {"error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc(limit=4)}


def _human_sim(args) -> dict:
    """Worker: the force pipeline on one (pair, object), at the MPC's default seed or at
    ``mpc_seed`` (the replay). Returns ``{"record", "trajectory"}``; ``trajectory`` (the
    demonstration annotated with contacts and forces) only on success."""
    from dexcanvas_core.sim.pipeline import simulate

    key, traj, object_id, tracker, mpc_seed = args
    rec: dict = {"object_id": object_id, "tracker": tracker, "mpc_seed": mpc_seed}
    w0 = time.perf_counter()
    try:
        res = simulate(traj, human_sim_config(object_id, tracker, mpc_seed))
        rec.update({k: res.metrics[k] for k in HUMAN_METRICS})
        annotated = res.trajectory if res.success else None
    except Exception as e:  # no human forces for this (pair, object): recorded, counted
        rec.update(_error(e))
        rec["success"] = False
        annotated = None
    rec["wall_s"] = time.perf_counter() - w0
    return {"key": key, "record": rec, "trajectory": annotated}


@cache
def _baseline(hand_name: str, wrist: str):
    """dex-retargeting for one hand, built once per worker process."""
    from retarget.baselines import DexRetargetingBaseline, DexRetargetingConfig
    from retarget.hands import get_hand

    return DexRetargetingBaseline(get_hand(hand_name), DexRetargetingConfig(wrist=wrist))


FORCE_KEYS = (
    "force_per_finger", "force_correlation_mean", "force_profile_correlation_mean",
    "force_correlation_mean_load_bearing", "force_profile_correlation_mean_load_bearing",
    "force_profile_correlation_mean_reached", "force_profile_correlation_mean_smoothed",
    "fingers_reached", "fingers_scored", "object_force_error_mean_n",
    "object_force_error_contact_frames_mean_n", "object_force_error_pct_weight",
    "contact_precision", "contact_recall",
)  # fmt: skip
"""A row's force columns (:func:`retarget.run.force_metrics`, + % of the weight)."""


def _force_columns(human_force, robot_d, sim_res, human, retargeter, variant: str) -> dict:
    """``force_metrics`` of one variant's re-simulation against the human's forces: every
    variant is compared with the human per-finger forces mapped onto this hand's fingers
    (``human_force``, ``Retargeter.human_finger_forces``; (d)'s ``robot_d.human_force``)."""
    from retarget.run import force_metrics

    robot = robot_d
    if variant != "d":  # only the human side is read from the robot (no force QP ran)
        robot = SimpleNamespace(
            human_force=human_force, wrench_shortfall=np.zeros(human_force.shape[0])
        )
    m = force_metrics(robot, sim_res, human, retargeter)
    if variant != "d":
        m["wrench_feasible_fraction"] = None  # a property of the force QP, (d) only
    return m


def _calibrated(rt, resim, robot, human, sim, m: dict, n: int) -> tuple[dict, object]:
    """(d)'s force calibration (``retarget.force_calibration``) of ``robot`` (whose re-simulation is
    ``sim``, metrics ``m``): the row's metrics and simulation become the chosen iterate's,
    ``robot.q_command`` its commands; the planned commands' result stays in ``planned_*``."""
    from retarget.force_calibration import ForceCalibrationConfig, calibrate_forces

    cal = calibrate_forces(rt, resim, robot, human, sim, ForceCalibrationConfig(iterations=n))
    cm = cal.metrics()
    out = {**m, **sim_metrics(cal.sim)}
    out.update(
        table_penetration_max_m=table_penetration(resim, cal.commands),
        planned_success=m["success"],
        planned_object_pos_err_max_m=m["object_pos_err_max_m"],
        calibration_iterate=cm["chosen_iterate"],
        calibration_s=cm["compute_s"],
        calibration_force_error_before=cm["force_error_before"],
        calibration_force_error_after=cm["force_error_after"],
        calibration_finger_cmd_deviation_mean_rad=cm["finger_cmd_deviation_mean_rad"],
    )
    robot.q_command = cal.commands
    return out, cal.sim


def _hand_job(args) -> list[dict]:
    """Worker: variants (a)–(d) of one hand on one (pair, object); one row per variant."""
    from dexcanvas_core.objects.geometry import object_geometry
    from dexcanvas_core.sim.physics import GRAVITY
    from retarget.baselines import KinematicMetrics, measure_trajectory
    from retarget.hands import get_hand
    from retarget.retargeter import RetargetConfig, Retargeter
    from retarget.run import refined_force_metrics
    from retarget.validate import Resimulator, ValidateConfig

    base, traj, human, dex_wrist, computed, overrides, refine_overrides, n_calibrate = args
    rows = {v: {**base, "variant": v} for v in RUN_VARIANTS}
    for v in RUN_VARIANTS:
        if v not in computed:
            rows[v]["skipped"] = NOT_REQUESTED
    sims: dict[str, object] = {}
    retargeters: dict[str, object] = {}
    robot_d = None
    try:
        hand = get_hand(base["hand"])
        geom = object_geometry(base["object_id"])
        weight_n = geom.mass_kg * GRAVITY
        for r in rows.values():
            r.update(mass_kg=geom.mass_kg, weight_n=weight_n)
        resim_soft = Resimulator(hand, geom)
        configs = {
            "b": RetargetConfig(**{**overrides, "use_contacts": False, "squeeze_depth": 0.0}),
            "c": RetargetConfig(**overrides),
            "d": RetargetConfig(**{**overrides, "force_matching": True}),
        }
        for v in ("b", "c", "d"):
            row = rows[v]
            if v not in computed:
                continue
            if v == "d" and human is None:
                row["skipped"] = "the force pipeline did not reproduce the demonstration"
                continue
            t0 = time.perf_counter()
            try:
                rt = Retargeter(hand, geom, configs[v])
                src = human if v == "d" else traj
                robot = rt.retarget(src)
                sim = (
                    Resimulator(
                        hand, geom, ValidateConfig(contact_timeconst=FORCE_CONTACT_TIMECONST)
                    )
                    if v == "d"
                    else resim_soft
                )
                m, sims[v] = resim_result(sim, robot.q_command, src)
                retargeters[v] = rt
                if v == "d":
                    robot_d = robot
                    if n_calibrate > 0 and sims[v] is not None:
                        m, sims[v] = _calibrated(rt, sim, robot, src, sims[v], m, n_calibrate)
                row.update(
                    ms_per_frame=robot.ms_per_frame, **KinematicMetrics.of(robot).summary(), **m
                )
            except Exception as e:  # one variant's failure is its own row's
                row.update(_error(e))
            row["wall_s"] = time.perf_counter() - t0
        # (a) on (b)'s targets, measured with (b)'s retargeter (same hand, same definitions)
        row = rows["a"]
        if "a" in computed:
            t0 = time.perf_counter()
            try:
                rt_b = retargeters.get("b") or Retargeter(hand, geom, configs["b"])
                tg = rt_b.human_targets(traj)
                baseline = _baseline(hand.name, dex_wrist)
                if rt_b.kp_sites != baseline.keypoint_sites:
                    raise RuntimeError(f"{hand.name}: baseline keypoint sites differ from ours")
                dex = baseline.retarget_targets(tg["keypoints"], tg["wrist_p"], tg["wrist_R"])
                m, sims["a"] = resim_result(resim_soft, dex.q, traj)
                row.update(
                    ms_per_frame=dex.ms_per_frame,
                    solver_failures=dex.solver_failures,
                    **measure_trajectory(rt_b, traj, dex.q, tg).summary(),
                    **m,
                )
            except Exception as e:
                row.update(_error(e))
            row["wall_s"] = time.perf_counter() - t0
        # (e) (d) + physics refinement where (d)'s replay fails
        row = rows["e"]
        if "e" not in computed:
            pass  # marked not requested above
        elif "skipped" in rows["d"] or "error" in rows["d"] or robot_d is None:
            row["skipped"] = rows["d"].get("skipped") or "variant (d) failed"
        elif rows["d"]["success"]:
            keep = ("success", "success_loose", "object_pos_err_max_m", "object_pos_err_mean_m",
                    "object_rot_err_mean_rad", "ms_per_frame", "keypoint_err_mean_m",
                    "penetration_max_m")  # fmt: skip
            row.update({k: rows["d"][k] for k in keep if k in rows["d"]})
            row.update(refined=False, finger_ctrl_deviation_mean_rad=0.0,
                       wrist_pos_deviation_mean_m=0.0)  # fmt: skip
        else:
            from retarget.refine import RefineConfig, refine

            t0 = time.perf_counter()
            try:
                rcfg = RefineConfig(
                    **{"contact_timeconst": FORCE_CONTACT_TIMECONST, **refine_overrides}
                )
                rf = refine(hand, geom, human, robot_d, retargeters["d"].tip_sites, rcfg)
                if rf.success and n_calibrate > 0:
                    from retarget.force_calibration import ForceCalibrationConfig
                    from retarget.refine import calibrate_refined

                    rf = calibrate_refined(
                        hand, geom, human, robot_d, retargeters["d"].tip_sites, rf, rcfg,
                        ForceCalibrationConfig(iterations=n_calibrate),
                        retargeters["d"].cfg.force_scale,
                    )  # fmt: skip
                    cm = rf.calibration
                    row.update(
                        refine_calibration_iterate=cm["chosen_iterate"],
                        refine_calibration_s=cm["compute_s"],
                        refine_calibration_force_error_before=cm["force_error_before"],
                        refine_calibration_force_error_after=cm["force_error_after"],
                    )
                rm = rf.metrics()
                row.update(
                    success=rm["success"],
                    success_loose=bool(
                        rm["frames_tracked"] == human.num_frames
                        and rm["object_pos_err_mean_m"] < 0.10
                        and rm["object_rot_err_mean_rad"] < 0.5
                    ),
                    object_pos_err_max_m=rm["object_pos_err_max_m"],
                    object_pos_err_mean_m=rm["object_pos_err_mean_m"],
                    object_rot_err_mean_rad=rm["object_rot_err_mean_rad"],
                    ms_per_frame=rows["d"]["ms_per_frame"],
                    keypoint_err_mean_m=rows["d"].get("keypoint_err_mean_m"),
                    penetration_max_m=rows["d"].get("penetration_max_m"),
                    refined=True,
                    refine_s=rm["compute_s"],
                    refine_attempts=rm["attempts"],
                    refine_failed_at_frame=rm["failed_at_frame"],
                    finger_ctrl_deviation_mean_rad=rm["finger_ctrl_deviation_mean_rad"],
                    wrist_pos_deviation_mean_m=rm["wrist_pos_deviation_mean_m"],
                )
                # forces of the refined simulation (over the frames it tracked)
                fm = refined_force_metrics(robot_d, rf, human, retargeters["d"])
                if fm is not None:
                    err = fm["object_force_error_mean_n"]
                    fm["object_force_error_pct_weight"] = None if err is None else err / weight_n
                    row.update(fm, wrench_feasible_fraction=None)
            except Exception as e:
                row.update(_error(e))
            row["wall_s"] = time.perf_counter() - t0
        # force columns: every re-simulated variant against the human's forces (also without
        # (d): an ablation of (c) alone, `--variants c`, is compared with the human too)
        if human is not None and sims:
            rt_f = retargeters.get("d") or retargeters.get("c") or retargeters.get("b")
            rt_f = rt_f or Retargeter(hand, geom, configs["c"])
            human_force = rt_f.human_finger_forces(human)
            for v, sim_res in sims.items():
                if sim_res is None or "error" in rows[v]:
                    continue
                try:
                    fm = _force_columns(human_force, robot_d, sim_res, human, rt_f, v)
                    err = fm["object_force_error_mean_n"]
                    fm["object_force_error_pct_weight"] = None if err is None else err / weight_n
                    rows[v].update(fm)
                except Exception as e:
                    rows[v]["force_metrics_error"] = f"{type(e).__name__}: {e}"
            # (e) where (d)'s replay succeeded is that replay: its forces too
            if rows["e"].get("refined") is False and "force_per_finger" in rows["d"]:
                rows["e"].update({k: rows["d"][k] for k in FORCE_KEYS if k in rows["d"]})
                rows["e"]["wrench_feasible_fraction"] = None
    except Exception as e:  # the hand or the scene could not be built: every variant fails
        for r in rows.values():
            if "error" not in r and "skipped" not in r:
                r.update(_error(e))
    return [rows[v] for v in RUN_VARIANTS]


# --------------------------------------------------------------------------------- aggregates
def _mean(rows: list[dict], key: str) -> float | None:
    v = [r[key] for r in rows if r.get(key) is not None]
    return float(np.mean(v)) if v else None


def _rate(rows: list[dict], key: str = "success") -> float | None:
    return float(np.mean([bool(r.get(key)) for r in rows])) if rows else None


def aggregate(rows: list[dict]) -> dict:
    """One variant's numbers over ``rows`` (module docstring): skipped rows are not runs, errors
    count as failures and are left out of the other columns."""
    runs = [r for r in rows if "skipped" not in r]
    ok = [r for r in runs if "error" not in r]
    won = [r for r in ok if r.get("success")]
    with_forces = [r for r in runs if r.get("human_forces")]
    timed = [r for r in ok if r.get("ms_per_frame") is not None]
    frames = sum(r["frames"] for r in timed)
    pens = [r["penetration_max_m"] for r in ok if r.get("penetration_max_m") is not None]
    return {
        "runs": len(runs),
        "errors": len(runs) - len(ok),
        "skipped": len(rows) - len(runs),
        "success_rate": _rate(runs),
        "success_loose_rate": _rate(runs, "success_loose"),
        "runs_with_human_forces": len(with_forces),
        "success_rate_with_human_forces": _rate(with_forces),
        "object_pos_err_mean_m": _mean(ok, "object_pos_err_mean_m"),
        "object_rot_err_mean_rad": _mean(ok, "object_rot_err_mean_rad"),
        "force_correlation_mean": _mean(ok, "force_correlation_mean"),
        "force_correlation_mean_successful": _mean(won, "force_correlation_mean"),
        "force_profile_correlation_mean": _mean(ok, "force_profile_correlation_mean"),
        "force_profile_correlation_mean_successful": _mean(won, "force_profile_correlation_mean"),
        "force_profile_correlation_mean_load_bearing_successful": _mean(
            won, "force_profile_correlation_mean_load_bearing"
        ),
        "force_profile_correlation_mean_reached_successful": _mean(
            won, "force_profile_correlation_mean_reached"
        ),
        "force_profile_correlation_mean_smoothed_successful": _mean(
            won, "force_profile_correlation_mean_smoothed"
        ),
        "object_force_error_mean_n": _mean(ok, "object_force_error_mean_n"),
        "object_force_error_pct_weight": _mean(ok, "object_force_error_pct_weight"),
        "object_force_error_mean_n_successful": _mean(won, "object_force_error_mean_n"),
        "object_force_error_pct_weight_successful": _mean(won, "object_force_error_pct_weight"),
        "runs_with_force_metrics": sum(
            1
            for r in ok
            if r.get("force_correlation_mean") is not None
            or r.get("object_force_error_mean_n") is not None
        ),
        "contact_precision": _mean(ok, "contact_precision"),
        "contact_recall": _mean(ok, "contact_recall"),
        "wrench_feasible_fraction": _mean(ok, "wrench_feasible_fraction"),
        "penetration_max_m": max(pens) if pens else None,
        "penetration_mean_of_max_m": float(np.mean(pens)) if pens else None,
        "sim_penetration_max_m": max(
            (r["sim_penetration_max_m"] for r in ok if r.get("sim_penetration_max_m") is not None),
            default=None,
        ),
        "ms_per_frame": (
            sum(r["ms_per_frame"] * r["frames"] for r in timed) / frames if frames else None
        ),
    }


def aggregate_variants(rows: list[dict]) -> dict:
    """``{variant: aggregate}``; not-implemented variants carry their note instead."""
    out = {v: aggregate([r for r in rows if r["variant"] == v]) for v in RUN_VARIANTS}
    out.update({v: {"implemented": False, "note": note} for v, note in NOT_IMPLEMENTED.items()})
    return {v: out[v] for v in VARIANTS}


def _light_heavy(recs: list[dict], ok, key) -> dict:
    """Success rates (``ok(record)``) of light-object and heavy-object records, over all of them
    and over the heavy variants whose light object was run too (``paired``: same ``key``)."""
    light = [r for r in recs if r["object_variant"] == "light"]
    heavy = [r for r in recs if r["object_variant"] == "heavy"]
    light_by = {key(r): r for r in light}
    paired = [
        (light_by[key(h)], h)
        for h in heavy
        if h.get("heavy_version_of") is not None and key(h) in light_by
    ]

    def rate(rs: list[dict]) -> float | None:
        return float(np.mean([bool(ok(r)) for r in rs])) if rs else None

    return {
        "light_runs": len(light),
        "light_success_rate": rate(light),
        "heavy_runs": len(heavy),
        "heavy_success_rate": rate(heavy),
        "paired_runs": len(paired),
        "paired_light_success_rate": rate([li for li, _ in paired]),
        "paired_heavy_success_rate": rate([h for _, h in paired]),
    }


def heavy_vs_light(rows: list[dict]) -> dict:
    """Per variant: strict success of light-object and heavy-object runs, over all runs and over
    the (hand, pair)s run with both a light object and its heavy variant (``paired``)."""
    return {
        v: _light_heavy(
            [r for r in rows if r["variant"] == v and "skipped" not in r],
            lambda r: r.get("success"),
            lambda r: (r["hand"], r["pair"]),
        )
        for v in RUN_VARIANTS
    }


def human_heavy_vs_light(human: list[dict]) -> dict:
    """The force pipeline's own success on light and heavy objects: the first simulations
    (``first``), and of those that reproduced their demonstration, the share the replay
    reproduced again (``replay``); ``paired``: the demonstrations simulated with both a light
    object and its heavy variant."""
    replayed = [r for r in human if "replay" in r]

    def by_demo(r: dict) -> int:
        return r["index"]

    return {
        "first": _light_heavy(human, lambda r: r["success"], by_demo),
        "replay": _light_heavy(replayed, lambda r: r["replay"]["success"], by_demo)
        if replayed
        else None,
    }


def replay_record(first, res: dict) -> dict:
    """A human simulation's ``replay`` entry: ``retarget.run.human_replay_outcome`` of the
    replay (``res``: a :func:`_human_sim` result at ``HUMAN_REPLAY_SEED``) against the first
    simulation's trajectory ``first``, with its CPU time, cache flag and error."""
    from retarget.run import human_replay_outcome

    rec = res["record"]
    return {
        **human_replay_outcome(first, res["trajectory"], rec),
        **{k: rec.get(k) for k in ("compute_s", "cached", "error")},
    }


CORRELATION_KEYS = ("force_profile_correlation_mean", "force_correlation_mean",
                    "force_profile_correlation_mean_load_bearing",
                    "force_correlation_mean_load_bearing",
                    "force_profile_correlation_mean_reached",
                    "force_profile_correlation_mean_smoothed")  # fmt: skip


def _replays(human: list[dict]) -> dict:
    """Each scored human replay's ``force_per_finger``, by ``(index, object_id)``."""
    return {
        (h["index"], h["object_id"]): h["replay"]["force_per_finger"]
        for h in human
        if "force_per_finger" in h.get("replay", {})
    }


def replay_ceiling(rows: list[dict], human: list[dict], variant: str = "d") -> dict:
    """The human replay's force correlations on the runs where ``variant`` succeeded, next to
    the variant's own on the same runs: for each such run with a scored replay, the replay's
    per-finger scores over the fingers the run scores (its hand's, those the human loaded),
    with the run's load shares (``retarget.run.correlation_means``); then means over runs.
    ``runs`` counts the runs compared."""
    from retarget.run import correlation_means

    replays = _replays(human)
    ours, ceiling = [], []
    for r in rows:
        if r["variant"] != variant or "skipped" in r or "error" in r or not r.get("success"):
            continue
        rep_per = replays.get((r["index"], r["object_id"]))
        per = r.get("force_per_finger")
        if rep_per is None or not per:
            continue
        scored = [
            f
            for f, v in per.items()
            if v["correlation"] is not None and rep_per.get(f, {}).get("correlation") is not None
        ]
        if not scored:
            continue
        ceiling.append(correlation_means({
            f: {**rep_per[f], **{k: per[f][k] for k in ("load_share", "contact_reach_m")
                                 if k in per[f]}}
            for f in scored
        }))  # fmt: skip
        ours.append({k: r.get(k) for k in CORRELATION_KEYS})

    def mean(ms: list[dict]) -> dict:
        return {k: _mean(ms, k) for k in CORRELATION_KEYS}

    return {"variant": variant, "runs": len(ours), "replay": mean(ceiling), "ours": mean(ours)}


REACH_BINS_M = (0.003, 0.005, 0.010, 0.020)
"""Upper edges of the reach bins of :func:`correlation_by_reach` (the last bin is open)."""


def _bins(edges_m: tuple[float, ...]) -> list[tuple[str, float, float]]:
    edges = (0.0, *edges_m, np.inf)
    return [
        (f"{1e3 * lo:.0f}–{1e3 * hi:.0f} mm" if np.isfinite(hi) else f"> {1e3 * lo:.0f} mm", lo, hi)
        for lo, hi in itertools.pairwise(edges)
    ]


def correlation_by_reach(rows: list[dict], human: list[dict]) -> dict:
    """Whole-clip force correlation of single fingers, (d) and (e)'s successful runs pooled
    finger by finger, binned by how close the kinematic plan brings the finger to the human's
    contact (``contact_reach_m``, :data:`retarget.run.REACH_M`), next to the human replay's on
    the same fingers where the run has one. Fingers without a reach (no contact target where
    the human loads) are their own bin. ``{variant: [{"bin", "fingers", "correlation",
    "replay_fingers", "replay_correlation"}]}``."""
    replays = _replays(human)
    out = {}
    for v in ("d", "e"):
        fingers = []  # (reach, ours, replay)
        for r in rows:
            if r["variant"] != v or "skipped" in r or "error" in r or not r.get("success"):
                continue
            rep = replays.get((r["index"], r["object_id"]), {})
            for f, x in (r.get("force_per_finger") or {}).items():
                if x.get("profile_correlation") is None or "contact_reach_m" not in x:
                    continue
                reach = x["contact_reach_m"]
                fingers.append((reach, x["profile_correlation"], rep.get(f, {}).get(
                    "profile_correlation")))  # fmt: skip
        out[v] = []
        for lab, lo, hi in [*_bins(REACH_BINS_M), ("no target", None, None)]:
            sel = [
                f for f in fingers
                if (f[0] is None if lo is None else f[0] is not None and lo <= f[0] < hi)
            ]  # fmt: skip
            reps = [f[2] for f in sel if f[2] is not None]
            out[v].append({
                "bin": lab,
                "fingers": len(sel),
                "correlation": float(np.mean([f[1] for f in sel])) if sel else None,
                "replay_fingers": len(reps),
                "replay_correlation": float(np.mean(reps)) if reps else None,
            })  # fmt: skip
    return out


CONTACT_ERROR_BINS_M = (0.002, 0.005, 0.010)
"""Upper edges of the contact-error bins of :func:`by_contact_error` (the last bin is open)."""


def by_contact_error(rows: list[dict]) -> dict:
    """Strict success of variants (c)–(e) by the run's kinematic contact error: the mean
    distance from each contacting robot link to the human's contact point, of variant (d)'s
    retargeting (the same targets as (c)'s; (e) refines (d)). A contact the robot cannot reach
    puts its finger elsewhere on the object, and the grasp the human used is not the one
    re-simulated. ``{variant: [{"bin": label, "runs", "success_rate"}]}``."""
    ref = {
        (r["hand"], r["index"], r["object_id"]): r.get("contact_err_mean_m")
        for r in rows
        if r["variant"] == "d" and "skipped" not in r and "error" not in r
    }
    out = {}
    for v in ("c", "d", "e"):
        rs = [r for r in rows if r["variant"] == v and "skipped" not in r]
        err = [ref.get((r["hand"], r["index"], r["object_id"])) for r in rs]
        out[v] = []
        for lab, lo, hi in _bins(CONTACT_ERROR_BINS_M):
            sel = [r for r, e in zip(rs, err, strict=True) if e is not None and lo <= e < hi]
            out[v].append({"bin": lab, "runs": len(sel), "success_rate": _rate(sel)})
    return out


WRENCH_FEASIBLE = 0.9
"""A run counts as one whose load the hand can carry when (d)'s force QP produced the required
object wrench on at least this share of its contact frames (``wrench_feasible_fraction``)."""


def heavy_vs_light_by_wrench(rows: list[dict]) -> dict:
    """Light and heavy strict success of (d) and (e), split by whether (d)'s force QP could
    produce the object wrench the human's forces make (friction cones at the retargeted
    contacts, the servos' torque limits) on at least ``WRENCH_FEASIBLE`` of the contact frames:
    where the grasp cannot carry a heavy object, no tracking of it will. Which limit binds
    (the contacts' placement or the servos) is not split.
    ``{variant: {"feasible" | "short": _light_heavy(...)}}``, (e) split by its (d) run's."""
    frac = {
        (r["hand"], r["index"], r["object_id"]): r.get("wrench_feasible_fraction")
        for r in rows
        if r["variant"] == "d" and "skipped" not in r and "error" not in r
    }
    out = {}
    for v in ("d", "e"):
        rs = [r for r in rows if r["variant"] == v and "skipped" not in r]
        f = [frac.get((r["hand"], r["index"], r["object_id"])) for r in rs]
        out[v] = {
            name: _light_heavy(
                [r for r, x in zip(rs, f, strict=True) if x is not None and keep(x)],
                lambda r: r.get("success"),
                lambda r: (r["hand"], r["pair"]),
            )
            for name, keep in (
                ("feasible", lambda x: x >= WRENCH_FEASIBLE),
                ("short", lambda x: x < WRENCH_FEASIBLE),
            )
        }
    return out


def wrench_table(scope: str, table: dict):
    from rich.table import Table

    t = Table(
        title=f"{scope}: light / heavy strict success % by whether the retargeted grasp can carry "
        "the load",
        caption=f"can carry: (d)'s force QP produced the human's object wrench on ≥ "
        f"{100 * WRENCH_FEASIBLE:.0f} % of the contact frames (friction cones at the retargeted "
        "contacts, the servos' torque limits); (runs)",
    )
    for c in ("variant", "wrench", "light %", "heavy %"):
        t.add_column(c, justify="left" if c in ("variant", "wrench") else "right", no_wrap=True)
    for v in ("d", "e"):
        for name, label in (("feasible", "can carry"), ("short", "falls short")):
            h = table[v][name]
            t.add_row(
                LABELS[v],
                label,
                f"{_f(h['light_success_rate'], 100, '.0f')} ({h['light_runs']})",
                f"{_f(h['heavy_success_rate'], 100, '.0f')} ({h['heavy_runs']})",
            )
    return t


def _binned_table(title: str, caption: str, what: str, table: dict, columns, cells):
    """A table with a row per bin of ``table[v]`` (lists of bins per variant, the same bins):
    ``columns`` the header after ``what``, ``cells(bins)`` a row's cells (``bins[v]``)."""
    from rich.table import Table

    t = Table(title=title, caption=caption)
    t.add_column(what, no_wrap=True)
    for c in columns:
        t.add_column(c, justify="right", no_wrap=True)
    first = next(iter(table.values()))
    for k, row in enumerate(first):
        t.add_row(row["bin"], *cells({v: bins[k] for v, bins in table.items()}))
    return t


def contact_error_table(scope: str, table: dict):
    return _binned_table(
        f"{scope}: strict success % by kinematic contact error (runs)",
        "contact error: mean distance from each contacting robot link to the human's contact "
        "point in (d)'s retargeting",
        "contact error",
        table,
        [LABELS[v] for v in ("c", "d", "e")],
        lambda b: [f"{_f(b[v]['success_rate'], 100, '.0f')} ({b[v]['runs']})" for v in "cde"],
    )


def reach_table(scope: str, table: dict):
    return _binned_table(
        f"{scope}: force correlation by the finger's reach (fingers; successful runs)",
        "reach: median distance from the robot finger to the human's contact point in (d)'s "
        "plan over the frames the human finger loads; whole-clip correlation per finger",
        "reach",
        table,
        [LABELS["d"], "human replay", LABELS["e"], "human replay"],
        lambda b: [
            f"{_f(b[v][k], fmt='.2f')} ({b[v][n]})"
            for v in "de"
            for k, n in (("correlation", "fingers"), ("replay_correlation", "replay_fingers"))
        ],
    )


def target_checks(
    scope: str, rows: list[dict], agg: dict, hv: dict, ceiling: dict | None = None
) -> list[dict]:
    """The issue's targets on one scope's rows (``met`` is ``None`` when not measured). With
    ``ceiling`` (``{variant: replay_ceiling(...)}``), each correlation target also carries the
    human replay's correlation on the variant's successful runs (``human_replay``, over
    ``human_replay_runs`` of them) and the variant's own on those same runs (``same_runs``)."""
    d = agg["d"]
    force_keys = {
        (r["hand"], r["pair"], r["object_id"])
        for r in rows
        if r["variant"] == "d" and "skipped" not in r
    }
    same = {  # (a) and (d) runs on the same (hand, pair, object); a skipped row is no run
        v: [
            r
            for r in rows
            if r["variant"] == v
            and "skipped" not in r
            and (r["hand"], r["pair"], r["object_id"]) in force_keys
        ]
        for v in ("a", "d")
    }
    sa, sd = _rate(same["a"]), _rate(same["d"])
    corr = d["force_correlation_mean_successful"]
    profile = d["force_profile_correlation_mean_successful"]
    ferr = d["object_force_error_pct_weight_successful"]
    e = agg["e"]

    def at_least(v, t):
        return None if v is None else bool(v >= t)

    def heavy(v: str) -> dict:
        pl, ph = hv[v]["paired_light_success_rate"], hv[v]["paired_heavy_success_rate"]
        return {
            "scope": scope,
            "name": "heavy",
            "target": f"heavy variants succeed as often as light ones (({v}), same hand and pair)",
            "value": [ph, pl],
            "runs": hv[v]["paired_runs"],
            "met": None if pl is None or ph is None else bool(ph >= pl),
        }

    ratio_met = None
    if sa is not None and sd is not None:
        ratio_met = bool(sd >= TARGET_RATIO * sa and sd > 0)

    def replay(v: str, key: str, suffix: str = "") -> dict:
        c = (ceiling or {}).get(v)
        if c is None:
            return {}
        return {
            f"human_replay{suffix}": c["replay"][key],
            f"same_runs{suffix}": c["ours"][key],
            "human_replay_runs": c["runs"],
        }

    return [
        {
            "scope": scope,
            "name": "success",
            "target": f"(d) strict success ≥ {100 * TARGET_SUCCESS:.0f} %",
            "value": d["success_rate"],
            "runs": d["runs"],
            "met": at_least(d["success_rate"], TARGET_SUCCESS),
        },
        {
            "scope": scope,
            "name": "vs dex",
            "target": f"(d) strict success ≥ {TARGET_RATIO:g}× (a)'s (same runs)",
            "value": [sd, sa],
            "runs": len(same["d"]),
            "met": ratio_met,
        },
        {
            "scope": scope,
            "name": "correlation",
            "target": f"force profile correlation ≥ {TARGET_CORRELATION:g} (successful (d) "
            "runs, whole demonstration)",
            "value": profile,
            "met": at_least(profile, TARGET_CORRELATION),
            "reached_fingers_value": d["force_profile_correlation_mean_reached_successful"],
            "smoothed_value": d["force_profile_correlation_mean_smoothed_successful"],
            **replay("d", "force_profile_correlation_mean"),
            **replay("d", "force_profile_correlation_mean_smoothed", "_smoothed"),
        },
        {
            "scope": scope,
            "name": "correlation",
            "target": f"… over contact frames only ≥ {TARGET_CORRELATION:g}",
            "value": corr,
            "met": at_least(corr, TARGET_CORRELATION),
            **replay("d", "force_correlation_mean"),
        },
        {
            "scope": scope,
            "name": "force error",
            "target": f"object force error ≤ {100 * TARGET_FORCE_PCT_WEIGHT:.0f} % of weight "
            "(successful (d) runs)",
            "value": ferr,
            "met": None if ferr is None else bool(ferr <= TARGET_FORCE_PCT_WEIGHT),
        },
        heavy("d"),
        # The issue asks for the success target "with (d) or (e)": (e)'s rows as well.
        {
            "scope": scope,
            "name": "success",
            "target": f"(e) strict success ≥ {100 * TARGET_SUCCESS:.0f} %",
            "value": e["success_rate"],
            "runs": e["runs"],
            "met": None if not e["runs"] else at_least(e["success_rate"], TARGET_SUCCESS),
        },
        heavy("e"),
        {
            "scope": scope,
            "name": "correlation",
            "target": f"force profile correlation ≥ {TARGET_CORRELATION:g} (successful (e) "
            "runs, whole demonstration)",
            "value": e["force_profile_correlation_mean_successful"],
            "met": at_least(e["force_profile_correlation_mean_successful"], TARGET_CORRELATION),
            **replay("e", "force_profile_correlation_mean"),
        },
        {
            "scope": scope,
            "name": "force error",
            "target": f"object force error ≤ {100 * TARGET_FORCE_PCT_WEIGHT:.0f} % of weight "
            "(successful (e) runs)",
            "value": e["object_force_error_pct_weight_successful"],
            "met": None
            if e["object_force_error_pct_weight_successful"] is None
            else bool(e["object_force_error_pct_weight_successful"] <= TARGET_FORCE_PCT_WEIGHT),
        },
    ]


# ------------------------------------------------------------------------------------- output
def _f(x, scale: float = 1.0, fmt: str = ".1f") -> str:
    return "–" if x is None else format(scale * x, fmt)


def _coloured(text: str, met: bool | None) -> str:
    if met is None:
        return text
    return f"[green]{text}[/green]" if met else f"[red]{text}[/red]"


def variants_table(title: str, agg: dict, ceiling: dict | None = None):
    """One scope's variants; with ``ceiling`` (:func:`replay_ceiling` of (d)), a last row with
    the human replay's force correlations on (d)'s successful runs."""
    from rich.table import Table

    from retarget.run import LOAD_BEARING_SHARE

    t = Table(
        title=title,
        caption="strict: no frame > 5 cm; loose: mean < 10 cm and < 0.5 rad (errors count as "
        "failures; (d) runs only where the force pipeline reproduced the demonstration). obj, "
        "rot: mean object errors. F corr (force correlation over the whole demonstration / over "
        "contact frames / whole demonstration, load-bearing fingers only (≥ "
        f"{100 * LOAD_BEARING_SHARE:.0f} % of the hand's force); successful runs), F err "
        "(object force error, N and % of m·g): runs with human forces, all / successful. "
        "pen: kinematic / re-simulation max. Every variant re-simulated with the force "
        f"pipeline's contacts (solref {1e3 * FORCE_CONTACT_TIMECONST:.0f} ms).",
    )
    cols = ("variant", "runs", "strict %", "loose %", "obj cm", "rot °", "F corr", "F err N",
            "F err %mg", "pen mm", "ms/frame")  # fmt: skip
    for c in cols:
        t.add_column(c, justify="left" if c == "variant" else "right", no_wrap=True)
    for v in VARIANTS:
        a = agg[v]
        if v in NOT_IMPLEMENTED:
            t.add_row(LABELS[v], NOT_IMPLEMENTED[v], *["n/a"] * (len(cols) - 2))
            continue
        runs = f"{a['runs']}"
        if a["errors"]:
            runs += f" ({a['errors']} err)"
        if a["skipped"]:
            runs += f" ({a['skipped']} skip)"
        t.add_row(
            LABELS[v],
            runs,
            _f(a["success_rate"], 100, ".0f"),
            _f(a["success_loose_rate"], 100, ".0f"),
            _f(a["object_pos_err_mean_m"], 100, ".2f"),
            _f(a["object_rot_err_mean_rad"], 180 / np.pi),
            f"{_f(a['force_profile_correlation_mean_successful'], fmt='.2f')} / "
            f"{_f(a['force_correlation_mean_successful'], fmt='.2f')} / "
            f"{_f(a['force_profile_correlation_mean_load_bearing_successful'], fmt='.2f')}",
            f"{_f(a['object_force_error_mean_n'], fmt='.2f')} / "
            f"{_f(a['object_force_error_mean_n_successful'], fmt='.2f')}",
            f"{_f(a['object_force_error_pct_weight'], 100, '.0f')} / "
            f"{_f(a['object_force_error_pct_weight_successful'], 100, '.0f')}",
            f"{_f(a['penetration_max_m'], 1e3)} / {_f(a['sim_penetration_max_m'], 1e3)}",
            _f(a["ms_per_frame"], fmt=".2f"),
        )
    if ceiling is not None and ceiling["runs"]:
        c = ceiling["replay"]
        t.add_row(
            f"human replay (MPC seed {HUMAN_REPLAY_SEED} vs 0)",
            f"{ceiling['runs']} (d) ok",
            *["–"] * 4,
            f"{_f(c['force_profile_correlation_mean'], fmt='.2f')} / "
            f"{_f(c['force_correlation_mean'], fmt='.2f')} / "
            f"{_f(c['force_profile_correlation_mean_load_bearing'], fmt='.2f')}",
            *["–"] * 4,
        )
    return t


def human_table(sims: list[dict]):
    from rich.table import Table

    ok = sum(1 for s in sims if s["success"])
    tracker = sims[0]["tracker"] if sims else "–"
    t = Table(
        title=f"human force pipeline ({tracker}): {ok}/{len(sims)} reproduced the demonstration",
        caption="the others have no human forces: (d) is skipped for them and the other "
        "variants' force columns stay empty. Replay: the same demonstration simulated again "
        "with another MPC seed, its per-finger forces scored against the first's (force "
        "correlation over the whole demonstration / over contact frames, all five fingers)",
    )
    replays = any("replay" in s for s in sims)
    cols = ("pair", "object", "mass kg", "reproduced", "max err cm", "CPU s")
    if replays:
        cols += (f"replay (seed {HUMAN_REPLAY_SEED})", "replay F corr")
    for c in cols:
        t.add_column(c, justify="left" if c in ("pair", "object") else "right", no_wrap=True)
    for s in sims:
        if "error" in s:
            status = f"[red]error: {s['error'][:60]}[/red]"
        elif s["success"]:
            status = "[green]yes[/green]"
        else:
            status = f"[red]no (frame {s['failed_at_frame']})[/red]"
        cells = [
            s["pair"],
            s["object_id"],
            _f(s.get("mass_kg"), fmt=".3f"),
            status,
            _f(s.get("object_pos_err_max_m"), 100),
            _f(s.get("compute_s")),
        ]
        if replays:
            r = s.get("replay")
            if r is None:
                cells += ["–", "–"]
            else:
                ok_r = "[green]yes[/green]" if r["success"] else "[red]no[/red]"
                cells += [
                    ok_r,
                    f"{_f(r.get('force_profile_correlation_mean'), fmt='.2f')} / "
                    f"{_f(r.get('force_correlation_mean'), fmt='.2f')}",
                ]
        t.add_row(*cells)
    return t


def heavy_table(hv_by_scope: dict, human_hv: dict | None = None):
    """Heavy vs light per scope and variant; with ``human_hv`` (:func:`human_heavy_vs_light`),
    the force pipeline's own rates below."""
    from rich.table import Table

    t = Table(
        title="heavy vs light: strict success %",
        caption="all: every light / heavy run; paired: the same (hand, pair) with the light "
        "object and its heavy variant (n pairs). human: the force pipeline's own success (the "
        f"replay at MPC seed {HUMAN_REPLAY_SEED}: of the simulations that reproduced their "
        "demonstration)",
    )
    for c in ("scope", "variant", "light %", "heavy %", "paired light %", "paired heavy %", "n"):
        t.add_column(c, justify="left" if c in ("scope", "variant") else "right", no_wrap=True)
    for scope, hv in hv_by_scope.items():
        for v in VARIANTS:
            if v in NOT_IMPLEMENTED:
                t.add_row(scope, LABELS[v], NOT_IMPLEMENTED[v], *["n/a"] * 4)
                continue
            h = hv[v]
            t.add_row(
                scope,
                LABELS[v],
                f"{_f(h['light_success_rate'], 100, '.0f')} ({h['light_runs']})",
                f"{_f(h['heavy_success_rate'], 100, '.0f')} ({h['heavy_runs']})",
                _f(h["paired_light_success_rate"], 100, ".0f"),
                _f(h["paired_heavy_success_rate"], 100, ".0f"),
                str(h["paired_runs"]),
            )
    for name, h in (human_hv or {}).items():
        if h is None:
            continue
        t.add_row(
            "human",
            "force pipeline" if name == "first" else f"replay (seed {HUMAN_REPLAY_SEED})",
            f"{_f(h['light_success_rate'], 100, '.0f')} ({h['light_runs']})",
            f"{_f(h['heavy_success_rate'], 100, '.0f')} ({h['heavy_runs']})",
            _f(h["paired_light_success_rate"], 100, ".0f"),
            _f(h["paired_heavy_success_rate"], 100, ".0f"),
            str(h["paired_runs"]),
        )
    return t


def targets_table(scope: str, checks: list[dict]):
    from rich.table import Table

    t = Table(title=f"targets (issue 7) on {scope}")
    t.add_column("target")
    t.add_column("measured", justify="right")
    t.add_column("target met?", justify="center")
    for c in checks:
        v = c["value"]
        if c["name"] in ("vs dex", "heavy"):
            a, b = v
            s = f"{_f(a, 100, '.0f')} % vs {_f(b, 100, '.0f')} % (n={c['runs']})"
            if c["name"] == "vs dex" and a is not None and b:
                s += f", {a / b:.1f}×"
        elif c["name"] == "correlation":
            s = _f(v, fmt=".2f")
            if c.get("reached_fingers_value") is not None:
                s += f"; fingers reaching the human's contacts {c['reached_fingers_value']:.2f}"
            if c.get("human_replay_runs"):
                s += (
                    f" (same {c['human_replay_runs']} runs: {_f(c['same_runs'], fmt='.2f')}; "
                    f"human replay {_f(c['human_replay'], fmt='.2f')})"
                )
            if c.get("smoothed_value") is not None:
                s += f"; over {1e3 * CAPTURE_SMOOTH_S:.0f} ms {c['smoothed_value']:.2f}"
                if c.get("human_replay_smoothed") is not None:
                    s += (
                        f" (same runs {_f(c['same_runs_smoothed'], fmt='.2f')}; human replay "
                        f"{_f(c['human_replay_smoothed'], fmt='.2f')})"
                    )
        else:
            s = f"{_f(v, 100, '.0f')} %" + (f" (n={c['runs']})" if "runs" in c else "")
        verdict = {True: "[green]yes[/green]", False: "[red]no[/red]", None: "n/a"}[c["met"]]
        t.add_row(c["target"], s, verdict)
    return t


def plot_success(
    per_hand: dict, scope_aggs: dict, path: Path, ceilings: dict | None = None
) -> Path:
    """Grouped bars: strict success [%] per hand (and per scope), one bar per variant; with
    ``ceilings`` (hand or scope → :func:`replay_ceiling` of (d)), a second panel: (d)'s force
    profile correlation on its successful runs next to the human replay's on the same runs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = {**per_hand, **scope_aggs}
    names = list(groups)
    run_v = list(RUN_VARIANTS)
    width = 0.8 / len(VARIANTS)
    x = np.arange(len(names))
    size = (max(6.0, 1.3 * len(names) + 2), 4.2)
    if ceilings:
        fig, (ax, ax2) = plt.subplots(
            2, 1, figsize=(size[0], 2 * size[1] + 0.8), gridspec_kw={"hspace": 0.55}
        )
    else:
        fig, ax = plt.subplots(figsize=size)
    for k, v in enumerate(VARIANTS):
        xs = x - 0.4 + (k + 0.5) * width
        if v in NOT_IMPLEMENTED:
            for xi in xs:
                ax.text(
                    xi, 1.5, "n/a", rotation=90, ha="center", va="bottom", fontsize=7, color="0.4"
                )
            ax.bar(
                xs,
                np.zeros(len(names)),
                width,
                label=f"{LABELS[v]}: not implemented",
                color="0.85",
                hatch="//",
            )
            continue
        vals = [groups[n][v]["success_rate"] for n in names]
        h = [100 * (s or 0.0) for s in vals]
        bars = ax.bar(xs, h, width, label=LABELS[v], color=f"C{run_v.index(v)}")
        for b, s in zip(bars, vals, strict=True):
            label = "–" if s is None else f"{100 * s:.0f}"
            ax.text(
                b.get_x() + b.get_width() / 2,
                b.get_height() + 1,
                label,
                ha="center",
                va="bottom",
                fontsize=6,
            )
    ax.axhline(100 * TARGET_SUCCESS, color="k", lw=0.8, ls="--")
    _target_label(ax, 100 * TARGET_SUCCESS, f"target (d)\nor (e) {100 * TARGET_SUCCESS:.0f} %")
    ax.set_xticks(x, names)
    ax.set_ylim(0, 110)
    ax.set_ylabel("strict success [%] (no frame > 5 cm)")
    ax.set_title("force preservation: re-simulated strict success by variant and hand")
    ax.legend(fontsize=7, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.1))
    if ceilings:
        _plot_ceiling(ax2, names, ceilings)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    fig.savefig(tmp, dpi=120, bbox_inches="tight")
    plt.close(fig)
    os.replace(tmp, path)
    return path


def _target_label(ax, y: float, text: str) -> None:
    """Name a target line in the right margin, clear of the bars' value labels."""
    ax.text(1.005, y, text, transform=ax.get_yaxis_transform(), ha="left", va="center", fontsize=7)


def _plot_ceiling(ax, names: list[str], ceilings: dict) -> None:
    """(d)'s whole-demonstration force correlation and the human replay's, on the same runs."""
    key = "force_profile_correlation_mean"
    x = np.arange(len(names))
    for k, (label, side, color) in enumerate(
        (("(d) + forces", "ours", f"C{list(RUN_VARIANTS).index('d')}"),
         (f"human replay (MPC seed {HUMAN_REPLAY_SEED} vs 0)", "replay", "0.55"))
    ):  # fmt: skip
        vals = [ceilings.get(n, {}).get(side, {}).get(key) for n in names]
        bars = ax.bar(x - 0.2 + 0.4 * k, [v or 0.0 for v in vals], 0.4, label=label, color=color)
        for b, v in zip(bars, vals, strict=True):
            text = "–" if v is None else f"{v:.2f}"
            xc = b.get_x() + b.get_width() / 2
            ax.text(xc, b.get_height() + 0.01, text, ha="center", va="bottom", fontsize=6)
    runs = [ceilings.get(n, {}).get("runs", 0) for n in names]
    ax.set_xticks(x, [f"{n}\n({r} runs)" for n, r in zip(names, runs, strict=True)])
    ax.axhline(TARGET_CORRELATION, color="k", lw=0.8, ls="--")
    _target_label(ax, TARGET_CORRELATION, f"target {TARGET_CORRELATION:g}")
    ax.set_ylim(0, 1.1)
    ax.set_ylabel("force profile correlation")
    ax.set_title("per-finger force correlation on (d)'s successful runs: ours and the human's own")
    ax.legend(fontsize=7, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.22))


# ------------------------------------------------------------------------ human-sim cache
@cache
def _sim_sources_digest() -> str:
    """Digest of the force pipeline's source (``dexcanvas_core.sim``, ``.mano``): a cached
    human simulation is only reused by the code that made it (read once per process)."""
    import hashlib

    import dexcanvas_core

    root = Path(dexcanvas_core.__file__).parent
    h = hashlib.sha256()
    for sub in ("sim", "mano"):
        for f in sorted((root / sub).rglob("*.py")):
            h.update(f.relative_to(root).as_posix().encode())
            h.update(f.read_bytes())
    return h.hexdigest()


def human_cache_key(traj, object_id: str, tracker: str, mpc_seed: int | None = None) -> str:
    """File stem of one human simulation in the cache: the demonstration's data, the object,
    the tracker's configuration (the replay's seed included) and the force pipeline's source."""
    import hashlib

    h = hashlib.sha256()
    h.update(repr(human_sim_config(object_id, tracker, mpc_seed)).encode())
    h.update(_sim_sources_digest().encode())
    h.update(str(traj.uuid).encode())
    hand, obj = traj.hand, traj.object
    arrays = (traj.timestamp, hand.global_pos, hand.global_rot_aa, hand.finger_pose, hand.betas,
              obj.pos, obj.rot_aa)  # fmt: skip
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return f"{object_id}-{tracker}-{h.hexdigest()[:24]}"


def load_human_sim(cache_dir: Path, key: str, console=None) -> dict | None:
    """The cached ``_human_sim`` result ``key``, or ``None`` (absent, or unreadable: said on the
    console and simulated again)."""
    import pickle

    path = Path(cache_dir) / f"{key}.pkl"
    if not path.is_file():
        return None
    try:
        with open(path, "rb") as fh:
            res = pickle.load(fh)
        if not (isinstance(res, dict) and "record" in res and "trajectory" in res):
            raise ValueError("not a human simulation record")
    except Exception as e:  # a truncated or foreign file: simulate again, overwrite it
        if console is not None:
            console.print(f"[yellow]human cache: {path.name} unreadable ({e}); simulating again")
        return None
    return {**res, "record": {**res["record"], "cached": True}}


def store_human_sim(cache_dir: Path, key: str, res: dict) -> None:
    """Write ``res`` to the cache atomically (temporary file, then rename)."""
    import pickle

    cache_dir = Path(cache_dir)
    cache_dir.mkdir(parents=True, exist_ok=True)
    path = cache_dir / f"{key}.pkl"
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as fh:
        pickle.dump({"record": res["record"], "trajectory": res["trajectory"]}, fh)
    os.replace(tmp, path)


# --------------------------------------------------------------------------------------- main
def run_jobs(cfg: BenchConfig, demos: list, plans: list, hands: list, console):
    """Every (pair, object) through the force pipeline, and as soon as one is done, its hand
    jobs, over ``cfg.workers`` spawned one-thread processes. Returns ``(human_records, rows,
    skipped)``: one record per human simulation, one row per hand × (pair, object) × variant,
    and the (hand, pair)s a hand cannot perform. With ``cfg.replays()``, each human simulation
    that reproduced its demonstration is simulated again at ``HUMAN_REPLAY_SEED`` and its record
    gets a ``replay`` (:func:`replay_record`)."""
    from retarget.errors import RetargetError
    from retarget.run import check_pair

    performable = {}
    skipped = []
    for i, (pair, _) in enumerate(demos):
        performable[i] = []
        for hand in hands:
            try:
                check_pair(hand, pair.manipulation_type)
                performable[i].append(hand)
            except RetargetError as e:
                skipped.append({"hand": hand.name, "pair": str(pair), "reason": str(e)})
    total = sum(len(p) * (1 + len(performable[i])) for i, p in enumerate(plans))
    human: list[dict] = []
    rows: list[dict] = []
    ctx = multiprocessing.get_context("spawn")
    with (
        _one_thread_env(),
        ProcessPoolExecutor(cfg.workers, mp_context=ctx, initializer=_init_worker) as pool,
        progress_bar(console) as prog,
    ):
        task = prog.add_task("human force pipeline", total=total)
        pending = {}
        keys = {}
        computed = cfg.computed_variants()
        firsts: dict[tuple[int, int], tuple[dict, object]] = {}  # (record, trajectory)
        n_jobs = [total]  # grows by one per replay

        def cached_or_submit(kind: str, i: int, k: int, seed: int | None) -> dict | None:
            """The cached simulation, or ``None`` after submitting it."""
            _, traj = demos[i]
            oid = plans[i][k]["object_id"]
            if cfg.human_cache is not None:
                keys[kind, i, k] = human_cache_key(traj, oid, cfg.human_tracker, seed)
                res = load_human_sim(cfg.human_cache, keys[kind, i, k], console)
                if res is not None:
                    return res
            job = ((i, k), traj, oid, cfg.human_tracker, seed)
            pending[pool.submit(_human_sim, job)] = (kind, i, k)
            return None

        def on_replay(i: int, k: int, res: dict) -> None:
            rec, first = firsts.pop((i, k))
            rec["replay"] = replay_record(first, res)

        def on_human(i: int, k: int, res: dict) -> None:
            """A human simulation is done (or read from the cache): its hand jobs, and its
            replay."""
            pair, traj = demos[i]
            obj = plans[i][k]
            prog.update(task, description=f"human force pipeline · {pair} · {obj['object_id']}")
            rec = {"index": i, "pair": str(pair), **obj, **res["record"]}
            human.append(rec)
            if cfg.replays() and res["trajectory"] is not None:
                firsts[i, k] = (rec, res["trajectory"])
                n_jobs[0] += 1
                prog.update(task, total=n_jobs[0])
                again = cached_or_submit("replay", i, k, HUMAN_REPLAY_SEED)
                if again is not None:
                    prog.advance(task)
                    on_replay(i, k, again)
            for hand in performable[i]:
                base = {
                    "hand": hand.name,
                    "index": i,
                    "pair": str(pair),
                    "group": pair.manipulation_type.group,
                    "manipulation_type": pair.manipulation_type.name,
                    **obj,
                    "frames": traj.num_frames,
                    "uuid": traj.uuid,
                    "human_forces": res["trajectory"] is not None,
                }
                job = (
                    base,
                    traj,
                    res["trajectory"],
                    cfg.dex_wrist,
                    computed,
                    cfg.overrides,
                    cfg.refine_overrides,
                    cfg.calibrate_iterations,
                )
                pending[pool.submit(_hand_job, job)] = ("hand", i, k)

        for i in range(len(demos)):
            for k in range(len(plans[i])):
                res = cached_or_submit("human", i, k, None)
                if res is not None:
                    prog.advance(task)
                    on_human(i, k, res)
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                kind, i, k = pending.pop(fut)
                pair, _ = demos[i]
                prog.advance(task)
                if kind == "hand":
                    rows.extend(fut.result())
                    obj = plans[i][k]
                    prog.update(task, description=f"retargeting · {pair} · {obj['object_id']}")
                    continue
                res = fut.result()
                if cfg.human_cache is not None:
                    store_human_sim(cfg.human_cache, keys[kind, i, k], res)
                (on_replay if kind == "replay" else on_human)(i, k, res)
    human.sort(key=lambda r: (r["index"], r["object_variant"] == "heavy"))
    return human, rows, skipped


def run_benchmark(cfg: BenchConfig, console=None) -> dict:
    """Run every hand × pair × object × variant, print the tables, write the JSON and the plot;
    return the JSON document."""
    from rich.console import Console

    from dexcanvas_core.sim.pipeline import SimConfig
    from dexcanvas_core.taxonomy import GROUPS
    from retarget.hands import available_hands, get_hand

    console = console or Console(width=None if sys.stdout.isatty() else 160)
    cfg = cfg.validate()
    t_start = time.perf_counter()
    load0 = os.getloadavg()
    hands = [get_hand(h) for h in (cfg.hands or available_hands())]
    five = [h.name for h in hands if is_five_finger(h)]
    demos, source, demo_failures = load_demonstrations(cfg, console)
    if not demos:
        raise SystemExit("no demonstrations to run")
    plans = [object_plan(p, cfg.heavy) for p, _ in demos]
    groups = {g: sum(1 for p, _ in demos if p.manipulation_type.group == g) for g in GROUPS}
    n_heavy = sum(1 for p in plans for o in p if o["heavy_version_of"])
    console.print(
        f"{len(demos)} pairs from {source} ({', '.join(f'{g} {n}' for g, n in groups.items())})"
        f" + {n_heavy} heavy version(s); hands: {', '.join(h.name for h in hands)}; human "
        f"tracker {cfg.human_tracker}; {cfg.workers} worker(s)"
        + (f"; variants {' '.join(cfg.variants)}" if cfg.variants != RUN_VARIANTS else "")
        + (f"; RetargetConfig {cfg.overrides}" if cfg.overrides else "")
        + (f"; RefineConfig {cfg.refine_overrides}" if cfg.refine_overrides else "")
        + (f"; human cache {cfg.human_cache}" if cfg.human_cache is not None else "")
        + (f"; human replay at MPC seed {HUMAN_REPLAY_SEED}" if cfg.replays() else "")
    )

    human, rows, skipped = run_jobs(cfg, demos, plans, hands, console)
    hand_order = {h.name: k for k, h in enumerate(hands)}
    rows.sort(
        key=lambda r: (
            hand_order[r["hand"]],
            r["index"],
            r["object_variant"] == "heavy",
            r["variant"],
        )
    )
    for r in rows:
        if "error" in r:
            console.print(
                f"[red]{r['hand']} · {r['pair']} · {r['object_id']} · "
                f"{LABELS[r['variant']]}: {r['error']}[/red]"
            )

    per_hand = {h.name: aggregate_variants([r for r in rows if r["hand"] == h.name]) for h in hands}
    scopes = {ALL_HANDS: rows}
    if five:
        scopes = {FIVE_FINGER: [r for r in rows if r["hand"] in five], **scopes}
    scope_aggs = {s: aggregate_variants(rs) for s, rs in scopes.items()}
    hv = {s: heavy_vs_light(rs) for s, rs in scopes.items()}
    by_contact = {s: by_contact_error(rs) for s, rs in scopes.items()}
    by_reach = {s: correlation_by_reach(rs, human) for s, rs in scopes.items()}
    by_wrench = {s: heavy_vs_light_by_wrench(rs) for s, rs in scopes.items()}
    target_scope = FIVE_FINGER if five else ALL_HANDS
    ceilings = per_hand_ceiling = None
    if cfg.replays():
        ceilings = {
            s: {v: replay_ceiling(rs, human, v) for v in ("d", "e")} for s, rs in scopes.items()
        }
        per_hand_ceiling = {
            h.name: replay_ceiling([r for r in rows if r["hand"] == h.name], human, "d")
            for h in hands
        }
    checks = target_checks(
        target_scope,
        scopes[target_scope],
        scope_aggs[target_scope],
        hv[target_scope],
        None if ceilings is None else ceilings[target_scope],
    )

    console.print(human_table(human))
    for h in hands:
        n_skip = sum(1 for s in skipped if s["hand"] == h.name)
        title = h.name + (" (five fingers)" if h.name in five else "")
        if n_skip:
            title += f" ({n_skip} pair(s) skipped: cannot perform)"
        hc = None if per_hand_ceiling is None else per_hand_ceiling[h.name]
        console.print(variants_table(title, per_hand[h.name], hc))
    for s, a in scope_aggs.items():
        if s == ALL_HANDS and len(hands) == 1:
            continue  # the same as the one hand's table
        names = ", ".join(five) if s == FIVE_FINGER else ", ".join(h.name for h in hands)
        console.print(
            variants_table(f"{s} ({names})", a, None if ceilings is None else ceilings[s]["d"])
        )
    human_hv = human_heavy_vs_light(human)
    console.print(heavy_table(hv, human_hv))
    if "d" in cfg.computed_variants():
        for s_, tab in by_wrench.items():
            if s_ == ALL_HANDS and len(hands) == 1:
                continue
            console.print(wrench_table(s_, tab))
    for s_, tab in by_contact.items():
        if s_ == ALL_HANDS and len(hands) == 1:
            continue
        console.print(contact_error_table(s_, tab))
        if "d" in cfg.computed_variants():
            console.print(reach_table(s_, by_reach[s_]))
    console.print(targets_table(target_scope, checks))

    plot_ceilings = None
    if ceilings is not None:
        plot_ceilings = {**per_hand_ceiling, **{s: c["d"] for s, c in ceilings.items()}}
    plot = plot_success(
        per_hand,
        {s: a for s, a in scope_aggs.items() if len(hands) > 1},
        cfg.plot_path(),
        plot_ceilings,
    )
    doc = {
        "benchmark": "force_preservation",
        "command": " ".join(["python benchmarks/force_preservation.py", *sys.argv[1:]]),
        "config": {
            **dataclasses.asdict(cfg),
            "out": str(cfg.out),
            "plot": str(plot),
            "human_cache": None if cfg.human_cache is None else str(cfg.human_cache),
        },
        "human_sim_config": SimConfig(tracker=cfg.human_tracker).as_dict(),
        "variants": {
            v: {"label": LABELS[v], "implemented": v not in NOT_IMPLEMENTED} for v in VARIANTS
        },
        "demonstrations": {
            "source": source,
            "pairs": [str(p) for p, _ in demos],
            "frames": {str(p): t.num_frames for p, t in demos},
            "objects": {str(p): plans[i] for i, (p, _) in enumerate(demos)},
            "generation_failures": demo_failures,
        },
        "human_simulations": human,
        "human_simulations_failed": [
            {
                "pair": s["pair"],
                "object_id": s["object_id"],
                "failed_at_frame": s.get("failed_at_frame"),
                "error": s.get("error"),
            }
            for s in human
            if not s["success"]
        ],
        "hands": [h.name for h in hands],
        "five_finger_hands": five,
        "skipped": skipped,
        "commit": git_commit(),
        "machine": machine_info(load0, threads_per_worker=1),
        "versions": versions(VERSION_DISTS),
        "definitions": {
            "success": "Resimulator strict rule (no frame with object error > 5 cm)",
            "success_loose": "mean object error < 10 cm and < 0.5 rad",
            "force_correlation_mean": "retarget.run.force_metrics: mean over corresponding "
            "fingers the human loaded (> 0.05 N on more than 2 frames) of the correlation of "
            "human and re-simulated robot contact-force magnitude profiles (frames where either "
            "exceeds 0.05 N); 0 for a robot finger that never presses",
            "force_profile_correlation_mean": "the same correlation over every frame of the "
            "demonstration (the force profile, contact on/off timing included)",
            "*_load_bearing": "the same means over the fingers whose mean human force is at "
            "least retarget.run.LOAD_BEARING_SHARE of the mapped fingers' summed mean force",
            "force_profile_correlation_mean_reached": "the whole-clip mean over the fingers "
            "whose contact_reach_m (the median distance from the robot finger to the human's "
            "contact point in (d)'s plan, over the frames the human finger loads) is at most "
            "retarget.run.REACH_M; correlation_by_reach pools single fingers by reach",
            "force_profile_correlation_mean_smoothed": "the whole-clip mean with both force "
            "profiles moving-averaged over the demonstration's bandwidth first "
            f"(retarget.run.profile_band_frames: the force pipeline's {1e3 * CAPTURE_SMOOTH_S:.0f}"
            " ms capture smoothing; "
            "the robots' contact chatter above it is not part of the human's profile)",
            "object_force_error_mean_n": "mean over frames where the human touches of |sum of "
            "robot contact forces - sum of human contact forces| on the object (force part of "
            "the wrench; no torque: the re-simulation reports no contact points)",
            "object_force_error_pct_weight": "object_force_error_mean_n / (m g) of the run's "
            "object",
            "*_successful": "over runs whose re-simulation met the strict rule",
            "success_rate_with_human_forces": "over runs whose (pair, object) the force "
            "pipeline reproduced",
            "penetration_max_m": "deepest kinematic hand-object penetration of q (max over "
            "frames; aggregates: max over runs)",
            "sim_penetration_max_m": "deepest hand-object penetration in the re-simulation",
            "ms_per_frame": "ours: RobotTrajectory.ms_per_frame (QP solve + squeeze or force "
            "QP); dex-retargeting: its per-frame call; frame-weighted in aggregates",
            "five_finger_hands": "hands with five distinct robot fingers",
            "heavy_vs_light_by_wrench": "light / heavy strict success of (d) and (e), split "
            "by (d)'s wrench_feasible_fraction >= WRENCH_FEASIBLE (feasible) or below (short): "
            "whether the force QP could produce the human's object wrench at the retargeted "
            "contacts within the servos' torque limits",
            "human_replay": "the force pipeline run again on the same (pair, object) with "
            f"MPC seed {HUMAN_REPLAY_SEED} (the first: 0); replay.force_* score its per-finger "
            "forces against the first simulation's as force_metrics scores a robot's "
            "(retarget.run.human_replay_metrics)",
            "human_replay_ceiling": "replay_ceiling: over a variant's successful runs with a "
            "scored replay, the replay's correlations on the fingers each run scores (and the "
            "run's load shares), next to the variant's own on the same runs",
        },
        "targets": checks,
        "aggregates": {
            "per_scope": scope_aggs,
            "per_hand": per_hand,
            "heavy_vs_light": hv,
            "heavy_vs_light_by_wrench": by_wrench,
            "human_heavy_vs_light": human_hv,
            "by_contact_error": by_contact,
            "correlation_by_reach": by_reach,
            "human_replay_ceiling": None
            if ceilings is None
            else {"per_scope": ceilings, "per_hand": per_hand_ceiling},
        },
        "runs": rows,
        "wall_time_s": time.perf_counter() - t_start,
    }
    atomic_write_json(Path(cfg.out), doc)
    console.print(f"wrote {cfg.out} and {plot} ({doc['wall_time_s']:.0f} s)")
    return doc


def main(argv: list[str] | None = None) -> int:
    from retarget.hands import available_hands

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--hands",
        nargs="+",
        default=None,
        choices=available_hands(),
        help="hands to run (default: all)",
    )
    ap.add_argument("--n-pairs", type=int, default=20, help="pairs over the four groups")
    ap.add_argument("--max-frames", type=int, default=None, help="crop each demonstration")
    ap.add_argument(
        "--human-tracker",
        choices=TRACKERS,
        default="mpc",
        help="force pipeline tracker (open_loop: fast smoke runs)",
    )
    ap.add_argument(
        "--heavy",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also run heavy variants of the pairs' objects",
    )
    ap.add_argument("--workers", type=int, default=2, help="processes, one thread each")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON output")
    ap.add_argument(
        "--plot", type=Path, default=None, help="PNG output (default: the JSON path with .png)"
    )
    ap.add_argument("--operator", default="operator1")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--dex-wrist",
        choices=("free", "fixed"),
        default="free",
        help="dex-retargeting's wrist: optimised (free) or the human wrist pose",
    )
    ap.add_argument(
        "--variants",
        nargs="+",
        choices=RUN_VARIANTS,
        default=list(RUN_VARIANTS),
        help="variants to run (default: all; e also runs d)",
    )
    ap.add_argument(
        "--set",
        dest="overrides",
        action="append",
        type=parse_override,
        default=[],
        metavar="NAME=VALUE",
        help="change a RetargetConfig field of our variants (repeatable), e.g. --set "
        "w_contacts=100",
    )
    ap.add_argument(
        "--refine-set",
        dest="refine_overrides",
        action="append",
        type=parse_override,
        default=[],
        metavar="NAME=VALUE",
        help="change a RefineConfig field of variant (e)'s refinement (repeatable), e.g. "
        "--refine-set retries=2",
    )
    ap.add_argument(
        "--calibrate-iterations",
        type=int,
        default=BenchConfig.calibrate_iterations,
        metavar="N",
        help="variant (d)'s force calibration: re-simulations correcting the commands until "
        f"the fingers press like the human's (default {BenchConfig.calibrate_iterations}; 0: "
        "the planned commands)",
    )
    ap.add_argument(
        "--human-cache",
        type=Path,
        default=None,
        metavar="DIR",
        help="reuse human simulations stored here (written on first use): ablations of the "
        "retargeting skip the force pipeline",
    )
    ap.add_argument(
        "--human-replay",
        action=argparse.BooleanOptionalAction,
        default=True,
        help=f"simulate each human demonstration again at MPC seed {HUMAN_REPLAY_SEED} and score "
        "its forces against the first's: the force correlation's ceiling (mpc tracker only)",
    )
    a = ap.parse_args(argv)
    from retarget.refine import RefineConfig
    from retarget.retargeter import RetargetConfig

    overrides = config_overrides(a.overrides, RetargetConfig)
    refine_overrides = config_overrides(a.refine_overrides, RefineConfig, "--refine-set")
    logging.basicConfig(level=logging.ERROR)
    cfg = BenchConfig(
        hands=tuple(dict.fromkeys(a.hands)) if a.hands else None,
        n_pairs=a.n_pairs,
        max_frames=a.max_frames,
        human_tracker=a.human_tracker,
        heavy=a.heavy,
        workers=a.workers,
        out=a.out,
        plot=a.plot,
        operator=a.operator,
        seed=a.seed,
        dex_wrist=a.dex_wrist,
        variants=tuple(dict.fromkeys(a.variants)),
        overrides=overrides,
        refine_overrides=refine_overrides,
        calibrate_iterations=a.calibrate_iterations,
        human_cache=a.human_cache,
        human_replay=a.human_replay,
    )
    run_benchmark(cfg)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
