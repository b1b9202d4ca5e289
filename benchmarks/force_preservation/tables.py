"""The terminal tables (rich) of the aggregates."""

from __future__ import annotations

import numpy as np
from rich.table import Table

from benchmarks._common import (
    mm,
    num,
)
from benchmarks.force_preservation.aggregate import WRENCH_FEASIBLE
from benchmarks.force_preservation.config import LABELS, NOT_IMPLEMENTED, VARIANTS
from dexcanvas_core.sim.signal import CAPTURE_SMOOTH_S
from retarget.force_scores import LOAD_BEARING_SHARE
from retarget.human_forces import HUMAN_REPLAY_SEED
from retarget.validate import FORCE_CONTACT_TIMECONST


def wrench_table(scope: str, table: dict):
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
                f"{num(h['light_success_rate'], 100, '.0f')} ({h['light_runs']})",
                f"{num(h['heavy_success_rate'], 100, '.0f')} ({h['heavy_runs']})",
            )
    return t


def _binned_table(title: str, caption: str, what: str, table: dict, columns, cells):
    """A table with a row per bin of ``table[v]`` (lists of bins per variant, the same bins):
    ``columns`` the header after ``what``, ``cells(bins)`` a row's cells (``bins[v]``)."""
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
        lambda b: [f"{num(b[v]['success_rate'], 100, '.0f')} ({b[v]['runs']})" for v in "cde"],
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
            f"{num(b[v][k], fmt='.2f')} ({b[v][n]})"
            for v in "de"
            for k, n in (("correlation", "fingers"), ("replay_correlation", "replay_fingers"))
        ],
    )


# ------------------------------------------------------------------------------------- output
def variants_table(title: str, agg: dict, ceiling: dict | None = None):
    """One scope's variants; with ``ceiling`` (:func:`replay_ceiling` of (d)), a last row with
    the human replay's force correlations on (d)'s successful runs."""
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
            num(a["success_rate"], 100, ".0f"),
            num(a["success_loose_rate"], 100, ".0f"),
            num(a["object_pos_err_mean_m"], 100, ".2f"),
            num(a["object_rot_err_mean_rad"], 180 / np.pi, ".1f"),
            f"{num(a['force_profile_correlation_mean_successful'], fmt='.2f')} / "
            f"{num(a['force_correlation_mean_successful'], fmt='.2f')} / "
            f"{num(a['force_profile_correlation_mean_load_bearing_successful'], fmt='.2f')}",
            f"{num(a['object_force_error_mean_n'], fmt='.2f')} / "
            f"{num(a['object_force_error_mean_n_successful'], fmt='.2f')}",
            f"{num(a['object_force_error_pct_weight'], 100, '.0f')} / "
            f"{num(a['object_force_error_pct_weight_successful'], 100, '.0f')}",
            f"{mm(a['penetration_max_m'])} / {mm(a['sim_penetration_max_m'])}",
            num(a["ms_per_frame"], fmt=".2f"),
        )
    if ceiling is not None and ceiling["runs"]:
        c = ceiling["replay"]
        t.add_row(
            f"human replay (MPC seed {HUMAN_REPLAY_SEED} vs 0)",
            f"{ceiling['runs']} (d) ok",
            *["–"] * 4,
            f"{num(c['force_profile_correlation_mean'], fmt='.2f')} / "
            f"{num(c['force_correlation_mean'], fmt='.2f')} / "
            f"{num(c['force_profile_correlation_mean_load_bearing'], fmt='.2f')}",
            *["–"] * 4,
        )
    return t


def human_table(sims: list[dict]):
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
            num(s.get("mass_kg"), fmt=".3f"),
            status,
            num(s.get("object_pos_err_max_m"), 100, ".1f"),
            num(s.get("compute_s"), fmt=".1f"),
        ]
        if replays:
            r = s.get("replay")
            if r is None:
                cells += ["–", "–"]
            else:
                ok_r = "[green]yes[/green]" if r["success"] else "[red]no[/red]"
                cells += [
                    ok_r,
                    f"{num(r.get('force_profile_correlation_mean'), fmt='.2f')} / "
                    f"{num(r.get('force_correlation_mean'), fmt='.2f')}",
                ]
        t.add_row(*cells)
    return t


def heavy_table(hv_by_scope: dict, human_hv: dict | None = None):
    """Heavy vs light per scope and variant; with ``human_hv`` (:func:`human_heavy_vs_light`),
    the force pipeline's own rates below."""
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
                f"{num(h['light_success_rate'], 100, '.0f')} ({h['light_runs']})",
                f"{num(h['heavy_success_rate'], 100, '.0f')} ({h['heavy_runs']})",
                num(h["paired_light_success_rate"], 100, ".0f"),
                num(h["paired_heavy_success_rate"], 100, ".0f"),
                str(h["paired_runs"]),
            )
    for name, h in (human_hv or {}).items():
        if h is None:
            continue
        t.add_row(
            "human",
            "force pipeline" if name == "first" else f"replay (seed {HUMAN_REPLAY_SEED})",
            f"{num(h['light_success_rate'], 100, '.0f')} ({h['light_runs']})",
            f"{num(h['heavy_success_rate'], 100, '.0f')} ({h['heavy_runs']})",
            num(h["paired_light_success_rate"], 100, ".0f"),
            num(h["paired_heavy_success_rate"], 100, ".0f"),
            str(h["paired_runs"]),
        )
    return t


def targets_table(scope: str, checks: list[dict]):
    t = Table(title=f"targets (issue 7) on {scope}")
    t.add_column("target")
    t.add_column("measured", justify="right")
    t.add_column("target met?", justify="center")
    for c in checks:
        v = c["value"]
        if c["name"] in ("vs dex", "heavy"):
            a, b = v
            s = f"{num(a, 100, '.0f')} % vs {num(b, 100, '.0f')} % (n={c['runs']})"
            if c["name"] == "vs dex" and a is not None and b:
                s += f", {a / b:.1f}×"
        elif c["name"] == "correlation":
            s = num(v, fmt=".2f")
            if c.get("reached_fingers_value") is not None:
                s += f"; fingers reaching the human's contacts {c['reached_fingers_value']:.2f}"
            if c.get("human_replay_runs"):
                s += (
                    f" (same {c['human_replay_runs']} runs: {num(c['same_runs'], fmt='.2f')}; "
                    f"human replay {num(c['human_replay'], fmt='.2f')})"
                )
            if c.get("smoothed_value") is not None:
                s += f"; over {1e3 * CAPTURE_SMOOTH_S:.0f} ms {c['smoothed_value']:.2f}"
                if c.get("human_replay_smoothed") is not None:
                    s += (
                        f" (same runs {num(c['same_runs_smoothed'], fmt='.2f')}; human replay "
                        f"{num(c['human_replay_smoothed'], fmt='.2f')})"
                    )
        else:
            s = f"{num(v, 100, '.0f')} %" + (f" (n={c['runs']})" if "runs" in c else "")
        verdict = {True: "[green]yes[/green]", False: "[red]no[/red]", None: "n/a"}[c["met"]]
        t.add_row(c["target"], s, verdict)
    return t
