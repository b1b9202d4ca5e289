"""Contact forces between the simulated hand and the object, per physics step and per frame.

Recipe (DESIGN.md, "Physics conventions"): ``mujoco.mj_contactForce`` gives each contact's force
in its contact frame (rows of ``contact.frame``: normal, t1, t2); rotated into the world, it is
the force on ``geom[1]``, so it is flipped when the object is ``geom[0]``. Contacts and constraint
forces are read right after ``mj_step``: both belong to the forward pass of the step just taken
(the state before integration), the same pass whose ``qacc`` moved the object.

Per data frame the forces are averaged over its physics steps. A contact *pair* of the output is
one hand geom against one object geom (MuJoCo may report several points for it): its force is
the frame-average of the summed force, its position the force-weighted mean point. The object
wrench is taken about the object's centre of mass and includes the torsional-friction torques of
condim-4 contacts.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from dexcanvas_core.trajectory import CONTACT_PARTS, FORCE_GROUPS, Contacts, part_group


@dataclass(frozen=True)
class ObjectContact:
    """One MuJoCo contact touching the object, in the world frame."""

    index: int  # into data.contact
    object_geom: int
    other_geom: int
    other_body: int
    pos: np.ndarray  # (3,) [m]
    normal: np.ndarray  # (3,) unit, from the other geom into the object
    force: np.ndarray  # (3,) [N] on the object
    torque: np.ndarray  # (3,) [N·m] torsional/rolling torque on the object
    dist: float  # signed distance [m] (negative: penetration)


def object_contacts(model: mujoco.MjModel, data: mujoco.MjData, object_body: int):
    """Every active contact between ``object_body`` and anything else (the recipe of the module
    docstring: the contact-frame force acts on ``geom[1]``, flipped when the object is
    ``geom[0]``). The one reader of contact forces for the force pipeline, the robot
    re-simulation and the visualisation."""
    f6 = np.zeros(6)
    for i in range(data.ncon):
        c = data.contact[i]
        g1, g2 = int(c.geom1), int(c.geom2)
        b1, b2 = model.geom_bodyid[g1], model.geom_bodyid[g2]
        if b2 == object_body and b1 != object_body:
            obj, other, sign = g2, g1, 1.0
        elif b1 == object_body and b2 != object_body:
            obj, other, sign = g1, g2, -1.0
        else:
            continue
        if c.efc_address < 0:
            continue
        mujoco.mj_contactForce(model, data, i, f6)
        R = c.frame.reshape(3, 3)  # rows: normal (geom1 → geom2), t1, t2 (world)
        yield ObjectContact(
            index=i,
            object_geom=obj,
            other_geom=other,
            other_body=int(model.geom_bodyid[other]),
            pos=c.pos.copy(),
            normal=sign * R[0],
            force=sign * (R.T @ f6[:3]),
            torque=sign * (R.T @ f6[3:]),
            dist=float(c.dist),
        )


@dataclass
class StepContacts:
    """Hand–object and table–object contacts of one physics step (world frame, on the object)."""

    hand_geom: np.ndarray  # (n,) hand geom id
    obj_geom: np.ndarray  # (n,)
    pos: np.ndarray  # (n, 3) [m]
    normal: np.ndarray  # (n, 3) unit, pointing from the hand into the object
    force: np.ndarray  # (n, 3) [N] on the object
    torque: np.ndarray  # (n, 3) [N·m] torsional/rolling torque on the object
    table_force: np.ndarray  # (3,) [N] table on object
    table_torque_com: np.ndarray  # (3,) [N·m] about the object COM


def read_contacts(scene, data: mujoco.MjData) -> StepContacts:
    """The contacts acting on the object in ``data`` (after ``mj_step`` or ``mj_forward``)."""
    hand_part = scene.hand.geom_part
    com = data.xipos[scene.object_body]
    hg, og, pos, nrm, frc, trq = [], [], [], [], [], []
    table_f = np.zeros(3)
    table_t = np.zeros(3)
    for c in object_contacts(scene.model, data, scene.object_body):
        if c.other_geom == scene.table_geom:
            table_f += c.force
            table_t += np.cross(c.pos - com, c.force) + c.torque
            continue
        if c.other_geom not in hand_part:
            continue
        hg.append(c.other_geom)
        og.append(c.object_geom)
        pos.append(c.pos)
        nrm.append(c.normal)
        frc.append(c.force)
        trq.append(c.torque)

    def arr(x, shape):
        return np.asarray(x, dtype=np.float64).reshape(shape)

    n = len(hg)
    return StepContacts(
        hand_geom=np.asarray(hg, dtype=np.int64),
        obj_geom=np.asarray(og, dtype=np.int64),
        pos=arr(pos, (n, 3)),
        normal=arr(nrm, (n, 3)),
        force=arr(frc, (n, 3)),
        torque=arr(trq, (n, 3)),
        table_force=table_f,
        table_torque_com=table_t,
    )


def wrench_about_com(sc: StepContacts, com: np.ndarray) -> np.ndarray:
    """``(6,)`` force [N] and torque about ``com`` [N·m] of the hand contacts on the object."""
    F = sc.force.sum(axis=0)
    tau = np.cross(sc.pos - com, sc.force).sum(axis=0) + sc.torque.sum(axis=0)
    return np.concatenate([F, tau])


@dataclass
class FrameAccumulator:
    """Averages the contacts of one data frame's physics steps (see the module docstring)."""

    substeps: int
    pairs: dict[tuple[int, int], list] = field(default_factory=dict)
    wrench: np.ndarray = field(default_factory=lambda: np.zeros(6))
    table: np.ndarray = field(default_factory=lambda: np.zeros(6))

    def add(self, sc: StepContacts, com: np.ndarray) -> None:
        self.wrench += wrench_about_com(sc, com) / self.substeps
        self.table += np.concatenate([sc.table_force, sc.table_torque_com]) / self.substeps
        for k in range(sc.hand_geom.shape[0]):
            key = (int(sc.hand_geom[k]), int(sc.obj_geom[k]))
            acc = self.pairs.setdefault(key, [np.zeros(3), np.zeros(3), np.zeros(3), 0.0])
            fn = float(np.linalg.norm(sc.force[k])) + 1e-12
            acc[0] += sc.force[k] / self.substeps  # frame-average force
            acc[1] += fn * sc.pos[k]  # force-weighted position
            acc[2] += fn * sc.normal[k]
            acc[3] += fn


@dataclass
class FrameContacts:
    """One frame's averaged hand–object contact pairs (world frame)."""

    hand_geom: np.ndarray  # (n,)
    pos: np.ndarray  # (n, 3)
    normal: np.ndarray  # (n, 3)
    force: np.ndarray  # (n, 3) on the object [N]
    wrench: np.ndarray  # (6,) hand on object, about the COM
    table_wrench: np.ndarray  # (6,) table on object, about the COM


def finish_frame(acc: FrameAccumulator) -> FrameContacts:
    keys = sorted(acc.pairs)
    n = len(keys)
    pos = np.zeros((n, 3))
    nrm = np.zeros((n, 3))
    frc = np.zeros((n, 3))
    for i, k in enumerate(keys):
        f, pw, nw, w = acc.pairs[k]
        frc[i] = f
        pos[i] = pw / w
        nn = np.linalg.norm(nw)
        nrm[i] = nw / nn if nn > 0 else 0.0
    return FrameContacts(
        hand_geom=np.array([k[0] for k in keys], dtype=np.int64),
        pos=pos,
        normal=nrm,
        force=frc,
        wrench=acc.wrench.copy(),
        table_wrench=acc.table.copy(),
    )


@dataclass
class FramePoses:
    """Frames needed to express contacts in the public layout's four frames."""

    R_wrist: np.ndarray  # (3, 3)
    p_wrist: np.ndarray  # (3,)
    R_obj: np.ndarray
    p_obj: np.ndarray
    R_body: dict[int, np.ndarray]  # hand geom id → its body's rotation
    p_body: dict[int, np.ndarray]


def contacts_from_frames(
    frames: list[FrameContacts],
    poses: list[FramePoses],
    scene,
    object_name: str,
    hand_name: str = "right",
    min_force: float = 1e-4,
) -> Contacts:
    """Records (one per frame and hand part) in the DexCanvas layout, with the full force per
    point (``force_world``). Pairs carrying less than ``min_force`` [N] are dropped."""
    part_of = scene.hand.geom_part
    rec_frame, rec_part, totals = [], [], {k: [] for k in _TOTALS}
    offsets = [0]
    pairs = {k: [] for k in _PAIRS}
    fworld = []
    for t, (fc, ps) in enumerate(zip(frames, poses, strict=True)):
        keep = np.linalg.norm(fc.force, axis=1) > min_force
        parts = np.array([CONTACT_PARTS.index(part_of[g]) for g in fc.hand_geom], dtype=np.int64)
        for part in np.unique(parts[keep]):
            sel = np.flatnonzero(keep & (parts == part))
            g0 = int(fc.hand_geom[sel[0]])
            Rb, pb = ps.R_body[g0], ps.p_body[g0]
            F = fc.force[sel].sum(axis=0)
            rec_frame.append(t)
            rec_part.append(CONTACT_PARTS[part])
            totals["total_force_world"].append(F)
            totals["total_force_wrist"].append(ps.R_wrist.T @ F)
            totals["total_force_joint"].append(Rb.T @ F)
            totals["total_force_object"].append(ps.R_obj.T @ F)
            for i in sel:
                p, f, nrm = fc.pos[i], fc.force[i], fc.normal[i]
                pairs["force_normal"].append((f @ nrm) * nrm)
                pairs["pos_world"].append(p)
                pairs["pos_wrist"].append(ps.R_wrist.T @ (p - ps.p_wrist))
                pairs["pos_joint"].append(Rb.T @ (p - pb))
                pairs["pos_object"].append(ps.R_obj.T @ (p - ps.p_obj))
                fworld.append(f)
            offsets.append(offsets[-1] + len(sel))
    K = len(rec_frame)
    P = offsets[-1]
    return Contacts(
        num_frames=len(frames),
        frame=np.asarray(rec_frame, dtype=np.int64),
        hand_name=[hand_name] * K,
        joint_name=rec_part,
        object_name=[object_name] * K,
        totals={k: np.asarray(v, np.float32).reshape(K, 3) for k, v in totals.items()},
        pair_offsets=np.asarray(offsets, dtype=np.int64),
        pairs={k: np.asarray(v, np.float32).reshape(P, 3) for k, v in pairs.items()},
        force_world=np.asarray(fworld, np.float32).reshape(P, 3),
    )


_TOTALS = ("total_force_world", "total_force_wrist", "total_force_joint", "total_force_object")
_PAIRS = ("force_normal", "pos_world", "pos_wrist", "pos_joint", "pos_object")


def finger_force_series(frames: list[FrameContacts], scene) -> np.ndarray:
    """``(T, 6, 3)`` [N] hand force on the object per ``FORCE_GROUPS`` row (thumb … pinky, palm)."""
    out = np.zeros((len(frames), len(FORCE_GROUPS), 3))
    part_of = scene.hand.geom_part
    for t, fc in enumerate(frames):
        for g, f in zip(fc.hand_geom, fc.force, strict=True):
            out[t, part_group(part_of[int(g)])] += f
    return out
