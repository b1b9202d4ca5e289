"""Wrist tracking in re-simulation: does the robot wrist follow a human wrist's fastest carries?

For every hand, the re-simulation (``retarget.validate.Resimulator``, no table, the object 10 m
away: nothing touches the hand) is given wrist commands at 120 Hz, the fingers held open:

* a straight **minimum-jerk carry** of the wrist out and back (direction (1, 0.6, 0.4)),
  reaching peak speed ``v`` (1, 2.5 and 3 m/s by default) with peak acceleration 15 m/s²
  (``--acc``; the carry's length and duration follow from both: ``D = v·T/1.875``,
  ``T = 5.77·v/(1.875·a)``), while the hand turns 90° (``--rotation-deg``) about a fixed
  oblique axis in 0.5 s (``--rotation-s``) and back on the return; 0.15 s at rest before,
  between and after.

Two wrist drivers (``ValidateConfig.wrist_driver``, :mod:`retarget.wrist_drive`):

* **before** — ``servo``: MuJoCo position servos (kp 2000 N/m, 100 N·m/rad, critically
  damped), the re-simulation's earlier driver (its rollouts are bit-identical to the earlier
  ``Resimulator``'s);
* **after** — ``computed_torque``: inertia, bias and the commanded motion's acceleration fed
  forward, PD feedback of the servos' stiffness, force ≤ 200 N, torque ≤ 20 N·m.

Measured per run: mean and max over frames of the wrist position error [mm] (simulated against
commanded wrist point) and rotation error [deg] (angle between the simulated and commanded
wrist orientations); the largest force and torque the arm applied and the share of physics
steps in which a limit bound; ms per frame (wall time of ``Resimulator.run`` / frames, the
median of ``--repeats``; this machine is shared, so one run's time is a sample). The
simulated clock takes 4 physics steps of 2 ms per 8.33 ms frame, so the motion plays 4 %
faster than the commands' timestamps say: the simulated peak speed and acceleration
(``sim_peak_*``, of the driver's reference) are listed beside the nominal ones.

Target (issue 50): mean error ≤ 5 mm and ≤ 2° at 2.5 m/s and 15 m/s², every hand.

Then, on a grasp (``--demo``, default the built-in ``cube2/tripod``; ``none`` skips it), each
hand's retargeted commands (``Retargeter`` defaults, ``q_command``) re-simulated with the
object on the table by both drivers: success, largest object error, wrist tracking, the arm's
largest force and the re-simulation's wall time.

Writes JSON (default ``benchmarks/results/wrist_tracking/<date>-<commit>.json``) and the page
``docs/benchmarks/wrist_tracking.md``::

    python -m benchmarks.wrist_tracking                     # every hand, 1 / 2.5 / 3 m/s
    python -m benchmarks.wrist_tracking --hands shadow --speeds 2.5
    python -m benchmarks.wrist_tracking --page-only         # the page from the newest JSON
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from benchmarks._common import (
    PAGES,
    RESULTS,
    atomic_write_json,
    command_line,
    display_path,
    git_commit,
    machine_info,
    newest_result,
    pct,
    progress_bar,
    result_path,
    versions,
)
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.safe_io import atomic_write_text
from dexcanvas_core.table import table_of
from dexcanvas_core.taxonomy import Pair
from dexcanvas_core.trajectory import HandTrack, ObjectTrack, Trajectory
from retarget.hands import available_hands, get_hand
from retarget.pipeline import check_pair
from retarget.retargeter import Retargeter
from retarget.validate import Resimulator, ValidateConfig
from retarget.viz.data import load_human
from retarget.wrist_drive import WristReference, frame_steps

NAME = "wrist_tracking"
"""The benchmark's name: its results folder ``benchmarks/results/<NAME>/``."""
PAGE = PAGES / "wrist_tracking.md"
DRIVERS = {"before": "servo", "after": "computed_torque"}
TARGET_SPEED, TARGET_POS_MM, TARGET_ROT_DEG = 2.5, 5.0, 2.0
FPS = 120.0
HOLD_S = 0.15
DIRECTION = (1.0, 0.6, 0.4)
ROT_AXIS = (0.3, 0.5, 0.8)
START = (-0.4, -0.3, 0.4)  # [m] the wrist's first position


def _min_jerk(tau: np.ndarray) -> np.ndarray:
    tau = np.clip(tau, 0.0, 1.0)
    return 10 * tau**3 - 15 * tau**4 + 6 * tau**5


def carry(speed: float, acc: float, rot_deg: float, rot_s: float) -> tuple:
    """``(t, q_wrist, length, duration)``: timestamps [s] at ``FPS``, wrist commands (T, 6)
    (module docstring), the carry's length [m] and duration [s]."""
    from scipy.spatial.transform import Rotation

    duration = 5.7735 * speed / (1.875 * acc)
    length = speed * duration / 1.875
    back = HOLD_S + max(duration, rot_s) + HOLD_S
    t = np.arange(0.0, back + max(duration, rot_s) + HOLD_S, 1 / FPS)
    s = _min_jerk((t - HOLD_S) / duration) - _min_jerk((t - back) / duration)
    u = np.asarray(DIRECTION) / np.linalg.norm(DIRECTION)
    p = np.asarray(START) + length * s[:, None] * u
    axis = np.asarray(ROT_AXIS) / np.linalg.norm(ROT_AXIS)
    angle = np.radians(rot_deg) * (_min_jerk((t - HOLD_S) / rot_s) - _min_jerk((t - back) / rot_s))
    euler = Rotation.from_rotvec(angle[:, None] * axis).as_euler("XYZ")
    return t, np.c_[p, euler], length, duration


def run_one(hand, t: np.ndarray, wrist: np.ndarray, driver: str, repeats: int) -> dict:
    """One hand × trajectory × driver: the row's numbers (module docstring)."""

    T = len(t)
    human = Trajectory(
        uuid="wrist-carry",
        timestamp=t,
        fps=FPS,
        hands=[HandTrack("right", np.zeros((T, 3)), np.zeros((T, 3)), np.zeros((T, 48)))],
        objects=[ObjectTrack("cube2", np.tile([10.0, 10.0, 0.5], (T, 1)), np.zeros((T, 3)))],
    )
    sim = Resimulator(
        hand, object_geometry("cube2"), ValidateConfig(table=False, wrist_driver=driver)
    )
    q = np.tile(hand.default_qpos(sim.model)[: sim.hand_nq], (T, 1))
    q[:, :6] = wrist
    seconds = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = sim.run(q, human)
        seconds.append(time.perf_counter() - t0)
    m = res.metrics()
    h = float(sim.model.opt.timestep)
    ref = WristReference.from_frames(wrist, frame_steps(t, h), h)
    return {
        "driver": driver,
        "frames": T,
        "pos_err_mean_mm": 1e3 * m["wrist_pos_tracking_err_mean_m"],
        "pos_err_max_mm": 1e3 * m["wrist_pos_tracking_err_max_m"],
        "rot_err_mean_deg": m["wrist_rot_tracking_err_mean_deg"],
        "rot_err_max_deg": m["wrist_rot_tracking_err_max_deg"],
        "force_max_n": m["wrist_force_max_n"],
        "torque_max_nm": m["wrist_torque_max_nm"],
        "force_limit_n": m["wrist_force_limit_n"],
        "torque_limit_nm": m["wrist_torque_limit_nm"],
        "force_saturation_fraction": m["wrist_force_saturation_fraction"],
        "torque_saturation_fraction": m["wrist_torque_saturation_fraction"],
        "ms_per_frame": 1e3 * float(np.median(seconds)) / T,
        "ms_per_frame_min": 1e3 * min(seconds) / T,
        "sim_peak_speed_m_s": float(np.linalg.norm(ref.v[:, :3], axis=1).max()),
        "sim_peak_acc_m_s2": float(np.linalg.norm(ref.a[:, :3], axis=1).max()),
        "hand_mass_kg": float(sim.model.body_subtreemass[sim.model.body("wrist").id]),
    }


def demo_rows(hands, pair: str, repeats: int, console) -> list[dict]:
    """The grasp ``pair``'s built-in demonstration, retargeted onto each hand and re-simulated
    by both drivers (module docstring)."""

    p = Pair.parse(pair)
    human = load_human(None, pair)
    geometry = object_geometry(p.object.id)
    out = []
    with progress_bar(console) as prog:
        task = prog.add_task(f"{pair}: retargeting + re-simulating", total=len(hands))
        for hand in hands:
            prog.update(task, description=f"{pair} · {hand.name}")
            try:
                check_pair(hand, p.manipulation_type)
            except Exception as e:  # recorded, not a benchmark failure
                out.append({"hand": hand.name, "pair": pair, "skipped": str(e)})
                prog.advance(task)
                continue
            table = table_of(human)
            robot = Retargeter(hand, geometry, table=table).retarget(human)
            row = {"hand": hand.name, "pair": pair, "frames": human.num_frames}
            for when, driver in DRIVERS.items():
                sim = Resimulator(hand, geometry, ValidateConfig(wrist_driver=driver), table=table)
                seconds = []
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    res = sim.run(robot.q_command, human)
                    seconds.append(time.perf_counter() - t0)
                m = res.metrics()
                row[when] = {
                    "driver": driver,
                    "success": m["success"],
                    "object_pos_err_max_mm": 1e3 * m["object_pos_err_max_m"],
                    "object_pos_err_mean_mm": 1e3 * m["object_pos_err_mean_m"],
                    "pos_err_mean_mm": 1e3 * m["wrist_pos_tracking_err_mean_m"],
                    "pos_err_max_mm": 1e3 * m["wrist_pos_tracking_err_max_m"],
                    "rot_err_mean_deg": m["wrist_rot_tracking_err_mean_deg"],
                    "force_max_n": m["wrist_force_max_n"],
                    "force_saturation_fraction": m["wrist_force_saturation_fraction"],
                    "resim_s": float(np.median(seconds)),
                    "ms_per_frame": 1e3 * float(np.median(seconds)) / human.num_frames,
                }
            out.append(row)
            prog.advance(task)
    return out


def target_checks(rows: list[dict]) -> list[dict]:
    """The issue's target per hand, on the ``after`` rows at ``TARGET_SPEED``."""
    out = []
    for r in rows:
        if r["when"] != "after" or r["speed_m_s"] != TARGET_SPEED:
            continue
        out.append(
            {
                "hand": r["hand"],
                "target": f"mean wrist error ≤ {TARGET_POS_MM:g} mm and ≤ {TARGET_ROT_DEG:g}° "
                f"at {TARGET_SPEED:g} m/s, {r['acc_m_s2']:g} m/s²",
                "value": [r["pos_err_mean_mm"], r["rot_err_mean_deg"]],
                "met": r["pos_err_mean_mm"] <= TARGET_POS_MM
                and r["rot_err_mean_deg"] <= TARGET_ROT_DEG,
            }
        )
    return out


# ----------------------------------------------------------------------------------- output
def _cells(b: dict, a: dict) -> list[str]:
    """before → after cells of one hand × speed."""
    return [
        f"{b['pos_err_mean_mm']:.1f} → {a['pos_err_mean_mm']:.2f}",
        f"{b['pos_err_max_mm']:.1f} → {a['pos_err_max_mm']:.2f}",
        f"{b['rot_err_mean_deg']:.2f} → {a['rot_err_mean_deg']:.3f}",
        f"{b['rot_err_max_deg']:.2f} → {a['rot_err_max_deg']:.3f}",
        f"{a['force_max_n']:.0f} / {a['torque_max_nm']:.1f}",
        f"{pct(a['force_saturation_fraction'], '.1f', '')} / "
        f"{pct(a['torque_saturation_fraction'], '.1f', '')}",
        f"{b['ms_per_frame']:.3f} → {a['ms_per_frame']:.3f}",
    ]


COLUMNS = (
    "hand",
    "speed [m/s]",
    "pos mean [mm]",
    "pos max [mm]",
    "rot mean [°]",
    "rot max [°]",
    "max force [N] / torque [N·m]",
    "saturated [%] force / torque",
    "ms/frame",
)


def _pairs(doc: dict):
    """``(hand, speed, before row, after row)`` in the document's order."""
    rows = doc["runs"]
    for r in rows:
        if r["when"] != "before":
            continue
        a = next(
            x
            for x in rows
            if x["when"] == "after" and x["hand"] == r["hand"] and x["speed_m_s"] == r["speed_m_s"]
        )
        yield r["hand"], r["speed_m_s"], r, a


def results_table(doc: dict):

    t = Table(
        title="wrist tracking: before (position servos) → after (computed torque)",
        caption=f"minimum-jerk carry, peak acceleration {doc['config']['acc_m_s2']:g} m/s², "
        f"{doc['config']['rotation_deg']:g}° in {doc['config']['rotation_s']:g} s, "
        f"{FPS:g} Hz; force/torque and saturation of the computed-torque driver "
        f"(limits {doc['limits']['force_n']:g} N, {doc['limits']['torque_nm']:g} N·m)",
    )
    for col in COLUMNS:
        t.add_column(col, justify="left" if col == "hand" else "right")
    for hand, speed, b, a in _pairs(doc):
        t.add_row(hand, f"{speed:g}", *_cells(b, a))
    return t


DEMO_COLUMNS = (
    "hand",
    "success",
    "object error max [mm]",
    "wrist pos mean / max [mm]",
    "wrist rot mean [°]",
    "max force [N]",
    "re-simulation [s]",
)


def _demo_cells(r: dict) -> list[str]:
    b, a = r["before"], r["after"]
    ok = {True: "yes", False: "no"}
    return [
        f"{ok[b['success']]} → {ok[a['success']]}",
        f"{b['object_pos_err_max_mm']:.1f} → {a['object_pos_err_max_mm']:.1f}",
        f"{b['pos_err_mean_mm']:.1f} / {b['pos_err_max_mm']:.1f} → "
        f"{a['pos_err_mean_mm']:.2f} / {a['pos_err_max_mm']:.2f}",
        f"{b['rot_err_mean_deg']:.2f} → {a['rot_err_mean_deg']:.3f}",
        f"{b['force_max_n']:.0f} → {a['force_max_n']:.0f}",
        f"{b['resim_s']:.2f} → {a['resim_s']:.2f}",
    ]


def demo_table(doc: dict):
    rows = [r for r in doc.get("demo", []) if "skipped" not in r]
    if not rows:
        return None
    t = Table(
        title=f"{rows[0]['pair']} (built-in, {rows[0]['frames']} frames): before → after",
        caption="object on the table; max force: the arm's largest force on the wrist",
    )
    for col in DEMO_COLUMNS:
        t.add_column(col, justify="left" if col == "hand" else "right")
    for r in rows:
        t.add_row(r["hand"], *_demo_cells(r))
    return t


def render_page(doc: dict, source: Path) -> str:
    """The markdown page of a result document read from ``source`` (a JSON file)."""
    m, c = doc["machine"], doc["config"]
    lines = [
        "# Wrist tracking in re-simulation",
        "",
        f"Generated by `python -m benchmarks.wrist_tracking` from `{display_path(source)}`"
        f"; commit `{doc['commit']}`, {m['platform']}, Python {m['python']}, "
        f"{doc['wall_time_s']:.0f} s.",
        "",
        f"Command: `{doc['command']}`. How it measures: the script's docstring.",
        "",
        f"Wrist commands at {FPS:g} Hz, fingers open, nothing touching the hand: a minimum-jerk "
        f"carry out and back reaching the peak speed of each row with peak acceleration "
        f"{c['acc_m_s2']:g} m/s², while the hand turns {c['rotation_deg']:g}° in "
        f"{c['rotation_s']:g} s and back. Cells read *before → after*: before, the position "
        "servos (kp 2000 N/m and 100 N·m/rad, critically damped); after, the computed-torque "
        "driver (`retarget/wrist_drive.py`), limited to "
        f"{doc['limits']['force_n']:g} N and {doc['limits']['torque_nm']:g} N·m. Errors are "
        "means and maxima over frames: the wrist point's distance from its command, the angle "
        "between the simulated and commanded wrist orientations. Force, torque and saturation "
        "(share of physics steps at a limit) are the computed-torque driver's. ms/frame: "
        "`Resimulator.run` wall time per frame, median of "
        f"{c['repeats']} on a shared machine.",
        "",
        "| " + " | ".join(COLUMNS) + " |",
        "|---|" + "---:|" * (len(COLUMNS) - 1),
    ]
    for hand, speed, b, a in _pairs(doc):
        lines.append(f"| {hand} | {speed:g} | " + " | ".join(_cells(b, a)) + " |")
    lines += [
        "",
        "The simulated clock takes 4 physics steps of 2 ms per 8.33 ms frame: the motion plays "
        "4 % faster than its timestamps, peak speed and acceleration "
        + ", ".join(
            f"{r['sim_peak_speed_m_s']:.2f} m/s and {r['sim_peak_acc_m_s2']:.1f} m/s² "
            f"(nominal {r['speed_m_s']:g})"
            for r in doc["runs"]
            if r["when"] == "after" and r["hand"] == doc["hands"][0]
        )
        + ".",
        "",
        "| target | hand | mean error | met |",
        "|---|---|---:|---|",
    ]
    for t in doc["targets"]:
        pos, rot = t["value"]
        lines.append(
            f"| {t['target']} | {t['hand']} | {pos:.2f} mm, {rot:.3f}° | "
            f"{'yes' if t['met'] else 'no'} |"
        )
    demo = [r for r in doc.get("demo", []) if "skipped" not in r]
    if demo:
        lines += [
            "",
            f"## A grasp: {demo[0]['pair']}",
            "",
            f"The built-in demonstration ({demo[0]['frames']} frames at {FPS:g} Hz) retargeted "
            "onto each hand (default settings) and its commands re-simulated with the object "
            "on the table by each driver (*before → after*). Success: no frame's object error "
            "above 5 cm. Max force: the arm's largest force on the wrist. Re-simulation: wall "
            "time of one `Resimulator.run`, median of "
            f"{doc['config']['repeats']}.",
            "",
            "| " + " | ".join(DEMO_COLUMNS) + " |",
            "|---|" + "---:|" * (len(DEMO_COLUMNS) - 1),
        ]
        lines += [f"| {r['hand']} | " + " | ".join(_demo_cells(r)) + " |" for r in demo]
        skipped = [r for r in doc["demo"] if "skipped" in r]
        if skipped:
            lines += ["", "Skipped: " + "; ".join(f"{r['hand']}: {r['skipped']}" for r in skipped)]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------- main
def run_benchmark(args, console) -> dict:
    t_start = time.perf_counter()
    load0 = os.getloadavg()
    hands = [get_hand(h) for h in (args.hands or available_hands())]
    trajectories = {v: carry(v, args.acc, args.rotation_deg, args.rotation_s) for v in args.speeds}
    rows = []
    with progress_bar(console) as prog:
        task = prog.add_task("re-simulating", total=len(hands) * len(args.speeds) * 2)
        for hand in hands:
            for v, (t, wrist, length, duration) in trajectories.items():
                for when, driver in DRIVERS.items():
                    prog.update(task, description=f"{hand.name} · {v:g} m/s · {driver}")
                    row = run_one(hand, t, wrist, driver, args.repeats)
                    rows.append(
                        {"hand": hand.name, "speed_m_s": v, "acc_m_s2": args.acc,
                         "carry_m": length, "carry_s": duration, "when": when, **row}
                    )  # fmt: skip
                    prog.advance(task)
    demo = [] if args.demo == "none" else demo_rows(hands, args.demo, args.repeats, console)
    g = hands[0].wrist_gains
    return {
        "benchmark": "wrist_tracking",
        "command": command_line("benchmarks.wrist_tracking"),
        "config": {
            "hands": [h.name for h in hands],
            "speeds_m_s": list(args.speeds),
            "acc_m_s2": args.acc,
            "rotation_deg": args.rotation_deg,
            "rotation_s": args.rotation_s,
            "fps": FPS,
            "repeats": args.repeats,
            "demo": args.demo,
        },
        "hands": [h.name for h in hands],
        "drivers": DRIVERS,
        "limits": {"force_n": g.force_slide, "torque_nm": g.torque_hinge},
        "commit": git_commit(),
        "machine": machine_info(load0),
        "versions": versions(("dexcanvas-retarget", "mujoco", "numpy", "scipy")),
        "definitions": {
            "pos_err_*_mm": "distance of the simulated wrist point (slide joints) from the "
            "command, mean / max over frames",
            "rot_err_*_deg": "angle between the simulated and commanded wrist orientations "
            "(intrinsic XYZ hinges), mean / max over frames",
            "force_max_n": "largest norm of the arm's force on the wrist (actuator forces + "
            "gravity compensation of the slide joints) over the physics steps",
            "torque_max_nm": "the same for the largest hinge torque",
            "*_saturation_fraction": "share of the clip's physics steps in which the limit "
            "bound (servo: a joint at its force range)",
            "ms_per_frame": "Resimulator.run wall time / frames, median of config.repeats",
            "sim_peak_*": "peak speed / acceleration of the computed-torque driver's "
            "reference in simulated time",
        },
        "targets": target_checks(rows),
        "runs": rows,
        "demo": demo,
        "wall_time_s": time.perf_counter() - t_start,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.wrist_tracking",
        description=__doc__.split("\n\n")[0],
    )
    ap.add_argument("--hands", nargs="+", default=None, help="hands to run (default: all)")
    ap.add_argument("--speeds", nargs="+", type=float, default=[1.0, 2.5, 3.0],
                    help="peak carry speeds [m/s]")  # fmt: skip
    ap.add_argument("--acc", type=float, default=15.0, help="peak acceleration [m/s²]")
    ap.add_argument("--rotation-deg", type=float, default=90.0, help="wrist turn [deg]")
    ap.add_argument("--rotation-s", type=float, default=0.5, help="duration of the turn [s]")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs per row (median)")
    ap.add_argument("--demo", default="cube2/tripod",
                    help="built-in grasp re-simulated by both drivers ('none': skip)")  # fmt: skip
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help="JSON output (default: benchmarks/results/wrist_tracking/<date>-<commit>.json; "
        "with --page-only: the newest there)",
    )
    ap.add_argument("--page", type=Path, default=PAGE, help="markdown page output")
    ap.add_argument("--page-only", action="store_true", help="write the page from --out")
    args = ap.parse_args(argv)
    console = Console(width=None if sys.stdout.isatty() else 160)
    if args.page_only:
        args.out = args.out or newest_result(NAME)
        if args.out is None:
            raise SystemExit(f"no results in {RESULTS / NAME}; run the benchmark first")
        doc = json.loads(args.out.read_text())
    else:
        if min(args.speeds) <= 0 or args.acc <= 0 or args.rotation_s <= 0 or args.repeats < 1:
            raise SystemExit("--speeds, --acc, --rotation-s and --repeats must be positive")
        doc = run_benchmark(args, console)
        args.out = args.out or result_path(NAME, doc["commit"])
        atomic_write_json(args.out, doc)
    console.print(results_table(doc))
    if (t := demo_table(doc)) is not None:
        console.print(t)
    for t in doc["targets"]:
        pos, rot = t["value"]
        ok = "[green]met[/green]" if t["met"] else "[red]not met[/red]"
        console.print(f"{t['hand']}: {t['target']}: {pos:.2f} mm, {rot:.3f}° — {ok}")
    atomic_write_text(args.page, render_page(doc, args.out))
    console.print(f"wrote {args.out} and {args.page} ({doc['wall_time_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
