"""The human-simulation cache (``--human-cache DIR``): each (demonstration, object, tracker
configuration, force-pipeline source) simulated once is stored under a key of those
(:func:`human_cache_key`) and read back by later runs instead of simulated again.

An entry is two files in ``DIR``, written atomically (temporary file, then rename), the record
last so that an entry with a readable record is complete:

* ``<key>.npz`` — the force-annotated demonstration's arrays (``numpy.savez``, read with
  ``allow_pickle=False``): every array of the ``Trajectory`` and its tracks and contacts, by
  field path; strings arrays stored as unicode and given back as the object arrays they were;
* ``<key>.json`` — the simulation's record (metrics, or its error) and the trajectory's
  structure: its dataclasses (only the trajectory's own, :data:`CLASSES`), their scalar fields,
  lists, tuples and dicts, and a reference to its array in the ``.npz`` where a field holds one.

The trajectory read back is the stored one exactly: the same classes, field values, array
dtypes, shapes and bytes (``tests/test_force_benchmark_options.py``). Nothing in a cache file
runs code when read (no pickle), so a cache directory can be shared.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
from functools import cache
from pathlib import Path

import numpy as np

import dexcanvas_core
from benchmarks._common import atomic_write_json
from dexcanvas_core.safe_io import atomic_write_bytes
from dexcanvas_core.table import Table
from dexcanvas_core.trajectory import Contacts, HandTrack, ObjectMove, ObjectTrack, Trajectory
from retarget.human_forces import human_sim_config

CLASSES = {c.__name__: c for c in (Trajectory, HandTrack, ObjectTrack, ObjectMove, Contacts, Table)}
"""The dataclasses a cached trajectory may hold, by name."""
FORMAT = 1
"""Version of the entry layout, stored in the record (a different one is simulated again)."""


@cache
def _sim_sources_digest() -> str:
    """Digest of the force pipeline's source (``dexcanvas_core.sim``, ``.mano``): a cached
    human simulation is only reused by the code that made it (read once per process)."""
    root = Path(dexcanvas_core.__file__).parent
    h = hashlib.sha256()
    for sub in ("sim", "mano"):
        for f in sorted((root / sub).rglob("*.py")):
            h.update(f.relative_to(root).as_posix().encode())
            h.update(f.read_bytes())
    return h.hexdigest()


def human_cache_key(traj, object_id: str, tracker: str, mpc_seed: int | None = None) -> str:
    """File stem of one human simulation in the cache: the demonstration's data, the object,
    the tracker's configuration (the replay's seed included) and the force pipeline's source."""
    h = hashlib.sha256()
    h.update(repr(human_sim_config(object_id, tracker, mpc_seed)).encode())
    h.update(_sim_sources_digest().encode())
    h.update(str(traj.uuid).encode())
    hand, obj = traj.hand, traj.object
    arrays = (traj.timestamp, hand.global_pos, hand.global_rot_aa, hand.finger_pose, hand.betas,
              obj.pos, obj.rot_aa)  # fmt: skip
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return f"{object_id}-{tracker}-{h.hexdigest()[:24]}"


def encode(value, arrays: dict, path: str = "t"):
    """``value`` as JSON-able data; its arrays (numpy arrays and scalars) go into ``arrays``
    under their field path and are referenced as ``{"array": path}``."""
    if isinstance(value, np.ndarray | np.generic):
        a = np.asarray(value)
        ref = {"array": path, "scalar": isinstance(value, np.generic)}
        if a.dtype == object:
            if not all(isinstance(x, str) for x in a.flat):
                raise TypeError(f"{path}: an object array holds other values than strings")
            a, ref["object"] = a.astype(str), True
        arrays[path] = a
        return ref
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        name = type(value).__name__
        if CLASSES.get(name) is not type(value):
            raise TypeError(f"{path}: {name} is not a trajectory class")
        fields = {f.name: encode(getattr(value, f.name), arrays, f"{path}.{f.name}")
                  for f in dataclasses.fields(value)}  # fmt: skip
        return {"class": name, "fields": fields}
    if isinstance(value, list | tuple):
        items = [encode(v, arrays, f"{path}[{i}]") for i, v in enumerate(value)]
        return {"list": items} if isinstance(value, list) else {"tuple": items}
    if isinstance(value, dict):
        if not all(isinstance(k, str) for k in value):
            raise TypeError(f"{path}: a dict with keys other than strings")
        return {"dict": {k: encode(v, arrays, f"{path}[{k!r}]") for k, v in value.items()}}
    if value is None or isinstance(value, bool | int | float | str):
        return {"value": value}
    raise TypeError(f"{path}: {type(value).__name__} cannot be cached")


def decode(data, arrays):
    """The value :func:`encode` turned into ``data`` (its arrays from ``arrays``); dataclasses
    are rebuilt field by field as stored (their ``__post_init__`` does not run again)."""
    if "array" in data:
        a = arrays[data["array"]]
        if data.get("object"):
            a = a.astype(object)
        return a[()] if data["scalar"] else a
    if "class" in data:
        cls = CLASSES[data["class"]]
        obj = cls.__new__(cls)
        for k, v in data["fields"].items():
            object.__setattr__(obj, k, decode(v, arrays))
        return obj
    if "list" in data:
        return [decode(v, arrays) for v in data["list"]]
    if "tuple" in data:
        return tuple(decode(v, arrays) for v in data["tuple"])
    if "dict" in data:
        return {k: decode(v, arrays) for k, v in data["dict"].items()}
    return data["value"]


def _paths(cache_dir: Path, key: str) -> tuple[Path, Path]:
    """``(record, arrays)`` paths of cache entry ``key``: ``<key>.json`` and ``<key>.npz``."""
    cache_dir = Path(cache_dir)
    return cache_dir / f"{key}.json", cache_dir / f"{key}.npz"


def load_human_sim(cache_dir: Path, key: str, console=None) -> dict | None:
    """The cached ``_human_sim`` result ``key`` (``{"record", "trajectory"}``, the record
    marked ``cached``), or ``None`` (absent, or unreadable: said on the console and simulated
    again)."""
    rec_path, npz_path = _paths(cache_dir, key)
    if not rec_path.is_file():
        return None
    try:
        doc = json.loads(rec_path.read_text())
        if not (isinstance(doc, dict) and isinstance(doc.get("record"), dict)):
            raise ValueError("not a human simulation record")
        if doc.get("format") != FORMAT:
            raise ValueError(f"format {doc.get('format')!r}, not {FORMAT}")
        traj = None
        if doc["trajectory"] is not None:
            with np.load(npz_path, allow_pickle=False) as z:
                traj = decode(doc["trajectory"], {k: z[k] for k in z.files})
            if not isinstance(traj, Trajectory):
                raise ValueError("not a trajectory")
    except Exception as e:  # a truncated or foreign entry: simulate again, overwrite it
        if console is not None:
            console.print(
                f"[yellow]human cache: {rec_path.name} unreadable ({e}); simulating again"
            )
        return None
    return {"record": {**doc["record"], "cached": True}, "trajectory": traj}


def store_human_sim(cache_dir: Path, key: str, res: dict) -> None:
    """Write ``res`` (``{"record", "trajectory"}``) to the cache: the arrays, then the record
    (module docstring)."""
    rec_path, npz_path = _paths(cache_dir, key)
    arrays: dict = {}
    traj = None if res["trajectory"] is None else encode(res["trajectory"], arrays)
    if traj is not None:
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        atomic_write_bytes(npz_path, buf.getvalue())
    atomic_write_json(rec_path, {"format": FORMAT, "record": res["record"], "trajectory": traj})
