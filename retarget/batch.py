"""``retarget batch``: a dataset (or its filter) × hands × one method, into one Lance dataset of
robot trajectories (:mod:`retarget.robot_dataset`).

One job is one demonstration × one hand, run through the in-memory API
(:func:`retarget.api.retarget_with`) in a worker: a local process pool (spawn start method,
one process per core by default) or Ray tasks (``ray_address``). A job that fails (an unknown
object, a pair the hand cannot perform, an exception) gives a ``failed`` row with its reason; the
batch goes on. The driver alone writes: finished rows are committed in chunks (one atomic Lance
commit each, :func:`retarget.robot_dataset.upsert_rows`); on a rerun the keys already present
are skipped (failed ones too, unless ``retry_failed``), so a batch killed at any point and run
again ends with the same rows, none lost or duplicated.
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import time
import traceback
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dexcanvas_core.builtin import default_dataset_path
from dexcanvas_core.capture import use_dataset_objects
from dexcanvas_core.checks import check_bool, check_int, check_str
from dexcanvas_core.errors import DexCanvasError
from dexcanvas_core.io import open_dataset
from dexcanvas_core.loaders.selection import load_row, select_rows
from dexcanvas_core.parallel import map_unordered
from dexcanvas_core.safe_io import check_output, output_lock
from retarget.api import retarget_with, run_config
from retarget.batch_report import job_progress, print_summary
from retarget.errors import RetargetError
from retarget.hands import get_hand
from retarget.robot_dataset import (
    check_robot_dataset,
    create_empty,
    method_key,
    read_keys,
    read_robot_rows,
    upsert_rows,
)

log = logging.getLogger(__name__)

COMMIT_SECONDS = 60.0
"""Finished rows wait at most this long [s] before the driver commits them."""


@dataclass(frozen=True)
class BatchConfig:
    """``retarget batch``: which demonstrations, which hands, which method, where, on what.

    >>> cfg = BatchConfig(hands=("shadow", "allegro"), out=Path("B.lance"), limit=4)
    >>> cfg.dataset is None, cfg.ray_address is None, cfg.commit_every
    (True, True, 8)
    """

    hands: tuple[str, ...]
    """Registered hand names (``retarget hands``)."""
    out: Path
    """The robot trajectory dataset (``*.lance``); resumed when it exists."""
    dataset: Path | None = None
    """DexCanvas-layout Lance dataset; ``None``: the whole built-in set."""
    types: tuple[str, ...] = ()
    """Only these manipulation types (names or gesture codes); empty: all."""
    objects: tuple[str, ...] = ()
    """Only these objects; empty: all."""
    operators: tuple[str, ...] = ()
    """Only these operators; empty: all."""
    rows: tuple[int, ...] = ()
    """Only these 0-based row positions (with the filters: those of them that match)."""
    limit: int | None = None
    """At most this many demonstrations (the first, in dataset order)."""
    max_frames: int | None = None
    """Crop each demonstration to its first this many frames (``None``: whole)."""
    forces: bool = False
    """Force matching (``retarget run --forces``)."""
    refine: bool = False
    """Physics refinement of runs that lose the object (``retarget run --refine``)."""
    overrides: dict = field(default_factory=dict)
    """``RetargetConfig`` fields (``--set NAME=VALUE``)."""
    workers: int | None = None
    """Local processes (default ``os.cpu_count()``); with Ray, the CPUs of ``local``."""
    ray_address: str | None = None
    """``None``: the local process pool; ``auto``, ``HOST:PORT``: that Ray cluster; ``local``:
    a private local Ray (bound to 127.0.0.1, no dashboard)."""
    retry_failed: bool = False
    """Run the jobs whose rows say ``failed`` again (their rows are replaced)."""
    overwrite: bool = False
    """Replace ``out`` instead of resuming it."""
    commit_every: int = 8
    """Commit finished rows in chunks of this many (or after ``COMMIT_SECONDS``)."""
    progress: bool = True
    """Progress bar, summary table and failures list on the terminal."""

    def __post_init__(self) -> None:
        err = RetargetError
        if not self.hands:
            raise RetargetError("no hand given: --hands NAME[,NAME...] (retarget hands)")
        for name in self.hands:
            check_str("hands", name, error=err)
        if len(set(self.hands)) != len(self.hands):
            raise RetargetError(f"--hands names a hand twice: {','.join(self.hands)}")
        if self.limit is not None:
            check_int("limit", self.limit, min=1, error=err)
        if self.max_frames is not None:
            check_int("max_frames", self.max_frames, min=2, error=err)
        if self.workers is not None:
            check_int("workers", self.workers, min=1, error=err)
        check_int("commit_every", self.commit_every, min=1, error=err)
        for name in ("forces", "refine", "retry_failed", "overwrite", "progress"):
            check_bool(name, getattr(self, name), error=err)
        for r in self.rows:
            check_int("rows", r, min=0, error=err)


@dataclass(frozen=True)
class Job:
    """One demonstration × one hand: everything a worker needs (picklable)."""

    dataset: Path
    dataset_given: bool
    source_row: int
    uuid: str
    pair: str
    hand: str
    method: str
    forces: bool
    refine: bool
    overrides: dict
    max_frames: int | None

    @property
    def key(self) -> tuple[str, str, str]:
        return (self.uuid, self.hand, self.method)


@functools.cache
def model_hash(hand: str) -> str:
    """SHA-256 of the hand's compiled MuJoCo model (``mj_saveModel``): the model identity."""
    import mujoco  # heavy; only in workers

    model = get_hand(hand).compile()
    buf = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buf)
    return hashlib.sha256(buf.tobytes()).hexdigest()


def run_job(job: Job) -> dict:
    """Run one job in this process: its row (:mod:`retarget.robot_dataset` columns); every
    failure becomes a ``failed`` row with its reason."""
    t0 = time.perf_counter()
    row = {
        "uuid": job.uuid,
        "source_row": job.source_row,
        "pair": job.pair,
        "hand": job.hand,
        "method": job.method,
        "dataset": str(job.dataset) if job.dataset_given else "built-in",
    }
    try:
        hand = get_hand(job.hand)
        row["model_source"] = hand.source.location
        traj = load_row(job.dataset, job.source_row)
        if job.max_frames is not None and traj.num_frames > job.max_frames:
            traj = traj.slice(0, job.max_frames)
        cfg = run_config(
            job.hand,
            job.forces,
            job.refine,
            job.dataset if job.dataset_given else None,
            **job.overrides,
        )
        out = retarget_with(traj, cfg, hand=hand)
        row.update(result_columns(out), model_hash=model_hash(job.hand))
    except (RetargetError, DexCanvasError) as e:
        row.update(status="failed", reason=str(e))
    except Exception as e:  # a job's failure is its row's, the batch goes on
        log.debug("job %s failed:\n%s", job.key, traceback.format_exc())
        row.update(status="failed", reason=f"{type(e).__name__}: {e}")
    row["elapsed_s"] = time.perf_counter() - t0
    return row


def result_columns(out) -> dict:
    """The data columns of a :class:`~retarget.api.Retargeted`."""
    robot, sim, refined = out.robot, out.sim, out.result.refined
    return {
        "status": "ok",
        "reason": None,
        "pair": str(out.result.subject),
        "joint_names": list(robot.joint_names),
        "tip_sites": list(robot.tip_sites),
        "force_parts": [*sim.fingers, "palm"],
        "fps": float(out.result.trajectory.fps),
        "frames": int(robot.num_frames),
        "timestamp": robot.timestamp,
        "q": robot.q,
        "q_command": robot.q_command,
        "q_sim": sim.q_sim,
        "ctrl_refined": None if refined is None else refined.ctrl,
        "object_pos_sim": sim.object_pos_sim,
        "object_rot_sim": sim.object_rot_sim,
        "object_pos_err": sim.object_pos_err,
        "object_rot_err": sim.object_rot_err,
        "tip_pos_world": robot.tip_pos_world,
        "finger_force_world": sim.finger_force_world,
        "keypoint_err": robot.keypoint_err,
        "success": bool(sim.success),
        "success_refined": out.metrics.get("success_refined"),
        "metrics": json.dumps(out.metrics, sort_keys=True),
        "config": json.dumps(out.metrics["retarget_config"], sort_keys=True),
    }


def plan_jobs(cfg: BatchConfig) -> list[Job]:
    """The batch's jobs in order (demonstration-major, hands in the given order); raises a
    ``RetargetError`` for a bad filter, hand or setting (before any work)."""
    for hand in cfg.hands:
        get_hand(hand)
    method = method_key(cfg.forces, cfg.refine, dict(cfg.overrides), cfg.max_frames)
    run_config(cfg.hands[0], cfg.forces, cfg.refine, **dict(cfg.overrides))  # bad --set now
    try:
        path = Path(cfg.dataset) if cfg.dataset is not None else default_dataset_path()
        use_dataset_objects(path)
        ds = open_dataset(path)
        sel = select_rows(
            ds,
            manipulation_types=list(cfg.types) or None,
            objects=list(cfg.objects) or None,
            operators=list(cfg.operators) or None,
        )
        meta = ds.scan_metadata()
    except DexCanvasError as e:
        raise RetargetError(str(e)) from e
    scene = [s["scene"] for s in meta.column("index").to_pylist()]
    gesture = [m["gesture"] for m in meta.column("trajectory_metadata").to_pylist()]
    picked = list(zip(sel.positions.tolist(), sel.uuids, strict=True))
    if cfg.rows:
        bad = [r for r in cfg.rows if r >= len(scene)]
        if bad:
            raise RetargetError(f"--rows {bad}: the dataset has {len(scene)} rows")
        wanted = set(cfg.rows)
        picked = [(p, u) for p, u in picked if p in wanted]
        if not picked:
            raise RetargetError(f"--rows {sorted(wanted)}: none matches the filters")
    picked = picked[: cfg.limit]
    uuids = [u for _, u in picked]
    if len(set(uuids)) != len(uuids):
        raise RetargetError("the selected rows repeat a uuid; rows are keyed by uuid")
    return [
        Job(
            path,
            cfg.dataset is not None,
            p,
            u,
            f"{scene[p]}/{gesture[p]}",
            hand,
            method,
            cfg.forces,
            cfg.refine,
            dict(cfg.overrides),
            cfg.max_frames,
        )
        for p, u in picked
        for hand in cfg.hands
    ]


def run_batch(cfg: BatchConfig) -> dict:
    """Run the batch ``cfg`` (module docstring); return its summary (:func:`summarize`).

    Raises:
        RetargetError: a bad option, filter, hand or setting, or an ``out`` that is not a robot
            trajectory dataset (all before any work).
        dexcanvas_core.safe_io.OutputError: ``out`` cannot be written, or another batch holds it.

    >>> import tempfile
    >>> out = Path(tempfile.mkdtemp()) / "B.lance"
    >>> cfg = BatchConfig(hands=("panda",), out=out, rows=(0,), max_frames=30, workers=1,
    ...                   progress=False)
    >>> s = run_batch(cfg)
    >>> s["jobs"], s["ran"], s["failed"], s["hands"]["panda"]["ok"]
    (1, 1, 0, 1)
    >>> run_batch(cfg)["skipped"]  # resumed: the finished job is not run again
    1
    """
    out = check_output(cfg.out, overwrite=True, kind="dir", what="--out")
    if out.exists() and not cfg.overwrite:
        check_robot_dataset(out)
    jobs = plan_jobs(cfg)
    with output_lock(out):
        if cfg.overwrite or not out.exists():
            create_empty(out)
        present = read_keys(out)
        todo = [
            j
            for j in jobs
            if j.key not in present or (cfg.retry_failed and present[j.key] == "failed")
        ]
        t0 = time.perf_counter()
        with job_progress(cfg.progress, len(todo)) as advance:
            _drive(cfg, out, todo, advance)
    summary = summarize(out, jobs, len(todo), time.perf_counter() - t0)
    if cfg.progress:
        print_summary(summary, out)
    return summary


def _drive(cfg: BatchConfig, out: Path, todo: list, advance) -> None:
    """Run ``todo`` on the chosen executor, committing finished rows in chunks; rows finished
    before an interruption are committed before it propagates."""
    pending: list[dict] = []
    last = time.monotonic()
    try:
        for row in execute(todo, cfg.workers, cfg.ray_address):
            pending.append(row)
            advance(row)
            if len(pending) >= cfg.commit_every or time.monotonic() - last > COMMIT_SECONDS:
                upsert_rows(out, pending)
                pending, last = [], time.monotonic()
    finally:
        upsert_rows(out, pending)


def execute(jobs: list[Job], workers: int | None, ray_address: str | None) -> Iterator[dict]:
    """The rows of ``jobs`` in the order they finish, on a local spawn process pool or Ray
    (:func:`dexcanvas_core.parallel.map_unordered`); a job whose worker died gives a failed row."""
    for job, row, error in map_unordered(run_job, jobs, workers=workers, ray_address=ray_address):
        if error is None:
            yield row
        else:
            yield {
                "uuid": job.uuid,
                "source_row": job.source_row,
                "pair": job.pair,
                "hand": job.hand,
                "method": job.method,
                "status": "failed",
                "reason": f"worker lost: {type(error).__name__}: {error}",
            }


def summarize(out: Path, jobs: list[Job], ran: int, seconds: float) -> dict:
    """The batch's outcome over all its jobs (this run's and earlier ones'): per hand jobs, ok,
    failed, success rate, mean keypoint error [m], CPU time [s]; the failures with reasons."""
    keys = {j.key for j in jobs}
    rows = [
        r
        for r in read_robot_rows(
            out,
            columns=[
                "uuid",
                "hand",
                "method",
                "pair",
                "status",
                "reason",
                "success",
                "metrics",
                "elapsed_s",
            ],
        )
        if (r["uuid"], r["hand"], json.dumps(r["method"], sort_keys=True)) in keys
    ]
    hands = {}
    for hand in dict.fromkeys(j.hand for j in jobs):
        mine = [r for r in rows if r["hand"] == hand]
        ok = [r for r in mine if r["status"] == "ok"]
        kp = [r["metrics"]["keypoint_err_mean_m"] for r in ok]
        hands[hand] = {
            "jobs": sum(j.hand == hand for j in jobs),
            "ok": len(ok),
            "failed": sum(r["status"] == "failed" for r in mine),
            "success_rate": float(np.mean([r["success"] for r in ok])) if ok else None,
            "keypoint_err_mean_m": float(np.mean(kp)) if kp else None,
            "cpu_s": float(sum(r["elapsed_s"] or 0.0 for r in mine)),
        }
    failures = [
        {"uuid": r["uuid"], "pair": r["pair"], "hand": r["hand"], "reason": r["reason"]}
        for r in rows
        if r["status"] == "failed"
    ]
    return {
        "out": str(out),
        "jobs": len(jobs),
        "ran": ran,
        "skipped": len(jobs) - ran,
        "rows": len(rows),
        "failed": len(failures),
        "seconds": seconds,
        "hands": hands,
        "failures": failures,
    }
