"""Derive ``inspire_right.xml`` (Inspire RH56 dexterous hand, right) from published kinematics.

Run from the repository root:
``python robots/inspire/derive.py > robots/inspire/inspire_right.xml``.
The output is deterministic; ``tests/test_hands.py`` checks that the committed file is what this
script writes.

Every number below is a published fact with its source (full citations in README.md):

* [URDF] dex-urdf ``robots/hands/inspire_hand/inspire_hand_right.urdf`` (dexsuite/dex-urdf,
  commit 41e0c8b), the right Inspire RH56 hand as published by the dex-retargeting authors from
  the manufacturer's description: joint origins (xyz, rpy), axes, limits, mimic multipliers and
  offsets, link masses and the base-link inertia, fingertip frames (``*_tip``), and the primitive
  collision boxes / cylinder of the base link.
* [RH56] Inspire Robots RH56DFX: 6 actuators (thumb rotation, thumb bend, index, middle, ring,
  little), 12 joints; the intermediate phalanges and the thumb's distal joints follow their
  actuated joint through linkages (the URDF ``<mimic>`` tags above).

Derivation: compose the URDF joint transforms at q = 0 (origin xyz, fixed-axis roll-pitch-yaw) to
get each joint's anchor and axis in the base frame (``hand_base_link``); write one body per link
with the base frame's orientation at the joint anchor, the axis expressed in the base frame. The
mimic joints become MuJoCo joint equality constraints (``q_follower = offset + multiplier *
q_leader``). Collision geometry is primitive: capsules from joint to joint to the fingertip frame
(radius 8 mm, see ``CAPSULE_RADIUS``) carrying the link masses of [URDF], and the base link's
collision boxes and flange cylinder from [URDF].
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

# --- [URDF] (name, parent, child, xyz [m], rpy [rad], axis, range [rad]) ---
JOINTS = (
    ("th_cmc_yaw", "base", "th_base", (-0.01696, -0.0691, -0.02045), (1.5708, -1.5708, 0.0),
     (0, 0, -1), (0.0, 1.308)),
    ("th_cmc_pitch", "th_base", "th_proximal", (-0.0088099, 0.010892, -0.00925),
     (1.5708, 0.0, 2.8587), (0, 0, 1), (0.0, 0.6)),
    ("th_mcp", "th_proximal", "th_middle", (0.04407, 0.034553, -0.0008), (0.0, 0.0, 0.0),
     (0, 0, 1), (0.0, 0.8)),
    ("th_ip", "th_middle", "th_distal", (0.020248, 0.010156, -0.0012), (0.0, 0.0, 0.0),
     (0, 0, 1), (0.0, 0.4)),
    ("ff_mcp", "base", "ff_proximal", (0.00028533, -0.13653, -0.032268), (-3.1067, 0.0, 0.0),
     (0, 0, 1), (0.0, 1.47)),
    ("ff_pip", "ff_proximal", "ff_distal", (-0.0026138, 0.032026, -0.001), (0.0, 0.0, 0.0),
     (0, 0, 1), (-0.04545, 1.56)),
    ("mf_mcp", "base", "mf_proximal", (0.00028533, -0.1371, -0.01295), (-3.1416, 0.0, 0.0),
     (0, 0, 1), (0.0, 1.47)),
    ("mf_pip", "mf_proximal", "mf_distal", (-0.0024229, 0.032041, -0.001), (0.0, 0.0, 0.0),
     (0, 0, 1), (-0.04545, 1.56)),
    ("rf_mcp", "base", "rf_proximal", (0.00028533, -0.13691, 0.0062872), (3.0892, 0.0, 0.0),
     (0, 0, 1), (0.0, 1.47)),
    ("rf_pip", "rf_proximal", "rf_distal", (-0.0024229, 0.032041, -0.001), (0.0, 0.0, 0.0),
     (0, 0, 1), (-0.04545, 1.56)),
    ("lf_mcp", "base", "lf_proximal", (0.00028533, -0.13571, 0.025488), (3.0369, 0.0, 0.0),
     (0, 0, 1), (0.0, 1.47)),
    ("lf_pip", "lf_proximal", "lf_distal", (-0.0024229, 0.032041, -0.001), (0.0, 0.0, 0.0),
     (0, 0, 1), (-0.04545, 1.56)),
)  # fmt: skip
# [URDF] fingertip frames in the distal link frames (thumb_tip, index_tip, ... pinky_tip)
TIPS = {
    "th": ("th_distal", (0.0202, 0.0140, -0.006)),
    "ff": ("ff_distal", (-0.0008, 0.045, -0.005)),
    "mf": ("mf_distal", (-0.001, 0.048, -0.005)),
    "rf": ("rf_distal", (-0.0008, 0.045, -0.005)),
    "lf": ("lf_distal", (-0.0008, 0.037, -0.005)),
}
# [URDF] <mimic>: follower = offset + multiplier * leader
MIMIC = (
    ("th_mcp", "th_cmc_pitch", 1.334, 0.0),
    ("th_ip", "th_cmc_pitch", 0.667, 0.0),
    ("ff_pip", "ff_mcp", 1.06399, -0.04545),
    ("mf_pip", "mf_mcp", 1.06399, -0.04545),
    ("rf_pip", "rf_mcp", 1.06399, -0.04545),
    ("lf_pip", "lf_mcp", 1.06399, -0.04545),
)
# [URDF] link masses [kg]
MASS = {
    "th_base": 0.0018869,  # thumb_proximal_base
    "th_proximal": 0.0066075,
    "th_middle": 0.0037847,  # thumb_intermediate
    "th_distal": 0.0033441,
    "ff_proximal": 0.0042403,
    "ff_distal": 0.0045683,  # index_intermediate (the distal phalanx is part of it)
    "mf_proximal": 0.0042403,
    "mf_distal": 0.0050396,
    "rf_proximal": 0.0042403,
    "rf_distal": 0.0045683,
    "lf_proximal": 0.0042403,
    "lf_distal": 0.0035996,
}
# [URDF] hand_base_link inertial: mass [kg], centre of mass [m], inertia (ixx iyy izz ixy ixz iyz)
BASE_MASS = 0.14143
BASE_COM = (-0.0025264, -0.066047, 0.0019598)
BASE_INERTIA = (0.00012281, 8.3832e-05, 7.6663e-05, 2.1711e-06, 1.7709e-06, -1.6551e-06)
# [URDF] hand_base_link collision: boxes (centre, full size) and the wrist flange cylinder
BASE_BOXES = (
    ((-0.0032, -0.038, 0.0), (0.0391, 0.0202, 0.0574)),
    ((-0.0032, -0.0682, 0.0), (0.0391, 0.04, 0.0814)),
    ((0.0, -0.1081, 0.0), (0.0322, 0.04, 0.0814)),
)
FLANGE = ((0.0, -0.0136, 0.0), 0.028, 0.0278)  # centre, radius, length (axis along y)
# Capsule radius: adjacent MCP axes are 19 mm apart ([URDF] index/middle/ring/little z offsets
# -0.0323, -0.0130, 0.0063, 0.0255), so phalanges are at most 19 mm wide; 8 mm keeps a 3 mm gap.
CAPSULE_RADIUS = 0.008


def _transform(xyz, rpy) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()  # URDF rpy: fixed-axis X, Y, Z
    T[:3, 3] = xyz
    return T


def derive() -> dict:
    """Per joint: (parent body, child body, anchor, axis, range) in the base frame at q = 0."""
    frames = {"base": np.eye(4)}
    out = {}
    for name, parent, child, xyz, rpy, axis, rng in JOINTS:
        frames[child] = frames[parent] @ _transform(xyz, rpy)
        a = frames[child][:3, :3] @ np.asarray(axis, float)
        out[name] = (parent, child, frames[child][:3, 3].copy(), np.round(a, 6) + 0.0, rng)
    tips = {f: (frames[b] @ np.array([*p, 1.0]))[:3] for f, (b, p) in TIPS.items()}
    return {"joints": out, "tips": tips}


def _fmt(v) -> str:
    return " ".join(f"{x:.6g}" if abs(x) > 1e-9 else "0" for x in np.asarray(v, float))


def to_mjcf() -> str:
    d = derive()
    joints, tips = d["joints"], d["tips"]
    r = CAPSULE_RADIUS
    lines = [
        "<!-- Inspire RH56 dexterous hand (right), authored for dexcanvas-retarget from published",
        "     kinematics. Generated by robots/inspire/derive.py; sources and derivation in",
        "     robots/inspire/README.md. Frame: the hand_base_link frame of the published URDF",
        "     (fingers -y, thumb side -z, palm normal -x). -->",
        '<mujoco model="inspire_right">',
        '  <compiler angle="radian" autolimits="true"/>',
        "  <default>",
        '    <default class="inspire">',
        '      <joint type="hinge" damping="0.05" armature="0.0005"/>',
        '      <geom type="capsule" contype="1" conaffinity="1" group="3" rgba="0.7 0.7 0.7 1"/>',
        '      <equality solref="0.005 1"/>',
        "    </default>",
        "  </default>",
        "  <worldbody>",
        '    <body name="base" childclass="inspire">',
        f'      <inertial pos="{_fmt(BASE_COM)}" mass="{BASE_MASS}" '
        f'fullinertia="{_fmt(BASE_INERTIA)}"/>',
        f'      <geom name="flange_collision" type="cylinder" pos="{_fmt(FLANGE[0])}" '
        f'quat="0.707107 0.707107 0 0" size="{FLANGE[1]} {FLANGE[2] / 2:.6g}"/>',
    ]
    for i, (c, size) in enumerate(BASE_BOXES):
        lines.append(
            f'      <geom name="palm_collision_{i}" type="box" pos="{_fmt(c)}" '
            f'size="{_fmt(np.asarray(size) / 2)}"/>'
        )
    chains = {
        "th": ("th_cmc_yaw", "th_cmc_pitch", "th_mcp", "th_ip"),
        "ff": ("ff_mcp", "ff_pip"),
        "mf": ("mf_mcp", "mf_pip"),
        "rf": ("rf_mcp", "rf_pip"),
        "lf": ("lf_mcp", "lf_pip"),
    }
    for f, names in chains.items():
        indent = "      "
        prev = np.zeros(3)
        for k, jn in enumerate(names):
            _, child, anchor, axis, rng = joints[jn]
            nxt = joints[names[k + 1]][2] if k + 1 < len(names) else tips[f]
            lines.append(f'{indent}<body name="{child}" pos="{_fmt(anchor - prev)}">')
            lines.append(f'{indent}  <joint name="{jn}" axis="{_fmt(axis)}" range="{_fmt(rng)}"/>')
            seg = nxt - anchor
            if k + 1 == len(names):  # distal: end one radius short of the fingertip frame
                seg = seg - r * seg / np.linalg.norm(seg)
            lines.append(
                f'{indent}  <geom name="{child}_collision" fromto="0 0 0 {_fmt(seg)}" size="{r}" '
                f'mass="{MASS[child]}"/>'
            )
            if k + 1 == len(names):
                lines.append(
                    f'{indent}  <site name="{f}_tip_site" pos="{_fmt(tips[f] - anchor)}" '
                    f'size="0.004"/>'
                )
            indent += "  "
            prev = anchor
        for _ in names:
            indent = indent[:-2]
            lines.append(f"{indent}</body>")
    lines += ["    </body>", "  </worldbody>", "  <equality>"]
    for follower, leader, mult, off in MIMIC:
        lines.append(
            f'    <joint name="{follower}_coupling" class="inspire" joint1="{follower}" '
            f'joint2="{leader}" polycoef="{off:.6g} {mult:.6g} 0 0 0"/>'
        )
    lines += ["  </equality>", "</mujoco>", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    import sys

    sys.stdout.write(to_mjcf())
