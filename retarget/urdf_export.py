"""A kinematic URDF of a hand's compiled ``MjModel``, exact to double precision.

:func:`export_urdf` writes one link per MuJoCo body (same name, same frame), a
revolute/prismatic joint per hinge/slide with the MuJoCo anchor, axis and range, a chain of
intermediate links where a body carries several joints (MuJoCo composes them in order), one
fixed-joint link per MuJoCo site (same name, same frame), and the model's couplings as URDF
``<mimic>`` joints (joint equalities ``q_f = c0 + c1 q_l``; Shadow's J1/J0 coupling tendons at
the middle of their range; :func:`model_couplings`). The 6-DoF floating wrist
(``wrist_tx/ty/tz`` slides, ``wrist_rx/ry/rz`` hinges) becomes three prismatic and three
revolute joints with the same names, axes and order, i.e. exactly dex-retargeting's own "dummy
free joint" chain (x, y, z translations, then intrinsic x, y, z rotations). Read by
dex-retargeting (:mod:`retarget.baselines.dex_retargeting`) and pytorch-kinematics
(:mod:`retarget.torch_fk`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from dexcanvas_core.safe_io import atomic_write_text
from retarget.errors import RetargetError
from retarget.hands.build import coupling_tendons

ROOT_LINK = "mj_world"
"""URDF root link: MuJoCo's world body frame."""


@dataclass(frozen=True)
class Mimic:
    """URDF mimic: ``q[follower] = multiplier * q[leader] + offset`` (radians or metres)."""

    follower: str
    leader: str
    multiplier: float
    offset: float
    source: str
    """Where the coupling comes from (``equality <name>`` or ``tendon <name>``)."""


@dataclass(frozen=True)
class UrdfExport:
    """What :func:`export_urdf` wrote."""

    path: Path
    joint_names: list[str]
    """Movable URDF joints in MuJoCo ``qpos`` order (the same names as MuJoCo's joints)."""
    site_links: dict[str, str]
    """MuJoCo site → URDF link of the same frame (fixed joint to its body's link): the site's
    name, or ``<site>__site`` when a body has that name."""
    body_links: dict[str, str]
    """MuJoCo body → URDF link of the same frame."""
    mimics: list[Mimic] = field(default_factory=list)


def _fmt(x: float) -> str:
    # repr() is the shortest string that parses back to the same double: the URDF is exact.
    return repr(float(x))


def _vec(v) -> str:
    return " ".join(_fmt(x) for x in v)


def _rpy(R: np.ndarray) -> np.ndarray:
    """URDF roll-pitch-yaw of ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (fixed axes x, y, z)."""
    with warnings.catch_warnings():
        # At pitch ±90° scipy sets yaw to 0 and warns; the angles still give R exactly.
        warnings.filterwarnings("ignore", message="Gimbal lock detected")
        return Rotation.from_matrix(R).as_euler("xyz")


def _quat_to_R(q: np.ndarray) -> np.ndarray:
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, np.asarray(q, dtype=np.float64))
    return R.reshape(3, 3)


def _origin(R: np.ndarray, p: np.ndarray) -> str:
    return f'<origin xyz="{_vec(p)}" rpy="{_vec(_rpy(R))}"/>'


def mj_name(m: mujoco.MjModel, obj: mujoco.mjtObj, i: int, fallback: str) -> str:
    """The name of MuJoCo object ``i`` of type ``obj``, or ``<fallback><i>`` when it has none."""
    return mujoco.mj_id2name(m, obj, i) or f"{fallback}{i}"


def model_couplings(m: mujoco.MjModel) -> list[Mimic]:
    """The model's couplings as mimic relations, chains resolved to their root leader.

    Joint equalities ``q₁ − q₁⁰ = c₀ + c₁ (q₂ − q₂⁰)`` (MuJoCo's polycoef, relative to
    ``qpos0``) and the narrow two-joint coupling tendons (``retarget.hands.build.
    coupling_tendons``: ``a q_a + b q_b`` held inside a ≤ 2 mm range, taken at its middle; the
    follower is the joint without an actuator) become ``q_f = multiplier · q_l + offset``.

    Raises:
        RetargetError: a nonlinear (degree > 1) joint equality, or a joint coupled to a constant.
    """

    def jname(j: int) -> str:
        return mj_name(m, mujoco.mjtObj.mjOBJ_JOINT, j, "joint")

    q0 = m.qpos0
    direct: dict[str, tuple[str, float, float, str]] = {}
    for e in range(m.neq):
        if not m.eq_active0[e] or m.eq_type[e] != mujoco.mjtEq.mjEQ_JOINT:
            continue
        ename = mj_name(m, mujoco.mjtObj.mjOBJ_EQUALITY, e, "equality")
        j1, j2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
        c = np.asarray(m.eq_data[e, :5], dtype=np.float64)
        if j2 < 0:
            raise RetargetError(
                f"equality {ename!r} fixes joint {jname(j1)!r} to a constant; a URDF mimic "
                "needs a leader joint"
            )
        if np.any(np.abs(c[2:]) > 0):
            raise RetargetError(
                f"equality {ename!r} is a polynomial of degree > 1 (polycoef {c.tolist()}); "
                "URDF mimic joints are linear"
            )
        a1, a2 = q0[m.jnt_qposadr[j1]], q0[m.jnt_qposadr[j2]]
        direct[jname(j1)] = (
            jname(j2),
            float(c[1]),
            float(a1 + c[0] - c[1] * a2),
            f"equality {ename}",
        )
    actuated = {int(m.actuator_trnid[a, 0]) for a in range(m.nu)
                if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT}  # fmt: skip
    for t in coupling_tendons(m):
        adr, num = int(m.tendon_adr[t]), int(m.tendon_num[t])
        if num != 2:
            continue
        (ja, ca), (jb, cb) = ((int(m.wrap_objid[w]), float(m.wrap_prm[w])) for w in (adr, adr + 1))
        mid = float(m.tendon_range[t].mean())
        # Follower: the joint nobody drives (the linkage moves it); else the first one.
        fol, cf, lead, cl = (jb, cb, ja, ca) if (ja in actuated and jb not in actuated) else (
            ja, ca, jb, cb)  # fmt: skip
        # cf q_f + cl q_l = mid  →  q_f = −cl/cf q_l + mid/cf
        tname = mj_name(m, mujoco.mjtObj.mjOBJ_TENDON, t, "tendon")
        direct[jname(fol)] = (jname(lead), -cl / cf, mid / cf, f"tendon {tname}")
    out = []
    for fol, (lead, mul, off, src) in direct.items():
        seen = {fol}
        while lead in direct:  # a leader that follows another joint: compose
            if lead in seen:
                raise RetargetError(f"coupling cycle through joint {lead!r}")
            seen.add(lead)
            nxt, mul2, off2, _ = direct[lead]
            lead, mul, off = nxt, mul * mul2, mul * off2 + off
        out.append(Mimic(fol, lead, mul, off, src))
    return out


def export_urdf(
    model: mujoco.MjModel,
    path: str | Path,
    *,
    robot_name: str = "hand",
    couplings: bool = True,
    hinge_limit: float = 2 * np.pi,
    slide_limit: float = 10.0,
) -> UrdfExport:
    """Write a kinematic URDF of a compiled hand ``MjModel`` (hinge and slide joints only).

    Every MuJoCo body becomes a link of the same name and frame; a body's joints become a chain
    ``<parent> →(joint 1)→ <body>__<joint 1> → … →(joint k)→ <body>__<joint k> →(fixed)→
    <body>``, each joint at its MuJoCo anchor with its axis; every site becomes a link (fixed
    joint) of the same name (``<site>__site`` if a body has it) and frame. Limited joints keep
    their range; unlimited hinges get ``±hinge_limit`` [rad] and unlimited slides
    ``±slide_limit`` [m] (URDF revolute and
    prismatic joints need limits; a ``continuous`` joint would be a 2-coordinate joint in
    Pinocchio). Inertials carry each body's mass, centre of mass and principal inertia.
    ``couplings`` adds :func:`model_couplings` as ``<mimic>`` elements (Pinocchio ignores them
    unless asked; dex-retargeting applies them).

    Raises:
        RetargetError: a free or ball joint, or a site/body name that would clash.
    """
    m = model
    path = Path(path)
    bname = [mj_name(m, mujoco.mjtObj.mjOBJ_BODY, b, "body") for b in range(m.nbody)]
    bname[0] = ROOT_LINK
    links: list[str] = []
    joints: list[str] = []
    used: set[str] = set()

    def add_link(name: str, body: int | None = None) -> None:
        if name in used:
            raise RetargetError(f"URDF export: link name {name!r} is used twice")
        used.add(name)
        inertial = ""
        if body is not None and body > 0 and m.body_mass[body] > 0:
            Ri = _quat_to_R(m.body_iquat[body])
            I = np.asarray(m.body_inertia[body], dtype=np.float64)
            inertial = (
                f"<inertial>{_origin(Ri, m.body_ipos[body])}"
                f'<mass value="{_fmt(m.body_mass[body])}"/>'
                f'<inertia ixx="{_fmt(I[0])}" ixy="0" ixz="0" iyy="{_fmt(I[1])}" iyz="0" '
                f'izz="{_fmt(I[2])}"/></inertial>'
            )
        links.append(f"  <link name={quoteattr(name)}>{inertial}</link>")

    mimics = {mm.follower: mm for mm in model_couplings(m)} if couplings else {}
    joint_order: list[str] = []
    add_link(ROOT_LINK)
    for b in range(1, m.nbody):
        parent = bname[int(m.body_parentid[b])]
        R_pb = _quat_to_R(m.body_quat[b])
        p_pb = np.asarray(m.body_pos[b], dtype=np.float64)
        jids = [j for j in range(m.njnt) if m.jnt_bodyid[j] == b]
        if not jids:
            add_link(bname[b], b)
            joints.append(
                f'  <joint name={quoteattr(f"{bname[b]}__fixed")} type="fixed">'
                f"<parent link={quoteattr(parent)}/><child link={quoteattr(bname[b])}/>"
                f"{_origin(R_pb, p_pb)}</joint>"
            )
            continue
        prev_link, R_o, p_o, anchor_prev = parent, R_pb, p_pb, np.zeros(3)
        for j in jids:
            jtype = int(m.jnt_type[j])
            jn = mj_name(m, mujoco.mjtObj.mjOBJ_JOINT, j, "joint")
            if jtype == mujoco.mjtJoint.mjJNT_HINGE:
                kind, lim = "revolute", hinge_limit
            elif jtype == mujoco.mjtJoint.mjJNT_SLIDE:
                kind, lim = "prismatic", slide_limit
            else:
                raise RetargetError(
                    f"URDF export: joint {jn!r} is a free or ball joint; only hinge and slide "
                    "joints can be exported"
                )
            anchor = np.asarray(m.jnt_pos[j], dtype=np.float64)
            # Joint frame in the previous link: the previous frame moved to this anchor.
            p_j = p_o + R_o @ (anchor - anchor_prev)
            lo, hi = m.jnt_range[j] if m.jnt_limited[j] else (-lim, lim)
            child = f"{bname[b]}__{jn}"
            add_link(child)
            mim = mimics.get(jn)
            mimic_xml = (
                f'<mimic joint={quoteattr(mim.leader)} multiplier="{_fmt(mim.multiplier)}" '
                f'offset="{_fmt(mim.offset)}"/>'
                if mim is not None
                else ""
            )
            joints.append(
                f'  <joint name={quoteattr(jn)} type="{kind}"><parent link={quoteattr(prev_link)}/>'
                f"<child link={quoteattr(child)}/>{_origin(R_o, p_j)}"
                f'<axis xyz="{_vec(m.jnt_axis[j])}"/>'
                f'<limit lower="{_fmt(lo)}" upper="{_fmt(hi)}" effort="1000" velocity="1000"/>'
                f"{mimic_xml}</joint>"
            )
            joint_order.append(jn)
            prev_link, R_o, p_o, anchor_prev = child, np.eye(3), np.zeros(3), anchor
        add_link(bname[b], b)
        joints.append(
            f'  <joint name={quoteattr(f"{bname[b]}__fixed")} type="fixed">'
            f"<parent link={quoteattr(prev_link)}/><child link={quoteattr(bname[b])}/>"
            f"{_origin(np.eye(3), -anchor_prev)}</joint>"
        )
    site_links = {}
    for s in range(m.nsite):
        sn = mj_name(m, mujoco.mjtObj.mjOBJ_SITE, s, "site")
        link = sn if sn not in used else f"{sn}__site"  # a body may share the site's name
        add_link(link)
        joints.append(
            f'  <joint name={quoteattr(f"{link}__fixed")} type="fixed">'
            f"<parent link={quoteattr(bname[int(m.site_bodyid[s])])}/>"
            f"<child link={quoteattr(link)}/>"
            f"{_origin(_quat_to_R(m.site_quat[s]), m.site_pos[s])}</joint>"
        )
        site_links[sn] = link
    xml = "\n".join(
        [
            '<?xml version="1.0"?>',
            "<!-- Kinematic export of a MuJoCo model by retarget.baselines.dex_retargeting -->",
            f"<robot name={quoteattr(robot_name)}>",
            *links,
            *joints,
            "</robot>",
            "",
        ]
    )
    atomic_write_text(path, xml)
    return UrdfExport(
        path=path,
        joint_names=joint_order,
        site_links=site_links,
        body_links={bname[b]: bname[b] for b in range(1, m.nbody)},
        mimics=list(mimics.values()),
    )
