"""The terminal summary of a run (``retarget run``): a rich table of its metrics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from dexcanvas_core.sim.mj_warnings import blew_up, describe
from dexcanvas_core.sim.signal import CAPTURE_SMOOTH_S
from retarget.force_scores import REACH_M
from retarget.metrics import CONTACT_OFF_TARGET_M
from retarget.validate import servo_summary


def _num(x: float | None) -> str:
    return "–" if x is None else f"{x:.2f}"


def _object_cell(rec: dict | None) -> str:
    """The summary's object row: id, mass, size and where the shape came from."""
    if not rec:
        return "—"
    size = " × ".join(f"{100 * v:.1f}" for v in rec["size_m"])
    text = f"{rec['id']}: {1000 * rec['mass_kg']:.0f} g, {size} cm, {rec['shape_source']}"
    if rec.get("mesh"):
        text += f" ({Path(rec['mesh']).name})"
    if rec.get("approximate"):
        text += (
            " [yellow](approximate: a stand-in for the real object; give its model with "
            "--objects-dir)[/yellow]"
        )
    return text


def _warnings_cell(warnings: dict) -> str:
    """MuJoCo's warnings of a simulation, red when the solver blew up (the run failed)."""
    if blew_up(warnings):
        return f"[red]{describe(warnings)}: the solver blew up, the run failed[/red]"
    return f"[yellow]{describe(warnings)}[/yellow]"


def print_summary(m: dict, out_dir: Path) -> None:
    """Print the run's ``metrics.json`` ``m`` as a table, with where it was written."""
    ok = "[green]SUCCESS[/green]" if m["success"] else "[red]FAILED[/red]"
    t = Table(title=f"{m['hand']} · {m['pair']} · {ok}", show_header=False)
    if m.get("time_scale", 1.0) != 1.0:
        t.add_row(
            "time scale",
            f"[yellow]executed {m['time_scale']:g}× slower than demonstrated[/yellow] "
            f"({m['frames']} frames at {m['fps']:.4g} Hz)",
        )
    t.add_row(
        "object error max / mean",
        f"{100 * m['object_pos_err_max_m']:.1f} / "
        f"{100 * m['object_pos_err_mean_m']:.1f} cm  (success: every frame ≤ 5 cm)",
    )
    t.add_row("object rotation error mean", f"{np.degrees(m['object_rot_err_mean_rad']):.1f}°")
    t.add_row("object", _object_cell(m.get("object")))
    t.add_row("loose rule (mean < 10 cm, < 0.5 rad)", "yes" if m["success_loose"] else "no")
    if m.get("mujoco_warnings"):
        t.add_row("MuJoCo warnings", _warnings_cell(m["mujoco_warnings"]))
    t.add_row("keypoint error mean", f"{1000 * m['keypoint_err_mean_m']:.1f} mm")
    if m["contact_err_mean_m"] is not None:
        t.add_row(
            "contact error mean",
            f"{1000 * m['contact_err_mean_m']:.1f} mm ({m['contact_frames']} contact frames)",
        )
    if m.get("contacts_off_target"):
        t.add_row(
            f"contacts off target (mean > {1000 * CONTACT_OFF_TARGET_M:.0f} mm)",
            ", ".join(
                f"{f} {1000 * m['contact_err_per_finger_m'][f]:.1f} mm"
                for f in m["contacts_off_target"]
            ),
        )
    t.add_row(
        "penetration max (kinematic / sim)",
        f"{1000 * m['penetration_max_m']:.1f} / {1000 * m['sim_penetration_max_m']:.1f} mm",
    )
    t.add_row("finger–finger penetration max", f"{1000 * m['self_penetration_max_m']:.1f} mm")
    if (servo := servo_summary(m)) is not None:
        t.add_row("servo tracking error mean (sim − command)", servo)
    forces = ", ".join(f"{k} {v:.2f}" for k, v in m["finger_force_mean_n"].items())
    t.add_row("mean contact force [N]", forces)
    band_ms = 1e3 * CAPTURE_SMOOTH_S  # profile_band_frames' window
    if m.get("force_correlation_mean") is not None:
        t.add_row(
            "force matching",
            f"correlation {_num(m['force_profile_correlation_mean'])} (whole clip) / "
            f"{_num(m['force_correlation_mean'])} (contact frames) / "
            f"{_num(m.get('force_profile_correlation_mean_smoothed'))} (whole clip over "
            f"{band_ms:.0f} ms); load-bearing fingers "
            f"{_num(m['force_profile_correlation_mean_load_bearing'])}; object force error "
            f"{_num(m['object_force_error_mean_n'])} N, wrench feasible "
            f"{100 * m['wrench_feasible_fraction']:.0f} % of contact frames"
            + (
                f"; {m['fingers_reached']} of {m['fingers_scored']} fingers reach the human's "
                f"contacts (≤ {1000 * REACH_M:.0f} mm), correlation "
                f"{_num(m['force_profile_correlation_mean_reached'])}"
                if "fingers_reached" in m
                else ""
            ),
        )
    if (hr := m.get("human_replay")) is not None:
        if hr["success"]:
            text = (
                f"correlation {_num(hr['force_profile_correlation_mean'])} (whole clip) / "
                f"{_num(hr['force_correlation_mean'])} (contact frames) / "
                f"{_num(hr.get('force_profile_correlation_mean_smoothed'))} (whole clip over "
                f"{band_ms:.0f} ms): the human's forces against themselves, the robot's ceiling"
            )
        else:
            text = f"[red]lost the object at frame {hr['failed_at_frame']}[/red]: no ceiling"
        t.add_row(f"human replay (MPC seed {hr['mpc_seed']})", text)
    if "calibration" in m:
        c = m["calibration"]
        first = c["iterates"][0]
        planned = "kept" if first["success"] else "lost"
        t.add_row(
            "force calibration",
            f"iterate {c['chosen_iterate']} of {len(c['iterates']) - 1} (the plan {planned} the "
            f"object); force error {_num(c['force_error_before'])} → "
            f"{_num(c['force_error_after'])}, correlation "
            f"{_num(c.get('profile_correlation_before'))} → "
            f"{_num(c.get('profile_correlation_after'))}; commands moved "
            f"{np.degrees(c['finger_cmd_deviation_mean_rad']):.2f}° (fingers); "
            f"{c['compute_s']:.1f} s",
        )
    if "refine" in m:
        r = m["refine"]
        ok = "[green]SUCCESS[/green]" if r["success"] else "[red]FAILED[/red]"
        t.add_row(
            "physics refinement",
            f"{ok}: object error max {100 * r['object_pos_err_max_m']:.1f} cm; commands moved "
            f"{np.degrees(r['finger_ctrl_deviation_mean_rad']):.1f}° (fingers), "
            f"{1000 * r['wrist_pos_deviation_mean_m']:.1f} mm (wrist); "
            f"{r['attempts']} attempt{'s' if r['attempts'] > 1 else ''}, {r['compute_s']:.1f} s"
            + (
                f"; MuJoCo warnings: {_warnings_cell(r['mujoco_warnings'])}"
                if r.get("mujoco_warnings")
                else ""
            )
            + (
                f"; force calibration: iterate {c['chosen_iterate']}, force error "
                f"{_num(c['force_error_before'])} → {_num(c['force_error_after'])}"
                if (c := r.get("calibration"))
                else ""
            ),
        )
        if r.get("forces"):
            rf = r["forces"]
            t.add_row(
                "refined force matching",
                f"correlation {_num(rf['force_profile_correlation_mean'])} (whole clip) / "
                f"{_num(rf['force_correlation_mean'])} (contact frames), object force error "
                f"{_num(rf['object_force_error_mean_n'])} N",
            )
    if m.get("retarget_overrides"):
        t.add_row(
            "settings (--set)", ", ".join(f"{k}={v!r}" for k, v in m["retarget_overrides"].items())
        )
    t.add_row("speed", f"{m['ms_per_frame']:.2f} ms/frame ({m['backend']})")
    t.add_row("written", f"{out_dir}/robot_trajectory.npz, metrics.json")
    Console().print(t)
