"""``retarget run``: retarget one demonstration onto one robot hand, re-simulate, write results.

``run_retarget(RunConfig(hand="shadow", pair="cube2/tripod"))`` is what the CLI calls; library
users can call it too. It writes into ``out``:

* ``robot_trajectory.npz`` — joint positions and servo commands (MuJoCo ``qpos`` order, names
  included), timestamps, fingertip positions, per-frame keypoint/contact errors and hand–object
  distances, simulated object pose, per-finger contact forces;
* ``metrics.json`` — the numbers (success, object errors, keypoint error, penetration, speed).

Both files are written atomically (temporary file, then rename).
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from retarget.errors import RetargetError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunConfig:
    """One retargeting run."""

    hand: str
    """Registered hand name (``retarget hands``)."""
    pair: str
    """``object/manipulation_type``, e.g. ``cube2/tripod``."""
    dataset: Path | None = None
    """DexCanvas-layout Lance dataset; ``None``: the built-in demonstrations."""
    index: int = 0
    """Which of the dataset's demonstrations of this pair (0-based)."""
    out: Path | None = None
    """Output directory; default ``runs/<hand>_<object>_<type>_<index>``."""
    backend: Literal["pinocchio", "mink"] = "pinocchio"
    progress: bool = True
    """Show progress bars and the summary on the terminal."""

    def output_dir(self) -> Path:
        if self.out is not None:
            return Path(self.out)
        obj, typ = self.pair.split("/", 1)
        return Path("runs") / f"{self.hand}_{obj}_{typ}_{self.index}"


def check_pair(hand, manipulation_type) -> None:
    """Raise if the hand cannot perform this manipulation type at all.

    In-hand manipulation (rolling, sliding, finger transfer, rotation) needs independently driven
    fingers: a parallel gripper (one actuated DoF) cannot do it. Four-finger hands drop the pinky
    (it is not needed by any type's object motion); the gripper merges index and middle.
    """
    model = hand.compile()
    finger_actuators = model.nu - 6
    if manipulation_type.group == "in_hand" and finger_actuators < 3:
        raise RetargetError(
            f"hand {hand.name!r} cannot perform {manipulation_type.name!r}: in-hand manipulation "
            f"needs independently driven fingers and {hand.name} has {finger_actuators} finger "
            "actuator(s); pick a dexterous hand (retarget hands)"
        )


def _load_demonstration(cfg: RunConfig, pair):
    from dexcanvas_core.io import open_dataset
    from dexcanvas_core.loaders.selection import select_rows

    if cfg.dataset is None:
        from dexcanvas_core.builtin import default_dataset_path

        path = default_dataset_path()
    else:
        path = Path(cfg.dataset)
    ds = open_dataset(path)
    sel = select_rows(
        ds, objects=[pair.object.id], manipulation_types=[pair.manipulation_type.name]
    )
    n = len(sel.positions)
    if not 0 <= cfg.index < n:
        raise RetargetError(
            f"--index {cfg.index} out of range: {ds.path} has {n} demonstration(s) of {pair}"
        )
    return ds.take([int(sel.positions[cfg.index])])[0]


def _atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def run_retarget(cfg: RunConfig) -> dict:
    """Retarget, re-simulate and write the outputs; return the metrics dict."""
    from dexcanvas_core.demos.geometry import object_geometry
    from dexcanvas_core.taxonomy import Pair
    from retarget.hands import get_hand
    from retarget.retargeter import RetargetConfig, Retargeter
    from retarget.validate import Resimulator

    pair = Pair.parse(cfg.pair)
    hand = get_hand(cfg.hand)
    check_pair(hand, pair.manipulation_type)
    traj = _load_demonstration(cfg, pair)
    geometry = object_geometry(pair.object.id)
    out_dir = cfg.output_dir()
    out_dir.mkdir(parents=True, exist_ok=True)

    progress_ctx = _Progress(cfg.progress)
    with progress_ctx as prog:
        t0 = time.perf_counter()
        retargeter = Retargeter(hand, geometry, RetargetConfig(backend=cfg.backend))
        setup_s = time.perf_counter() - t0
        robot = retargeter.retarget(traj, progress=prog.task("retargeting", traj.num_frames))
        sim = Resimulator(hand, geometry).run(
            robot.q_command, traj, progress=prog.task("re-simulating", traj.num_frames)
        )

    kin_pen = (
        float(max(0.0, -np.min(robot.min_distance)))
        if np.isfinite(robot.min_distance).any()
        else 0.0
    )
    contact_err = robot.contact_err[np.isfinite(robot.contact_err)]
    metrics = {
        "hand": hand.name,
        "pair": str(pair),
        "uuid": traj.uuid,
        "dataset": str(cfg.dataset) if cfg.dataset else "built-in",
        "backend": cfg.backend,
        "frames": traj.num_frames,
        "fps": traj.fps,
        **sim.metrics(),
        "keypoint_err_mean_m": float(robot.keypoint_err.mean()),
        "penetration_max_m": kin_pen,
        "sim_penetration_max_m": float(sim.penetration_max_m),
        "contact_err_mean_m": float(contact_err.mean()) if contact_err.size else None,
        "contact_frames": int(robot.contact_active.any(axis=1).sum()),
        "ms_per_frame": robot.ms_per_frame,
        "setup_s": setup_s,
        "retarget_config": asdict(retargeter.cfg),
    }
    robot.meta["simulation"] = sim.meta
    _save(out_dir, robot, sim)
    _atomic_write_text(out_dir / "metrics.json", json.dumps(metrics, indent=2, sort_keys=True))
    if cfg.progress:
        _print_summary(metrics, out_dir)
    return metrics


def _save(out_dir: Path, robot, sim) -> None:
    robot.save_npz(
        out_dir / "robot_trajectory.npz",
        extra={
            "object_pos_sim": sim.object_pos_sim,
            "object_rot_sim": sim.object_rot_sim,
            "object_pos_err": sim.object_pos_err,
            "object_rot_err": sim.object_rot_err,
            "finger_force_world": sim.finger_force_world,
            "force_parts": np.array([*sim.fingers, "palm"]),
        },
    )


class _Progress:
    """rich progress bars (or nothing when ``enabled`` is False)."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self._p = None

    def __enter__(self):
        if self.enabled:
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

            self._p = Progress(
                "[progress.description]{task.description}",
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                transient=False,
            )
            self._p.__enter__()
        return self

    def __exit__(self, *exc):
        if self._p is not None:
            self._p.__exit__(*exc)
        return False

    def task(self, name: str, total: int):
        if self._p is None:
            return None
        tid = self._p.add_task(name, total=total)
        return lambda done, _total: self._p.update(tid, completed=done)


def _print_summary(m: dict, out_dir: Path) -> None:
    from rich.console import Console
    from rich.table import Table

    ok = "[green]SUCCESS[/green]" if m["success"] else "[red]FAILED[/red]"
    t = Table(title=f"{m['hand']} · {m['pair']} · {ok}", show_header=False)
    t.add_row(
        "object error max / mean",
        f"{100 * m['object_pos_err_max_m']:.1f} / "
        f"{100 * m['object_pos_err_mean_m']:.1f} cm  (success: every frame ≤ 5 cm)",
    )
    t.add_row("object rotation error mean", f"{np.degrees(m['object_rot_err_mean_rad']):.1f}°")
    t.add_row("loose rule (mean < 10 cm, < 0.5 rad)", "yes" if m["success_loose"] else "no")
    t.add_row("keypoint error mean", f"{1000 * m['keypoint_err_mean_m']:.1f} mm")
    if m["contact_err_mean_m"] is not None:
        t.add_row(
            "contact error mean",
            f"{1000 * m['contact_err_mean_m']:.1f} mm ({m['contact_frames']} contact frames)",
        )
    t.add_row(
        "penetration max (kinematic / sim)",
        f"{1000 * m['penetration_max_m']:.1f} / {1000 * m['sim_penetration_max_m']:.1f} mm",
    )
    forces = ", ".join(f"{k} {v:.2f}" for k, v in m["finger_force_mean_n"].items())
    t.add_row("mean contact force [N]", forces)
    t.add_row("speed", f"{m['ms_per_frame']:.2f} ms/frame ({m['backend']})")
    t.add_row("written", f"{out_dir}/robot_trajectory.npz, metrics.json")
    Console().print(t)
