"""Plots of a run (matplotlib, Agg backend; PNG or SVG by the file's suffix).

* :func:`plot_finger_forces` — contact force magnitude per finger over time, human vs robot
  (and, for a force-matched run, the force the plan asked of each robot finger), with each
  series' maximum as a dashed line (the DexCanvas paper's Figure 5b);
* :func:`plot_object_error` — object position and rotation error over time with the 5 cm
  success threshold (the DexCanvas rule) and the failing frames shaded;
* :func:`plot_servo_tracking` — how far the re-simulated fingers and wrist trail their
  commands;
* :func:`plot_contact_heatmap` — per manipulation type, how often each of the 16 hand parts
  touches the object, human and robot side by side, aggregated over runs (Figure 6b).

Data helpers (:func:`finger_forces`, :func:`heatmap_rows`) turn runs into what is plotted, so
the numbers can be checked without a picture.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.safe_io import atomic_path
from dexcanvas_core.taxonomy.manipulation import MANIPULATION_TYPES
from dexcanvas_core.trajectory import CONTACT_PARTS, FORCE_GROUPS
from retarget.viz import style
from retarget.viz.errors import VizError

FORMATS = (".png", ".svg")
DPI = 110
SUCCESS_THRESHOLD_M = 0.05
"""DexCanvas success rule: no frame with object position error above 5 cm."""


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _save(fig, out: Path) -> Path:
    out = Path(out)
    if out.suffix.lower() not in FORMATS:
        raise VizError(f"plot file {out.name!r}: use one of {', '.join(FORMATS)}")
    with atomic_path(out) as tmp:
        fig.savefig(
            tmp,
            format=out.suffix.lower().lstrip("."),
            dpi=DPI,
            bbox_inches="tight",
            metadata={"Date": None} if out.suffix.lower() == ".svg" else None,
        )
    _pyplot().close(fig)
    return out


def _titled(fig, out: Path, title: str, what: str) -> Path:
    """Left-aligned figure title ``"title · what"``, then :func:`_save`."""
    fig.suptitle(f"{title + ' · ' if title else ''}{what}", fontsize=10, x=0.02, ha="left")
    return _save(fig, out)


# ---------------------------------------------------------------------------- forces


def finger_forces(
    run_arrays: Mapping[str, np.ndarray], hand, human=None
) -> dict[str, np.ndarray | None]:
    """Per-finger contact force magnitudes [N], rows in ``FORCE_GROUPS`` order.

    Returns ``{"robot": (T, 6), "human": (T, 6) or None, "plan": (T, 6) or None}``. Robot:
    the re-simulation's ``finger_force_world`` of the robot finger each human finger drives
    (NaN for a human finger the robot lacks; fingers sharing a robot finger show the same
    values) and of the palm. Human: ``Trajectory.contacts.finger_totals()`` when the
    demonstration has contact records, else a force-matched run's own ``human_force`` (the
    forces it matched, from the force pipeline; NaN for the palm and the fingers the robot
    lacks). Plan: a force-matched run's ``robot_force`` (the force QP's contact force of each
    mapped human finger's robot finger; NaN likewise), ``None`` for other runs.
    """
    parts = [str(p) for p in run_arrays["force_parts"]]
    F = np.linalg.norm(np.asarray(run_arrays["finger_force_world"], dtype=np.float64), axis=-1)
    T = F.shape[0]
    robot = np.full((T, len(FORCE_GROUPS)), np.nan)
    for row, name in enumerate(FORCE_GROUPS):
        r = "palm" if name == "palm" else hand.fingers.get(name)
        if r is not None and r in parts:
            robot[:, row] = F[:, parts.index(r)]
    human_mag = None
    if human is not None and human.contacts is not None and human.contacts.num_records:
        human_mag = np.linalg.norm(human.contacts.finger_totals().astype(np.float64), axis=-1)
    mapped = hand.mapped_human_fingers  # a force-matched run's arrays' columns

    def per_finger(key: str) -> np.ndarray:
        P = np.linalg.norm(np.asarray(run_arrays[key], dtype=np.float64), axis=-1)
        if P.shape != (T, len(mapped)):
            raise VizError(
                f"{key} must be (T, {len(mapped)}, 3), one per {hand.name} finger; got "
                f"{np.shape(run_arrays[key])}"
            )
        out = np.full((T, len(FORCE_GROUPS)), np.nan)
        for i, f in enumerate(mapped):
            out[:, FORCE_GROUPS.index(f)] = P[:, i]
        return out

    plan = per_finger("robot_force") if "robot_force" in run_arrays else None
    if human_mag is None and "human_force" in run_arrays:
        human_mag = per_finger("human_force")  # the forces it matched (no palm: NaN)
    return {"robot": robot, "human": human_mag, "plan": plan}


def plot_finger_forces(
    out: Path,
    time_s: np.ndarray,
    robot: np.ndarray,
    human: np.ndarray | None = None,
    *,
    title: str = "",
    robot_label: str = "robot (re-simulation)",
    human_label: str = "human (demonstration)",
    plan: np.ndarray | None = None,
    plan_label: str = "robot plan (force QP)",
    notes: Mapping[str, str] | None = None,
) -> Path:
    """Force magnitude [N] per finger over time: one panel per ``FORCE_GROUPS`` row, the
    robot's line in the finger's colour, the human's in black, the plan's (``plan``, same
    shape) dotted grey, dashed lines at each maximum; ``notes`` (per ``FORCE_GROUPS`` name)
    are written in the panel's corner (e.g. the finger's force correlation)."""
    plt = _pyplot()
    time_s = np.asarray(time_s, dtype=np.float64)
    robot = np.asarray(robot, dtype=np.float64)
    if robot.shape != (time_s.shape[0], len(FORCE_GROUPS)):
        raise VizError(f"robot forces must be (T, 6) with T = {time_s.shape[0]}, got {robot.shape}")
    if human is not None and np.asarray(human).shape != robot.shape:
        raise VizError(f"human forces must be {robot.shape}, got {np.asarray(human).shape}")
    if plan is not None and np.asarray(plan).shape != robot.shape:
        raise VizError(f"planned forces must be {robot.shape}, got {np.asarray(plan).shape}")
    fig, axes = plt.subplots(len(FORCE_GROUPS), 1, figsize=(8, 9), sharex=True)
    shown = [np.asarray(a) for a in (robot, human, plan) if a is not None]
    top = max([0.1] + [float(np.nanmax(a)) for a in shown if np.isfinite(a).any()])
    for row, (ax, name) in enumerate(zip(axes, FORCE_GROUPS, strict=True)):
        color = style.GROUP_COLORS[name][:3]
        series = [(robot[:, row], robot_label, color, "-")]
        if human is not None:
            series.append((np.asarray(human)[:, row], human_label, (0.1, 0.1, 0.1), "-"))
        if plan is not None:
            series.append((np.asarray(plan)[:, row], plan_label, (0.45, 0.45, 0.45), ":"))
        for y, label, c, ls in series:
            if not np.isfinite(y).any():
                continue
            ax.plot(time_s, y, ls, color=c, lw=1.3, label=label)
            peak = float(np.nanmax(y))
            if peak <= 0.0:
                continue
            ax.axhline(peak, color=c, lw=0.9, ls="--", alpha=0.8)
            ax.annotate(
                f"max {peak:.2f} N",
                (time_s[-1], peak),
                xytext=(4, 0),
                textcoords="offset points",
                va="center",
                fontsize=7,
                color=c,
            )
        if not np.isfinite(robot[:, row]).any():
            ax.text(
                0.5,
                0.5,
                "no robot finger",
                transform=ax.transAxes,
                ha="center",
                va="center",
                fontsize=8,
                color="0.4",
            )
        if notes and notes.get(name):
            # on a white box: legible over the maxima's dashed lines near the panel's top
            ax.text(
                0.01, 0.92, notes[name], transform=ax.transAxes, ha="left", va="top",
                fontsize=7, color="0.25", zorder=5,
                bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "none", "pad": 1.0},
            )  # fmt: skip
        ax.set_ylabel(f"{name}\n[N]", fontsize=8)
        ax.set_ylim(0, 1.15 * top)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    axes[-1].set_xlabel("time [s]")
    handles = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(lab, h)
    fig.legend(handles.values(), handles.keys(), loc="upper right", fontsize=8, frameon=False)
    head = title or "contact force per finger"
    if human is None:
        head += "\n(human: the demonstration has no contact forces)"
    fig.suptitle(head, fontsize=10, x=0.02, ha="left")
    return _save(fig, out)


# ---------------------------------------------------------------------------- object error


def plot_object_error(
    out: Path,
    time_s: np.ndarray,
    pos_err_m: np.ndarray,
    rot_err_rad: np.ndarray,
    *,
    threshold_m: float = SUCCESS_THRESHOLD_M,
    title: str = "",
) -> Path:
    """Object position error [cm] with the success threshold and rotation error [deg]."""
    plt = _pyplot()
    t = np.asarray(time_s, dtype=np.float64)
    pos = 100 * np.asarray(pos_err_m, dtype=np.float64)
    rot = np.degrees(np.asarray(rot_err_rad, dtype=np.float64))
    if not (pos.shape == rot.shape == t.shape):
        raise VizError(
            f"time, position and rotation errors differ in length: "
            f"{t.shape}, {pos.shape}, {rot.shape}"
        )
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 4.6), sharex=True)
    thr = 100 * threshold_m
    ax1.plot(t, pos, color=style.OBJECT_RGBA[:3], lw=1.4, label="position error")
    ax1.axhline(thr, color="#c0392b", ls="--", lw=1.0, label=f"success threshold {thr:.0f} cm")
    over = pos > thr
    if over.any():
        ax1.fill_between(
            t,
            0,
            pos.max() * 1.05,
            where=over,
            color="#c0392b",
            alpha=0.12,
            step="mid",
            label="failing frames",
        )
    ax1.set_ylabel("position error [cm]")
    ax1.set_ylim(0, max(pos.max(), thr) * 1.15)
    ax1.legend(fontsize=8, loc="upper left", frameon=False)
    ax1.grid(alpha=0.3)
    ax2.plot(t, rot, color="#34495e", lw=1.4)
    ax2.set_ylabel("rotation error [deg]")
    ax2.set_xlabel("time [s]")
    ax2.set_ylim(0, max(rot.max(), 1.0) * 1.15)
    ax2.grid(alpha=0.3)
    verdict = "success" if not over.any() else f"fails at t = {t[np.argmax(over)]:.2f} s"
    return _titled(fig, out, title, f"object error ({verdict}; max {pos.max():.1f} cm)")


# ---------------------------------------------------------------------------- servo tracking


def plot_servo_tracking(
    out: Path,
    time_s: np.ndarray,
    finger_err_rad: np.ndarray,
    fingers: Sequence[str],
    wrist_pos_err_m: np.ndarray,
    *,
    human_fingers: Mapping[str, str] | None = None,
    title: str = "",
) -> Path:
    """How far the re-simulated hand trails its commands: per robot finger, its worst
    joint's ``|q_sim − q_command|`` [deg] (a finger pressing on the object trails by its force
    offset; one that trails in free air is too slow for the motion), and the wrist's position
    error [mm]. ``human_fingers`` (robot finger → human finger) colours the fingers as the
    force plots do."""
    plt = _pyplot()
    t = np.asarray(time_s, dtype=np.float64)
    err = np.degrees(np.asarray(finger_err_rad, dtype=np.float64))
    wrist = 1000 * np.asarray(wrist_pos_err_m, dtype=np.float64)
    if err.shape != (t.shape[0], len(fingers)) or wrist.shape != t.shape:
        raise VizError(
            f"servo errors must be (T, {len(fingers)}) and (T,) with T = {t.shape[0]}, "
            f"got {err.shape} and {wrist.shape}"
        )
    fig, (ax1, ax2) = plt.subplots(
        2, 1, figsize=(8, 4.6), sharex=True, gridspec_kw={"height_ratios": [2, 1]}
    )
    for i, f in enumerate(fingers):
        human = (human_fingers or {}).get(f)
        color = style.GROUP_COLORS[human][:3] if human in style.GROUP_COLORS else None
        label = f"{f} ({human})" if human else f
        ax1.plot(t, err[:, i], color=color, lw=1.2, label=f"{label}: mean {err[:, i].mean():.1f}°")
    ax1.set_ylabel("worst finger joint [deg]")
    ax1.set_ylim(0, max(float(err.max()) if err.size else 0.0, 1.0) * 1.15)
    ax1.legend(fontsize=7, loc="upper left", frameon=False, ncol=2)
    ax1.grid(alpha=0.3)
    ax2.plot(t, wrist, color="#34495e", lw=1.2)
    ax2.set_ylabel("wrist [mm]")
    ax2.set_xlabel("time [s]")
    ax2.set_ylim(0, max(float(wrist.max()), 1.0) * 1.15)
    ax2.grid(alpha=0.3)
    return _titled(fig, out, title, "servo tracking error (simulation − command)")


# ---------------------------------------------------------------------------- heatmap


def heatmap_rows(
    entries: Sequence[tuple[str, np.ndarray | None, np.ndarray | None]],
) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Aggregate per-run part frequencies by manipulation type.

    ``entries``: ``(type_name, human (16,) or None, robot (16,) or None)`` per run. Returns the
    types (taxonomy order), the mean human and robot frequency tables ``(types, 16)`` (NaN where
    no run of that type has the data) and the number of runs per type.
    """
    taxonomy = list(MANIPULATION_TYPES)

    def order(name: str):  # taxonomy order; unknown names last, alphabetically
        return (taxonomy.index(name), name) if name in taxonomy else (len(taxonomy), name)

    types = sorted({e[0] for e in entries}, key=order)
    P = len(CONTACT_PARTS)
    human = np.full((len(types), P), np.nan)
    robot = np.full((len(types), P), np.nan)
    counts = np.zeros(len(types), np.int64)
    for i, typ in enumerate(types):
        rows = [e for e in entries if e[0] == typ]
        counts[i] = len(rows)
        for table, k in ((human, 1), (robot, 2)):
            vals = [np.asarray(r[k], dtype=np.float64) for r in rows if r[k] is not None]
            for v in vals:
                if v.shape != (P,):
                    raise VizError(f"part frequencies must have shape ({P},), got {v.shape}")
            if vals:
                table[i] = np.mean(vals, axis=0)
    return types, human, robot, counts


def plot_contact_heatmap(
    out: Path,
    entries: Sequence[tuple[str, np.ndarray | None, np.ndarray | None]],
    *,
    title: str = "",
    human_label: str = "human",
    robot_label: str = "robot (re-simulation)",
) -> Path:
    """Heatmap: manipulation types × 16 hand parts, fraction of frames in contact, human and
    robot panels (:func:`heatmap_rows` aggregates ``entries``)."""
    if not entries:
        raise VizError("a contact heatmap needs at least one run")
    plt = _pyplot()
    types, human, robot, counts = heatmap_rows(entries)
    labels = [_part_label(p) for p in CONTACT_PARTS]
    fig, axes = plt.subplots(
        1,
        2,
        figsize=(12, max(2.9, 1.6 + 0.42 * len(types))),
        sharey=True,
        constrained_layout=True,
    )
    im = None
    for ax, table, name in ((axes[0], human, human_label), (axes[1], robot, robot_label)):
        masked = np.ma.masked_invalid(table)
        im = ax.imshow(masked, vmin=0.0, vmax=1.0, cmap="magma_r", aspect="auto")
        ax.set_xticks(range(len(labels)), labels, rotation=60, ha="right", fontsize=7)
        ax.set_title(name, fontsize=9)
        for i in range(table.shape[0]):
            for j in range(table.shape[1]):
                v = table[i, j]
                if np.isfinite(v) and v >= 0.005:
                    ax.text(
                        j,
                        i,
                        f"{v:.2f}"[1:] if v < 1 else "1",
                        ha="center",
                        va="center",
                        fontsize=6,
                        color="white" if v > 0.55 else "black",
                    )
        if not np.isfinite(table).any():
            ax.text(0.5, 0.5, "no data", transform=ax.transAxes, ha="center", va="center")
    axes[0].set_yticks(
        range(len(types)), [f"{t} ({n})" for t, n in zip(types, counts, strict=True)], fontsize=8
    )
    fig.colorbar(im, ax=axes, shrink=0.9, label="fraction of frames in contact")
    fig.suptitle(title or "contacts per hand part (runs per type in brackets)", fontsize=10)
    return _save(fig, out)


def _part_label(part: str) -> str:
    return part.replace("_", " ")


__all__ = [
    "FINGERS",
    "finger_forces",
    "heatmap_rows",
    "plot_contact_heatmap",
    "plot_finger_forces",
    "plot_object_error",
]
