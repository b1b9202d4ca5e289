"""Aggregates per condition, force signatures, heavy vs light, and the target checks."""

from __future__ import annotations

import numpy as np

from benchmarks.force_pipeline.config import (
    HEAVY,
    TARGET_COMPUTE_S,
    TARGET_NEWTON_EULER,
    TARGET_SUCCESS,
    TARGET_WEIGHT,
)
from dexcanvas_core.taxonomy import MANIPULATION_TYPES
from dexcanvas_core.trajectory import FORCE_GROUPS


# --------------------------------------------------------------------------------- aggregates
def _values(rows: list[dict], key: str) -> np.ndarray:
    return np.array([r[key] for r in rows if r.get(key) is not None], dtype=float)


def _stat(a: np.ndarray, fn) -> float | None:
    return float(fn(a)) if a.size else None


def aggregate(rows: list[dict]) -> dict:
    """One condition's aggregates (module docstring); errors count as failures."""
    ok = [r for r in rows if "error" not in r]
    weight_dev = np.abs(_values(ok, "hold_weight_ratio") - 1.0)
    return {
        "runs": len(rows),
        "errors": len(rows) - len(ok),
        "success_rate": _stat(np.array([bool(r.get("success")) for r in rows]), np.mean),
        "success_loose_rate": _stat(
            np.array([bool(r.get("success_loose")) for r in rows]), np.mean
        ),
        "object_pos_err_mean_m": _stat(_values(ok, "object_pos_err_mean_m"), np.mean),
        "object_pos_err_max_m_median": _stat(_values(ok, "object_pos_err_max_m"), np.median),
        "object_rot_err_mean_rad": _stat(_values(ok, "object_rot_err_mean_rad"), np.mean),
        "compute_s_per_demo_s_median": _stat(_values(ok, "compute_s_per_demo_s"), np.median),
        "compute_s_per_demo_s_max": _stat(_values(ok, "compute_s_per_demo_s"), np.max),
        "newton_euler_sim_median": _stat(_values(ok, "newton_euler_sim_median"), np.median),
        "newton_euler_capture_median": _stat(_values(ok, "newton_euler_capture_median"), np.median),
        "newton_euler_capture_hold_median": _stat(
            _values(ok, "newton_euler_capture_hold_median"), np.median
        ),
        "runs_with_hold": int(weight_dev.size),
        "hold_weight_dev_median": _stat(weight_dev, np.median),
        "hold_weight_dev_max": _stat(weight_dev, np.max),
    }


def force_signature(rows: list[dict]) -> dict:
    """Per manipulation type (catalogue order): runs with a hold and the mean force share of
    each part (``FORCE_GROUPS``)."""

    out = {}
    for t in MANIPULATION_TYPES:
        shares = [
            r["hold_force_share"]
            for r in rows
            if r["manipulation_type"] == t and r.get("hold_force_share")
        ]
        runs = sum(1 for r in rows if r["manipulation_type"] == t)
        if not runs:
            continue
        out[t] = {
            "runs": runs,
            "runs_with_hold": len(shares),
            "share": {g: float(np.mean([s[g] for s in shares])) for g in FORCE_GROUPS}
            if shares
            else None,
        }
    return out


def _hold_force(r: dict) -> float | None:
    f = r.get("hold_finger_force_mean_n")
    return float(sum(f.values())) if f else None


def heavy_vs_light(rows: list[dict]) -> dict:
    """Per pair with a heavy run: the clean (light) and heavy runs side by side, and medians."""
    light = {r["index"]: r for r in rows if r["condition"] == "clean"}
    pairs = []
    for h in (r for r in rows if r["condition"] == HEAVY):
        li = light.get(h["index"])
        if li is None or "error" in li or "error" in h:
            pairs.append({"pair": h["pair"], "error": (li or {}).get("error") or h.get("error")})
            continue
        f_l, f_h = _hold_force(li), _hold_force(h)
        mass_ratio = h["mass_kg"] / li["mass_kg"]
        force_ratio = f_h / f_l if f_l and f_h else None
        w_l, w_h = li["hold_weight_ratio"], h["hold_weight_ratio"]
        # vertical load carried by the hand in the hold: weight ratio × m·g
        load_ratio = (w_h * h["mass_kg"]) / (w_l * li["mass_kg"]) if w_l and w_h else None
        pairs.append(
            {
                "pair": h["pair"],
                "light": li["simulated_object"],
                "heavy": h["simulated_object"],
                "mass_light_kg": li["mass_kg"],
                "mass_heavy_kg": h["mass_kg"],
                "mass_ratio": mass_ratio,
                "success_light": li["success"],
                "success_heavy": h["success"],
                "hold_weight_ratio_light": li["hold_weight_ratio"],
                "hold_weight_ratio_heavy": h["hold_weight_ratio"],
                "hold_force_light_n": f_l,
                "hold_force_heavy_n": f_h,
                "force_ratio": force_ratio,
                "load_ratio": load_ratio,
                "force_ratio_over_mass_ratio": None
                if force_ratio is None
                else force_ratio / mass_ratio,
            }
        )
    ok = [p for p in pairs if "error" not in p]
    return {
        "pairs": pairs,
        "median_mass_ratio": _stat(_values(ok, "mass_ratio"), np.median),
        "median_force_ratio": _stat(_values(ok, "force_ratio"), np.median),
        "median_load_ratio": _stat(_values(ok, "load_ratio"), np.median),
        "median_force_ratio_over_mass_ratio": _stat(
            _values(ok, "force_ratio_over_mass_ratio"), np.median
        ),
    }


def target_checks(condition: str, a: dict) -> list[dict]:
    """The paper's targets against one condition's aggregates (``met`` is ``None`` when the
    quantity was not measured)."""
    s, ne = TARGET_SUCCESS[condition], 100 * TARGET_NEWTON_EULER
    spec = (  # name, target, aggregate, threshold, at least (else at most)
        ("success", f"strict success ≥ {100 * s:.0f} %", "success_rate", s, True),
        ("compute", f"≤ {TARGET_COMPUTE_S:g} s per demo-s (median)",
         "compute_s_per_demo_s_median", TARGET_COMPUTE_S, False),
        ("NE sim", f"Newton–Euler (sim) ≤ {ne:g} % m·g", "newton_euler_sim_median",
         TARGET_NEWTON_EULER, False),
        ("NE capture", f"Newton–Euler (capture) ≤ {ne:g} % m·g",
         "newton_euler_capture_median", TARGET_NEWTON_EULER, False),
        ("weight", f"hold weight within {100 * TARGET_WEIGHT:g} % (median)",
         "hold_weight_dev_median", TARGET_WEIGHT, False),
    )  # fmt: skip
    out = []
    for name, target, key, threshold, at_least in spec:
        v = a[key]
        met = None if v is None else bool(v >= threshold if at_least else v <= threshold)
        out.append({"condition": condition, "name": name, "target": target, "value": v,
                    "threshold": threshold, "met": met})  # fmt: skip
    return out
