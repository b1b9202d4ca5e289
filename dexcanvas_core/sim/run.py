"""``dexcanvas simulate`` and ``dexcanvas synthesize``: the force pipeline from the shell.

``run_simulate`` tracks one demonstration (built-in by default) and writes a Lance dataset
holding the annotated row (contacts, per-finger forces through the contact records, the object
wrench, solver settings), a ``metrics.json`` and a per-finger force plot next to it.

``run_synthesize`` expands a dataset: ``expand`` perturbed rollouts per source row, keeping the
successful ones. Work is checkpointed per source row in ``<out>.work/`` (one small dataset per
row, written atomically) so an interrupted run resumes where it stopped; the final dataset is
assembled atomically at the end.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dexcanvas_core.errors import DatasetError, MissingDependencyError, UnknownNameError
from dexcanvas_core.io import open_dataset, write_dataset
from dexcanvas_core.loaders.selection import load_demonstration, load_row, subject_of
from dexcanvas_core.parallel import map_unordered
from dexcanvas_core.safe_io import atomic_write_text, check_output, output_lock
from dexcanvas_core.sim.mj_warnings import blew_up, describe
from dexcanvas_core.sim.pipeline import SimConfig, simulate
from dexcanvas_core.sim.plots import plot_finger_forces
from dexcanvas_core.sim.synthesis import PerturbationRanges, synthesize_one
from dexcanvas_core.taxonomy import object_spec


@dataclass(frozen=True)
class SimulateConfig:
    """One ``dexcanvas simulate``: ``pair`` (built-in or ``dataset``), or without a pair the
    ``dataset``'s row ``index`` (which names its object)."""

    pair: str | None
    out: Path
    dataset: Path | None = None
    index: int = 0
    sim: SimConfig = field(default_factory=SimConfig)
    overwrite: bool = False
    progress: bool = True
    plot: bool = True
    all_rows: bool = False
    """Track every row of ``dataset`` (the first ``limit``) instead of one; rows run as jobs
    on ``workers`` local processes or Ray (``ray_address``), checkpointed per row so an
    interrupted run resumes (:func:`run_simulate_all`)."""
    limit: int | None = None
    workers: int = 1
    ray_address: str | None = None


def run_simulate(cfg: SimulateConfig) -> dict:
    """Track one demonstration (or, with ``all_rows``, every row of the dataset), write the
    dataset, metrics and plot; return the metrics (``success``: every row kept its object)."""
    if cfg.all_rows:
        return run_simulate_all(cfg)
    out = check_output(cfg.out, overwrite=cfg.overwrite, kind="dir")
    with output_lock(out):
        return _simulate(cfg, out)


def _simulate_row(args) -> tuple[str, int, list[dict]]:
    """Worker: the force pipeline on one source row, checkpointed as ``work/<uuid>.lance``
    (when the rollout kept the object) and ``work/<uuid>.json`` (its metrics)."""
    dataset, position, sim_cfg, work = args
    traj = open_dataset(dataset).take([position])[0]
    res = simulate(traj, sim_cfg)
    metrics = {**res.metrics, "uuid": traj.uuid, "row": position, "pair": str(subject_of(traj))}
    if res.success:
        write_dataset([res.trajectory], Path(work) / f"{traj.uuid}.lance", mode="overwrite")
    atomic_write_text(
        Path(work) / f"{traj.uuid}.json", json.dumps([metrics], sort_keys=True, default=float)
    )
    return traj.uuid, int(res.success), [metrics]


def run_simulate_all(cfg: SimulateConfig) -> dict:
    """``dexcanvas simulate --dataset D --all``: the force pipeline on every row of ``D`` (the
    first ``limit``) as jobs on the pool or Ray; the rollouts that kept their object form the
    output dataset, every row's metrics go to ``OUT.report.json``; resumable like
    ``synthesize``. Returns a summary with ``success`` (every row kept its object)."""
    if cfg.dataset is None:
        raise DatasetError("--all tracks every row of a dataset: give --dataset PATH")
    if cfg.limit is not None and cfg.limit < 1:
        raise DatasetError(f"--limit must be at least 1, got {cfg.limit}; leave it out for all")
    out = check_output(cfg.out, overwrite=cfg.overwrite, kind="dir")
    with output_lock(out):
        cfg.sim.validate()
        uuids, positions = _source_rows(cfg.dataset, cfg.limit)
        settings = {"dataset": str(cfg.dataset), "sim": cfg.sim.as_dict(), "all": True}
        work = _work_dir(out, settings)
        jobs = [(str(cfg.dataset), p, cfg.sim, str(work)) for p in positions
                if not (work / f"{uuids[p]}.json").exists()]  # fmt: skip
        _run_row_jobs(_simulate_row, jobs, len(positions), "tracking rows", cfg)
        summary = _assemble(out, work, uuids, positions, cfg.overwrite, what=" rows tracked")
    summary["success"] = summary["kept"] == summary["rollouts"]
    if cfg.progress:
        print(
            f"{summary['kept']} of {summary['rollouts']} rows kept their object; wrote {out} "
            f"and {out.name}.report.json"
        )
    return summary


def _simulate(cfg: SimulateConfig, out: Path) -> dict:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    cfg.sim.validate()
    if cfg.pair is not None:
        traj = load_demonstration(cfg.pair, cfg.index, cfg.dataset)
        label = cfg.pair
    elif cfg.dataset is not None:
        traj = load_row(cfg.dataset, cfg.index)
        label = str(subject_of(traj))
    else:
        raise DatasetError("say which demonstration: --pair OBJECT/TYPE, or --dataset D --index I")
    if cfg.progress:
        with Progress(
            "[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
            TimeElapsedColumn(),
        ) as bar:  # fmt: skip
            task = bar.add_task(f"tracking {label} ({cfg.sim.tracker})", total=traj.num_frames)
            bar.advance(task)
            res = simulate(traj, cfg.sim, progress=lambda n: bar.advance(task, n))
    else:
        res = simulate(traj, cfg.sim)
    write_dataset([res.trajectory], out, mode="overwrite" if cfg.overwrite else "create")
    metrics = {**res.metrics, "pair": label, "dataset": str(cfg.dataset or "built-in")}
    atomic_write_text(
        out.with_name(out.name + ".metrics.json"),
        json.dumps(metrics, indent=2, sort_keys=True, default=float),
    )
    if cfg.plot:
        try:
            plot_finger_forces(res, out.with_name(out.name + ".forces.png"), title=label)
        except MissingDependencyError as e:  # the data is written; only the picture is missing
            print(f"note: no force plot ({e})")
    if cfg.progress:
        print_summary(metrics, out)
    return metrics


def failure_line(f: dict) -> str:
    """One line of a rollout's failure diagnosis (``dexcanvas_core.sim.diagnosis``)."""
    return (
        f"{f['reason']} at {f['time_s']:.2f} s: wrist {f['wrist_lag_mm']:.0f} mm behind, the "
        f"object moved {f['slip_mm']:.0f} mm in the hand over 0.3 s, last contact at frame "
        f"{f['last_contact_frame']}"
    )


def print_summary(m: dict, out: Path) -> None:
    from rich.console import Console
    from rich.table import Table

    ok = "[green]SUCCESS[/green]" if m["success"] else "[red]FAILED[/red]"
    t = Table(title=f"force pipeline · {m['pair']} · {ok}", show_header=False)
    tracked = f"{m['frames_tracked']}/{m['frames']}"
    if m["failed_at_frame"] is not None:
        tracked += f" (object error > 5 cm at frame {m['failed_at_frame']})"
    t.add_row("frames tracked", tracked)
    if m.get("failure"):
        t.add_row("why it failed", failure_line(m["failure"]))
    t.add_row(
        "object error max / mean",
        f"{100 * m['object_pos_err_max_m']:.2f} / {100 * m['object_pos_err_mean_m']:.2f} cm, "
        f"rotation mean {np.degrees(m['object_rot_err_mean_rad']):.1f}°",
    )
    t.add_row("loose rule (mean < 10 cm, < 0.5 rad)", "yes" if m["success_loose"] else "no")
    if m.get("mujoco_warnings"):
        style = "red" if blew_up(m["mujoco_warnings"]) else "yellow"
        t.add_row("MuJoCo warnings", f"[{style}]{describe(m['mujoco_warnings'])}[/{style}]")
    obj = f"{1000 * m['mass_kg']:.0f} g"
    if m.get("approximate_object"):
        obj += (
            " [yellow](approximate: a built-in stand-in for the real object; give its model "
            "with --objects-dir)[/yellow]"
        )
    t.add_row("object mass", obj)
    if m["hold_weight_ratio"] is not None:
        t.add_row(
            "static hold",
            f"{m['hold_frames']} frames, hand carries {100 * m['hold_weight_ratio']:.1f} % of m·g",
        )
        f = m["hold_finger_force_mean_n"]
        t.add_row("mean force in hold [N]", ", ".join(f"{k} {v:.2f}" for k, v in f.items()))
    t.add_row(
        "Newton–Euler residual (median)",
        f"sim {100 * m['newton_euler_sim_median']:.2f} %, vs capture "
        f"{100 * m['newton_euler_capture_median']:.2f} % of m·g",
    )
    t.add_row("contact frames", str(m["contact_frames"]))
    t.add_row("compute", f"{m['compute_s']:.1f} s ({m['compute_s_per_demo_s']:.2f} s per demo-s)")
    t.add_row("written", f"{out} (+ .metrics.json, .forces.png)")
    Console().print(t)


# -- synthesis -------------------------------------------------------------------------------


@dataclass(frozen=True)
class SynthesizeConfig:
    dataset: Path
    out: Path
    expand: int = 10
    seed: int = 0
    workers: int = 1
    ray_address: str | None = None
    """``None``: ``workers`` local processes; ``auto``, ``HOST:PORT``: the source rows as Ray
    tasks on that cluster; ``local``: a private local Ray
    (:func:`dexcanvas_core.parallel.map_unordered`)."""
    sim: SimConfig = field(default_factory=SimConfig)
    limit: int | None = None
    """Only the first ``limit`` source rows (for trials)."""
    ranges: PerturbationRanges = field(default_factory=PerturbationRanges)
    overwrite: bool = False
    progress: bool = True


def _synth_row(args) -> tuple[str, int, list[dict]]:
    """Worker: all rollouts of one source row, checkpointed as ``work/<uuid>.lance``."""
    dataset, position, expand, seed, sim_cfg, ranges, work = args
    traj = open_dataset(dataset).take([position])[0]
    kept, reports = [], []
    for i in range(expand):
        tr, metrics = synthesize_one(traj, i, seed, sim_cfg, ranges)
        reports.append(metrics)
        if tr is not None:
            kept.append(tr)
    part = Path(work) / f"{traj.uuid}.lance"
    if kept:
        write_dataset(kept, part, mode="overwrite")
    atomic_write_text(
        Path(work) / f"{traj.uuid}.json", json.dumps(reports, sort_keys=True, default=float)
    )
    return traj.uuid, len(kept), reports


def check_objects_known(object_ids, dataset: str) -> None:
    """Stop before any work when rows name objects that neither the catalogue nor the objects
    in use (``--objects``, ``--objects-dir``) know, naming them and how to supply them."""
    unknown = []
    for oid in sorted(object_ids):
        try:
            object_spec(oid)
        except UnknownNameError:
            unknown.append(oid)
    if unknown:
        raise DatasetError(
            f"rows name objects that are not in the catalogue: {', '.join(unknown)}; describe "
            "them in an objects manifest (TOML: [<id>] mesh = 'path.obj', mass_kg = ...) and "
            "pass it with --objects MANIFEST",
            dataset=dataset,
        )


def run_synthesize(cfg: SynthesizeConfig) -> dict:
    """Expand ``dataset`` ``expand``× (module docstring); return a summary."""
    if cfg.expand < 1:
        raise DatasetError("--expand must be at least 1")
    if cfg.limit is not None and cfg.limit < 1:
        raise DatasetError(
            f"--limit must be at least 1 (the number of source rows to expand), got {cfg.limit}; "
            "leave it out to expand every row"
        )
    out = check_output(cfg.out, overwrite=cfg.overwrite, kind="dir")
    with output_lock(out):
        return _synthesize(cfg, out)


def _source_rows(dataset, limit: int | None) -> tuple[list[str], list[int]]:
    """The source dataset's row uuids and the positions to process (the first ``limit``),
    after checking that every object they name is known."""
    src = open_dataset(dataset)
    index = src.scan_metadata().column("index").combine_chunks()
    uuids = [str(u) for u in index.field("uuid").to_pylist()]
    positions = list(range(len(uuids)))[:limit]
    scenes = index.field("scene").to_pylist()
    check_objects_known({scenes[p] for p in positions if scenes[p]}, str(dataset))
    return uuids, positions


def _work_dir(out: Path, settings: dict) -> Path:
    """``<out>.work/``, the per-row checkpoints of an interrupted run with these
    ``settings`` (another run's is refused)."""
    work = out.with_name(out.name + ".work")
    work.mkdir(parents=True, exist_ok=True)
    stamp = work / "settings.json"
    if stamp.exists() and json.loads(stamp.read_text()) != json.loads(json.dumps(settings)):
        raise DatasetError(
            f"{work} holds an interrupted run with other settings; delete it or rerun with the "
            "same settings to resume",
            dataset=str(work),
        )
    atomic_write_text(stamp, json.dumps(settings, sort_keys=True))
    return work


def _run_row_jobs(worker, jobs: list, total: int, label: str, cfg) -> None:
    """Run the per-row ``jobs`` (those not checkpointed yet, of ``total``) on Ray
    (``cfg.ray_address``), ``cfg.workers`` spawned local processes, or in this process."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    with Progress(
        "[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
        TimeElapsedColumn(), disable=not cfg.progress,
    ) as bar:  # fmt: skip
        task = bar.add_task(label, total=total, completed=total - len(jobs))
        if cfg.ray_address is not None or (cfg.workers > 1 and len(jobs) > 1):
            # spawned processes or Ray tasks: a forked copy of this process's Lance state can
            # deadlock (objects given with --objects reach them through $DEXCANVAS_OBJECTS)
            for _, _, error in map_unordered(
                worker, jobs, workers=cfg.workers, ray_address=cfg.ray_address
            ):
                if error is not None:
                    raise error
                bar.advance(task)
        else:
            for job in jobs:
                worker(job)
                bar.advance(task)


def _assemble(out: Path, work: Path, uuids, positions, overwrite: bool, what: str) -> dict:
    """Write the kept trajectories of every row's checkpoint as ``out`` and every report as
    ``out.report.json``; remove the checkpoints; return the summary."""
    kept, reports = [], []
    for p in positions:
        reports += json.loads((work / f"{uuids[p]}.json").read_text())
        part = work / f"{uuids[p]}.lance"
        if part.exists():
            kept += list(open_dataset(part).iter_trajectories())
    if not kept:
        raise DatasetError(
            f"no rollout succeeded out of {len(reports)}{what}; nothing to write (reports in "
            f"{work})",
            dataset=str(out),
        )
    write_dataset(kept, out, mode="overwrite" if overwrite else "create")
    summary = {
        "source_rows": len(positions),
        "rollouts": len(reports),
        "kept": len(kept),
        "success_rate": len(kept) / max(1, len(reports)),
        "out": str(out),
    }
    atomic_write_text(
        out.with_name(out.name + ".report.json"),
        json.dumps({"summary": summary, "rollouts": reports}, indent=1, default=float),
    )
    shutil.rmtree(work, ignore_errors=True)
    return summary


def _synthesize(cfg: SynthesizeConfig, out: Path) -> dict:
    cfg.sim.validate()
    uuids, positions = _source_rows(cfg.dataset, cfg.limit)
    settings = {"dataset": str(cfg.dataset), "expand": cfg.expand, "seed": cfg.seed,
                "sim": cfg.sim.as_dict(), "ranges": dataclasses.asdict(cfg.ranges)}  # fmt: skip
    work = _work_dir(out, settings)
    todo = [p for p in positions if not (work / f"{uuids[p]}.json").exists()]
    jobs = [
        (str(cfg.dataset), p, cfg.expand, cfg.seed, cfg.sim, cfg.ranges, str(work)) for p in todo
    ]
    _run_row_jobs(_synth_row, jobs, len(positions), f"synthesizing ×{cfg.expand}", cfg)
    summary = _assemble(out, work, uuids, positions, cfg.overwrite, what="")
    if cfg.progress:
        print(
            f"kept {summary['kept']} of {summary['rollouts']} rollouts "
            f"({100 * summary['success_rate']:.0f} %) from {len(positions)} source rows → {out}"
        )
    return summary
