"""Real motion: robot hands and the MANO force pipeline on real captures and fast real-like motions.

The built-in demonstrations move slowly (wrist ≤ 0.55 m/s); real wrists carry objects at
2.5–3 m/s. This benchmark runs the toolkit on two kinds of cases:

* **real captures** under ``--captures DIR`` (nothing is downloaded; a missing set is named, with
  where to get it): ``DIR/mano-npz/*.npz`` (format ``mano-npz``), ``DIR/dexycb/`` (DexYCB as
  HO-3D-style meta pickles, format ``ho3d``: the sequences whose object is one of the DexCanvas
  YCB items, ``--per-object N`` each, chosen deterministically; the YCB models from
  ``--models DIR``) and ``DIR/taco/`` (format ``taco``). Left hands are mirrored to right ones
  (``mirror_left``). A format whose reader this checkout lacks
  (``dexcanvas_core.capture.formats.READERS``) is skipped, and said so. Each capture is imported
  (``dexcanvas import``) into its own dataset; an object that neither the capture nor the
  catalogue gives a mass (e.g. the mustard bottle) gets ``--density`` (500 kg/m³) × its mesh's
  volume;
* **stress cases**: built-in pick-and-place demonstrations whose hand holds the object
  (``--pairs``), each turned into fast rigid motions of the held object inserted into its hold
  (``dexcanvas_core.capture.stress``: carry 0.3 m at 1.5 m/s; transport 0.45 m at 2 m/s, 0.7 m
  at 2.5 m/s, 1.0 m at 3 m/s; tool use 60° at 4 rad/s; the lift 3× faster), exported as
  ``mano-npz`` and imported into one dataset. Each case's peak wrist speed and acceleration are
  recorded.

Runs, per hand (``--hands``, default every five-finger hand) × case × mode: ``keypoints``
(``retarget run``), ``forces`` (``--forces``), ``forces_refine`` (``--forces --refine``); and per
case the MANO force pipeline (``dexcanvas simulate``, mode ``mano``). The force modes take the
human's forces from that simulation (the same one ``retarget run --forces`` would make, at the
same seed); where it lost the object they fail without running ("no human forces"), as
``retarget run --forces`` does.

Measured per run:

* **strict success in the contact window**: no frame between the row's ``object_move`` start and
  end frames with an object position error above 5 cm (the re-simulation's per-frame error in
  ``robot_trajectory.npz``; ``forces_refine`` where the open loop failed there: the physics
  refinement's, which succeeds when it never lost the object or lost it after the window's end).
  The DexCanvas rule over the whole clip is kept beside it (``success``);
* **wrist tracking error**: mean over the clip of the re-simulated wrist's distance [mm] and
  largest hinge error [deg] from its command (the open-loop re-simulation's);
* **object error max** in the window [cm] (runs the refinement kept: its max over the frames it
  tracked), **kinematic penetration max** [mm], **ms/frame** (the retargeting loop) and the
  run's **wall time** [s];
* the MANO pipeline: strict success in the window, and for a failure its frame, phase (before,
  in or after the window) and the force pipeline's own diagnosis (``failure`` of its metrics,
  ``dexcanvas_core.sim.diagnosis``: wrist lag, lost contact, slip or knocked, with the wrist lag
  and slip behind the call).

Jobs run on ``--workers`` spawned processes and are resumable: each finished job's record is
written atomically to ``--work DIR`` (default ``benchmarks/results/real_motion_work/``), and a
rerun skips it (``--retry-errors`` reruns those that raised); the imported datasets are kept
there too. Prints a table per mode (cases × hands and MANO) and a summary (per hand × mode), and
writes ``benchmarks/results/real_motion.json`` and the page ``docs/benchmarks/real_motion.md``
(``benchmarks/pages.py`` regenerates it from the JSON).

    python benchmarks/real_motion.py --captures DIR --models DIR --workers 2
    python benchmarks/real_motion.py --hands shadow --modes keypoints --cases carry --limit 1
    python benchmarks/pages.py
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import multiprocessing
import os
import re
import sys
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from _common import git_commit, json_default, machine_info, versions

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "real_motion.json"
DEFAULT_WORK = ROOT / "benchmarks" / "results" / "real_motion_work"
PAGE = ROOT / "docs" / "benchmarks" / "real_motion.md"

MODES = ("keypoints", "forces", "forces_refine")
MANO = "mano"
ALL_MODES = (*MODES, MANO)
MODE_FLAGS = {"keypoints": "", "forces": "--forces", "forces_refine": "--forces --refine"}

STRICT_M = 0.05
"""A frame whose object position error exceeds this [m] fails the run (DexCanvas rule)."""

STRESS_PAIRS = ("cube2/tripod", "cube1/large_diameter", "cylinder3/adducted_thumb")
"""Built-in pick-and-place demonstrations whose five-finger grasp lifts the object. (Objects
made of several primitives, e.g. ``mayonnaisebottle``, are not exported as one closed mesh where
their parts touch at vertices: ``mesh_check`` skips them, saying so.)"""

DEXYCB_ITEMS = {
    "006": "mustard bottle",
    "011": "banana",
    "019": "pitcher base",
    "024": "bowl",
    "035": "power drill",
    "037": "scissors",
    "052": "extra-large clamp",
}
"""DexYCB objects (YCB id prefix) that are DexCanvas items."""

CAPTURE_SETS = {
    "mano-npz": (
        "mano-npz",
        "mano-npz captures (*.npz, the keys of dexcanvas_core/capture/arrays.py; "
        "dexcanvas_core.capture.export.write_mano_npz writes them)",
    ),
    "dexycb": (
        "ho3d",
        "DexYCB HO3D-style meta pickles (github Shurui8860/dexYCB_dataloader)",
    ),
    "taco": (
        "taco",
        "TACO source data (taco2024.github.io: <sequence>.pkl hand and object tracks with "
        "their <sequence>.obj object meshes)",
    ),
}
"""``--captures`` sub-directory → (format, what it holds and where it comes from)."""

DEFAULT_DENSITY = 500.0
"""[kg/m³] mass from the mesh volume for captured objects nothing else gives a mass to."""

# The targets (reported against, not enforced).
TARGET_MANO = 0.80
TARGET_REFINE = 0.70
TARGET_WRIST_M = 0.005

# MANO failure reasons (module docstring).

THREAD_ENV = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def stress_motions() -> tuple:
    """The stress cases made of each demonstration (module docstring)."""
    from dexcanvas_core.capture.stress import StressMotion

    return (
        StressMotion("carry", peak_speed=1.5, distance_m=0.3),
        StressMotion("transport", peak_speed=2.0, distance_m=0.45),
        StressMotion("transport", peak_speed=2.5, distance_m=0.7, direction=(1.0, 0.0)),
        StressMotion("transport", peak_speed=3.0, distance_m=1.0, direction=(1.0, 1.0)),
        StressMotion("tool_use", peak_speed=4.0, angle_rad=math.radians(60), direction=(1, 0)),
        StressMotion("fast_lift", time_scale=3.0),
    )


# ------------------------------------------------------------------------------------ cases
@dataclass(frozen=True)
class Case:
    """One sequence to run: row ``index`` of the imported ``dataset``."""

    name: str
    """``<source label>/<capture name>``, e.g. ``stress/cube2-tripod__carry-0.3m-1.5mps``."""
    source: str
    """``stress``, ``mano-npz``, ``dexycb`` or ``taco``."""
    dataset: str
    index: int
    uuid: str
    object: str
    frames: int
    fps: float
    window: tuple[int, int] | None
    """First and last frame of the object's motion (``object_move``); ``None``: the clip."""
    info: dict = field(default_factory=dict)
    """Peaks (``peak_speed_mps``, ``peak_accel_mps2``, ``peak_angular_speed_radps``) and
    where the case came from."""

    def as_dict(self) -> dict:
        d = asdict(self)
        d["window"] = None if self.window is None else list(self.window)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> Case:
        w = d.get("window")
        return cls(**{**d, "window": None if w is None else (int(w[0]), int(w[1]))})


def capture_name(pair: str, motion) -> str:
    """The capture (file stem) name of ``motion`` made of the demonstration of ``pair``."""
    return f"{pair.replace('/', '-')}__{motion.name}"


def write_stress_captures(
    sources: dict[str, dict], motions, dest: Path, originals: bool = False
) -> list[dict]:
    """Write each stress case of each source demonstration (``{pair: mano-npz arrays}``) as
    ``dest/<capture_name>.npz``; with ``originals`` the unmodified demonstrations too. Returns
    one record per file: ``name``, ``pair``, ``motion`` and the peaks of ``stress_arrays``."""
    from dexcanvas_core.capture.export import write_mano_npz
    from dexcanvas_core.capture.stress import peaks, stress_arrays

    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    out = []
    for pair, arrays in sources.items():
        if originals:
            name = f"{pair.replace('/', '-')}__original"
            write_mano_npz(dest / f"{name}.npz", arrays)
            out.append({"name": name, "pair": pair, "motion": "original", **peaks(arrays)})
        for motion in motions:
            arr, report = stress_arrays(arrays, motion)
            name = capture_name(pair, motion)
            write_mano_npz(dest / f"{name}.npz", arr)
            out.append({"name": name, "pair": pair, "motion": motion.name, **report})
    return out


def demonstration_arrays(pair: str) -> dict:
    """The built-in demonstration of ``pair`` as ``mano-npz`` arrays (its object's shape as a
    mesh)."""
    from dexcanvas_core.capture.export import geometry_mesh, trajectory_to_arrays
    from dexcanvas_core.loaders.selection import load_demonstration
    from dexcanvas_core.objects.geometry import object_geometry

    traj = load_demonstration(pair)
    return trajectory_to_arrays(traj, geometry_mesh(object_geometry(traj.object.name)))


def mesh_check(arrays: dict, work: Path) -> None:
    """Raise the import's error when the arrays' object mesh is not a closed surface."""
    import trimesh

    from dexcanvas_core.objects.mesh import load_object_mesh

    tm = trimesh.Trimesh(arrays["object_vertices"], arrays["object_faces"], process=False)
    path = Path(work) / f".mesh-check-{os.getpid()}.obj"
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        path.write_text(trimesh.exchange.obj.export_obj(tm, include_normals=False))
        load_object_mesh(path)
    finally:
        path.unlink(missing_ok=True)


def cases_of_dataset(dataset: Path, label: str, extra: dict | None = None) -> list[Case]:
    """A :class:`Case` per row of the imported ``dataset`` (``extra``: per capture name, info to
    keep, e.g. the stress report; the peaks are measured on the row when it has none)."""
    from dexcanvas_core.capture import use_dataset_objects
    from dexcanvas_core.capture.stress import peaks
    from dexcanvas_core.io import open_dataset

    use_dataset_objects(dataset)
    cases = []
    for i, traj in enumerate(open_dataset(dataset).iter_trajectories()):
        name = traj.uuid.removeprefix("import-").rsplit("-", 1)[0]
        info = dict((extra or {}).get(name, {}))
        if "peak_speed_mps" not in info:
            info.update(
                peaks(
                    {
                        "fps": traj.fps,
                        "wrist_pos": traj.hand.joint_pos[:, 0],
                        "global_orient": traj.hand.global_rot_aa,
                    }
                )
            )
        move = traj.object_move[0] if traj.object_move else None
        cases.append(
            Case(
                name=f"{label}/{name}",
                source=label,
                dataset=str(dataset),
                index=i,
                uuid=traj.uuid,
                object=traj.object.name,
                frames=traj.num_frames,
                fps=float(traj.fps),
                window=None if move is None else (int(move.start_frame), int(move.end_frame)),
                info=info,
            )
        )
    return cases


def content_digest(paths) -> str:
    """A digest of the files at ``paths`` (a directory: its files' names, sizes and times), so
    that a changed capture is imported again."""
    h = hashlib.sha256()
    for p in map(Path, paths):
        if p.is_file():
            h.update(p.read_bytes())
        elif p.is_dir():
            for f in sorted(q for q in p.rglob("*") if q.is_file()):
                st = f.stat()
                h.update(f"{f.relative_to(p)}|{st.st_size}|{st.st_mtime_ns}".encode())
    return h.hexdigest()


def import_once(fmt: str, paths: list[Path], out: Path, **options) -> tuple[bool, dict]:
    """Import ``paths`` (format ``fmt``) into ``out`` unless ``out`` already holds exactly that
    import (its stamp ``<out>.import.json`` records the inputs). ``(imported now, stamp)``."""
    from dexcanvas_core.capture import ImportConfig, run_import

    stamp = out.with_name(out.name + ".import.json")
    inputs = {
        "format": fmt,
        "paths": [str(p) for p in paths],
        "content": content_digest(paths),
        **{k: None if v is None else str(v) for k, v in options.items()},
    }
    if out.exists() and stamp.is_file():
        try:
            old = json.loads(stamp.read_text())
        except (OSError, json.JSONDecodeError):
            old = None
        if old is not None and old.get("inputs") == inputs:
            return False, old
    res = run_import(
        ImportConfig(
            format=fmt,
            paths=tuple(Path(p) for p in paths),
            out=out,
            overwrite=True,
            **{k: v for k, v in options.items() if v is not None},
        )
    )
    doc = {"inputs": inputs, "sequences": res.sequences, "objects": res.objects}
    _atomic_write(stamp, json.dumps(doc, default=str, indent=1))
    return True, doc


def build_stress_cases(work: Path, pairs, originals: bool, console) -> tuple[list[Case], list]:
    """The stress cases, imported into ``work/stress.lance`` (reused when unchanged)."""
    motions = stress_motions()
    from dexcanvas_core.capture.stress import hold_range

    sources, notes = {}, []
    for pair in pairs:
        try:
            arrays = demonstration_arrays(pair)
            hold_range(arrays)  # it lifts its object
            mesh_check(arrays, work)
        except Exception as e:
            notes.append(f"stress: {pair} skipped ({type(e).__name__}: {e})")
            continue
        sources[pair] = arrays
    if not sources:
        return [], notes
    captures = work / "stress_captures"
    reports = write_stress_captures(sources, motions, captures, originals)
    files = [captures / f"{r['name']}.npz" for r in reports]
    fresh, _ = import_once("mano-npz", files, work / "stress.lance")
    how = "imported" if fresh else "reused"
    console.print(f"stress cases: {len(reports)} ({how} {work / 'stress.lance'})")
    extra = {r["name"]: {k: v for k, v in r.items() if k != "name"} for r in reports}
    return cases_of_dataset(work / "stress.lance", "stress", extra), notes


def dexycb_object_name(seq_dir: Path) -> str | None:
    """The YCB id (``objName``) of a DexYCB sequence, from its first meta pickle."""
    from dexcanvas_core.safe_pickle import load_pickle  # comes with the ho3d reader

    pkl = min(Path(seq_dir, "meta").glob("*.pkl"), default=None)
    if pkl is None:
        return None
    meta = load_pickle(pkl, what="DexYCB meta file")
    name = meta.get("objName") if isinstance(meta, dict) else None
    return None if name is None else str(name)


def select_dexycb(root: Path, per_object: int, object_name_of=dexycb_object_name) -> list[Path]:
    """``per_object`` sequence directories (``<subject>/<sequence>/meta/*.pkl``) of each
    :data:`DEXYCB_ITEMS` object under ``root``: sorted, taken round-robin over the subjects
    (deterministic)."""
    seqs = sorted({m.parent for m in Path(root).glob("**/meta") if any(m.glob("*.pkl"))})
    by_item: dict[str, dict[str, list[Path]]] = {}
    for s in seqs:
        name = object_name_of(s)
        prefix = (name or "").split("_", 1)[0]
        if prefix in DEXYCB_ITEMS:
            by_item.setdefault(prefix, {}).setdefault(s.parent.name, []).append(s)
    out = []
    for prefix in sorted(by_item):
        subjects = by_item[prefix]
        order = sorted(subjects)
        picked, k = [], 0
        while len(picked) < per_object and any(subjects.values()):
            lst = subjects[order[k % len(order)]]
            if lst:
                picked.append(lst.pop(0))
            k += 1
        out += picked
    return out


def find_real_captures(
    captures: Path | None, models: Path | None, per_object: int, readers=None, select=None
) -> tuple[list[tuple[str, str, list[Path]]], list[str]]:
    """``([(label, format, paths)], notes)``: the real capture sets found under ``captures``
    (one path per capture) and a note for each set that is missing or cannot be read here."""
    if readers is None:
        from dexcanvas_core.capture.formats import READERS as readers
    select = select or select_dexycb
    if captures is None:
        return [], ["no --captures DIR: real captures skipped (stress cases only)"]
    root = Path(captures).expanduser()
    found, notes = [], []
    for label, (fmt, what) in CAPTURE_SETS.items():
        d = root / label
        if fmt not in readers:
            notes.append(
                f"{label}: format {fmt!r} has no reader in this checkout "
                f"(dexcanvas_core.capture.formats.READERS: {', '.join(sorted(readers))}); "
                f"skipped {d}"
            )
            continue
        if label == "mano-npz":
            paths = sorted(d.glob("*.npz")) if d.is_dir() else []
        elif label == "taco":
            paths = sorted(d.glob("*.pkl")) if d.is_dir() else []
        else:
            try:
                paths = select(d, per_object) if d.is_dir() else []
            except Exception as e:
                notes.append(f"{label}: could not choose sequences ({type(e).__name__}: {e})")
                continue
        if not paths:
            extra = (
                f" with one of {', '.join(sorted(DEXYCB_ITEMS.values()))}"
                if label == "dexycb" and d.is_dir()
                else ""
            )
            notes.append(f"{what} not found under {d}{extra}")
            continue
        if label == "dexycb" and models is None:
            notes.append(
                f"dexycb: {len(paths)} sequence(s) found under {d}, but no YCB models: give "
                "--models DIR (the YCB object models, one directory per YCB id)"
            )
            continue
        found.append((label, fmt, paths))
    return found, notes


def build_real_cases(found, work: Path, models, density, console) -> tuple[list[Case], list]:
    """Import each real capture into ``work/<label>/<name>.lance`` (reused when unchanged)."""
    cases, notes = [], []
    for label, fmt, paths in found:
        n_new = 0
        if label == "dexycb":  # whole subject folders: their sequences share one camera's up
            by_subject: dict[Path, list[Path]] = {}
            for p in paths:
                by_subject.setdefault(p.parent, []).append(p)
            for subject, seqs in sorted(by_subject.items()):
                out = work / label / f"{_slug(subject.name)}.lance"
                try:
                    fresh, _ = import_once(
                        fmt, [subject], out, mirror_left=True, models_dir=models, density=density
                    )
                    n_new += fresh
                    want = [f"{subject.name}_{q.name}" for q in seqs]
                    cases += [
                        c
                        for c in cases_of_dataset(out, label, {})
                        if any(c.name.split("/", 1)[1].startswith(w) for w in want)
                    ]
                except Exception as e:
                    notes.append(f"{label}: {subject} not imported ({type(e).__name__}: {e})")
            console.print(f"{label}: {len(paths)} capture(s) ({n_new} folder(s) imported now)")
            continue
        for p in paths:
            out = work / label / f"{_slug(p.stem if p.is_file() else p.name)}.lance"
            try:
                fresh, _ = import_once(
                    fmt, [p], out, mirror_left=True, models_dir=models, density=density
                )
                n_new += fresh
                cases += cases_of_dataset(out, label, {})
            except Exception as e:
                notes.append(f"{label}: {p} not imported ({type(e).__name__}: {e})")
        console.print(f"{label}: {len(paths)} capture(s) ({n_new} imported now)")
    return cases, notes


def filter_cases(cases: list[Case], patterns, limit: int | None) -> list[Case]:
    """Cases whose name contains any of ``patterns`` (all when none), the first ``limit``."""
    if patterns:
        cases = [c for c in cases if any(p in c.name for p in patterns)]
    return cases[:limit] if limit is not None else cases


# ------------------------------------------------------------------------------- job store
def _slug(s: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.+-]+", "_", s)


def _atomic_write(path: Path, text: str) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


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
        return self.dir / f"{_slug(key.replace('/', '+'))}.json"

    def run_dir(self, key: str) -> Path:
        return self.root / "runs" / _slug(key.replace("/", "+"))

    def load(self, key: str) -> dict | None:
        try:
            rec = json.loads(self.path(key).read_text())
        except (OSError, json.JSONDecodeError):
            return None
        return rec if isinstance(rec, dict) and rec.get("key") == key else None

    def save(self, rec: dict) -> Path:
        p = self.path(rec["key"])
        _atomic_write(p, json.dumps(rec, indent=1, default=json_default))
        return p

    def done(self, key: str, uuid: str | None = None, retry_errors: bool = False) -> dict | None:
        """The record of a finished job (of the case ``uuid`` when given), else ``None``."""
        rec = self.load(key)
        if rec is None or (uuid is not None and rec.get("uuid") != uuid):
            return None
        if retry_errors and rec.get("error"):
            return None
        return rec


# ---------------------------------------------------------------------------------- metrics
def window_bounds(window, frames: int) -> tuple[int, int]:
    """``(first, last)`` frame of the contact window clipped to the clip (the clip when none)."""
    if window is None:
        return 0, frames - 1
    return max(0, int(window[0])), min(frames - 1, int(window[1]))


def window_check(err, window, threshold: float = STRICT_M) -> dict:
    """Strict success inside the contact window from per-frame object errors ``err`` (T,) [m]:
    ``ok`` (no frame of the window above ``threshold``), its ``max_m`` and ``first_bad_frame``."""
    err = np.asarray(err, dtype=np.float64)
    s, e = window_bounds(window, len(err))
    seg = err[s : e + 1]
    bad = np.flatnonzero(~(seg <= threshold))  # NaN counts as bad
    return {
        "ok": bool(seg.size > 0 and bad.size == 0),
        "max_m": float(np.nanmax(seg)) if seg.size and np.isfinite(seg).any() else None,
        "first_bad_frame": int(s + bad[0]) if bad.size else None,
    }


def kept_through_window(success: bool, failed_at: int | None, window, frames: int) -> bool:
    """Strict success in the window of a tracker that stops at its failure (the refinement, the
    force pipeline): it never failed, or failed after the window's last frame."""
    if success or failed_at is None:
        return bool(success or failed_at is None)
    return int(failed_at) > window_bounds(window, frames)[1]


def retarget_record(m: dict, arrays: dict, case: Case) -> dict:
    """A retarget job's numbers from ``run_retarget``'s metrics ``m`` and its
    ``robot_trajectory.npz`` ``arrays`` (module docstring)."""
    w = window_check(arrays["object_pos_err"], case.window)
    s, e = window_bounds(case.window, len(arrays["object_pos_err"]))
    wp = np.asarray(arrays["wrist_pos_tracking_err"], dtype=np.float64)
    rec = {
        "success": bool(m["success"]),
        "strict_success": w["ok"],
        "strict_from": "open loop",
        "first_failure_frame": m.get("first_failure_frame"),
        "window_first_failure_frame": w["first_bad_frame"],
        "object_err_max_window_m": w["max_m"],
        "object_err_max_m": m["object_pos_err_max_m"],
        "wrist_pos_err_mean_m": m.get("wrist_pos_tracking_err_mean_m", float(wp.mean())),
        "wrist_rot_err_mean_deg": m.get("wrist_rot_tracking_err_mean_deg"),
        "wrist_pos_err_window_mean_m": float(wp[s : e + 1].mean()),
        "penetration_max_m": m["penetration_max_m"],
        "sim_penetration_max_m": m.get("sim_penetration_max_m"),
        "keypoint_err_mean_m": m.get("keypoint_err_mean_m"),
        "ms_per_frame": m.get("ms_per_frame"),
    }
    r = m.get("refine")
    if r is not None:
        rec["refine"] = {
            k: r.get(k)
            for k in (
                "success",
                "failed_at_frame",
                "object_pos_err_max_m",
                "attempts",
                "compute_s",
                "wrist_pos_deviation_mean_m",
            )
        }
        if not w["ok"] and kept_through_window(
            bool(r["success"]), r.get("failed_at_frame"), case.window, case.frames
        ):
            rec.update(
                strict_success=True,
                strict_from="refined",
                object_err_max_window_m=r.get("object_pos_err_max_m"),
            )
    return rec


def failure_phase(failed_at: int, window, frames: int) -> str:
    """Where the failure frame lies relative to the contact window."""
    s, e = window_bounds(window, frames)
    return (
        "before the window"
        if failed_at < s
        else ("in the window" if failed_at <= e else "after the window")
    )


def mano_record(m: dict, traj, case: Case) -> dict:
    """A MANO job's numbers from ``run_simulate``'s metrics ``m`` and its annotated row
    ``traj`` (cut at the failure when it lost the object)."""
    failed = m.get("failed_at_frame")
    rec = {
        "success": bool(m["success"]),
        "strict_success": kept_through_window(bool(m["success"]), failed, case.window, case.frames),
        "failed_at_frame": failed,
        "object_err_max_m": m.get("object_pos_err_max_m"),
        "compute_s": m.get("compute_s"),
        "compute_s_per_demo_s": m.get("compute_s_per_demo_s"),
        "mass_kg": m.get("mass_kg"),
    }
    try:
        arrays = mano_arrays(traj)
    except Exception as e:  # an older or partial row: no per-frame detail
        arrays = None
        rec["detail_error"] = f"{type(e).__name__}: {e}"
    if arrays is not None:
        w = window_check(arrays["obj_err"], case.window)
        rec["object_err_max_window_m"] = w["max_m"] if rec["strict_success"] else None
        rec["wrist_pos_err_mean_m"] = float(arrays["wrist_err"].mean())
    if failed is not None:
        # the force pipeline's own diagnosis (dexcanvas_core.sim.diagnosis)
        why = m.get("failure") or {"reason": f"object error > 5 cm at frame {failed}"}
        rec["failure"] = {**why, "phase": failure_phase(failed, case.window, case.frames)}
    return rec


def mano_arrays(traj) -> dict:
    """Per-frame object error and wrist error from its command, from the force pipeline's
    annotated row."""
    sim_pos = np.asarray(traj.extras["sim_object_pos"], dtype=np.float64)
    T = len(sim_pos)
    obj_err = np.linalg.norm(sim_pos - np.asarray(traj.object.pos[:T], dtype=np.float64), axis=1)
    h = traj.hand
    wrist_err = np.linalg.norm(
        np.asarray(h.urdf_dof[:T, :3], np.float64) - np.asarray(h.urdf_dof_target[:T, :3]), axis=1
    )
    return {"obj_err": obj_err, "wrist_err": wrist_err}


# ------------------------------------------------------------------------------------- jobs
def _init_worker() -> None:
    import logging

    logging.basicConfig(level=logging.ERROR)
    try:
        import torch
    except ImportError:  # pragma: no cover
        return
    torch.set_num_threads(1)
    torch.set_num_interop_threads(1)


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
        from dexcanvas_core.capture import use_dataset_objects

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
    from dexcanvas_core.io import open_dataset
    from dexcanvas_core.sim.run import SimulateConfig, run_simulate

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
    from retarget.run import RunConfig, run_retarget

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
        from rich.markup import escape
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

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
        ctx = multiprocessing.get_context("spawn")
        saved = {k: os.environ.get(k) for k in THREAD_ENV}
        os.environ.update({k: "1" for k in THREAD_ENV})
        try:
            with (
                ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init_worker) as pool,
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
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v

    def _result(self, fut, spec: dict, console) -> dict:
        from rich.markup import escape

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


# ------------------------------------------------------------------------------ aggregates
def _mean(vals) -> float | None:
    v = [x for x in vals if x is not None]
    return float(np.mean(v)) if v else None


def _object_err(r: dict) -> float | None:
    """A run's object error max in the window (the refinement's where it kept the object;
    a MANO run that failed: over the frames it tracked)."""
    e = r.get("object_err_max_window_m")
    return e if e is not None else r.get("object_err_max_m")


def aggregate(recs: list[dict]) -> dict:
    """Strict success rate (errors and skipped runs count as failures) and the means of the
    runs that ran."""
    ran = [r for r in recs if not r.get("error") and not r.get("skipped")]
    return {
        "runs": len(recs),
        "errors": sum(1 for r in recs if r.get("error")),
        "skipped": sum(1 for r in recs if r.get("skipped")),
        "strict_success_rate": float(np.mean([bool(r.get("strict_success")) for r in recs]))
        if recs
        else None,
        "success_rate": float(np.mean([bool(r.get("success")) for r in recs])) if recs else None,
        "wrist_pos_err_mean_m": _mean(r.get("wrist_pos_err_mean_m") for r in ran),
        "wrist_rot_err_mean_deg": _mean(r.get("wrist_rot_err_mean_deg") for r in ran),
        "object_err_max_median_m": (
            float(np.median(v))
            if (v := [e for r in ran if (e := _object_err(r)) is not None])
            else None
        ),
        "penetration_max_m": max(
            (r["penetration_max_m"] for r in ran if r.get("penetration_max_m") is not None),
            default=None,
        ),
        "ms_per_frame_mean": _mean(r.get("ms_per_frame") for r in ran),
        "wall_s_total": float(sum(r.get("wall_s") or 0.0 for r in recs)),
    }


def failure_reasons(recs: list[dict]) -> dict:
    """Count of the MANO pipeline's failure reasons."""
    out: dict[str, int] = {}
    for r in recs:
        f = r.get("failure")
        if f:
            out[f["reason"]] = out.get(f["reason"], 0) + 1
    return out


def summarize(records: list[dict], hands, five) -> dict:
    """Per ``hand/mode`` and MANO aggregates, and the targets."""
    per = {}
    for h in hands:
        for mode in MODES:
            rs = [r for r in records if r["hand"] == h and r["mode"] == mode]
            if rs:
                per[f"{h}/{mode}"] = aggregate(rs)
    mano = [r for r in records if r["mode"] == MANO]
    if mano:
        per[MANO] = {**aggregate(mano), "failure_reasons": failure_reasons(mano)}
    for mode in MODES:
        rs = [r for r in records if r["mode"] == mode and r["hand"] in five]
        if rs and len({r["hand"] for r in rs}) > 1:
            per[f"five-finger/{mode}"] = aggregate(rs)
    return {"per_hand_mode": per, "targets": target_checks(per, five)}


def target_checks(per: dict, five) -> list[dict]:
    checks = []
    if MANO in per:
        v = per[MANO]["strict_success_rate"]
        checks.append(
            {
                "target": f"MANO force pipeline strict success ≥ {100 * TARGET_MANO:.0f} %",
                "value": v,
                "met": v is not None and v >= TARGET_MANO,
            }
        )
    scopes = [("five-finger hands", "five-finger")] if len(five) > 1 else []
    scopes += [(h, h) for h in five]
    for scope, key in scopes:
        a = per.get(f"{key}/forces_refine")
        if a is None:
            continue
        v, w = a["strict_success_rate"], a["wrist_pos_err_mean_m"]
        checks.append(
            {
                "target": f"--forces --refine strict success ≥ {100 * TARGET_REFINE:.0f} %",
                "scope": scope,
                "value": v,
                "met": v is not None and v >= TARGET_REFINE,
            }
        )
        checks.append(
            {
                "target": f"--forces --refine wrist tracking ≤ {1e3 * TARGET_WRIST_M:g} mm mean",
                "scope": scope,
                "value": w,
                "met": w is not None and w <= TARGET_WRIST_M,
            }
        )
    return checks


# ---------------------------------------------------------------------------------- output
def _cell(r: dict | None) -> str:
    if r is None:
        return "·"
    if r.get("error"):
        return "error"
    if r.get("skipped"):
        return "no forces"
    ok = "✓" if r.get("strict_success") else "✗"
    e = r.get("object_err_max_window_m")
    if r.get("mode") == MANO and not r.get("strict_success"):
        f = r.get("failure") or {}
        return f"{ok} {f.get('reason', '')} @{r.get('failed_at_frame')}"
    if r.get("strict_from") == "refined":
        ok += "r"
    return ok if e is None else f"{ok} {100 * e:.1f}"


def mode_rows(records: list[dict], cases: list[str], hands, mode: str) -> list[list[str]]:
    """Rows of a mode's table: the case, each hand's cell, the MANO pipeline's cell."""
    by = {(r["hand"], r["mode"], r["case"]): r for r in records}
    return [
        [c, *(_cell(by.get((h, mode, c))) for h in hands), _cell(by.get((MANO, MANO, c)))]
        for c in cases
    ]


def _mm(x) -> str:
    return "–" if x is None else f"{1e3 * x:.1f}"


def _cm(x) -> str:
    return "–" if x is None else f"{1e2 * x:.1f}"


def _pct(x) -> str:
    return "–" if x is None else f"{100 * x:.0f} %"


def _num(x, fmt: str = ".2f") -> str:
    return "–" if x is None else format(x, fmt)


SUMMARY_COLUMNS = (
    "hand / mode",
    "runs",
    "strict success",
    "wrist err mm",
    "wrist err deg",
    "object err max cm (median)",
    "penetration max mm",
    "ms/frame",
    "wall s",
)


def summary_rows(per: dict) -> list[list[str]]:
    rows = []
    for name, a in per.items():
        runs = f"{a['runs']}"
        if a["errors"] or a["skipped"]:
            runs += f" ({a['errors']} err, {a['skipped']} no forces)"
        rows.append(
            [
                name,
                runs,
                _pct(a["strict_success_rate"]),
                _mm(a["wrist_pos_err_mean_m"]),
                _num(a["wrist_rot_err_mean_deg"], ".1f"),
                _cm(a["object_err_max_median_m"]),
                _mm(a["penetration_max_m"]),
                _num(a["ms_per_frame_mean"]),
                f"{a['wall_s_total']:.0f}",
            ]
        )
    return rows


def print_tables(doc: dict, console) -> None:
    from rich.table import Table

    cases = [c["name"] for c in doc["cases"]]
    hands = doc["hands"]
    for mode in doc["config"]["modes"]:
        if mode == MANO:
            continue
        t = Table(
            title=f"{mode} ({MODE_FLAGS[mode] or 'plain'}): strict success in the contact "
            "window, object error max there \\[cm] (r: by the refinement)"
        )
        for col in ("case", *hands, "MANO"):
            t.add_column(col, justify="left" if col == "case" else "right")
        for row in mode_rows(doc["records"], cases, hands, mode):
            t.add_row(*row)
        console.print(t)
    if set(doc["config"]["modes"]) == {MANO}:
        t = Table(title="MANO force pipeline: strict success in the contact window")
        for col in ("case", "MANO"):
            t.add_column(col)
        for row in mode_rows(doc["records"], cases, [], MANO):
            t.add_row(*row)
        console.print(t)
    t = Table(title="summary per hand × mode")
    for col in SUMMARY_COLUMNS:
        t.add_column(col, justify="left" if col == "hand / mode" else "right")
    for row in summary_rows(doc["summary"]["per_hand_mode"]):
        t.add_row(*row)
    console.print(t)
    if doc["summary"]["targets"]:
        t = Table(title="targets (issue)")
        for col in ("target", "scope", "measured", "met"):
            t.add_column(col)
        for c in doc["summary"]["targets"]:
            v = c["value"]
            s = "–" if v is None else (f"{1e3 * v:.2f} mm" if "mm" in c["target"] else _pct(v))
            t.add_row(
                c["target"],
                c.get("scope", ""),
                s,
                "[green]yes[/green]" if c["met"] else "[red]no[/red]",
            )
        console.print(t)


def page_markdown(doc: dict) -> str:
    """The page ``docs/benchmarks/real_motion.md`` of a result document."""
    m = doc.get("machine", {})
    cases = doc["cases"]
    hands = doc["hands"]
    lines = [
        "# Real motion: real captures and fast real-like motions",
        "",
        "Generated by `benchmarks/pages.py` (or `benchmarks/real_motion.py`) from "
        "`benchmarks/results/real_motion.json`; do not edit. How it measures: the script's "
        "docstring.",
        "",
        f"Commit `{doc.get('commit')}`, {m.get('platform', '?')}, {m.get('cpu_count', '?')} "
        f"CPUs, {doc.get('wall_time_s', 0):.0f} s: `{doc.get('command', '?')}`",
        "",
        "Strict success: no frame between the row's object-motion start and end with an object "
        "error above 5 cm. Cells: ✓ / ✗ and the object error max in that window [cm] (✓r: kept "
        "by the physics refinement); MANO failures: the reason and frame; `no forces`: the "
        "force pipeline lost the object, so the force modes had no human forces to match.",
        "",
    ]
    if doc["summary"]["targets"]:
        lines += ["## Targets", "", "| target | scope | measured | met |", "|---|---|---:|---|"]
        for c in doc["summary"]["targets"]:
            v = c["value"]
            s = "–" if v is None else (f"{1e3 * v:.2f} mm" if "mm" in c["target"] else _pct(v))
            lines.append(
                f"| {c['target']} | {c.get('scope', '')} | {s} | {'yes' if c['met'] else 'no'} |"
            )
        lines.append("")
    lines += [
        "## Summary",
        "",
        "| " + " | ".join(SUMMARY_COLUMNS) + " |",
        "|---|" + "---:|" * (len(SUMMARY_COLUMNS) - 1),
    ]
    lines += ["| " + " | ".join(r) + " |" for r in summary_rows(doc["summary"]["per_hand_mode"])]
    reasons = doc["summary"]["per_hand_mode"].get(MANO, {}).get("failure_reasons")
    if reasons:
        lines += [
            "",
            "MANO force pipeline failures: "
            + ", ".join(f"{k} {v}" for k, v in sorted(reasons.items()))
            + ".",
        ]
    for mode in doc["config"]["modes"]:
        if mode == MANO:
            continue
        lines += [
            "",
            f"## {mode} (`retarget run {MODE_FLAGS[mode]}`)".replace(" `)", "`)"),
            "",
            "| case | " + " | ".join([*hands, "MANO"]) + " |",
            "|---|" + "---:|" * (len(hands) + 1),
        ]
        for row in mode_rows(doc["records"], [c["name"] for c in cases], hands, mode):
            lines.append("| " + " | ".join(row) + " |")
    lines += [
        "",
        "## Cases",
        "",
        "| case | frames | window | peak speed [m/s] | "
        "peak acceleration [m/s²] | peak angular speed [rad/s] |",
        "|---|---:|---|---:|---:|---:|",
    ]
    for c in cases:
        i = c.get("info", {})
        w = "–" if c["window"] is None else f"{c['window'][0]}–{c['window'][1]}"
        lines.append(
            f"| {c['name']} | {c['frames']} | {w} | {_num(i.get('peak_speed_mps'))} | "
            f"{_num(i.get('peak_accel_mps2'), '.1f')} | "
            f"{_num(i.get('peak_angular_speed_radps'))} |"
        )
    if doc.get("notes"):
        lines += ["", "## Not run", ""] + [f"- {n}" for n in doc["notes"]]
    errors = [r for r in doc["records"] if r.get("error")]
    if errors:
        lines += ["", "## Errors", ""] + [f"- `{r['key']}`: {r['error']}" for r in errors]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------ main
@dataclass(frozen=True)
class BenchConfig:
    captures: Path | None = None
    models: Path | None = None
    per_object: int = 1
    density: float = DEFAULT_DENSITY
    hands: tuple[str, ...] | None = None
    modes: tuple[str, ...] = ALL_MODES
    cases: tuple[str, ...] = ()
    limit: int | None = None
    pairs: tuple[str, ...] = STRESS_PAIRS
    originals: bool = False
    workers: int = 1
    work: Path = DEFAULT_WORK
    out: Path = DEFAULT_OUT
    page: Path | None = PAGE
    retry_errors: bool = False

    def validate(self) -> BenchConfig:
        bad = [m for m in self.modes if m not in ALL_MODES]
        if bad:
            raise SystemExit(f"unknown mode(s) {bad}; choose from {', '.join(ALL_MODES)}")
        if self.workers < 1 or self.per_object < 1:
            raise SystemExit("--workers and --per-object must be >= 1")
        if self.limit is not None and self.limit < 1:
            raise SystemExit("--limit must be >= 1")
        return self


def is_five_finger(hand) -> bool:
    """Five distinct robot fingers (Shadow, SVH, Ability, Inspire)."""
    return len(set(hand.robot_fingers)) == 5


def resolve_hands(names) -> tuple[list[str], list[str]]:
    """``(hands, five-finger hands among them)``; default: every five-finger hand."""
    from retarget.hands import available_hands, get_hand

    hands = list(names) if names else list(available_hands())
    five = [h for h in hands if is_five_finger(get_hand(h))]
    return (hands if names else five), five


def run_benchmark(cfg: BenchConfig, console=None) -> dict:
    """Build the cases, run the jobs not finished yet, print the tables, write the JSON and
    the page; return the JSON document."""
    from rich.console import Console
    from rich.markup import escape

    console = console or Console(width=None if sys.stdout.isatty() else 140)
    cfg = cfg.validate()
    t0 = time.perf_counter()
    load0 = os.getloadavg()
    work = Path(cfg.work)
    work.mkdir(parents=True, exist_ok=True)
    hands, five = resolve_hands(cfg.hands) if any(m in cfg.modes for m in MODES) else ([], [])
    found, notes = find_real_captures(cfg.captures, cfg.models, cfg.per_object)
    for n in notes:
        console.print(f"[yellow]note:[/yellow] {escape(n)}")
    cases, more = build_stress_cases(work, cfg.pairs, cfg.originals, console)
    real, more2 = build_real_cases(found, work, cfg.models, cfg.density, console)
    notes += more + more2
    for n in more + more2:
        console.print(f"[yellow]note:[/yellow] {escape(n)}")
    cases = filter_cases(real + cases, cfg.cases, cfg.limit)
    if not cases:
        raise SystemExit("no cases to run (check --cases / --captures)")
    console.print(
        f"{len(cases)} case(s); hands: {', '.join(hands) or '-'}; modes: {', '.join(cfg.modes)}"
    )
    mano_jobs, hand_jobs = plan_jobs(cases, hands, cfg.modes, work)
    sched = Scheduler(JobStore(work), cfg.retry_errors)
    sched.run(mano_jobs, hand_jobs, cfg.workers, console)
    keys = [s["key"] for s in mano_jobs if MANO in cfg.modes] + [s["key"] for s in hand_jobs]
    records = [sched.records[k] for k in keys if k in sched.records]
    doc = {
        "benchmark": "real_motion",
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        "config": {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()},
        "hands": hands,
        "five_finger_hands": five,
        "cases": [c.as_dict() for c in cases],
        "notes": notes,
        "records": records,
        "summary": summarize(records, hands, five),
        "commit": git_commit(),
        "machine": machine_info(load0, workers=cfg.workers),
        "versions": versions(("dexcanvas-retarget", "mujoco", "pin", "numpy", "lance")),
        "definitions": {
            "strict_success": "no frame of the contact window (object_move start..end) with "
            "object error > 5 cm; forces_refine: the refinement's result where the open loop "
            "failed there (kept through the window's end)",
            "success": "DexCanvas rule over the whole clip (open loop; MANO: the pipeline's)",
            "object_err_max_window_m": "max object error in the window (refined: the "
            "refinement's max over the frames it tracked)",
            "wrist_pos_err_mean_m": "mean over the clip of the re-simulated wrist's distance "
            "from its command (MANO: the simulated wrist from its target)",
            "penetration_max_m": "deepest kinematic hand-object penetration",
            "failure": "MANO: reason at the failure's onset (wrist lag ≥ 2 cm in the 0.1 s "
            "before / fewer than 2 hand parts pressing / slip) and phase",
        },
        "wall_time_s": time.perf_counter() - t0,
    }
    print_tables(doc, console)
    Path(cfg.out).parent.mkdir(parents=True, exist_ok=True)
    _atomic_write(Path(cfg.out), json.dumps(doc, indent=1, default=json_default))
    console.print(f"wrote {cfg.out} ({doc['wall_time_s']:.0f} s)")
    if cfg.page is not None:
        _atomic_write(Path(cfg.page), page_markdown(doc))
        console.print(f"wrote {cfg.page}")
    return doc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--captures",
        type=Path,
        default=None,
        help="directory with mano-npz/, dexycb/, taco/ (never downloaded)",
    )
    ap.add_argument("--models", type=Path, default=None, help="YCB object models (dexycb)")
    ap.add_argument("--per-object", type=int, default=1, help="DexYCB sequences per item")
    ap.add_argument(
        "--density",
        type=float,
        default=DEFAULT_DENSITY,
        help="kg/m³ for captured objects without a known mass",
    )
    ap.add_argument(
        "--hands", nargs="+", default=None, help="hands (default: every five-finger hand)"
    )
    ap.add_argument("--modes", nargs="+", default=list(ALL_MODES), choices=ALL_MODES)
    ap.add_argument(
        "--cases",
        nargs="+",
        default=[],
        metavar="SUBSTRING",
        help="only the cases whose name contains one of these",
    )
    ap.add_argument("--limit", type=int, default=None, help="only the first N cases")
    ap.add_argument(
        "--pairs",
        nargs="+",
        default=list(STRESS_PAIRS),
        help="built-in demonstrations the stress cases are made of",
    )
    ap.add_argument(
        "--originals", action="store_true", help="also run the unmodified demonstrations"
    )
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument(
        "--work",
        type=Path,
        default=DEFAULT_WORK,
        help="job records, runs and imported datasets (resumable)",
    )
    ap.add_argument("--retry-errors", action="store_true", help="rerun jobs that raised")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON output")
    ap.add_argument("--page", type=Path, default=PAGE, help="markdown page output")
    ap.add_argument("--no-page", action="store_true", help="do not write the page")
    a = ap.parse_args(argv)
    cfg = BenchConfig(
        captures=a.captures,
        models=a.models,
        per_object=a.per_object,
        density=a.density,
        hands=tuple(a.hands) if a.hands else None,
        modes=tuple(a.modes),
        cases=tuple(a.cases),
        limit=a.limit,
        pairs=tuple(a.pairs),
        originals=a.originals,
        workers=a.workers,
        work=a.work,
        out=a.out,
        page=None if a.no_page else a.page,
        retry_errors=a.retry_errors,
    )
    run_benchmark(cfg)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
