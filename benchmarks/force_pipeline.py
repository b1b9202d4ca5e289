"""Force pipeline: tracking success, physical consistency and force signatures on a fixed suite.

The suite: ``--n-pairs`` (default 32) feasible pairs of the built-in generator
(``dexcanvas_core.demos``), taken round-robin over the 21 manipulation types (shuffled within a
type by ``--seed``, operators cycled: ``benchmarks/_common.py``, the same demonstrations as
``benchmarks/mocap_fit.py``), one generated demonstration per pair. Every demonstration is
tracked in MuJoCo by the simulated MANO hand (``dexcanvas_core.sim.pipeline.simulate``,
``--tracker`` ``mpc`` or ``open_loop``, default settings otherwise) in up to three conditions
(``--conditions``):

* ``clean`` — the generated demonstration as it is;
* ``mocap`` — the same demonstration through the mocap stage: the marker stream
  (``mocap.render_markers``: 1 mm per-axis noise, 10 % single-sample dropouts, the renderer's
  default occlusion gaps and label swaps) fitted back (``mocap.fit_markers``, default options);
  the fitted MANO hand and object tracks are simulated, with the demonstration's object id;
* ``mocap_size`` — the mocap-fitted demonstration with the object's size changed by +20 % on
  even-numbered pairs and −20 % on odd ones (``SimConfig(object_scale=…)``; the hand reference
  follows the resized surface, ``sim.resize``, as in synthesis).

Heavy vs light: for every pair whose object has a weighted ``H`` variant in the catalogue
(``taxonomy.heavy_variant``: cube2 → cube2h), the clean demonstration is also simulated with
``SimConfig(object_id=<heavy id>)`` (same geometry, the heavy mass) unless ``--no-heavy``.

Reported per condition (one table; errors count as failures, the other columns are over the
runs that did not raise):

* strict success (DexCanvas: no frame with object position error > 5 cm, whole clip tracked)
  and loose success (mean error < 10 cm and < 0.5 rad), as rates over the pairs;
* object translation error [cm] and rotation error [deg]: mean over runs of each run's mean
  (a failed run's over the frames tracked until it failed);
* compute [s per demo-second]: median over runs of the tracking's process CPU time divided by
  the demonstration's duration; workers run one thread each, so this is one core's cost;
* Newton–Euler residual [% of m·g]: median over runs of each run's median of
  ‖F_hand + F_table + m·g − m·a‖ / (m·g), with ``a`` the simulated object's acceleration (sim)
  and the captured one (capture; both sides smoothed over 50 ms);
* static-hold weight ratio: median over runs with static-hold frames (object off the table,
  captured acceleration < 0.5 m/s²) of |mean vertical hand force / (m·g) − 1| [%];
* "target met?": the paper's targets — strict success ≥ 90 % nominal (``clean``, ``mocap``;
  the paper states it for its mocap-fitted suite) and ≥ 80 % with size perturbation
  (``mocap_size``), ≤ 5 s compute per demo-second, Newton–Euler ≤ 5 % (sim and capture), hold
  weight within 3 %.

Also printed: the force signature per manipulation type (first condition run): the mean over
that type's runs with a static hold of each part's share of the summed mean contact-force
magnitudes (thumb, index, middle, ring, pinky, palm); and heavy vs light per pair: masses and
their ratio, hold weight ratios, summed mean hold force [N] and its ratio.

Writes JSON (default ``benchmarks/results/force_pipeline.json``, atomically): every run's
metrics, the demonstrations (with the mocap fit's errors), the aggregates and target checks;
and per-finger force plots (``sim.plots.plot_finger_forces``) of every run of the first
``--plots`` pairs into ``force_plots/`` next to the JSON. Runs are parallel over ``--workers``
processes (spawned; one OMP/MKL/torch thread each)::

    python benchmarks/force_pipeline.py                     # 32 pairs, 3 conditions, MPC
    python benchmarks/force_pipeline.py --n-pairs 2 --conditions clean mocap \\
        --tracker open_loop --workers 1 --plots 1 --out /tmp/fp.json   # smoke run
    python benchmarks/force_pipeline.py --conditions mocap --no-heavy \
        --set grip_force_floor_n=None --out /tmp/fp_ablation.json       # an ablation
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import multiprocessing
import os
import sys
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from _common import (
    atomic_write_json,
    generate_one,
    git_commit,
    machine_info,
    operator_for,
    parse_override,
    pick_pairs,
    progress_bar,
)

DEFAULT_OUT = Path(__file__).parent / "results" / "force_pipeline.json"
PLOTS_DIR = "force_plots"
"""Plot folder, next to the JSON output."""

CONDITIONS = ("clean", "mocap", "mocap_size")
HEAVY = "clean_heavy"
"""Run label of the clean demonstration simulated with the heavy object variant."""
TRACKERS = ("mpc", "open_loop")

MOCAP_NOISE_MM = 1.0
"""Per-axis marker noise σ [mm] of the mocap conditions."""
MOCAP_DROPOUT = 0.1
"""Probability that a marker sample is missing (single-frame dropouts)."""
SIZE_PERTURBATION = 0.2
"""``mocap_size``: object size × (1 + 0.2) on even pairs, × (1 − 0.2) on odd ones."""

# The paper's targets (reported against, not enforced).
TARGET_SUCCESS = {"clean": 0.90, "mocap": 0.90, "mocap_size": 0.80}
TARGET_COMPUTE_S = 5.0
TARGET_NEWTON_EULER = 0.05
TARGET_WEIGHT = 0.03

THREAD_ENV = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


@dataclass(frozen=True)
class BenchConfig:
    """One benchmark run."""

    n_pairs: int = 32
    """Pairs (demonstrations); ≥ 21 covers every manipulation type."""
    conditions: tuple[str, ...] = CONDITIONS
    """Conditions to run, a subset of ``CONDITIONS``."""
    workers: int = 2
    """Worker processes (one thread each)."""
    tracker: str = "mpc"
    """``mpc`` (sampling MPC) or ``open_loop``."""
    out: Path = DEFAULT_OUT
    """JSON output; plots go to ``force_plots/`` next to it."""
    seed: int = 0
    """Seed of the pair selection, the demonstrations and the marker streams."""
    plots: int = 4
    """Force plots for every run of the first ``plots`` pairs."""
    heavy: bool = True
    """Also run the clean demonstration with the heavy object variant (when one exists)."""
    tracking: tuple[tuple[str, object], ...] = ()
    """``TrackingConfig`` fields overridden in every run (ablations: ``--set
    grip_force_min_n=2``); recorded in the JSON's ``sim_config``."""

    def validate(self) -> BenchConfig:
        from dexcanvas_core.errors import ValidationError

        if self.n_pairs < 1:
            raise ValidationError(f"n_pairs must be ≥ 1, got {self.n_pairs}", field="n_pairs")
        bad = [c for c in self.conditions if c not in CONDITIONS]
        if bad or not self.conditions:
            raise ValidationError(
                f"unknown condition(s) {bad or '(none)'}; available: {', '.join(CONDITIONS)}",
                field="conditions",
            )
        if self.workers < 1:
            raise ValidationError(f"workers must be ≥ 1, got {self.workers}", field="workers")
        if self.tracker not in TRACKERS:
            raise ValidationError(
                f"unknown tracker {self.tracker!r}; available: {', '.join(TRACKERS)}",
                field="tracker",
            )
        if self.plots < 0:
            raise ValidationError(f"plots must be ≥ 0, got {self.plots}", field="plots")
        tracking_config(self)  # unknown fields and bad values fail here, before any run
        return self


def tracking_config(cfg: BenchConfig):
    """The runs' ``TrackingConfig``: the defaults with ``cfg.tracking``'s overrides (names
    checked, numbers for numeric fields, booleans for flags; ``None`` where the field allows
    it). Range checks stay with the code that uses the field."""
    from dexcanvas_core.errors import ValidationError
    from dexcanvas_core.sim.tracker import TrackingConfig

    fields = {f.name: f for f in dataclasses.fields(TrackingConfig)}
    bad = [k for k, _ in cfg.tracking if k not in fields]
    if bad:
        raise ValidationError(
            f"unknown TrackingConfig field(s) {', '.join(bad)}; available: "
            f"{', '.join(sorted(fields))}",
            field="tracking",
        )
    defaults = TrackingConfig()
    for k, v in cfg.tracking:
        d = getattr(defaults, k)
        optional = "None" in str(fields[k].type)
        if v is None and optional:
            continue
        number = isinstance(v, (int, float)) and not isinstance(v, bool)
        if isinstance(d, bool) and not isinstance(v, bool):
            raise ValidationError(f"{k} takes True or False, got {v!r}", field="tracking")
        if isinstance(d, (int, float)) and not isinstance(d, bool) and not number:
            raise ValidationError(
                f"{k} takes a number{' or None' if optional else ''}, got {v!r}", field="tracking"
            )
    return dataclasses.replace(defaults, **dict(cfg.tracking))


# ------------------------------------------------------------------------------------- plan
def object_scale(condition: str, i: int) -> float:
    """The object size factor of pair ``i`` in ``condition``."""
    if condition != "mocap_size":
        return 1.0
    return 1.0 + SIZE_PERTURBATION if i % 2 == 0 else 1.0 - SIZE_PERTURBATION


def plan_runs(i: int, pair, cfg: BenchConfig) -> list[tuple[str, object]]:
    """``[(condition, SimConfig)]`` of pair ``i``, in report order."""
    from dexcanvas_core.sim.pipeline import SimConfig
    from dexcanvas_core.taxonomy import heavy_variant

    base = SimConfig(tracker=cfg.tracker, tracking=tracking_config(cfg))
    runs = [
        (c, dataclasses.replace(base, object_scale=object_scale(c, i)))
        for c in CONDITIONS
        if c in cfg.conditions
    ]
    heavy = heavy_variant(pair.object.id)
    if cfg.heavy and "clean" in cfg.conditions and heavy is not None:
        runs.append((HEAVY, dataclasses.replace(base, object_id=heavy.id)))
    return runs


# ------------------------------------------------------------------------------------ workers
def _init_worker() -> None:
    """One thread per worker: the BLAS/OpenMP variables are set by the parent before the
    spawn (they must be in place when numpy loads), torch's pools here."""
    logging.basicConfig(level=logging.ERROR)
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a dependency of the mocap fit
        return
    torch.set_num_threads(1)
    torch.set_num_interop_threads(1)


def _error(e: BaseException) -> dict:
    return {"error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc(limit=4)}


def _prepare(args) -> dict:
    """Worker: generate the demonstration of pair ``i`` and, if asked, its mocap fit.

    Returns ``{"record": dict, "clean": Trajectory | None, "mocap": Trajectory | None}``.
    """
    from dexcanvas_core.mocap import fit_markers, render_markers
    from dexcanvas_core.rotations import rotation_angle_between_aa

    i, pair, seed, mocap = args
    rec: dict = {
        "index": i,
        "pair": str(pair),
        "manipulation_type": pair.manipulation_type.name,
        "object": pair.object.id,
        "operator": operator_for(i),
    }
    out: dict = {"record": rec, "clean": None, "mocap": None}
    t0 = time.perf_counter()
    try:
        demo, used = generate_one(pair, i, seed)
    except Exception as e:
        rec.update(_error(e))
        return out
    traj = demo.trajectory
    rec.update(
        seed=used,
        uuid=traj.uuid,
        frames=traj.num_frames,
        duration_s=traj.num_frames / traj.fps,
        plausible=bool(demo.report.passed),
        generation_s=time.perf_counter() - t0,
    )
    out["clean"] = traj
    if not mocap:
        return out
    try:
        stream = render_markers(traj, noise_mm=MOCAP_NOISE_MM, dropout=MOCAP_DROPOUT, seed=seed + i)
        t0 = time.perf_counter()
        fit = fit_markers(
            stream,
            object_id=traj.object.name,
            uuid=traj.uuid,
            operator=traj.operator,
            gesture=traj.gesture,
        )
        ft = fit.trajectory
        kp = np.linalg.norm(ft.hand.joint_pos - traj.hand.joint_pos, axis=-1)
        rec["mocap_fit"] = {
            "fit_s": time.perf_counter() - t0,
            "keypoint_err_mean_mm": float(1e3 * kp.mean()),
            "object_pos_err_mean_mm": float(
                1e3 * np.linalg.norm(ft.object.pos - traj.object.pos, axis=-1).mean()
            ),
            "object_rot_err_mean_deg": float(
                np.degrees(rotation_angle_between_aa(ft.object.rot_aa, traj.object.rot_aa)).mean()
            ),
            "frames_long_gap": int(fit.flags.long_gap.sum()),
            "frames_interpolated": int(fit.flags.interpolated.sum()),
        }
        out["mocap"] = ft
    except Exception as e:
        rec["mocap_fit"] = _error(e)
    return out


def hold_force_share(finger_mean: dict | None) -> dict | None:
    """Each part's share of the summed mean hold-force magnitudes, or ``None`` (no hold or no
    force)."""
    if not finger_mean:
        return None
    total = sum(finger_mean.values())
    if total <= 1e-9:
        return None
    return {k: v / total for k, v in finger_mean.items()}


def _simulate(args) -> dict:
    """Worker: one simulated run; its metrics (or the error), and its plot if asked."""
    from dexcanvas_core.sim.pipeline import simulate

    i, pair, condition, sim_cfg, traj, plot_path = args
    row = {
        "index": i,
        "pair": str(pair),
        "condition": condition,
        "manipulation_type": pair.manipulation_type.name,
        "tracker": sim_cfg.tracker,
        "object_scale": sim_cfg.object_scale,
        "object_id": sim_cfg.object_id,
    }
    w0 = time.perf_counter()
    try:
        res = simulate(traj, sim_cfg)
        row.update({k: v for k, v in res.metrics.items() if k != "config"})
        row["hold_force_share"] = hold_force_share(res.metrics["hold_finger_force_mean_n"])
        if plot_path is not None:
            from dexcanvas_core.sim.plots import plot_finger_forces

            title = f"{pair} · {condition}" + (
                f" (size ×{sim_cfg.object_scale:g})" if sim_cfg.object_scale != 1.0 else ""
            )
            row["plot"] = str(plot_finger_forces(res, plot_path, title=title))
    except Exception as e:  # recorded in the JSON and counted as a failure
        row.update(_error(e))
        row["success"] = row["success_loose"] = False
    row["wall_s"] = time.perf_counter() - w0
    return row


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
    from dexcanvas_core.taxonomy import MANIPULATION_TYPES
    from dexcanvas_core.trajectory import FORCE_GROUPS

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


# ------------------------------------------------------------------------------------- output
def _f(x, scale: float = 1.0, fmt: str = ".2f") -> str:
    return "–" if x is None else format(scale * x, fmt)


def _coloured(text: str, met: bool | None) -> str:
    if met is None:
        return text
    return f"[green]{text}[/green]" if met else f"[red]{text}[/red]"


def conditions_table(title: str, aggs: dict, checks: dict):
    from rich.table import Table

    t = Table(
        title=title,
        caption="success: strict = no frame > 5 cm (DexCanvas), loose = mean < 10 cm and "
        "< 0.5 rad; errors: mean over runs of each run's mean; compute: median CPU s per "
        "demo-s on one core; Newton–Euler: median over runs of the run median, % of m·g; "
        "weight: median |hold force / m·g − 1|. Targets (paper): success ≥ 90 % nominal, "
        "≥ 80 % size ±20 %; ≤ 5 s per demo-s; Newton–Euler ≤ 5 %; weight within 3 %.",
    )
    cols = (
        "condition",
        "runs",
        "strict %",
        "loose %",
        "trans err cm",
        "rot err °",
        "compute s/demo-s",
        "NE sim %",
        "NE capture %",
        "weight |r−1| %",
        "target met?",
    )
    for c in cols:
        left = c in ("condition", "target met?")
        t.add_column(c, justify="left" if left else "right", no_wrap=left)
    for cond, a in aggs.items():
        met = {c["name"]: c["met"] for c in checks[cond]}
        missed = [n for n, m in met.items() if m is False]
        unmeasured = [n for n, m in met.items() if m is None]
        verdict = "[green]yes[/green]" if not missed else "[red]no[/red]: " + ", ".join(missed)
        if unmeasured:
            verdict += f"; n/a: {', '.join(unmeasured)}"
        runs = f"{a['runs']}" + (f" ({a['errors']} err)" if a["errors"] else "")
        t.add_row(
            cond,
            runs,
            _coloured(_f(a["success_rate"], 100, ".0f"), met["success"]),
            _f(a["success_loose_rate"], 100, ".0f"),
            _f(a["object_pos_err_mean_m"], 100),
            _f(a["object_rot_err_mean_rad"], 180 / np.pi, ".1f"),
            _coloured(_f(a["compute_s_per_demo_s_median"]), met["compute"]),
            _coloured(_f(a["newton_euler_sim_median"], 100), met["NE sim"]),
            _coloured(_f(a["newton_euler_capture_median"], 100), met["NE capture"]),
            _coloured(
                _f(a["hold_weight_dev_median"], 100) + f" (n={a['runs_with_hold']})",
                met["weight"],
            ),
            verdict,
        )
    return t


def signature_table(title: str, sig: dict):
    from rich.table import Table

    from dexcanvas_core.trajectory import FORCE_GROUPS

    t = Table(
        title=title,
        caption="mean share [%] of the summed mean contact-force magnitudes "
        "over static-hold frames; n: runs with a hold / runs",
    )
    t.add_column("manipulation type")
    t.add_column("n", justify="right")
    for g in FORCE_GROUPS:
        t.add_column(g, justify="right")
    for typ, s in sig.items():
        shares = s["share"]
        cells = [_f(shares[g], 100, ".0f") if shares else "–" for g in FORCE_GROUPS]
        t.add_row(typ, f"{s['runs_with_hold']}/{s['runs']}", *cells)
    return t


def heavy_table(hv: dict):
    from rich.table import Table

    t = Table(
        title="heavy vs light (clean demonstration, heavy object variant)",
        caption=f"medians: mass ratio {_f(hv['median_mass_ratio'])}, vertical load ratio "
        f"{_f(hv['median_load_ratio'])}, hold-force ratio "
        f"{_f(hv['median_force_ratio'])}, force ratio / mass ratio "
        f"{_f(hv['median_force_ratio_over_mass_ratio'])}; hold force: sum over parts of the mean "
        "contact-force magnitude in static-hold frames (grip squeeze included); vertical load: "
        "mean upward hand force in the hold",
    )
    for c in (
        "pair",
        "heavy",
        "mass kg light/heavy",
        "mass ratio",
        "success l/h",
        "weight ratio % l/h",
        "load ratio",
        "hold force N l/h",
        "force ratio",
    ):
        t.add_column(c, justify="left" if c in ("pair", "heavy") else "right", no_wrap=c == "pair")
    for p in hv["pairs"]:
        if "error" in p:
            t.add_row(p["pair"], "", f"[red]{p['error']}[/red]", *[""] * 6)
            continue
        t.add_row(
            p["pair"],
            p["heavy"],
            f"{p['mass_light_kg']:.3f} / {p['mass_heavy_kg']:.3f}",
            f"{p['mass_ratio']:.2f}",
            f"{'y' if p['success_light'] else 'n'} / {'y' if p['success_heavy'] else 'n'}",
            f"{_f(p['hold_weight_ratio_light'], 100, '.1f')} / "
            f"{_f(p['hold_weight_ratio_heavy'], 100, '.1f')}",
            _f(p["load_ratio"]),
            f"{_f(p['hold_force_light_n'])} / {_f(p['hold_force_heavy_n'])}",
            _f(p["force_ratio"]),
        )
    return t


def _versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for dist in ("dexcanvas-retarget", "mujoco", "numpy", "scipy", "torch"):
        try:
            out[dist] = version(dist)
        except PackageNotFoundError:
            out[dist] = None
    return out


# --------------------------------------------------------------------------------------- main
@contextmanager
def _one_thread_env():
    """BLAS/OpenMP at one thread for the processes spawned inside (restored on exit)."""
    saved = {k: os.environ.get(k) for k in THREAD_ENV}
    os.environ.update({k: "1" for k in THREAD_ENV})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _sim_jobs(i: int, pair, prepared: dict, plan: list, cfg: BenchConfig, plot_dir: Path):
    """``(jobs, rows)``: the simulation jobs of pair ``i`` once its demonstration is ready, and
    error rows for the runs that have no trajectory (generation or mocap fit failed)."""
    rec = prepared["record"]
    jobs, rows = [], []
    for cond, sim_cfg in plan:
        traj = prepared["mocap"] if cond.startswith("mocap") else prepared["clean"]
        if traj is None:
            why = rec.get("error") or rec["mocap_fit"]["error"]
            rows.append({"index": i, "pair": str(pair), "condition": cond,
                         "manipulation_type": pair.manipulation_type.name,
                         "error": f"no demonstration: {why}", "success": False,
                         "success_loose": False})  # fmt: skip
            continue
        plot = None
        if i < cfg.plots:
            name = f"{i:02d}_{pair.object.id}_{pair.manipulation_type.name}_{cond}.png"
            plot = plot_dir / name
        jobs.append((i, pair, cond, sim_cfg, traj, plot))
    return jobs, rows


def run_jobs(cfg: BenchConfig, pairs: list, plans: list, plot_dir: Path, console):
    """Generate (and mocap-fit) every pair's demonstration, then simulate its runs as soon as
    it is ready, over ``cfg.workers`` spawned one-thread processes; ``(demos, rows)``."""
    mocap = any(c.startswith("mocap") for c in cfg.conditions)
    total = len(pairs) + sum(len(p) for p in plans)
    demos: dict[int, dict] = {}
    rows: list[dict] = []
    ctx = multiprocessing.get_context("spawn")
    with (
        _one_thread_env(),
        ProcessPoolExecutor(cfg.workers, mp_context=ctx, initializer=_init_worker) as pool,
        progress_bar(console) as prog,
    ):
        task = prog.add_task("generating + fitting", total=total)
        pending = {pool.submit(_prepare, (i, p, cfg.seed, mocap)): (i, None)
                   for i, p in enumerate(pairs)}  # fmt: skip
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                i, condition = pending.pop(fut)
                prog.advance(task)
                if condition is not None:  # a simulation
                    rows.append(fut.result())
                    prog.update(task, description=f"simulating · {pairs[i]} · {condition}")
                    continue
                prepared = fut.result()
                demos[i] = prepared["record"]
                jobs, failed = _sim_jobs(i, pairs[i], prepared, plans[i], cfg, plot_dir)
                rows += failed
                prog.advance(task, len(failed))
                for job in jobs:
                    pending[pool.submit(_simulate, job)] = (i, job[2])
    return demos, rows


def run_benchmark(cfg: BenchConfig, console=None) -> dict:
    """Run the suite in every condition, print the tables, write the JSON and plots; return
    the JSON document."""
    from rich.console import Console

    from dexcanvas_core.sim.pipeline import SimConfig

    console = console or Console(width=None if sys.stdout.isatty() else 140)
    cfg = cfg.validate()
    t_start = time.perf_counter()
    load0 = os.getloadavg()
    pairs = pick_pairs(cfg.n_pairs, cfg.seed)
    plans = [plan_runs(i, p, cfg) for i, p in enumerate(pairs)]
    n_sims = sum(len(p) for p in plans)
    plot_dir = Path(cfg.out).parent / PLOTS_DIR
    if cfg.plots:
        plot_dir.mkdir(parents=True, exist_ok=True)
    n_types = len({p.manipulation_type.name for p in pairs})
    console.print(
        f"{len(pairs)} pairs ({n_types} manipulation types), conditions: "
        f"{', '.join(cfg.conditions)}; {n_sims} simulations "
        f"({sum(1 for p in plans for c, _ in p if c == HEAVY)} heavy), tracker {cfg.tracker}, "
        f"{cfg.workers} worker(s)"
    )

    demos, rows = run_jobs(cfg, pairs, plans, plot_dir, console)
    order = {c: k for k, c in enumerate((*CONDITIONS, HEAVY))}
    rows.sort(key=lambda r: (r["index"], order[r["condition"]]))
    for r in rows:
        if "error" in r:
            console.print(f"[red]{r['pair']} · {r['condition']}: {r['error']}[/red]")
    aggs = {c: aggregate([r for r in rows if r["condition"] == c]) for c in cfg.conditions}
    checks = {c: target_checks(c, a) for c, a in aggs.items()}
    signatures = {
        c: force_signature([r for r in rows if r["condition"] == c and "error" not in r])
        for c in cfg.conditions
    }
    hv = heavy_vs_light(rows)

    console.print(
        conditions_table(
            f"force pipeline: {len(pairs)} pairs, {n_types} types, tracker {cfg.tracker}",
            aggs,
            checks,
        )
    )
    first = cfg.conditions[0]
    console.print(
        signature_table(f"force signature per manipulation type ({first})", signatures[first])
    )
    if hv["pairs"]:
        console.print(heavy_table(hv))

    plots = sorted(r["plot"] for r in rows if r.get("plot"))
    doc = {
        "benchmark": "force_pipeline",
        "command": " ".join(["python benchmarks/force_pipeline.py", *sys.argv[1:]]),
        "config": {**dataclasses.asdict(cfg), "out": str(cfg.out)},
        "sim_config": SimConfig(tracker=cfg.tracker, tracking=tracking_config(cfg)).as_dict(),
        "mocap": {
            "noise_mm": MOCAP_NOISE_MM,
            "dropout": MOCAP_DROPOUT,
            "render": "render_markers defaults otherwise (gaps, swaps)",
            "fit": "fit_markers default options",
        },
        "size_perturbation": SIZE_PERTURBATION,
        "demonstrations": [demos[i] for i in sorted(demos)],
        "commit": git_commit(),
        "machine": machine_info(load0, threads_per_worker=1),
        "versions": _versions(),
        "definitions": {
            "success_rate": "strict DexCanvas rule over runs (errors count as failures)",
            "object_pos_err_mean_m": "mean over runs of each run's mean object position error",
            "compute_s_per_demo_s_median": "median over runs of tracking process-CPU seconds "
            "per second of demonstration (one thread)",
            "newton_euler_*_median": "median over runs of each run's median residual / (m·g)",
            "hold_weight_dev_median": "median over runs with static-hold frames of "
            "|hold_weight_ratio - 1|",
            "hold_force_share": "per run: each part's share of the summed mean contact-force "
            "magnitudes over static-hold frames",
            "hold_force_n": "sum over parts of the mean contact-force magnitude in static hold",
        },
        "summary": {
            "per_condition": aggs,
            "targets": [c for cs in checks.values() for c in cs],
            "force_signature": signatures,
            "heavy_vs_light": hv,
        },
        "plots": plots,
        "runs": rows,
        "wall_time_s": time.perf_counter() - t_start,
    }
    atomic_write_json(Path(cfg.out), doc)
    console.print(
        f"wrote {cfg.out}"
        + (f" and {len(plots)} plot(s) in {plot_dir}" if plots else "")
        + f" ({doc['wall_time_s']:.0f} s)"
    )
    return doc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n-pairs", type=int, default=32, help="pairs (≥ 21: every type)")
    ap.add_argument(
        "--conditions",
        nargs="+",
        choices=CONDITIONS,
        default=list(CONDITIONS),
        help="clean, mocap (markers → fit), mocap_size (fit, object size ±20 %%)",
    )
    ap.add_argument("--workers", type=int, default=2, help="processes, one thread each")
    ap.add_argument("--tracker", choices=TRACKERS, default="mpc")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON output")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--plots", type=int, default=4, help="plot every run of the first N pairs")
    ap.add_argument(
        "--heavy",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also run clean demonstrations with the heavy object variant",
    )
    ap.add_argument(
        "--set",
        dest="tracking",
        metavar="FIELD=VALUE",
        type=parse_override,
        action="append",
        default=[],
        help="override a TrackingConfig field in every run (repeatable), e.g. "
        "--set grip_force_min_n=2.0",
    )
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    cfg = BenchConfig(
        n_pairs=a.n_pairs,
        conditions=tuple(dict.fromkeys(a.conditions)),
        workers=a.workers,
        tracker=a.tracker,
        out=a.out,
        seed=a.seed,
        plots=a.plots,
        heavy=a.heavy,
        tracking=tuple(a.tracking),
    )
    run_benchmark(cfg)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
