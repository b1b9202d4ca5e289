"""The resumable job store, the work per job (one mode, hand and case) and the scheduler that runs
them."""

from __future__ import annotations

import json
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from benchmarks._common import (
    json_default,
    worker_pool,
)
from benchmarks.real_motion.aggregate import mano_record, retarget_record
from benchmarks.real_motion.cases import Case, slug
from benchmarks.real_motion.config import MANO, MODES
from dexcanvas_core.capture import use_dataset_objects
from dexcanvas_core.io import open_dataset
from dexcanvas_core.safe_io import atomic_write_text
from dexcanvas_core.sim.run import SimulateConfig, run_simulate
from retarget.run import RunConfig, run_retarget


# ------------------------------------------------------------------------------- job store
def job_key(mode: str, hand: str, case: str) -> str:
    return f"{mode}/{hand}/{case}"


class JobStore:
    """Finished jobs' records, one JSON file per job under ``root/jobs/``, written atomically
    (a temporary file renamed into place: an interrupted write leaves only a hidden temporary
    file, which is ignored)."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.dir = self.root / "jobs"

    def path(self, key: str) -> Path:
        return self.dir / f"{slug(key.replace('/', '+'))}.json"

    def run_dir(self, key: str) -> Path:
        return self.root / "runs" / slug(key.replace("/", "+"))

    def load(self, key: str) -> dict | None:
        try:
            rec = json.loads(self.path(key).read_text())
        except (OSError, json.JSONDecodeError):
            return None
        return rec if isinstance(rec, dict) and rec.get("key") == key else None

    def save(self, rec: dict) -> Path:
        p = self.path(rec["key"])
        atomic_write_text(p, json.dumps(rec, indent=1, default=json_default))
        return p

    def done(self, key: str, uuid: str | None = None, retry_errors: bool = False) -> dict | None:
        """The record of a finished job (of the case ``uuid`` when given), else ``None``."""
        rec = self.load(key)
        if rec is None or (uuid is not None and rec.get("uuid") != uuid):
            return None
        if retry_errors and rec.get("error"):
            return None
        return rec


# ------------------------------------------------------------------------------------- jobs
def run_job(spec: dict) -> dict:
    """Worker: one job (``spec``: ``key``, ``mode``, ``hand``, ``case``, ``work``, and for the
    force modes ``human_dataset``); its record is saved to the job store before returning.
    An exception is recorded (``error``) as a failed run."""
    case = Case.from_dict(spec["case"])
    store = JobStore(Path(spec["work"]))
    rec = {
        "key": spec["key"],
        "case": case.name,
        "hand": spec["hand"],
        "mode": spec["mode"],
        "uuid": case.uuid,
        "frames": case.frames,
    }
    t0 = time.perf_counter()
    try:
        use_dataset_objects(case.dataset)
        run_dir = store.run_dir(spec["key"])
        if spec["mode"] == MANO:
            rec.update(_run_mano(case, run_dir))
        else:
            rec.update(_run_retarget(spec, case, run_dir))
    except Exception as e:
        rec.update(
            success=False,
            strict_success=False,
            error=f"{type(e).__name__}: {e}",
            traceback=traceback.format_exc(limit=4),
        )
    rec["wall_s"] = time.perf_counter() - t0
    store.save(rec)
    return rec


def _run_mano(case: Case, run_dir: Path) -> dict:

    out = run_dir / "human.lance"
    run_dir.mkdir(parents=True, exist_ok=True)
    m = run_simulate(
        SimulateConfig(
            pair=None,
            dataset=Path(case.dataset),
            index=case.index,
            out=out,
            overwrite=True,
            plot=False,
            progress=False,
        )
    )
    traj = open_dataset(out).take([0])[0]
    return {**mano_record(m, traj, case), "human_dataset": str(out)}


def _run_retarget(spec: dict, case: Case, run_dir: Path) -> dict:

    mode = spec["mode"]
    forces = mode != "keypoints"
    dataset, index = Path(case.dataset), case.index
    human = spec.get("human_dataset")
    if forces and human and Path(human).exists():
        dataset, index = Path(human), 0  # the force pipeline's annotated row of this case
    m = run_retarget(
        RunConfig(
            hand=spec["hand"],
            dataset=dataset,
            index=index,
            forces=forces,
            refine=mode == "forces_refine",
            out=run_dir,
            overwrite=True,  # the job's own directory: a rerun replaces its earlier attempt
            progress=False,
        )
    )
    with np.load(run_dir / "robot_trajectory.npz") as z:
        arrays = {k: z[k] for k in ("object_pos_err", "wrist_pos_tracking_err")}
    return retarget_record(m, arrays, case)


def no_forces_record(spec: dict, mano: dict) -> dict:
    """A force-mode job whose case the force pipeline did not reproduce: failed, not run."""
    case = spec["case"]
    why = (
        mano.get("error")
        or f"the force pipeline lost the object at frame {mano.get('failed_at_frame')}"
    )
    return {
        "key": spec["key"],
        "case": case["name"],
        "hand": spec["hand"],
        "mode": spec["mode"],
        "uuid": case["uuid"],
        "frames": case["frames"],
        "success": False,
        "strict_success": False,
        "skipped": f"no human forces: {why}",
        "wall_s": 0.0,
    }


def plan_jobs(cases: list[Case], hands, modes, work: Path) -> tuple[list[dict], list[dict]]:
    """``(mano_jobs, hand_jobs)``: job specs for every case (the MANO job whenever ``mano`` or
    a force mode is asked), each hand × mode."""
    mano, hand_jobs = [], []
    need_mano = MANO in modes or any(m in modes for m in ("forces", "forces_refine"))
    for c in cases:
        d = c.as_dict()
        if need_mano:
            mano.append(
                {
                    "key": job_key(MANO, MANO, c.name),
                    "mode": MANO,
                    "hand": MANO,
                    "case": d,
                    "work": str(work),
                }
            )
        for h in hands:
            for mode in MODES:
                if mode in modes:
                    hand_jobs.append(
                        {
                            "key": job_key(mode, h, c.name),
                            "mode": mode,
                            "hand": h,
                            "case": d,
                            "work": str(work),
                        }
                    )
    return mano, hand_jobs


@dataclass
class Scheduler:
    """Runs the jobs not finished yet (the force modes once their case's MANO job is), on a
    process pool; collects every record."""

    store: JobStore
    retry_errors: bool = False
    records: dict = field(default_factory=dict)
    broken: bool = False
    """A worker process died (the pool is unusable): nothing more is submitted."""

    def finished(self, spec: dict) -> dict | None:
        rec = self.store.done(spec["key"], spec["case"]["uuid"], self.retry_errors)
        if rec is not None:
            self.records[spec["key"]] = rec
        return rec

    def ready(self, spec: dict) -> dict | None:
        """A hand job's spec completed with its human forces, a record when it cannot run, or
        the spec unchanged when it needs no MANO job."""
        if spec["mode"] == "keypoints":
            return spec
        mano = self.records.get(job_key(MANO, MANO, spec["case"]["name"]))
        if mano is None:
            return None
        if not mano.get("success"):
            rec = no_forces_record(spec, mano)
            self.store.save(rec)
            self.records[spec["key"]] = rec
            return rec
        return {**spec, "human_dataset": mano.get("human_dataset")}

    def run(self, mano_jobs, hand_jobs, workers: int, console) -> None:
        todo_mano = [s for s in mano_jobs if self.finished(s) is None]
        todo_hand = [s for s in hand_jobs if self.finished(s) is None]
        total = len(mano_jobs) + len(hand_jobs)
        done0 = total - len(todo_mano) - len(todo_hand)
        console.print(
            f"{total} jobs: {done0} finished before (in {self.store.dir}), "
            f"{len(todo_mano) + len(todo_hand)} to run on {workers} worker(s)"
        )
        if not todo_mano and not todo_hand:
            return
        with worker_pool(workers) as pool:
            with (
                Progress(
                    "[progress.description]{task.description}",
                    BarColumn(),
                    MofNCompleteColumn(),
                    TimeElapsedColumn(),
                    "eta",
                    TimeRemainingColumn(),
                    console=console,
                ) as prog,
            ):
                task = prog.add_task("jobs", total=total, completed=done0)
                pending: dict = {}

                def submit(spec: dict) -> None:
                    if not self.broken:
                        try:
                            pending[pool.submit(run_job, spec)] = spec
                        except BrokenProcessPool:
                            self.broken = True

                def release(specs: list[dict]) -> list[dict]:
                    """Submit the hand jobs that can run; the rest still wait."""
                    still = []
                    for s in specs:
                        r = self.ready(s)
                        if r is None:
                            still.append(s)
                        elif "strict_success" in r:  # recorded without running
                            prog.advance(task)
                        else:
                            submit(r)
                    return still

                for s in todo_mano:
                    submit(s)
                waiting = release(todo_hand)
                while pending:
                    done, _ = wait(pending, return_when=FIRST_COMPLETED)
                    for fut in done:
                        rec = self._result(fut, pending.pop(fut), console)
                        prog.advance(task)
                        prog.update(task, description=escape(_describe(rec)))
                    waiting = release(waiting)
            if self.broken:
                console.print(
                    "[red]a worker process died: the jobs it had and those after it did not "
                    "run; rerun the same command to resume[/red]"
                )

    def _result(self, fut, spec: dict, console) -> dict:
        try:
            rec = fut.result()
        except Exception as e:  # the worker process died: not stored, a rerun retries it
            self.broken = self.broken or isinstance(e, BrokenProcessPool)
            rec = {
                "key": spec["key"],
                "case": spec["case"]["name"],
                "hand": spec["hand"],
                "mode": spec["mode"],
                "uuid": spec["case"]["uuid"],
                "success": False,
                "strict_success": False,
                "error": f"worker died: {type(e).__name__}: {e}",
            }
        if rec.get("error"):
            console.print(f"[red]{escape(rec['key'])}: {escape(rec['error'])}[/red]")
        self.records[spec["key"]] = rec
        return rec


def _describe(rec: dict) -> str:
    ok = "ok" if rec.get("strict_success") else "fail"
    return f"{rec['mode']} · {rec['hand']} · {rec['case']}: {ok}"
