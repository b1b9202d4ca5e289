"""What a picture of a run shows, frame by frame: robot hand, object, human hand, contacts.

A *run directory* is what ``retarget run`` writes (``robot_trajectory.npz``, ``metrics.json``).
:func:`load_run` reads it with checks; :func:`load_human` finds the human demonstration it was
made from (dataset and ``uuid`` are in ``metrics.json``); :func:`record_resimulation` replays the
re-simulation (deterministic: the same object trajectory as the run) and records what
``retarget run`` does not store: the simulated hand joints and every robot contact point with
its force; :func:`scene_data` puts it all into one :class:`SceneData`.

Contacts are kept as padded per-frame arrays (:class:`ContactFrames`), each point with the
force of the hand on the object [N] (world frame) and its hand part: a ``FORCE_GROUPS`` row
(thumb, index, middle, ring, pinky, palm; colours per finger) and a ``CONTACT_PARTS`` index (the
16 hand parts of the DexCanvas contact records; robot bodies are mapped onto them by
:func:`robot_body_parts`).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from dexcanvas_core.table import DEFAULT_TABLE, Table, table_of
from dexcanvas_core.trajectory import CONTACT_PARTS, FORCE_GROUPS, Contacts, Trajectory, part_group
from retarget.viz.errors import VizError

log = logging.getLogger(__name__)

RUN_FILES = ("robot_trajectory.npz", "metrics.json")
"""The files of a run directory (``retarget run``)."""

_NPZ_KEYS = (
    "q",
    "q_command",
    "timestamp",
    "joint_names",
    "object_pos_sim",
    "object_rot_sim",
    "object_pos_err",
    "object_rot_err",
    "finger_force_world",
    "force_parts",
)
_METRICS_KEYS = ("hand", "pair", "uuid", "dataset", "frames", "fps")

# Segments of each human finger as CONTACT_PARTS names, proximal to distal.
_FINGER_SEGMENTS = {
    "thumb": ("thumb_cmc", "thumb_mcp", "thumb_ip"),
    **{f: (f"{f}_mcp", f"{f}_pip", f"{f}_dip") for f in ("index", "middle", "ring", "pinky")},
}


# ---------------------------------------------------------------------------- contacts


@dataclass
class ContactFrames:
    """Contact points of one hand, padded per frame (``N`` = most points in any frame)."""

    pos_world: np.ndarray
    """(T, N, 3) [m] contact points, world frame."""
    force_world: np.ndarray
    """(T, N, 3) [N] force of the hand on the object at each point, world frame."""
    valid: np.ndarray
    """(T, N) bool."""
    group: np.ndarray
    """(T, N) int: row of ``FORCE_GROUPS`` (thumb … pinky, palm); -1 where invalid."""
    part: np.ndarray
    """(T, N) int: index into ``CONTACT_PARTS``; -1 where invalid or unknown."""
    source: str = ""
    """Where the points come from (shown in legends), e.g. ``'re-simulation'``."""

    @property
    def num_frames(self) -> int:
        return self.valid.shape[0]

    @classmethod
    def empty(cls, num_frames: int, source: str = "") -> ContactFrames:
        return cls(
            pos_world=np.zeros((num_frames, 0, 3)),
            force_world=np.zeros((num_frames, 0, 3)),
            valid=np.zeros((num_frames, 0), bool),
            group=np.zeros((num_frames, 0), np.int64),
            part=np.zeros((num_frames, 0), np.int64),
            source=source,
        )

    @classmethod
    def from_contacts(cls, contacts: Contacts, source: str = "demonstration") -> ContactFrames:
        """From a trajectory's contact records (``Trajectory.contacts``)."""
        d = contacts.dense()
        part = d["part"]
        group = np.full(part.shape, -1, np.int64)
        ok = part >= 0
        group[ok] = [part_group(CONTACT_PARTS[p]) for p in part[ok]]
        return cls(
            pos_world=d["pos_world"].astype(np.float64),
            force_world=d["force_world"].astype(np.float64),
            valid=d["valid"],
            group=group,
            part=part,
            source=source,
        )

    @classmethod
    def from_records(
        cls, records: list[list[tuple[np.ndarray, np.ndarray, int, int]]], source: str = ""
    ) -> ContactFrames:
        """From per-frame lists of ``(pos_world, force_world, group, part)``."""
        T = len(records)
        N = max((len(r) for r in records), default=0)
        out = cls.empty(T, source)
        out.pos_world = np.zeros((T, N, 3))
        out.force_world = np.zeros((T, N, 3))
        out.valid = np.zeros((T, N), bool)
        out.group = np.full((T, N), -1, np.int64)
        out.part = np.full((T, N), -1, np.int64)
        for t, rec in enumerate(records):
            for k, (p, f, g, part) in enumerate(rec):
                out.pos_world[t, k] = p
                out.force_world[t, k] = f
                out.valid[t, k] = True
                out.group[t, k] = g
                out.part[t, k] = part
        return out

    def at(self, t: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points (n, 3) [m], forces (n, 3) [N] and groups (n,) of frame ``t``."""
        v = self.valid[t]
        return self.pos_world[t, v], self.force_world[t, v], self.group[t, v]

    def max_per_group(self, frames: np.ndarray | None = None) -> np.ndarray:
        """(6,) most points of one ``FORCE_GROUPS`` row in any of ``frames`` (default: all)."""
        sel = np.arange(self.num_frames) if frames is None else np.asarray(frames)
        out = np.zeros(len(FORCE_GROUPS), np.int64)
        for t in sel:
            g = self.group[t, self.valid[t]]
            if g.size:
                out = np.maximum(out, np.bincount(g, minlength=len(FORCE_GROUPS)))
        return out

    def part_frequency(self) -> np.ndarray:
        """(16,) fraction of frames in which each ``CONTACT_PARTS`` part touches the object."""
        T = self.num_frames
        hit = np.zeros((T, len(CONTACT_PARTS)), bool)
        t_idx, k_idx = np.nonzero(self.valid & (self.part >= 0))
        hit[t_idx, self.part[t_idx, k_idx]] = True
        return hit.mean(axis=0) if T else np.zeros(len(CONTACT_PARTS))


INFER_TOLERANCE_M = 0.002
"""A hand capsule closer than this [m] to the object surface counts as touching it (the
built-in demonstrations keep pads within ±1.5 mm of the surface at contact frames)."""


def infer_contacts(traj: Trajectory, geometry, tol_m: float = INFER_TOLERANCE_M) -> ContactFrames:
    """Contacts of a demonstration that has no contact records, from its keypoints alone.

    The hand is the capsule model of the demonstration generator
    (``dexcanvas_core.demos.hand.CAPSULES``: one capsule per phalanx, five for the palm, default
    hand size); a capsule touches the object where its surface is within ``tol_m`` of the
    object's. The contact point is the object-surface point nearest the capsule's closest axis
    sample; there is no force (zero vectors).
    """
    from dexcanvas_core.mano.hand_model import CAPSULES, SAMPLE_SPACING
    from dexcanvas_core.rotations import aa_to_matrix

    kp = np.asarray(traj.hand.joint_pos, dtype=np.float64)  # (T, 21, 3)
    T = kp.shape[0]
    R = np.asarray(aa_to_matrix(np.asarray(traj.object.rot_aa, dtype=np.float64)))  # (T, 3, 3)
    p_obj = np.asarray(traj.object.pos, dtype=np.float64)
    records: list[list] = [[] for _ in range(T)]
    for cap in CAPSULES:
        a, b = kp[:, cap.a], kp[:, cap.b]
        length = float(np.nanmax(np.linalg.norm(b - a, axis=1)))
        n = max(2, int(np.ceil(length / SAMPLE_SPACING)) + 1)
        s = np.linspace(0.0, 1.0, n)
        pts = a[:, None] + s[None, :, None] * (b - a)[:, None]  # (T, n, 3) world
        local = np.einsum("tji,tnj->tni", R, pts - p_obj[:, None])  # world → object frame
        d = geometry.signed_distance(local) - cap.radius
        k = np.argmin(d, axis=1)
        touching = d[np.arange(T), k] < tol_m
        if not touching.any():
            continue
        t_idx = np.flatnonzero(touching)
        near = geometry.closest_point(local[t_idx, k[t_idx]])  # object frame
        near_world = np.einsum("tij,tj->ti", R[t_idx], near) + p_obj[t_idx]
        g, part = part_group(cap.part), CONTACT_PARTS.index(cap.part)
        for t, q in zip(t_idx, near_world, strict=True):
            records[t].append((q, np.zeros(3), g, part))
    return ContactFrames.from_records(records, source="inferred from keypoints (no forces)")


def human_contacts(traj: Trajectory, geometry) -> ContactFrames:
    """The demonstration's recorded contacts, or contacts inferred from its keypoints."""
    if traj.contacts is not None and traj.contacts.num_pairs:
        return ContactFrames.from_contacts(traj.contacts)
    return infer_contacts(traj, geometry)


# ---------------------------------------------------------------------------- run directory


@dataclass
class RunFiles:
    """The contents of a run directory."""

    run_dir: Path
    metrics: dict
    arrays: dict[str, np.ndarray]
    """Every array of ``robot_trajectory.npz``."""

    @property
    def num_frames(self) -> int:
        return int(self.arrays["q"].shape[0])

    @property
    def timestamp(self) -> np.ndarray:
        return np.asarray(self.arrays["timestamp"], dtype=np.float64)


def load_run(run_dir: str | Path) -> RunFiles:
    """Read a run directory written by ``retarget run``; raise :class:`VizError` naming what is
    missing or malformed."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise VizError(
            f"run directory {str(run_dir)!r} does not exist (make one with retarget run)"
        )
    missing = [f for f in RUN_FILES if not (run_dir / f).is_file()]
    if missing:
        raise VizError(
            f"run directory {str(run_dir)!r} has no {' or '.join(missing)} "
            f"(a run directory holds {', '.join(RUN_FILES)}; make one with retarget run)"
        )
    try:
        metrics = json.loads((run_dir / "metrics.json").read_text())
    except (OSError, ValueError) as e:
        raise VizError(f"{run_dir / 'metrics.json'}: cannot read it as JSON: {e}") from e
    absent = [k for k in _METRICS_KEYS if k not in metrics]
    if absent:
        raise VizError(f"{run_dir / 'metrics.json'}: missing field(s) {', '.join(absent)}")
    try:
        with np.load(run_dir / "robot_trajectory.npz", allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError) as e:
        raise VizError(f"{run_dir / 'robot_trajectory.npz'}: cannot read it: {e}") from e
    absent = [k for k in _NPZ_KEYS if k not in arrays]
    if absent:
        raise VizError(f"{run_dir / 'robot_trajectory.npz'}: missing array(s) {', '.join(absent)}")
    T = arrays["q"].shape[0]
    for k in _NPZ_KEYS:
        if k not in ("joint_names", "force_parts") and arrays[k].shape[0] != T:
            raise VizError(
                f"{run_dir / 'robot_trajectory.npz'}: {k} has {arrays[k].shape[0]} frames, "
                f"q has {T}"
            )
    return RunFiles(run_dir=run_dir, metrics=metrics, arrays=arrays)


def load_human(
    dataset: str | Path | None, pair: str | None, *, uuid: str | None = None, index: int = 0
) -> Trajectory:
    """The human demonstration of ``pair`` in ``dataset`` (``None`` or ``'built-in'``: the
    built-in demonstrations), by ``uuid`` when given, else the ``index``-th of the pair; with a
    dataset and no pair, the row ``index``."""
    from dexcanvas_core.capture import use_dataset_objects
    from dexcanvas_core.io import open_dataset
    from dexcanvas_core.loaders.selection import select_rows
    from dexcanvas_core.taxonomy import Pair

    builtin = dataset is None or str(dataset) == "built-in"
    if builtin:
        from dexcanvas_core.builtin import builtin_demonstration_path

        if pair is None:
            raise VizError("the built-in demonstrations are chosen by pair: give --pair")
        p = Pair.parse(pair)
        path = builtin_demonstration_path(p)
    else:
        path = Path(dataset)
        use_dataset_objects(path)
    ds = open_dataset(path)
    if not builtin and (uuid is not None or pair is None):
        sel = select_rows(ds)
        if uuid is not None:
            if uuid not in sel.uuids:
                raise VizError(
                    f"dataset {str(path)!r} has no demonstration {uuid!r} (the run was made "
                    "from a different dataset?)"
                )
            return ds.take([int(sel.positions[sel.uuids.index(uuid)])])[0]
        if not 0 <= index < len(sel.positions):
            raise VizError(f"index {index} out of range: {path} has {len(sel.positions)} rows")
        return ds.take([int(sel.positions[index])])[0]
    p = Pair.parse(pair)
    sel = select_rows(ds, objects=[p.object.id], manipulation_types=[p.manipulation_type.name])
    if uuid is not None:
        if uuid not in sel.uuids:
            raise VizError(
                f"dataset {str(path)!r} has no demonstration {uuid!r} of {p} (the run was made "
                "from a different dataset?)"
            )
        pos = sel.positions[sel.uuids.index(uuid)]
    else:
        n = len(sel.positions)
        if not 0 <= index < n:
            raise VizError(f"index {index} out of range: {path} has {n} demonstration(s) of {p}")
        pos = sel.positions[index]
    return ds.take([int(pos)])[0]


def load_human_for_run(run: RunFiles) -> Trajectory:
    """The demonstration a run was made from (``metrics.json``: dataset, pair, uuid), executed
    as slowly as the run executed it (``time_scale``, :func:`retarget.run.time_scaled`)."""
    from retarget.run import time_scaled

    m = run.metrics
    traj = time_scaled(
        load_human(m["dataset"], m["pair"], uuid=m["uuid"]), m.get("time_scale", 1.0)
    )
    if traj.num_frames != run.num_frames:
        raise VizError(
            f"demonstration {m['uuid']} has {traj.num_frames} frames, the run in "
            f"{run.run_dir} has {run.num_frames}"
        )
    return traj


# ---------------------------------------------------------------------------- robot contacts


def robot_body_parts(hand, model) -> tuple[np.ndarray, np.ndarray]:
    """Map every body of ``model`` onto the human hand parts.

    Returns ``(group, part)``, each ``(nbody,)`` int: the ``FORCE_GROUPS`` row and the
    ``CONTACT_PARTS`` index of each hand body (-1 for bodies that are not the hand's). A robot
    finger counts as the first human finger (thumb … pinky) mapped onto it; its bodies that
    form rigid segments (a body without joints moves with its parent); the segments that carry
    collision geoms are matched to the human segments: the last three to ``mcp, pip, dip``
    (thumb ``cmc, mcp, ip``) and any before them to ``mcp`` (``cmc``); two segments to ``mcp,
    dip`` (thumb ``mcp, ip``: the distal link stands for the fused distal phalanges); one to
    ``dip`` (``ip``). Bodies hanging off a finger's last body belong to that finger; every
    other hand body is the palm. An approximation: robot links are not phalanges.
    """
    parts = hand.hand_parts(model)
    hand_nbody = hand.compile().nbody  # the hand's bodies come first in every scene
    robot_to_human = hand.robot_to_human
    has_collision = np.zeros(model.nbody, bool)
    for g in range(model.ngeom):
        if model.geom_contype[g] or model.geom_conaffinity[g]:
            has_collision[model.geom_bodyid[g]] = True
    group = np.full(model.nbody, -1, np.int64)
    part = np.full(model.nbody, -1, np.int64)
    palm = FORCE_GROUPS.index("palm")
    for name in parts.get("palm", []):
        b = model.body(name).id
        if b < hand_nbody:
            group[b], part[b] = palm, CONTACT_PARTS.index("palm")
    for robot_finger, human in robot_to_human.items():
        bodies = [model.body(n).id for n in parts.get(robot_finger, [])]
        # Rigid segments, proximal to distal: a body without joints moves with its parent.
        segments: list[list[int]] = []
        for b in bodies:
            if model.body_jntnum[b] > 0 or not segments:
                segments.append([b])
            else:
                segments[-1].append(b)
        solid = [seg for seg in segments if has_collision[seg].any()]
        names = _FINGER_SEGMENTS[human]
        for b in bodies:
            group[b] = FORCE_GROUPS.index(human)
            part[b] = CONTACT_PARTS.index(names[0])
        n = len(solid)
        if n >= 3:
            which = [0] * (n - 3) + [0, 1, 2]
        elif n == 2:  # proximal phalanx + a distal link (middle and distal phalanges fused)
            which = [1, 2] if human == "thumb" else [0, 2]
        else:
            which = [2] * n
        for seg, k in zip(solid, which, strict=True):
            part[seg] = CONTACT_PARTS.index(names[k])
    # Bodies hanging off a finger beyond its tip site (e.g. a fingertip body) belong to it.
    for b in range(1, hand_nbody):  # parents have smaller ids than their children
        parent = model.body_parentid[b]
        if group[b] == palm and group[parent] not in (-1, palm):
            group[b], part[b] = group[parent], part[parent]
    return group, part


@dataclass
class RobotSimRecord:
    """What :func:`record_resimulation` recorded, per data frame."""

    result: object
    """The ``retarget.validate.ValidationResult`` (the run's metrics come from the same)."""
    qpos: np.ndarray
    """(T, hand_nq) simulated hand joint positions at the end of each frame."""
    contacts: ContactFrames
    """Robot contact points at the last physics step of each frame."""


def record_resimulation(
    hand,
    geometry,
    q_command: np.ndarray,
    human: Trajectory,
    progress: Callable[[int, int], None] | None = None,
    metrics: dict | None = None,
) -> RobotSimRecord:
    """Re-simulate ``q_command`` like ``retarget run`` does and record the robot's state.

    ``metrics``: the run's ``metrics.json``; a force-matching run (``"forces": true``) was
    re-simulated with stiff contacts, and is replayed the same way.

    The simulation is the one of ``retarget.validate.Resimulator`` (same model, same settings,
    deterministic); after each data frame the simulated hand joints and every hand–object
    contact (point, force of the hand on the object, hand part) are read from its state.
    """
    import mujoco

    from dexcanvas_core.sim.forces import object_contacts
    from retarget.validate import Resimulator

    class RecordingResimulator(Resimulator):
        last_data: mujoco.MjData | None = None

        def _contact_forces(self, d):  # after every physics step: keep the data to read later
            self.last_data = d
            return super()._contact_forces(d)

    from retarget.run import FORCE_CONTACT_TIMECONST
    from retarget.validate import ValidateConfig

    stiff = bool(metrics and metrics.get("forces"))
    from dexcanvas_core.table import table_of

    sim = RecordingResimulator(
        hand,
        geometry,
        ValidateConfig(contact_timeconst=FORCE_CONTACT_TIMECONST if stiff else None),
        table=table_of(human),
    )
    m = sim.model
    group_of_body, part_of_body = robot_body_parts(hand, m)
    T = human.num_frames
    qpos = np.zeros((T, sim.hand_nq))
    records: list[list] = [[] for _ in range(T)]

    def on_frame(done: int, total: int) -> None:  # called once each frame's steps are done
        t = done - 1
        d = sim.last_data
        qpos[t] = d.qpos[: sim.hand_nq]
        for c in object_contacts(m, d, sim.object_body):
            if group_of_body[c.other_body] < 0:
                continue  # the table
            records[t].append(
                (c.pos, c.force, int(group_of_body[c.other_body]), int(part_of_body[c.other_body]))
            )
        if progress is not None:
            progress(done, total)

    result = sim.run(q_command, human, progress=on_frame)
    return RobotSimRecord(
        result=result,
        qpos=qpos,
        contacts=ContactFrames.from_records(records, source="re-simulation"),
    )


# ---------------------------------------------------------------------------- scene data


@dataclass
class SceneData:
    """Everything drawn, per data frame (world frame, z up, metres)."""

    hand_name: str
    object_id: str
    pair: str
    fps: float
    """Data frame rate [Hz]."""
    timestamp: np.ndarray
    """(T,) [s]."""
    robot_qpos: np.ndarray
    """(T, hand_nq) robot hand joints shown (MuJoCo ``qpos`` order, floating wrist first)."""
    robot_source: Literal["sim", "kinematic"]
    """``sim``: the re-simulated hand; ``kinematic``: the retargeted solution."""
    object_pos: np.ndarray
    """(T, 3) [m] object drawn with the robot (simulated when ``robot_source`` is ``sim``)."""
    object_rot_aa: np.ndarray
    """(T, 3) [rad]."""
    ref_object_pos: np.ndarray
    """(T, 3) [m] the human's object (the reference the simulation must follow)."""
    ref_object_rot_aa: np.ndarray
    human_keypoints: np.ndarray | None
    """(T, 21, 3) [m] MANO21 keypoints of the human hand."""
    human_contacts: ContactFrames | None
    robot_contacts: ContactFrames | None
    metrics: dict
    table: Table = DEFAULT_TABLE
    """The demonstration's table (drawn as its box)."""

    @property
    def num_frames(self) -> int:
        return self.timestamp.shape[0]

    def check_frames(self, frames) -> np.ndarray:
        """``frames`` as an int array; :class:`VizError` for any outside ``0 … T-1``."""
        out = np.asarray(list(frames), dtype=np.int64)
        T = self.num_frames
        bad = out[(out < 0) | (out >= T)]
        if bad.size:
            raise VizError(
                f"frame {int(bad[0])} out of range: {self.pair} on {self.hand_name} has "
                f"{T} frames (0–{T - 1})"
            )
        return out


def scene_data(
    run: RunFiles,
    human: Trajectory | None,
    *,
    hand=None,
    robot_source: Literal["sim", "kinematic"] = "sim",
    sim: RobotSimRecord | None = None,
) -> SceneData:
    """Combine a run, its human demonstration and (for ``robot_source='sim'``) a recorded
    re-simulation (made here when ``sim`` is None) into what the renderers draw."""
    from dexcanvas_core.objects.geometry import object_geometry

    if robot_source not in ("sim", "kinematic"):
        raise VizError(f"robot_source must be 'sim' or 'kinematic', got {robot_source!r}")
    m = run.metrics
    object_id = (m.get("object") or {}).get("id") or m["pair"].split("/", 1)[0]
    if hand is None:
        from retarget.hands import get_hand

        hand = get_hand(m["hand"])
    a = run.arrays
    T = run.num_frames
    if human is not None and human.num_frames != T:
        raise VizError(f"the demonstration has {human.num_frames} frames, the run has {T}")
    robot_contacts = None
    if robot_source == "sim":
        if sim is None:
            if human is None:
                raise VizError("showing the re-simulated hand needs the human demonstration")
            sim = record_resimulation(
                hand, object_geometry(object_id), a["q_command"], human, metrics=m
            )
        qpos = sim.qpos
        robot_contacts = sim.contacts
        obj_pos, obj_rot = a["object_pos_sim"], a["object_rot_sim"]
    else:
        qpos = a["q"]
        obj_pos = human.object.pos if human is not None else a["object_pos_sim"]
        obj_rot = human.object.rot_aa if human is not None else a["object_rot_sim"]
    if human is not None:
        ref_pos, ref_rot = human.object.pos, human.object.rot_aa
        kp = human.hand.joint_pos
        hc = human_contacts(human, object_geometry(object_id))
    else:
        ref_pos, ref_rot, kp, hc = obj_pos, obj_rot, None, None
    return SceneData(
        hand_name=hand.name,
        object_id=object_id,
        pair=str(m["pair"]),
        fps=float(m["fps"]),
        timestamp=run.timestamp,
        robot_qpos=np.asarray(qpos, dtype=np.float64),
        robot_source=robot_source,
        object_pos=np.asarray(obj_pos, dtype=np.float64),
        object_rot_aa=np.asarray(obj_rot, dtype=np.float64),
        ref_object_pos=np.asarray(ref_pos, dtype=np.float64),
        ref_object_rot_aa=np.asarray(ref_rot, dtype=np.float64),
        human_keypoints=None if kp is None else np.asarray(kp, dtype=np.float64),
        human_contacts=hc,
        robot_contacts=robot_contacts,
        metrics=m,
        table=table_of(human) if human is not None else DEFAULT_TABLE,
    )
