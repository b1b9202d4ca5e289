"""Building a hand's MuJoCo model from its description (:class:`~retarget.hands.model.HandModel`).

:func:`build_spec` attaches the source model under the floating wrist of
:mod:`retarget.hands.base`, adds the keypoint sites ``<finger>_tip_site`` and
``<finger>_<joint>_site``, the joint equality couplings, the actuators named ``<joint>_act`` and
names the collision geoms ``*_collision``. Everything else (Pinocchio model, QP objectives,
re-simulation) is derived from the compiled ``mujoco.MjModel``.

Physical conventions (``docs/design.md``, conventions): ``implicitfast``
integrator, elliptic friction cones, ``impratio`` 10, timestep 2 ms, condim 4 on fingertip geoms
and 3 elsewhere. The hand's weight is carried by gravity compensation (``gravcomp`` 1 on every hand
body): the arm that would hold the hand is not modelled, and the fingers' position servos are not
asked to hold their own weight.
"""

from __future__ import annotations

import logging

import mujoco
import numpy as np

from retarget.errors import HandModelError
from retarget.hands.base import WRIST_BODY, WRIST_JOINTS, WRIST_SITE, SitePlacement

log = logging.getLogger(__name__)

# --- simulation options (docs/design.md, conventions) ---
TIMESTEP = 0.002  # [s]; DESIGN: timestep <= 2.5 ms
IMPRATIO = 10.0  # DESIGN: elliptic cones with impratio ~ 10


def _quat_wxyz(R: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=float).reshape(9))
    return q


def build_spec(hand, *, self_collision: bool = False):
    """A new ``mujoco.MjSpec`` of ``hand`` (a :class:`~retarget.hands.model.HandModel`): floating
    wrist + the hand, sites, couplings, actuators.

    ``self_collision``: let the hand's collision geoms touch each other (off by default;
    hand–object contacts are always on). Collision geoms use ``contype`` 2 and
    ``conaffinity`` 1, so they touch any geom with the default ``contype``/``conaffinity``
    of 1 but not each other; with ``self_collision`` both are 3, the source's explicit
    contact pairs are kept, and the body pairs already touching at the open posture (palm
    and finger bases) are excluded.
    """
    try:
        src = hand.loader()
    except HandModelError:
        raise
    except Exception as e:  # a missing package file, a parse error in a third-party model
        raise HandModelError(
            f"hand {hand.name!r}: cannot load its model from {hand.source.location}: {e}"
        ) from e
    _prepare_source(src)
    root = src.body(hand.root_body)
    if root is None:
        raise HandModelError(f"hand {hand.name!r}: no body {hand.root_body!r} in its model")
    root.pos = [0.0, 0.0, 0.0]
    root.quat = [1.0, 0.0, 0.0, 0.0]

    spec = mujoco.MjSpec()
    spec.modelname = f"{hand.name}_right"
    spec.compiler.degree = False
    spec.option.timestep = TIMESTEP
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = IMPRATIO
    for attr in ("iterations", "ls_iterations", "tolerance"):
        setattr(src.option, attr, getattr(spec.option, attr))

    # 1 g, 1e-7 kg·m^2: negligible next to any hand, but keeps the floating base valid when
    # the hand's root body has joints of its own (Shadow's WRJ1).
    wrist = spec.worldbody.add_body(
        name=WRIST_BODY, mass=1e-3, inertia=[1e-7, 1e-7, 1e-7], explicitinertial=True
    )
    g = hand.wrist_gains
    for i, jn in enumerate(WRIST_JOINTS):
        axis = np.eye(3)[i % 3]
        slide = i < 3
        wrist.add_joint(
            name=jn,
            type=mujoco.mjtJoint.mjJNT_SLIDE if slide else mujoco.mjtJoint.mjJNT_HINGE,
            axis=axis,
            armature=g.armature_slide if slide else g.armature_hinge,
            range=[-g.range_slide, g.range_slide] if slide else [-g.range_hinge, g.range_hinge],
            limited=mujoco.mjtLimited.mjLIMITED_FALSE,
        )
    wrist.add_site(name=WRIST_SITE, size=[0.006, 0.006, 0.006], rgba=[1, 0, 0, 1], group=4)
    T = hand.T_mano_robot_wrist
    frame = wrist.add_frame(pos=T[:3, 3], quat=_quat_wxyz(T[:3, :3]))
    _attach_keeping_names(frame, root)
    _finish(hand, spec, self_collision=self_collision)
    # The copy forgets the attachment: compiling it does not repeat MuJoCo's notice that an
    # empty-prefix attachment happened (names are unique here by construction).
    spec = spec.copy()
    if self_collision:
        _exclude_resting_contacts(hand, spec)
    return spec


def _finish(hand, spec, *, self_collision: bool) -> None:
    bodies = {b.name: b for b in spec.bodies if b.name}
    # --- sites ---
    for f, place in hand.tip_sites.items():
        name = f"{f}_tip_site"
        if place is None:
            if spec.site(name) is None:
                raise HandModelError(f"hand {hand.name!r}: model has no site {name!r}")
            continue
        _add_site(spec, bodies, name, place, rgba=(0, 1, 0, 1))
    for kp, place in hand.joint_sites.items():
        _add_site(spec, bodies, hand.joint_site_name(kp), place, rgba=(0, 0, 1, 1))

    # --- joints ---
    finger_joints = [j for j in spec.joints if j.name not in WRIST_JOINTS]
    names = {j.name for j in finger_joints}
    for jn, rng in hand.joint_ranges.items():
        if jn not in names:
            raise HandModelError(f"hand {hand.name!r}: joint_ranges names unknown {jn!r}")
        spec.joint(jn).range = list(rng)
        spec.joint(jn).limited = mujoco.mjtLimited.mjLIMITED_TRUE
    for j in finger_joints:
        if hand.joint_armature is not None:
            j.armature = hand.joint_armature
        if hand.joint_damping is not None:
            d = np.atleast_1d(np.array(j.damping, dtype=float))
            d[0] = hand.joint_damping
            j.damping = d if d.size > 1 else float(d[0])
        if hand.joint_frictionloss is not None:
            j.frictionloss = hand.joint_frictionloss

    # --- couplings ---
    for c in hand.couplings:
        for jn in (c.follower, c.leader):
            if jn not in names:
                raise HandModelError(f"hand {hand.name!r}: coupling names unknown joint {jn!r}")
        eq = spec.add_equality(
            name=f"{c.follower}_coupling",
            type=mujoco.mjtEq.mjEQ_JOINT,
            name1=c.follower,
            name2=c.leader,
        )
        data = np.zeros(len(eq.data))
        data[:2] = (c.offset, c.multiplier)  # polycoef: follower = c0 + c1 * leader
        eq.data = data
        eq.solref = [0.005, 1.0]  # stiffer than the default 0.02 s: a linkage, not a spring

    # --- collision geoms, contact parameters ---
    tip_bodies = set()
    for f, place in hand.tip_sites.items():
        site = spec.site(f"{f}_tip_site")
        tip_bodies.add(site.parent.name if place is None else place.body)
    cp = hand.contact
    bit = 3 if self_collision else 2
    renamed: dict[str, str] = {}
    per_body: dict[str, int] = {}
    for geom in spec.geoms:
        body = geom.parent.name
        if geom.contype == 0 and geom.conaffinity == 0:
            geom.group = 2 if geom.group in (0, 1) else geom.group  # visual
            continue
        geom.contype = bit
        geom.conaffinity = 1 | (2 if self_collision else 0)
        geom.group = 3
        geom.friction = list(cp.friction)
        geom.solref = list(cp.solref)
        geom.solimp = list(cp.solimp)
        geom.condim = cp.tip_condim if body in tip_bodies else cp.condim
        if not geom.name.endswith("_collision"):
            k = per_body.get(body, 0)
            per_body[body] = k + 1
            new = f"{body}_collision" if k == 0 else f"{body}_collision_{k}"
            while spec.geom(new) is not None:
                k += 1
                per_body[body] = k + 1
                new = f"{body}_collision_{k}"
            if geom.name:
                renamed[geom.name] = new
            geom.name = new
    for pair in list(spec.pairs):
        if not self_collision:
            spec.delete(pair)
            continue
        pair.geomname1 = renamed.get(pair.geomname1, pair.geomname1)
        pair.geomname2 = renamed.get(pair.geomname2, pair.geomname2)

    # --- gravity compensation (the unmodelled arm carries the hand) ---
    for b in spec.bodies:
        if b.name:
            b.gravcomp = 1.0

    # --- actuators: the wrist, then the hand's ---
    g = hand.wrist_gains
    for i, jn in enumerate(WRIST_JOINTS):
        slide = i < 3
        act = spec.add_actuator(name=f"{jn}_act", target=jn)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_position(kp=g.kp_slide if slide else g.kp_hinge, dampratio=g.dampratio)
        lim = g.force_slide if slide else g.torque_hinge
        act.forcerange = [-lim, lim]
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        r = g.range_slide if slide else g.range_hinge
        act.ctrlrange = [-r, r]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
    for a in hand.actuators:
        j = spec.joint(a.joint)
        if j is None:
            raise HandModelError(f"hand {hand.name!r}: actuator on unknown joint {a.joint!r}")
        act = spec.add_actuator(name=f"{a.joint}_act", target=a.joint)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_position(kp=a.kp, kv=a.kv if a.kv > 0 else -1)
        rng = a.ctrlrange if a.ctrlrange is not None else tuple(j.range)
        act.ctrlrange = list(rng)
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        if a.forcerange is not None:
            act.forcerange = list(a.forcerange)
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE


def _exclude_resting_contacts(hand, spec) -> None:
    """Exclude the body pairs that touch at the open posture (palm vs finger bases …)."""
    m = spec.compile()
    d = mujoco.MjData(m)
    d.qpos[:] = hand.default_qpos(m)
    mujoco.mj_forward(m, d)
    seen: set[tuple[str, str]] = set()
    pairs_in_contact: set[str] = set()
    for i in range(d.ncon):
        c = d.contact[i]
        b1, b2 = (m.body(m.geom_bodyid[g]).name for g in c.geom)
        key = (min(b1, b2), max(b1, b2))
        if key not in seen:
            seen.add(key)
            spec.add_exclude(bodyname1=key[0], bodyname2=key[1])
        pairs_in_contact.add(f"{m.geom(c.geom[0]).name}/{m.geom(c.geom[1]).name}")
    for pair in list(spec.pairs):
        names = {f"{pair.geomname1}/{pair.geomname2}", f"{pair.geomname2}/{pair.geomname1}"}
        if names & pairs_in_contact:
            spec.delete(pair)


def _add_site(spec, bodies, name: str, place: SitePlacement, rgba) -> None:
    body = bodies.get(place.body)
    if body is None:
        raise HandModelError(f"site {name!r}: no body {place.body!r} in the model")
    if spec.site(name) is not None:
        raise HandModelError(f"site {name!r} already exists in the model")
    body.add_site(name=name, pos=list(place.pos), size=[0.004, 0.004, 0.004], rgba=list(rgba),
                  group=4)  # fmt: skip


def _attach_keeping_names(frame, body) -> None:
    """``frame.attach_body(body)`` with an empty prefix, so the source's names are kept.

    MuJoCo warns that empty-prefix attachments may not save back to XML with the child's
    defaults; the hand specs built here are compiled, not re-saved through the child, so the
    notice is captured instead of printed. Any other warning is passed on to ``logging``.
    """
    notices: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(notices.append)
    try:
        frame.attach_body(body, "", "")
    finally:
        mujoco.set_mju_user_warning(previous)
    for msg in notices:
        if "empty prefix" not in msg:
            log.warning("MuJoCo: %s", msg)


def coupling_tendons(m) -> list[int]:
    """Ids of the fixed tendons that couple joints: over two or more joints, limited to a range
    no wider than ``COUPLING_TENDON_WIDTH_M`` (2 mm; Shadow's ``T_*J1c``; its other two-joint
    tendons only bound the sum)."""
    # Here, not at the top: importing retarget.limits compiles its kernels (6 s cold).
    from retarget.limits.coupling import COUPLING_TENDON_WIDTH_M

    out = []
    for t in range(m.ntendon):
        adr, num = m.tendon_adr[t], m.tendon_num[t]
        fixed = all(m.wrap_type[adr + k] == mujoco.mjtWrap.mjWRAP_JOINT for k in range(num))
        lo, hi = m.tendon_range[t]
        if fixed and num >= 2 and m.tendon_limited[t] and hi - lo <= COUPLING_TENDON_WIDTH_M:
            out.append(t)
    return out


def _prepare_source(src) -> None:
    """Drop what is not the hand's kinematics: actuators, sensors, keyframes, global sizes."""
    for kind in ("actuators", "sensors", "keys"):
        for el in list(getattr(src, kind)):
            src.delete(el)
    # Global sizes / user-data widths would conflict with the parent spec when attaching.
    for attr in ("njmax", "nconmax", "nstack"):
        setattr(src, attr, -1)
    for attr in (
        "nuser_body", "nuser_jnt", "nuser_geom", "nuser_site", "nuser_cam", "nuser_tendon",
        "nuser_actuator", "nuser_sensor",
    ):  # fmt: skip
        setattr(src, attr, -1)
