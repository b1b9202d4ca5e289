"""SCHUNK SVH five-finger hand (right), from robosuite-models' MuJoCo gripper model.

Source: ``robosuite_models/assets/grippers/schunk_svh_right_hand.xml`` (robosuite-models, MIT),
located with ``importlib.util.find_spec``. Only the hand from ``right_hand_base_link`` is kept;
robosuite's mount body, sensors and its 20 torque motors (one per joint, ignoring the real hand's
couplings) are dropped.

Kinematics: 20 joints, 9 actuated (as the real SVH): Thumb_Flexion, Thumb_Opposition,
Index_Finger_Distal, Index_Finger_Proximal, Middle_Finger_Distal, Middle_Finger_Proximal,
Ring_Finger, Pinky, Finger_Spread. The other 11 joints follow through the hand's linkages; their
ratios are the ``<mimic>`` multipliers of SCHUNK's own description (SCHUNK-SE-Co-KG
schunk_svh_ros_driver, ``schunk_svh_description/urdf/svh.urdf.xacro``), added here as joint
equality constraints.

Two multipliers push a follower past its own limit at the top of the leader's range
(``0.5 * 0.5829 > 0.28833`` for the spread joints, ``1.0454 * 1.334 > 1.334`` for ``j15``), so the
servo ranges of Finger_Spread and Middle_Finger_Distal stop where the follower reaches its limit.

Frame: ``right_hand_base_link``, origin at the wrist flange; fingers +z, index finger and thumb on
the -x side, finger flexion axes -x (fingers flex towards +y): distal = +z, radial = -x,
volar = +y. Wrist point: the origin (the flange).
"""

from __future__ import annotations

from retarget.hands.base import (
    ActuatorSpec,
    JointCoupling,
    ModelSource,
    SitePlacement,
    WristAlignment,
    WristOffset,
)
from retarget.hands.model import HandModel
from retarget.hands.sources import package_path

_P = "right_hand_"
_XACRO = "SCHUNK schunk_svh_description/urdf/svh.urdf.xacro <mimic>"
# (follower, leader, multiplier) — svh.urdf.xacro; offsets are all 0
_MIMIC = (
    ("j5", "Thumb_Opposition", 1.0),
    ("j3", "Thumb_Flexion", 1.01511),
    ("j4", "Thumb_Flexion", 1.44889),
    ("j14", "Index_Finger_Distal", 1.045),
    ("j15", "Middle_Finger_Distal", 1.0454),
    ("j12", "Ring_Finger", 1.3588),
    ("j16", "Ring_Finger", 1.42093),
    ("j13", "Pinky", 1.3588),
    ("j17", "Pinky", 1.42307),
    ("index_spread", "Finger_Spread", 0.5),
    ("ring_spread", "Finger_Spread", 0.5),
)
# Servo ranges limited so that no follower is driven past its joint limit (limits from the
# source model, equal to svh.urdf.xacro): spread 2 * 0.28833, j15: 1.334 / 1.0454.
_CTRLRANGE = {
    "Finger_Spread": (0.0, 2 * 0.28833),
    "Middle_Finger_Distal": (0.0, 1.334 / 1.0454),
}
# Design values (SCHUNK publishes no simulation gains): 2 N·m/rad servos, 0.05 N·m·s/rad
# damping; armature 1e-3 kg·m^2 on every finger joint because the source's links have masses of
# 1 g with 1e-8 kg·m^2 inertias, which make the coupled chains numerically stiff.
KP = 2.0
KV = 0.05
ARMATURE = 0.001

_ACTUATED = (
    "Thumb_Flexion",
    "Thumb_Opposition",
    "Index_Finger_Distal",
    "Index_Finger_Proximal",
    "Middle_Finger_Distal",
    "Middle_Finger_Proximal",
    "Ring_Finger",
    "Pinky",
    "Finger_Spread",
)
# robosuite's *_tip sites: 14 mm along the distal link's x axis
_TIP = (0.014, 0.0, 0.0)


def _load():
    import mujoco

    path = package_path("robosuite_models", "assets", "grippers", "schunk_svh_right_hand.xml",
                        pip_name="robosuite-models")  # fmt: skip
    return mujoco.MjSpec.from_file(str(path))


def _chain(human: str, links: str) -> dict[str, SitePlacement]:
    return {f"{human}{i + 1}": SitePlacement(f"{_P}{c}") for i, c in enumerate(links)}


HAND = HandModel(
    name="svh",
    description="SCHUNK SVH (right), 5 fingers, 20 joints, 9 actuators with linkage couplings",
    source=ModelSource(
        kind="package",
        location="robosuite-models: robosuite_models/assets/grippers/schunk_svh_right_hand.xml",
        licence="MIT (robosuite-models)",
        upstream="ARISE-Initiative robosuite_models; SCHUNK schunk_svh_ros_driver",
    ),
    loader=_load,
    root_body=f"{_P}base_link",
    fingers={"thumb": "th", "index": "ff", "middle": "mf", "ring": "rf", "pinky": "lf"},
    tip_sites={
        "th": SitePlacement(f"{_P}c", _TIP),
        "ff": SitePlacement(f"{_P}t", _TIP),
        "mf": SitePlacement(f"{_P}s", _TIP),
        "rf": SitePlacement(f"{_P}r", _TIP),
        "lf": SitePlacement(f"{_P}q", _TIP),
    },
    joint_sites={
        **_chain("thumb", "abc"),  # CMC: Thumb_Flexion, MCP: j3, IP: j4
        **_chain("index", "lpt"),  # MCP: Index_Finger_Proximal, PIP: ..._Distal, DIP: j14
        **_chain("middle", "kos"),
        **_chain("ring", "jnr"),
        **_chain("pinky", "imq"),
    },
    wrist=WristAlignment(distal=(0.0, 0.0, 1.0), radial=(-1.0, 0.0, 0.0)),
    actuators=tuple(
        ActuatorSpec(f"{_P}{j}", KP, kv=KV, ctrlrange=_CTRLRANGE.get(j), source="design value")
        for j in _ACTUATED
    ),
    couplings=tuple(
        JointCoupling(f"{_P}{f}", f"{_P}{lead}", m, source=_XACRO) for f, lead, m in _MIMIC
    ),
    coupling_notes="11 mimic joints of svh.urdf.xacro as joint equalities (9 actuators)",
    joint_armature=ARMATURE,
    joint_damping=0.0,
    joint_frictionloss=0.0,
    default_posture={},  # all 0: fingers straight, thumb not opposed
    # Measured: `retarget calibrate-wrist --hand svh --pairs 12`; the
    # frames lie a median 9.3° (90th percentile 14.6°) from the mean rotation.
    wrist_offset=WristOffset(
        rotvec=(0.1268, -0.1493, 0.3065),  # rad, |20.8°|
        translation=(0.0154, 0.0239, 0.0164),  # m
        source="retarget calibrate-wrist: 12 generated pairs of operator2 (seed 1), 3600 frames",
    ),
    # The wrist is placed by the fingertips and contacts: the human wrist's pose (even with the
    # offset above, 9.3° median scatter) held them off. benchmarks/retarget_speed_quality.py
    # --hands svh --n-pairs 20, 1 → 0: keypoint error 15.05 → 13.90 mm
    # (dex-retargeting 13.34), strict re-sim success 45 → 45 %.
    wrist_weight=0.0,
)
