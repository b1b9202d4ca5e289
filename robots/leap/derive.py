"""Derive ``leap_right.xml`` (LEAP Hand, right) from its published kinematics.

Run from the repository root: ``python robots/leap/derive.py > robots/leap/leap_right.xml``.
The output is deterministic; ``tests/test_hands.py`` checks that the committed file is what this
script writes.

Every number below is a published fact with its source (see README.md for the full citations):

* [URDF]  LEAP_Hand_Sim ``assets/leap_hand/robot.urdf`` (leap-hand/LEAP_Hand_Sim, commit e8fc513,
  MIT): joint origins (xyz, rpy), joint axes, joint limits, link masses, palm inertia.
* [DEX]   dex-urdf ``robots/hands/leap_hand/leap_hand_right.urdf`` (dexsuite/dex-urdf, commit
  77eb4ac): fingertip end points (``*_tip_head`` frames) and the primitive collision boxes of the
  palm and phalanges, from which the palm boxes and the 10 mm capsule radius are taken.
* [PAPER] Shaw, Agarwal, Pathak, "LEAP Hand: Low-Cost, Efficient, and Anthropomorphic Hand for
  Robot Learning", RSS 2023: 16 DoF, 4 fingers (3 fingers + thumb), 4 joints per finger,
  MCP flexion followed by the "universal" abduction joint.
* [SIM]   LEAP_Hand_Sim ``leapsim/cfg/task/LeapHandRot.yaml``: position-control gains
  pgain 3, dgain 0.1 (used in ``retarget/hands/leap.py``, not here).

Derivation: compose the URDF joint transforms (origin xyz, fixed-axis roll-pitch-yaw) at q = 0 to
get every joint's anchor and axis in the palm frame (``palm_lower``), then write one body per link
with the palm's orientation, placed at the joint anchor, with the joint axis expressed in the palm
frame. Anchors on axes parallel to the finger's flexion axes are slid along their axis onto the
finger's centreline (the line through the abduction anchor), which does not change the kinematics.
Collision geometry is primitive: capsules along the centreline with the link mass of [URDF] (inertia
from the capsule), boxes for the palm from [DEX].
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

# --- [URDF] joint origins: label -> (xyz [m], rpy [rad], range [rad]) ---
PI_2 = np.pi / 2
_INDEX_CHAIN = {
    # joint "1": MCP flexion, palm_lower -> mcp_joint
    "mcp": ((-0.0070952, 0.0230578, -0.0187224), (PI_2, PI_2, 0.0), (-0.314, 2.23)),
    # joint "0": MCP abduction ("universal abduction"), mcp_joint -> pip
    "abd": ((-0.0122, 0.0381, 0.0145), (-PI_2, 0.0, PI_2), (-1.047, 1.047)),
    # joint "2": PIP, pip -> dip
    "pip": ((0.015, 0.0143, -0.013), (PI_2, -PI_2, 0.0), (-0.506, 1.885)),
    # joint "3": DIP, dip -> fingertip
    "dip": ((0.0, -0.0361, 0.0002), (0.0, 0.0, 0.0), (-0.366, 2.042)),
}
# joints "5" and "9": the middle and ring fingers' MCP origins (same rpy and child chain as index)
_FINGER_MCP_ORIGIN = {
    "ff": (-0.0070952, 0.0230578, -0.0187224),
    "mf": (-0.0070952, -0.0223922, -0.0187224),
    "rf": (-0.0070952, -0.0678422, -0.0187224),
}
_THUMB_CHAIN = {
    # joint "12": palm_lower -> thumb base (pip_4)
    "cmc": ((-0.0693952, -0.0012422, -0.0216224), (0.0, PI_2, 0.0), (-0.349, 2.094)),
    # joint "13": -> thumb_pip
    "axl": ((0.0, 0.0143, -0.013), (PI_2, -PI_2, 0.0), (-0.47, 2.443)),
    # joint "14": -> thumb_dip
    "mcp": ((0.0, 0.0145, -0.017), (-PI_2, 0.0, 0.0), (-1.20, 1.90)),
    # joint "15": -> thumb_fingertip
    "ip": ((0.0, 0.0466, 0.0002), (0.0, 0.0, np.pi), (-1.34, 1.88)),
}
JOINT_AXIS_CHILD = (0.0, 0.0, -1.0)  # every LEAP joint: axis xyz="0 0 -1" [URDF]

# --- [DEX] fingertip end points in the distal link frames ---
FINGER_TIP_IN_DISTAL = (0.0, -0.048, 0.015)  # index_tip_head / middle_tip_head / ring_tip_head
THUMB_TIP_IN_DISTAL = (0.0, -0.06, -0.015)  # thumb_tip_head

# --- [URDF] link masses [kg] ---
MASS = {
    "palm": 0.237,
    "mcp_joint": 0.044,
    "pip": 0.032,
    "dip": 0.037,
    "fingertip": 0.016,
    "thumb_base": 0.032,  # pip_4
    "thumb_pip": 0.003,
    "thumb_dip": 0.038,
    "thumb_fingertip": 0.049,
}
# [URDF] palm_lower inertia about its origin, link axes [kg m^2]: ixx iyy izz ixy ixz iyz
PALM_INERTIA = (0.000354094, 0.000260915, 0.000529257, -0.000001193, -0.000002445, -0.000002905)

# [DEX] phalanx collision boxes are 20 mm wide (e.g. fingertip box 0.02 x 0.006 x 0.03) -> 10 mm
CAPSULE_RADIUS = 0.010
# [DEX] palm_lower collision boxes (centre xyz, full size xyz) [m], axis-aligned in the palm frame
PALM_BOXES = (
    ((-0.03, -0.035, -0.003), (0.02, 0.12, 0.03)),
    ((-0.048, -0.033, -0.0115), (0.024, 0.116, 0.046)),
    ((-0.078, -0.053, -0.0115), (0.044, 0.052, 0.046)),
    ((-0.078, -0.003, 0.01), (0.044, 0.056, 0.004)),
    ((-0.009, 0.008, -0.011), (0.022, 0.026, 0.034)),
    ((-0.009, -0.037, -0.011), (0.022, 0.026, 0.034)),
    ((-0.009, -0.082, -0.011), (0.022, 0.026, 0.034)),
)


def _transform(xyz, rpy) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()  # URDF rpy: fixed-axis X, Y, Z
    T[:3, 3] = xyz
    return T


def _chain(origin_xyz, chain: dict) -> list[tuple[str, np.ndarray, np.ndarray, tuple]]:
    """(label, anchor, axis, range) per joint in the palm frame at q = 0, and the last frame."""
    frame = np.eye(4)
    out = []
    for i, (label, (xyz, rpy, rng)) in enumerate(chain.items()):
        frame = frame @ _transform(origin_xyz if i == 0 else xyz, rpy)
        axis = frame[:3, :3] @ np.asarray(JOINT_AXIS_CHILD)
        out.append((label, frame[:3, 3].copy(), np.round(axis, 6) + 0.0, rng))
    return out, frame


def _fmt(v) -> str:
    return " ".join(f"{x:.6g}" if abs(x) > 1e-9 else "0" for x in np.asarray(v, float))


def derive() -> dict:
    """Joint anchors/axes and tip points of every finger in the palm frame."""
    fingers = {}
    for f, origin in _FINGER_MCP_ORIGIN.items():
        joints, last = _chain(origin, _INDEX_CHAIN)
        tip = (last @ np.array([*FINGER_TIP_IN_DISTAL, 1.0]))[:3]
        # centreline: through the abduction anchor (its axis is the palm normal), at the height
        # (z) of the PIP/DIP anchors; slide the anchors of the flexion axes (along y) onto it.
        y_c = joints[1][1][1]
        z_c = joints[2][1][2]
        pts = []
        for label, anchor, axis, rng in joints:
            p = anchor.copy()
            if abs(axis[1]) > 0.99:  # flexion axis along +-y: slide along y, keep x, z
                p[1] = y_c
            else:  # abduction axis along +-z: slide along z
                p[2] = z_c
            pts.append((label, p, axis, rng))
        fingers[f] = (pts, tip)
    joints, last = _chain(_THUMB_CHAIN["cmc"][0], _THUMB_CHAIN)
    tip = (last @ np.array([*THUMB_TIP_IN_DISTAL, 1.0]))[:3]
    z_c = joints[0][1][2]
    pts = []
    for label, anchor, axis, rng in joints:
        p = anchor.copy()
        if abs(axis[2]) > 0.99:  # thumb MCP/IP axes along +-z: slide onto the thumb's plane
            p[2] = z_c
        pts.append((label, p, axis, rng))
    fingers["th"] = (pts, tip)
    return fingers


_LINK_MASS = {
    "ff": ("mcp_joint", "pip", "dip", "fingertip"),
    "th": ("thumb_base", "thumb_pip", "thumb_dip", "thumb_fingertip"),
}
_BODY = {
    "ff": ("base", "proximal", "middle", "distal"),
    "th": ("base", "proximal", "middle", "distal"),
}


def to_mjcf() -> str:
    fingers = derive()
    r = CAPSULE_RADIUS
    lines = [
        "<!-- LEAP Hand (right), authored for dexcanvas-retarget from published kinematics.",
        "     Generated by robots/leap/derive.py; sources and derivation in robots/leap/README.md.",
        "     Frame: the LEAP palm_lower frame (fingers +x, index side +y, palm normal -z). -->",
        '<mujoco model="leap_right">',
        '  <compiler angle="radian" autolimits="true"/>',
        "  <default>",
        '    <default class="leap">',
        '      <joint type="hinge" armature="0.001"/>',
        '      <geom type="capsule" contype="1" conaffinity="1" group="3" rgba="0.2 0.2 0.2 1"/>',
        "    </default>",
        "  </default>",
        "  <worldbody>",
        '    <body name="palm" childclass="leap">',
        f'      <inertial pos="0 0 0" mass="{MASS["palm"]}" fullinertia="{_fmt(PALM_INERTIA)}"/>',
    ]
    for i, (c, size) in enumerate(PALM_BOXES):
        lines.append(
            f'      <geom name="palm_collision_{i}" type="box" pos="{_fmt(c)}" '
            f'size="{_fmt(np.asarray(size) / 2)}"/>'
        )
    for f, (pts, tip) in fingers.items():
        kind = "th" if f == "th" else "ff"
        indent = "      "
        opened = 0
        for k, (label, p, axis, rng) in enumerate(pts):
            parent = np.zeros(3) if k == 0 else pts[k - 1][1]
            nxt = pts[k + 1][1] if k + 1 < len(pts) else tip
            body = f"{f}_{_BODY[kind][k]}"
            lines.append(f'{indent}<body name="{body}" pos="{_fmt(p - parent)}">')
            lines.append(
                f'{indent}  <joint name="{f}_{label}" axis="{_fmt(axis)}" range="{_fmt(rng)}"/>'
            )
            d = nxt - p
            if k + 1 == len(pts):  # distal: end the capsule one radius short of the tip
                d = d - r * d / np.linalg.norm(d)
            lines.append(
                f'{indent}  <geom name="{body}_collision" fromto="0 0 0 {_fmt(d)}" size="{r}" '
                f'mass="{MASS[_LINK_MASS[kind][k]]}"/>'
            )
            if k + 1 == len(pts):
                lines.append(
                    f'{indent}  <site name="{f}_tip_site" pos="{_fmt(tip - p)}" size="0.004"/>'
                )
            indent += "  "
            opened += 1
        for _ in range(opened):
            indent = indent[:-2]
            lines.append(f"{indent}</body>")
    lines += ["    </body>", "  </worldbody>", "</mujoco>", ""]
    return "\n".join(lines)


def tip_points() -> dict[str, np.ndarray]:
    """Fingertip end points in the palm frame (used to place the ``*_tip_site`` sites)."""
    return {f: tip for f, (_, tip) in derive().items()}


if __name__ == "__main__":
    import sys

    sys.stdout.write(to_mjcf())
    for f, (pts, tip) in derive().items():
        sys.stderr.write(f"{f}: " + ", ".join(f"{lab}@{_fmt(p)}" for lab, p, _, _ in pts))
        sys.stderr.write(f", tip@{_fmt(tip)}\n")
