"""The cases: stress captures written and imported once, real captures found and imported, the cases
of a dataset."""

from __future__ import annotations

import hashlib
import json
import os
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path

from benchmarks.real_motion.config import CAPTURE_SETS, DEXYCB_ITEMS, stress_motions
from dexcanvas_core.capture import ImportConfig, run_import, use_dataset_objects
from dexcanvas_core.capture.export import geometry_mesh, trajectory_to_arrays, write_mano_npz
from dexcanvas_core.capture.formats import READERS
from dexcanvas_core.capture.stress import hold_range, peaks, stress_arrays
from dexcanvas_core.io import open_dataset
from dexcanvas_core.loaders.selection import load_demonstration
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.objects.mesh import load_object_mesh
from dexcanvas_core.safe_io import atomic_write_text
from dexcanvas_core.safe_pickle import load_pickle  # comes with the ho3d reader


def slug(s: str) -> str:
    """``s`` as a file name: runs of other characters than letters, digits and ``_.+-`` become
    ``_``."""
    return re.sub(r"[^A-Za-z0-9_.+-]+", "_", s)


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

    traj = load_demonstration(pair)
    return trajectory_to_arrays(traj, geometry_mesh(object_geometry(traj.object.name)))


def mesh_check(arrays: dict, work: Path) -> None:
    """Raise the import's error when the arrays' object mesh is not a closed surface."""
    import trimesh

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
    atomic_write_text(stamp, json.dumps(doc, default=str, indent=1))
    return True, doc


def build_stress_cases(work: Path, pairs, originals: bool, console) -> tuple[list[Case], list]:
    """The stress cases, imported into ``work/stress.lance`` (reused when unchanged)."""
    motions = stress_motions()

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
        readers = READERS
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
                out = work / label / f"{slug(subject.name)}.lance"
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
            out = work / label / f"{slug(p.stem if p.is_file() else p.name)}.lance"
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
