"""A position-servoed finger pressing a fixed box: the force tests' shared MuJoCo scene."""

from __future__ import annotations

import mujoco
import numpy as np

WRIST_JOINTS = ("x", "y", "z", "rx", "ry", "rz")


def finger_pressing_a_fixed_box(solref: float, wrist: bool = False) -> mujoco.MjModel:
    """A two-joint finger (``j1``, ``j2``) with position servos (kp 5 and 3 N·m/rad) whose distal
    link (geom ``tip``, site ``tip_site`` at its end) rests on a fixed box; every geom's contact
    time constant is ``solref`` [s] (MuJoCo's default 0.02 lets the finger sink in and press
    less than commanded). ``wrist``: the finger hangs from a six-joint wrist (three slides, three
    hinges, stiff servos: the layout of every robot hand here), its joints first in ``qpos``."""
    spec = mujoco.MjSpec()
    spec.compiler.degree = False
    spec.option.timestep = 0.002
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    base = spec.worldbody
    if wrist:
        base = base.add_body(name="wrist", pos=[0, 0, 0.1], gravcomp=1)
        for i, name in enumerate(WRIST_JOINTS):
            kind = mujoco.mjtJoint.mjJNT_SLIDE if i < 3 else mujoco.mjtJoint.mjJNT_HINGE
            base.add_joint(name=name, type=kind, axis=np.eye(3)[i % 3], damping=5.0,
                           armature=1e-3)  # fmt: skip
        base.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.005, 0, 0], density=1000,
                      contype=0, conaffinity=0)  # fmt: skip
    b1 = base.add_body(name="l1", pos=[0, 0, 0] if wrist else [0, 0, 0.1], gravcomp=1)
    b1.add_joint(name="j1", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 1, 0], damping=0.05,
                 armature=1e-4)  # fmt: skip
    b1.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, 0.05, 0, 0],
                size=[0.008, 0, 0], density=1000)  # fmt: skip
    b2 = b1.add_body(name="l2", pos=[0.05, 0, 0], gravcomp=1)
    b2.add_joint(name="j2", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 1, 0], damping=0.05,
                 armature=1e-4)  # fmt: skip
    b2.add_geom(name="tip", type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, 0.04, 0, 0],
                size=[0.008, 0, 0], density=1000)  # fmt: skip
    b2.add_site(name="tip_site", pos=[0.04, 0, 0])
    spec.worldbody.add_geom(name="box", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.05, 0.05, 0.02],
                            pos=[0.115, 0, 0.1 - 0.008 - 0.02])  # fmt: skip
    servos = [(j, 2000.0) for j in WRIST_JOINTS] if wrist else []
    for j, kp in (*servos, ("j1", 5.0), ("j2", 3.0)):
        a = spec.add_actuator(name=j, target=j, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.set_to_position(kp=kp, dampratio=1.0)
    for g in spec.geoms:
        g.solref = [solref, 1.0]
    return spec.compile()
