"""The terminal tables (rich)."""

from __future__ import annotations

import numpy as np
from rich.table import Table

from benchmarks._common import (
    coloured,
    num,
)
from dexcanvas_core.trajectory import FORCE_GROUPS


# ------------------------------------------------------------------------------------- output
def conditions_table(title: str, aggs: dict, checks: dict):
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
            coloured(num(a["success_rate"], 100, ".0f"), met["success"]),
            num(a["success_loose_rate"], 100, ".0f"),
            num(a["object_pos_err_mean_m"], 100),
            num(a["object_rot_err_mean_rad"], 180 / np.pi, ".1f"),
            coloured(num(a["compute_s_per_demo_s_median"]), met["compute"]),
            coloured(num(a["newton_euler_sim_median"], 100), met["NE sim"]),
            coloured(num(a["newton_euler_capture_median"], 100), met["NE capture"]),
            coloured(
                num(a["hold_weight_dev_median"], 100) + f" (n={a['runs_with_hold']})",
                met["weight"],
            ),
            verdict,
        )
    return t


def signature_table(title: str, sig: dict):
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
        cells = [num(shares[g], 100, ".0f") if shares else "–" for g in FORCE_GROUPS]
        t.add_row(typ, f"{s['runs_with_hold']}/{s['runs']}", *cells)
    return t


def heavy_table(hv: dict):
    t = Table(
        title="heavy vs light (clean demonstration, heavy object variant)",
        caption=f"medians: mass ratio {num(hv['median_mass_ratio'])}, vertical load ratio "
        f"{num(hv['median_load_ratio'])}, hold-force ratio "
        f"{num(hv['median_force_ratio'])}, force ratio / mass ratio "
        f"{num(hv['median_force_ratio_over_mass_ratio'])}; hold force: sum over parts of the mean "
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
            f"{num(p['hold_weight_ratio_light'], 100, '.1f')} / "
            f"{num(p['hold_weight_ratio_heavy'], 100, '.1f')}",
            num(p["load_ratio"]),
            f"{num(p['hold_force_light_n'])} / {num(p['hold_force_heavy_n'])}",
            num(p["force_ratio"]),
        )
    return t
