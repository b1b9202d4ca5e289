"""A job's record (strict success inside the contact window, failure phase), and the aggregates and
target checks over the records."""

from __future__ import annotations

import numpy as np

from benchmarks.real_motion.cases import Case
from benchmarks.real_motion.config import (
    MANO,
    MODES,
    STRICT_M,
    TARGET_MANO,
    TARGET_REFINE,
    TARGET_WRIST_M,
)


# ---------------------------------------------------------------------------------- metrics
def window_bounds(window, frames: int) -> tuple[int, int]:
    """``(first, last)`` frame of the contact window clipped to the clip (the clip when none)."""
    if window is None:
        return 0, frames - 1
    return max(0, int(window[0])), min(frames - 1, int(window[1]))


def window_check(err, window, threshold: float = STRICT_M) -> dict:
    """Strict success inside the contact window from per-frame object errors ``err`` (T,) [m]:
    ``ok`` (no frame of the window above ``threshold``), its ``max_m`` and ``first_bad_frame``."""
    err = np.asarray(err, dtype=np.float64)
    s, e = window_bounds(window, len(err))
    seg = err[s : e + 1]
    bad = np.flatnonzero(~(seg <= threshold))  # NaN counts as bad
    return {
        "ok": bool(seg.size > 0 and bad.size == 0),
        "max_m": float(np.nanmax(seg)) if seg.size and np.isfinite(seg).any() else None,
        "first_bad_frame": int(s + bad[0]) if bad.size else None,
    }


def kept_through_window(success: bool, failed_at: int | None, window, frames: int) -> bool:
    """Strict success in the window of a tracker that stops at its failure (the refinement, the
    force pipeline): it never failed, or failed after the window's last frame."""
    if success or failed_at is None:
        return bool(success or failed_at is None)
    return int(failed_at) > window_bounds(window, frames)[1]


def retarget_record(m: dict, arrays: dict, case: Case) -> dict:
    """A retarget job's numbers from ``run_retarget``'s metrics ``m`` and its
    ``robot_trajectory.npz`` ``arrays`` (module docstring)."""
    w = window_check(arrays["object_pos_err"], case.window)
    s, e = window_bounds(case.window, len(arrays["object_pos_err"]))
    wp = np.asarray(arrays["wrist_pos_tracking_err"], dtype=np.float64)
    rec = {
        "success": bool(m["success"]),
        "strict_success": w["ok"],
        "strict_from": "open loop",
        "first_failure_frame": m.get("first_failure_frame"),
        "window_first_failure_frame": w["first_bad_frame"],
        "object_err_max_window_m": w["max_m"],
        "object_err_max_m": m["object_pos_err_max_m"],
        "wrist_pos_err_mean_m": m.get("wrist_pos_tracking_err_mean_m", float(wp.mean())),
        "wrist_rot_err_mean_deg": m.get("wrist_rot_tracking_err_mean_deg"),
        "wrist_pos_err_window_mean_m": float(wp[s : e + 1].mean()),
        "penetration_max_m": m["penetration_max_m"],
        "sim_penetration_max_m": m.get("sim_penetration_max_m"),
        "keypoint_err_mean_m": m.get("keypoint_err_mean_m"),
        "ms_per_frame": m.get("ms_per_frame"),
    }
    r = m.get("refine")
    if r is not None:
        rec["refine"] = {
            k: r.get(k)
            for k in (
                "success",
                "failed_at_frame",
                "object_pos_err_max_m",
                "attempts",
                "compute_s",
                "wrist_pos_deviation_mean_m",
            )
        }
        if not w["ok"] and kept_through_window(
            bool(r["success"]), r.get("failed_at_frame"), case.window, case.frames
        ):
            rec.update(
                strict_success=True,
                strict_from="refined",
                object_err_max_window_m=r.get("object_pos_err_max_m"),
            )
    return rec


def failure_phase(failed_at: int, window, frames: int) -> str:
    """Where the failure frame lies relative to the contact window."""
    s, e = window_bounds(window, frames)
    return (
        "before the window"
        if failed_at < s
        else ("in the window" if failed_at <= e else "after the window")
    )


def mano_record(m: dict, traj, case: Case) -> dict:
    """A MANO job's numbers from ``run_simulate``'s metrics ``m`` and its annotated row
    ``traj`` (cut at the failure when it lost the object)."""
    failed = m.get("failed_at_frame")
    rec = {
        "success": bool(m["success"]),
        "strict_success": kept_through_window(bool(m["success"]), failed, case.window, case.frames),
        "failed_at_frame": failed,
        "object_err_max_m": m.get("object_pos_err_max_m"),
        "compute_s": m.get("compute_s"),
        "compute_s_per_demo_s": m.get("compute_s_per_demo_s"),
        "mass_kg": m.get("mass_kg"),
    }
    try:
        arrays = mano_arrays(traj)
    except Exception as e:  # an older or partial row: no per-frame detail
        arrays = None
        rec["detail_error"] = f"{type(e).__name__}: {e}"
    if arrays is not None:
        w = window_check(arrays["obj_err"], case.window)
        rec["object_err_max_window_m"] = w["max_m"] if rec["strict_success"] else None
        rec["wrist_pos_err_mean_m"] = float(arrays["wrist_err"].mean())
    if failed is not None:
        # the force pipeline's own diagnosis (dexcanvas_core.sim.diagnosis)
        why = m.get("failure") or {"reason": f"object error > 5 cm at frame {failed}"}
        rec["failure"] = {**why, "phase": failure_phase(failed, case.window, case.frames)}
    return rec


def mano_arrays(traj) -> dict:
    """Per-frame object error and wrist error from its command, from the force pipeline's
    annotated row."""
    sim_pos = np.asarray(traj.extras["sim_object_pos"], dtype=np.float64)
    T = len(sim_pos)
    obj_err = np.linalg.norm(sim_pos - np.asarray(traj.object.pos[:T], dtype=np.float64), axis=1)
    h = traj.hand
    wrist_err = np.linalg.norm(
        np.asarray(h.urdf_dof[:T, :3], np.float64) - np.asarray(h.urdf_dof_target[:T, :3]), axis=1
    )
    return {"obj_err": obj_err, "wrist_err": wrist_err}


# ------------------------------------------------------------------------------ aggregates
def _mean(vals) -> float | None:
    v = [x for x in vals if x is not None]
    return float(np.mean(v)) if v else None


def _object_err(r: dict) -> float | None:
    """A run's object error max in the window (the refinement's where it kept the object;
    a MANO run that failed: over the frames it tracked)."""
    e = r.get("object_err_max_window_m")
    return e if e is not None else r.get("object_err_max_m")


def aggregate(recs: list[dict]) -> dict:
    """Strict success rate (errors and skipped runs count as failures) and the means of the
    runs that ran."""
    ran = [r for r in recs if not r.get("error") and not r.get("skipped")]
    return {
        "runs": len(recs),
        "errors": sum(1 for r in recs if r.get("error")),
        "skipped": sum(1 for r in recs if r.get("skipped")),
        "strict_success_rate": float(np.mean([bool(r.get("strict_success")) for r in recs]))
        if recs
        else None,
        "success_rate": float(np.mean([bool(r.get("success")) for r in recs])) if recs else None,
        "wrist_pos_err_mean_m": _mean(r.get("wrist_pos_err_mean_m") for r in ran),
        "wrist_rot_err_mean_deg": _mean(r.get("wrist_rot_err_mean_deg") for r in ran),
        "object_err_max_median_m": (
            float(np.median(v))
            if (v := [e for r in ran if (e := _object_err(r)) is not None])
            else None
        ),
        "penetration_max_m": max(
            (r["penetration_max_m"] for r in ran if r.get("penetration_max_m") is not None),
            default=None,
        ),
        "ms_per_frame_mean": _mean(r.get("ms_per_frame") for r in ran),
        "wall_s_total": float(sum(r.get("wall_s") or 0.0 for r in recs)),
    }


def failure_reasons(recs: list[dict]) -> dict:
    """Count of the MANO pipeline's failure reasons."""
    out: dict[str, int] = {}
    for r in recs:
        f = r.get("failure")
        if f:
            out[f["reason"]] = out.get(f["reason"], 0) + 1
    return out


def summarize(records: list[dict], hands, five) -> dict:
    """Per ``hand/mode`` and MANO aggregates, and the targets."""
    per = {}
    for h in hands:
        for mode in MODES:
            rs = [r for r in records if r["hand"] == h and r["mode"] == mode]
            if rs:
                per[f"{h}/{mode}"] = aggregate(rs)
    mano = [r for r in records if r["mode"] == MANO]
    if mano:
        per[MANO] = {**aggregate(mano), "failure_reasons": failure_reasons(mano)}
    for mode in MODES:
        rs = [r for r in records if r["mode"] == mode and r["hand"] in five]
        if rs and len({r["hand"] for r in rs}) > 1:
            per[f"five-finger/{mode}"] = aggregate(rs)
    return {"per_hand_mode": per, "targets": target_checks(per, five)}


def target_checks(per: dict, five) -> list[dict]:
    checks = []
    if MANO in per:
        v = per[MANO]["strict_success_rate"]
        checks.append(
            {
                "target": f"MANO force pipeline strict success ≥ {100 * TARGET_MANO:.0f} %",
                "value": v,
                "met": v is not None and v >= TARGET_MANO,
            }
        )
    scopes = [("five-finger hands", "five-finger")] if len(five) > 1 else []
    scopes += [(h, h) for h in five]
    for scope, key in scopes:
        a = per.get(f"{key}/forces_refine")
        if a is None:
            continue
        v, w = a["strict_success_rate"], a["wrist_pos_err_mean_m"]
        checks.append(
            {
                "target": f"--forces --refine strict success ≥ {100 * TARGET_REFINE:.0f} %",
                "scope": scope,
                "value": v,
                "met": v is not None and v >= TARGET_REFINE,
            }
        )
        checks.append(
            {
                "target": f"--forces --refine wrist tracking ≤ {1e3 * TARGET_WRIST_M:g} mm mean",
                "scope": scope,
                "value": w,
                "met": w is not None and w <= TARGET_WRIST_M,
            }
        )
    return checks
