"""Helpers shared by the benchmarks: the demonstration suites, re-simulation, worker processes,
table cells, and the committed results (``benchmarks/results/<name>/<date>-<commit>.json``:
where a run writes, which file is the newest, the commit, machine and command it records).

Two suites of the built-in generator (``dexcanvas_core.demos``):

* by manipulation type (``benchmarks.force_pipeline``, ``mocap_fit``): ``pick_pairs``
  takes feasible (object, manipulation type) pairs round-robin over the 21 types (shuffled within
  a type by the seed), ``generate_one`` generates the demonstration of the ``i``-th pair with
  operator ``i mod 5`` and seed ``seed + i`` (retrying an infeasible seed), so every benchmark
  that uses them sees the same demonstrations for the same ``--seed``;
* by group (``retarget_speed_quality``, ``force_preservation``): ``load_demonstrations``
  takes pairs in ``select_pairs`` order (spread evenly over power, intermediate, precision and
  in-hand), one operator and seed, each demonstration cropped by ``Trajectory.crop``.

``resim`` re-simulates a robot joint trajectory (``retarget.validate.Resimulator``) and adds the
hand-below-the-table diagnostic (``table_penetration``).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import multiprocessing
import os
import platform
import subprocess
import sys
import traceback
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from datetime import datetime, timezone
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

from dexcanvas_core.demos.feasibility import spread_pairs as select_pairs  # the suite's order
from dexcanvas_core.safe_io import atomic_write_text
from retarget.overrides import parse_override  # noqa: F401 (the benchmarks' --set type)

GENERATION_ATTEMPTS = 3
"""Seeds tried per pair (``seed + i + 1000·attempt``) before a pair is given up."""


def pick_pairs(n: int, seed: int) -> list:
    """``n`` feasible pairs, round-robin over the manipulation types (shuffled within a type)."""
    from dexcanvas_core.demos import feasible_pairs

    rng = np.random.default_rng(seed)
    by_type: dict[str, list] = {}
    for p in feasible_pairs():
        by_type.setdefault(p.manipulation_type.name, []).append(p)
    for v in by_type.values():
        rng.shuffle(v)
    types = sorted(by_type)
    out = []
    k = 0
    while len(out) < n:
        t = types[k % len(types)]
        out.append(by_type[t][(k // len(types)) % len(by_type[t])])
        k += 1
    return out


def operator_for(i: int) -> str:
    """The operator of the ``i``-th demonstration of a suite (cycled over the five)."""
    from dexcanvas_core.demos import OPERATORS

    ops = sorted(OPERATORS)
    return ops[i % len(ops)]


def generate_one(pair, i: int, seed: int) -> tuple:
    """``(demo, seed_used)``: the ``i``-th demonstration of a suite (module docstring).

    Raises the last generation error when every attempt failed.
    """
    from dexcanvas_core.demos import generate_demo

    for attempt in range(GENERATION_ATTEMPTS):
        s = seed + i + 1000 * attempt
        try:
            return generate_demo(pair, operator_for(i), s), s
        except Exception as e:  # a rare infeasible seed: try another
            if attempt == GENERATION_ATTEMPTS - 1:
                raise
            logging.warning("demo %s failed (%s); retrying with another seed", pair, e)
    raise AssertionError("unreachable")


def generate(n: int, seed: int) -> list:
    """The trajectories of the first ``n`` pairs (a pair whose every attempt fails is skipped)."""
    trajs = []
    for i, pair in enumerate(pick_pairs(n, seed)):
        try:
            demo, _ = generate_one(pair, i, seed)
        except Exception as e:
            logging.warning("demo %s skipped (%s)", pair, e)
            continue
        trajs.append(demo.trajectory if hasattr(demo, "trajectory") else demo)
    return trajs


def json_default(o):
    """JSON for numpy scalars and arrays and paths (``json.dumps(default=...)``)."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def atomic_write_json(path: Path, obj, indent: int = 2) -> None:
    """Write ``obj`` as indented JSON (:func:`json_default` for numpy values and paths),
    atomically (:func:`dexcanvas_core.safe_io.atomic_write_text`)."""
    atomic_write_text(path, json.dumps(obj, indent=indent, default=json_default))


# ------------------------------------------------------------------------ committed results
ROOT = Path(__file__).resolve().parent.parent
"""The repository's root."""
RESULTS = ROOT / "benchmarks" / "results"
"""The committed results: ``<name>/<date>-<commit>.json``, one file per run of a benchmark."""
PAGES = ROOT / "docs" / "benchmarks"
"""The benchmark pages, generated from the newest result of each benchmark."""


def result_path(name: str, commit: str | None, results: Path = RESULTS) -> Path:
    """Where a run of benchmark ``name`` at ``commit`` (:func:`git_commit`) writes its JSON by
    default: ``results/<name>/<date>-<commit>.json``, the date today's in UTC (ISO format)."""
    day = datetime.now(timezone.utc).date().isoformat()
    return Path(results) / name / f"{day}-{commit or 'unknown'}.json"


def _commit_time(commit: str) -> int:
    """The commit time [s since the epoch] of ``commit`` in this checkout (0 if unknown)."""
    try:
        out = subprocess.run(
            ["git", "-C", str(ROOT), "show", "-s", "--format=%ct", commit],
            capture_output=True, text=True, check=True,
        ).stdout.strip()  # fmt: skip
        return int(out)
    except (OSError, ValueError, subprocess.CalledProcessError):
        return 0


def newest_result(name: str, results: Path = RESULTS) -> Path | None:
    """The newest JSON of benchmark ``name`` in ``results/<name>/`` (``None`` if there is
    none): the latest date in the file names, then the latest commit time of the commit they
    name (``<date>-<commit>[+dirty].json``), then the latest modification time."""
    files = sorted(Path(results, name).glob("*.json"))
    if not files:
        return None

    def key(p: Path) -> tuple:
        day, commit = p.stem[:10], p.stem[11:].split("+")[0]
        return day, _commit_time(commit), p.stat().st_mtime

    return max(files, key=key)


def display_path(path: Path) -> str:
    """``path`` relative to the repository root where it lies inside it (as pages show it),
    else as given."""
    try:
        return Path(path).resolve().relative_to(ROOT).as_posix()
    except ValueError:
        return str(path)


def command_line(module: str, argv: list[str] | None = None) -> str:
    """The command that ran a benchmark: ``python -m <module>`` and its arguments (``argv``;
    default: this process's)."""
    return " ".join([f"python -m {module}", *(sys.argv[1:] if argv is None else argv)])


def config_overrides(pairs, config_cls, option: str = "--set") -> dict:
    """``option`` (``--set``) pairs ``[(name, value)]`` as keyword arguments of the dataclass
    ``config_cls``: an unknown name, or values its ``validate()`` refuses, exit with the
    message before any run (``retarget.overrides.build_config``)."""
    from retarget.errors import RetargetError
    from retarget.overrides import build_config

    out = dict(pairs or ())
    try:
        build_config(config_cls, out, option)
    except RetargetError as e:
        raise SystemExit(str(e)) from None
    return out


# ------------------------------------------------------------------ the group-spread suite
def load_demonstrations(cfg, console) -> tuple[list, str, list[dict]]:
    """``[(pair, trajectory)]``, the demonstrations' source, and the pairs that failed.

    ``cfg``: any object with ``n_pairs``, ``operator``, ``seed`` and ``max_frames`` (the
    benchmarks' ``BenchConfig``s). ``n_pairs`` generated demonstrations of the pairs in
    :func:`select_pairs` order, an equal quota per group, each cropped by ``Trajectory.crop``.
    """
    from dexcanvas_core.taxonomy import GROUPS

    try:
        from dexcanvas_core.demos import feasible_pairs, generate_demo
    except ImportError as e:
        console.print(
            f"[yellow]note:[/yellow] dexcanvas_core.demos has no generate_demo/feasible_pairs "
            f"yet ({e}); falling back to dexcanvas_core.example (6 pick-and-place pairs, no "
            "in-hand group)"
        )
        from dexcanvas_core.example import example_trajectories
        from dexcanvas_core.taxonomy import Pair

        seen, out = set(), []
        for traj in example_trajectories(seed=cfg.seed):
            if traj.operator != cfg.operator or traj.scene in seen:
                continue
            seen.add(traj.scene)
            out.append((Pair.of(traj.scene, traj.gesture), traj.crop(cfg.max_frames)))
        return out[: cfg.n_pairs], "dexcanvas_core.example.example_trajectories", []

    candidates = select_pairs(feasible_pairs())
    quota = {g: cfg.n_pairs // len(GROUPS) + (1 if i < cfg.n_pairs % len(GROUPS) else 0)
             for i, g in enumerate(GROUPS)}  # fmt: skip
    out, failed = [], []
    with progress_bar(console) as prog:
        task = prog.add_task("generating demonstrations", total=cfg.n_pairs)
        for p in candidates:
            g = p.manipulation_type.group
            if quota[g] == 0:
                continue
            try:
                demo = generate_demo(p, operator=cfg.operator, seed=cfg.seed)
            except Exception as e:  # a pair the generator cannot script: take the next one
                failed.append({"pair": str(p), "error": f"{type(e).__name__}: {e}"})
                continue
            quota[g] -= 1
            out.append((p, demo.trajectory.crop(cfg.max_frames)))
            prog.advance(task)
            if len(out) == cfg.n_pairs:
                break
    return out, "dexcanvas_core.demos.generate_demo", failed


# -------------------------------------------------------------------------- re-simulation
def table_penetration(sim, q: np.ndarray) -> float | None:
    """Deepest penetration [m] of the hand's collision geoms into the re-simulation's table
    (z = 0 plane) along the joint trajectory ``q``, kinematically (no simulation). A diagnostic:
    the retargeting scene has no table, so a hand posed below it is pushed up in simulation."""
    import mujoco

    from retarget.scene import TABLE_GEOM

    m = sim.model
    table = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, TABLE_GEOM)
    if table < 0:
        return None
    geoms = [
        g
        for g in range(m.ngeom)
        if g != table
        and m.geom_bodyid[g] != sim.object_body
        and (m.geom_contype[g] or m.geom_conaffinity[g])
    ]
    d = mujoco.MjData(m)
    fromto = np.zeros(6)
    worst = 0.0
    for qt in q:
        d.qpos[: sim.hand_nq] = qt
        mujoco.mj_kinematics(m, d)
        for g in geoms:
            worst = max(worst, -mujoco.mj_geomDistance(m, d, g, table, 0.05, fromto))
    return worst


def resim(sim, q, traj) -> dict:
    """Re-simulate ``q`` with ``sim`` (a ``Resimulator``): its metrics, the kinematic table
    penetration, and a failed rollout (``success`` False, ``sim_error``) if it diverged."""
    return resim_result(sim, q, traj)[0]


def resim_result(sim, q, traj) -> tuple[dict, object]:
    """:func:`resim`'s metrics and the ``ValidationResult`` itself (``None`` if it diverged)."""
    from retarget.errors import RetargetError

    out = {"table_penetration_max_m": table_penetration(sim, q)}
    try:
        res = sim.run(q, traj)
    except RetargetError as e:  # a diverged simulation is a failed rollout
        return {**out, "success": False, "success_loose": False, "sim_error": str(e)}, None
    return {**out, **sim_metrics(res)}, res


def sim_metrics(res) -> dict:
    """A ``ValidationResult``'s metrics for a row: its penetration is the simulated one
    (``sim_penetration_max_m``; the row's ``penetration_max_m`` is the kinematic one)."""
    m = res.metrics()
    m["sim_penetration_max_m"] = m.pop("penetration_max_m")
    return m


# ----------------------------------------------------------------------- terminal, records
def progress_bar(console):
    """A rich progress bar: description, bar, done/total, elapsed time."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    return Progress(
        "[progress.description]{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
    )


def machine_info(load_start, **extra) -> dict:
    """What a result's ``machine`` records: platform, Python, CPU count, the load average at the
    start (``load_start``, ``os.getloadavg()`` then) and now, and ``extra`` (e.g. workers)."""
    return {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpu_count": os.cpu_count(),
        "loadavg_start": load_start,
        "loadavg_end": os.getloadavg(),
        **extra,
    }


def git_commit() -> str | None:
    """The checkout's commit (``git rev-parse --short HEAD``, ``+dirty`` with uncommitted
    changes to tracked files), or ``None`` outside a git checkout."""
    try:
        head = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
            capture_output=True, text=True, check=True,
        ).stdout.strip()  # fmt: skip
        dirty = subprocess.run(
            ["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True, text=True, check=True,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        return None
    return head + ("+dirty" if dirty else "")


def versions(dists) -> dict:
    """Installed version of each distribution in ``dists`` (``None`` when absent)."""
    out = {}
    for dist in dists:
        try:
            out[dist] = version(dist)
        except PackageNotFoundError:
            out[dist] = None
    return out


# ----------------------------------------------------------------------------- table cells
DASH = "–"
"""A missing value's cell."""


def num(x, scale: float = 1.0, fmt: str = ".2f") -> str:
    """``scale · x`` formatted with ``fmt``, or :data:`DASH` for ``None``."""
    return DASH if x is None else format(scale * x, fmt)


def mm(x, fmt: str = ".1f") -> str:
    """A length [m] in mm (no unit), or :data:`DASH`."""
    return num(x, 1e3, fmt)


def cm(x, fmt: str = ".1f") -> str:
    """A length [m] in cm (no unit), or :data:`DASH`."""
    return num(x, 1e2, fmt)


def pct(x, fmt: str = ".0f", unit: str = " %") -> str:
    """A share in per cent followed by ``unit``, or :data:`DASH`."""
    return DASH if x is None else f"{format(100 * x, fmt)}{unit}"


def coloured(text: str, met: bool | None) -> str:
    """``text`` in rich markup: green where a target is ``met``, red where not, plain for
    ``None``."""
    if met is None:
        return text
    return f"[green]{text}[/green]" if met else f"[red]{text}[/red]"


# ---------------------------------------------------------------------------------- workers
THREAD_ENV = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
"""The BLAS/OpenMP thread-count variables set to 1 for the worker processes."""


def init_worker() -> None:
    """One thread per worker: the BLAS/OpenMP variables are set by the parent before the
    spawn (they must be in place when numpy loads, :func:`one_thread_env`), torch's pools
    here."""
    logging.basicConfig(level=logging.ERROR)
    try:
        import torch  # heavy: only the worker processes need it here
    except ImportError:  # pragma: no cover - torch is a dependency of the mocap fit
        return
    torch.set_num_threads(1)
    torch.set_num_interop_threads(1)


@contextmanager
def one_thread_env():
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


@contextmanager
def worker_pool(workers: int):
    """A pool of ``workers`` spawned processes of one thread each (:func:`one_thread_env`,
    :func:`init_worker`); shut down (waiting for its jobs) on exit."""
    ctx = multiprocessing.get_context("spawn")
    with (
        one_thread_env(),
        ProcessPoolExecutor(workers, mp_context=ctx, initializer=init_worker) as pool,
    ):
        yield pool


def resolve_out(cfg, name: str):
    """``cfg`` (a frozen config with an ``out`` field) with ``out`` set: its own, or where a run
    of benchmark ``name`` at this checkout's commit writes by default (:func:`result_path`)."""
    if cfg.out is not None:
        return cfg
    return dataclasses.replace(cfg, out=result_path(name, git_commit()))


def error_record(e: BaseException) -> dict:
    """A failed job's row fields: the error and a short traceback."""
    return {"error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc(limit=4)}


def is_five_finger(hand) -> bool:
    """Five distinct robot fingers (Shadow, SVH, Ability, Inspire)."""
    return len(set(hand.robot_fingers)) == 5
