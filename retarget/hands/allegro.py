"""Allegro Hand V4 (right), from example-robot-data's URDF.

Source: ``cmeel.prefix/share/example-robot-data/robots/allegro_hand_description/urdf/
allegro_right_hand.urdf`` (example-robot-data, BSD; upstream Wonik Robotics
``allegro_hand_description``). MuJoCo loads the URDF through ``mujoco.MjSpec.from_string`` with a
``<mujoco><compiler balanceinertia="true" .../></mujoco>`` extension: ``balanceinertia`` because
some link inertias violate the triangle inequality, ``meshdir`` pointing at the package's
``meshes/`` (``strippath`` drops the ``package://`` prefixes), ``fusestatic="false"`` to keep the
``link_*_tip`` bodies.

Kinematics: 16 joints, 4 fingers (index joints 0–3, middle 4–7, ring 8–11, thumb 12–15), each
actuated; no couplings. The little finger has no robot counterpart (dropped).

Frame: ``palm_link``, origin at the top of the palm (between the finger bases); fingers +z, the
index finger and thumb on the +y side, fingers flex towards +x (joint_1.0 axis +y): distal = +z,
radial = +y, volar = +x. The wrist point is the centre of the palm box's bottom face: the URDF's
palm collision box (centre (-0.0093, 0, -0.0475), size 0.0408 × 0.1130 × 0.095 m) ends at
z = -0.095.

URDF ``<dynamics damping="3" friction="10">`` would make MuJoCo joints with 10 N·m of dry
friction; joint damping and friction are set as in MuJoCo Menagerie's ``wonik_allegro``
(damping 1, no friction loss).
"""

from __future__ import annotations

from retarget.hands.base import (
    ActuatorSpec,
    ModelSource,
    SitePlacement,
    WristAlignment,
    WristOffset,
)
from retarget.hands.model import HandModel
from retarget.hands.sources import example_robot_data_path, urdf_with_mujoco_compiler

# MuJoCo Menagerie wonik_allegro/right_hand.xml: <position kp="10"/>, <joint damping="1"/>
KP = 10.0  # [N·m/rad]
DAMPING = 1.0  # [N·m·s/rad]
# allegro_right_hand.urdf: <limit effort="15"/> on every joint [N·m] (the URDF's value; the real
# hand's motors are far weaker, see README "approximations")
EFFORT = 15.0
FINGERTIP_RADIUS = 0.012  # [m] URDF link_*_tip collision sphere radius


def _load():
    import mujoco

    root = example_robot_data_path("allegro_hand_description")
    text = (root / "urdf" / "allegro_right_hand.urdf").read_text()
    text = urdf_with_mujoco_compiler(
        text,
        balanceinertia="true",
        discardvisual="false",
        fusestatic="false",
        strippath="true",
        meshdir=str(root / "meshes"),
    )
    return mujoco.MjSpec.from_string(text)


_FINGERS = {"ff": 0, "mf": 4, "rf": 8}  # first joint index of each finger


def _finger_sites(human: str, first: int) -> dict[str, SitePlacement]:
    return {
        f"{human}1": SitePlacement(f"link_{first + 1}.0"),  # MCP flexion (joint first+1)
        f"{human}2": SitePlacement(f"link_{first + 2}.0"),  # PIP
        f"{human}3": SitePlacement(f"link_{first + 3}.0"),  # DIP
    }


HAND = HandModel(
    name="allegro",
    description="Wonik Allegro Hand V4 (right), 4 fingers x 4 joints",
    source=ModelSource(
        kind="package",
        location=(
            "example-robot-data: share/example-robot-data/robots/allegro_hand_description/"
            "urdf/allegro_right_hand.urdf"
        ),
        licence="BSD (example-robot-data)",
        upstream="Wonik Robotics allegro_hand_description (allegro_hand_linux_v4)",
    ),
    loader=_load,
    root_body="palm_link",
    fingers={"thumb": "th", "index": "ff", "middle": "mf", "ring": "rf", "pinky": None},
    # fingertip sites at the distal end of each tip sphere (URDF link_*_tip, radius 12 mm)
    tip_sites={
        "th": SitePlacement("link_15.0_tip", (0.0, 0.0, FINGERTIP_RADIUS)),
        "ff": SitePlacement("link_3.0_tip", (0.0, 0.0, FINGERTIP_RADIUS)),
        "mf": SitePlacement("link_7.0_tip", (0.0, 0.0, FINGERTIP_RADIUS)),
        "rf": SitePlacement("link_11.0_tip", (0.0, 0.0, FINGERTIP_RADIUS)),
    },
    joint_sites={
        "thumb1": SitePlacement("link_13.0"),  # CMC: base of the thumb's moving chain
        "thumb2": SitePlacement("link_14.0"),  # MCP: joint_14.0
        "thumb3": SitePlacement("link_15.0"),  # IP: joint_15.0
        **_finger_sites("index", 0),
        **_finger_sites("middle", 4),
        **_finger_sites("ring", 8),
    },
    wrist=WristAlignment(
        distal=(0.0, 0.0, 1.0), radial=(0.0, 1.0, 0.0), wrist_point=(-0.0093, 0.0, -0.095)
    ),
    actuators=tuple(
        ActuatorSpec(
            f"joint_{i}.0",
            KP,
            forcerange=(-EFFORT, EFFORT),
            source="kp: MuJoCo Menagerie wonik_allegro; force limit: URDF effort",
        )
        for i in range(16)
    ),
    joint_damping=DAMPING,
    joint_frictionloss=0.0,
    default_posture={"joint_12.0": 0.263},  # thumb rotation at its lower limit (URDF), others 0
    # Measured: `retarget calibrate-wrist --hand allegro --pairs 12`; the
    # frames lie a median 8.3° (90th percentile 14.3°) from the mean rotation.
    wrist_offset=WristOffset(
        rotvec=(-0.0970, -0.1907, -0.1150),  # rad, |13.9°|
        translation=(0.0012, 0.0020, 0.0154),  # m
        source="retarget calibrate-wrist: 12 generated pairs of operator2 (seed 1), 3600 frames",
    ),
    # The middle distal joint rests on its extension limit (-0.227 rad) in the built-in
    # cube2/tripod's grasp and cannot press from there: the heavy cube of `retarget run --hand
    # allegro --pair cube2H/tripod --forces` dropped with the wrist offset (12.1 cm) and is
    # held with this margin (1.06 cm; 0.1 rad: 2.42 cm). See RetargetConfig.joint_limits.margin.
    joint_limit_margin=0.05,
)
