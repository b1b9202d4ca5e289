"""The work per case: a human simulation, the variants of one hand on one (pair, object), and the
pool that runs them."""

from __future__ import annotations

import time
from concurrent.futures import FIRST_COMPLETED, wait
from functools import cache
from types import SimpleNamespace

import numpy as np

from benchmarks._common import (
    error_record,
    progress_bar,
    resim_result,
    sim_metrics,
    table_penetration,
    worker_pool,
)
from benchmarks.force_preservation.aggregate import replay_record
from benchmarks.force_preservation.cache import human_cache_key, load_human_sim, store_human_sim
from benchmarks.force_preservation.config import (
    HUMAN_METRICS,
    NOT_REQUESTED,
    RUN_VARIANTS,
    BenchConfig,
)
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.sim.physics import GRAVITY
from dexcanvas_core.sim.pipeline import simulate
from dexcanvas_core.taxonomy import Pair
from retarget.baselines import (
    DexRetargetingBaseline,
    DexRetargetingConfig,
    KinematicMetrics,
    measure_trajectory,
)
from retarget.config import RetargetConfig
from retarget.errors import RetargetError
from retarget.hands import get_hand
from retarget.human_forces import HUMAN_REPLAY_SEED, human_sim_config
from retarget.metrics import force_metrics, refined_force_metrics
from retarget.pipeline import check_pair, refine_config, refine_lost, retarget_demonstration
from retarget.retargeter import Retargeter
from retarget.validate import Resimulator


# ------------------------------------------------------------------------------------ workers
def _human_sim(args) -> dict:
    """Worker: the force pipeline on one (pair, object), at the MPC's default seed or at
    ``mpc_seed`` (the replay). Returns ``{"record", "trajectory"}``; ``trajectory`` (the
    demonstration annotated with contacts and forces) only on success."""

    key, traj, object_id, tracker, mpc_seed = args
    rec: dict = {"object_id": object_id, "tracker": tracker, "mpc_seed": mpc_seed}
    w0 = time.perf_counter()
    try:
        res = simulate(traj, human_sim_config(object_id, tracker, mpc_seed))
        rec.update({k: res.metrics[k] for k in HUMAN_METRICS})
        annotated = res.trajectory if res.success else None
    except Exception as e:  # no human forces for this (pair, object): recorded, counted
        rec.update(error_record(e))
        rec["success"] = False
        annotated = None
    rec["wall_s"] = time.perf_counter() - w0
    return {"key": key, "record": rec, "trajectory": annotated}


@cache
def _baseline(hand_name: str, wrist: str):
    """dex-retargeting for one hand, built once per worker process."""

    return DexRetargetingBaseline(get_hand(hand_name), DexRetargetingConfig(wrist=wrist))


FORCE_KEYS = (
    "force_per_finger", "force_correlation_mean", "force_profile_correlation_mean",
    "force_correlation_mean_load_bearing", "force_profile_correlation_mean_load_bearing",
    "force_profile_correlation_mean_reached", "force_profile_correlation_mean_smoothed",
    "fingers_reached", "fingers_scored", "object_force_error_mean_n",
    "object_force_error_contact_frames_mean_n", "object_force_error_pct_weight",
    "contact_precision", "contact_recall",
)  # fmt: skip
"""A row's force columns (:func:`retarget.metrics.force_metrics`, + % of the weight)."""


def _force_columns(human_force, robot_d, sim_res, human, retargeter, variant: str) -> dict:
    """``force_metrics`` of one variant's re-simulation against the human's forces: every
    variant is compared with the human per-finger forces mapped onto this hand's fingers
    (``human_force``, ``Retargeter.human_finger_forces``; (d)'s ``robot_d.human_force``)."""

    robot = robot_d
    if variant != "d":  # only the human side is read from the robot (no force QP ran)
        robot = SimpleNamespace(
            human_force=human_force, wrench_shortfall=np.zeros(human_force.shape[0])
        )
    m = force_metrics(robot, sim_res, human, retargeter)
    if variant != "d":
        m["wrench_feasible_fraction"] = None  # a property of the force QP, (d) only
    return m


def _pipeline_columns(res) -> dict:
    """(d)'s row columns from its pipeline result (``retarget.pipeline.PipelineResult``): the
    re-simulation's metrics and table penetration; with force calibration, the chosen
    iterate's (its commands are ``res.robot.q_command``) and the planned commands' success
    in ``planned_*``."""
    out = {
        "table_penetration_max_m": table_penetration(res.resimulator, res.robot.q_command),
        **sim_metrics(res.sim),
    }
    if res.calibration is not None:
        cm = res.calibration.metrics()
        planned = sim_metrics(res.planned_sim)
        out.update(
            planned_success=planned["success"],
            planned_object_pos_err_max_m=planned["object_pos_err_max_m"],
            calibration_iterate=cm["chosen_iterate"],
            calibration_s=cm["compute_s"],
            calibration_force_error_before=cm["force_error_before"],
            calibration_force_error_after=cm["force_error_after"],
            calibration_finger_cmd_deviation_mean_rad=cm["finger_cmd_deviation_mean_rad"],
        )
    return out


# -------------------------------------------------------------- one hand on one (pair, object)
# Variants (b), (c): the retargeter with other settings, re-simulated; (d), (e): the pipeline of
# `retarget run --forces [--refine]` (retarget.pipeline).
def _hand_job(args) -> list[dict]:
    """Worker: variants (a)–(d) of one hand on one (pair, object); one row per variant."""

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
            "b": RetargetConfig.from_overrides(
                {**overrides, "use_contacts": False, "squeeze_depth": 0.0}
            ),
            "c": RetargetConfig.from_overrides(overrides),
            "d": RetargetConfig.from_overrides({**overrides, "force_matching": True}),
        }
        for v in ("b", "c"):
            row = rows[v]
            if v not in computed:
                continue
            t0 = time.perf_counter()
            try:
                rt = Retargeter(hand, geom, configs[v])
                robot = rt.retarget(traj)
                m, sims[v] = resim_result(resim_soft, robot.q_command, traj)
                retargeters[v] = rt
                row.update(
                    ms_per_frame=robot.ms_per_frame, **KinematicMetrics.of(robot).summary(), **m
                )
            except Exception as e:  # one variant's failure is its own row's
                row.update(error_record(e))
            row["wall_s"] = time.perf_counter() - t0
        # (d) force matching, force-calibrated: the pipeline of `retarget run --forces`
        row = rows["d"]
        if "d" in computed and human is None:
            row["skipped"] = "the force pipeline did not reproduce the demonstration"
        elif "d" in computed:
            t0 = time.perf_counter()
            try:
                mtype = base["pair"].split("/", 1)[1]  # the object may be its heavy twin
                subject = Pair.parse(f"{base['object_id']}/{mtype}")
                res_d = retarget_demonstration(
                    human, subject, hand, configs["d"], calibrate_iterations=n_calibrate
                )
                robot_d, sims["d"], retargeters["d"] = res_d.robot, res_d.sim, res_d.retargeter
                row.update(
                    ms_per_frame=robot_d.ms_per_frame,
                    **KinematicMetrics.of(robot_d).summary(),
                    **_pipeline_columns(res_d),
                )
            except Exception as e:  # one variant's failure is its own row's
                row.update(error_record(e))
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
                row.update(error_record(e))
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
            t0 = time.perf_counter()
            try:
                rf = refine_lost(res_d, refine_config(True, **refine_overrides), n_calibrate)
                if rf.calibration is not None:
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
                row.update(error_record(e))
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
                r.update(error_record(e))
    return [rows[v] for v in RUN_VARIANTS]


# --------------------------------------------------------------------------------------- main
def run_jobs(cfg: BenchConfig, demos: list, plans: list, hands: list, console):
    """Every (pair, object) through the force pipeline, and as soon as one is done, its hand
    jobs, over ``cfg.workers`` spawned one-thread processes. Returns ``(human_records, rows,
    skipped)``: one record per human simulation, one row per hand × (pair, object) × variant,
    and the (hand, pair)s a hand cannot perform. With ``cfg.replays()``, each human simulation
    that reproduced its demonstration is simulated again at ``HUMAN_REPLAY_SEED`` and its record
    gets a ``replay`` (:func:`replay_record`)."""

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
    with worker_pool(cfg.workers) as pool, progress_bar(console) as prog:
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
