"""PSYONIC Ability Hand (right), from robosuite-models' MuJoCo gripper model.

Source: ``robosuite_models/assets/grippers/ability_right_hand.xml`` (robosuite-models, MIT), located
with ``importlib.util.find_spec`` (importing ``robosuite_models`` needs robosuite). The file is
built for robosuite (a ``right_hand`` mount body with the end-effector sites, force/torque
sensors, torque motors on all 10 joints); only the hand from its ``base`` body is kept, and the
motors are replaced by position servos on the 6 actuated joints.

Kinematics: 10 joints; index…little have an MCP (``*_q1``) and a PIP (``*_q2``) joint driven by
one motor through a four-bar linkage, modelled as PSYONIC does in its own MuJoCo model: the
linear fit ``q2 = 0.72349796 + 1.05851325 * q1`` (psyonicinc/ability-hand-api
``URDF/mujoco/README.md``), here a joint equality constraint. Thumb: rotator (``thumb_q1``) and
flexor (``thumb_q2``), both actuated. 6 actuators.

Frame: robosuite's ``base`` body, origin at the wrist mount; fingers +z, the index finger and
thumb on the -x side; the MCP axes are ≈ -x, so fingers flex towards +y: distal = +z,
radial = -x, volar = +y. Wrist point: the origin (the mount).
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

_PSYONIC = "psyonicinc/ability-hand-api URDF/mujoco/hands/abh_right_large.xml"
# PIP-MCP linkage, linear fit: psyonicinc/ability-hand-api URDF/mujoco/README.md
PIP_MULTIPLIER = 1.05851325
PIP_OFFSET = 0.72349796  # [rad]
# PSYONIC's MuJoCo model: finger MCP range 0…1.74 rad, thumb flexor 0…1.91, rotator -2.09…0;
# position servos kp = 1 N·m/rad, kv = 0; joint damping 0.01 N·m·s/rad.
MCP_RANGE = (0.0, 1.74)
THUMB_FLEXOR_RANGE = (0.0, 1.91)
THUMB_ROTATOR_RANGE = (-2.09, 0.0)
KP = 1.0
DAMPING = 0.01

_FINGERS = (("ff", "index"), ("mf", "middle"), ("rf", "ring"), ("lf", "pinky"))


def _load():
    import mujoco

    path = package_path("robosuite_models", "assets", "grippers", "ability_right_hand.xml",
                        pip_name="robosuite-models")  # fmt: skip
    return mujoco.MjSpec.from_file(str(path))


HAND = HandModel(
    name="ability",
    description="PSYONIC Ability Hand (right), 5 fingers, linkage-coupled PIP joints",
    source=ModelSource(
        kind="package",
        location="robosuite-models: robosuite_models/assets/grippers/ability_right_hand.xml",
        licence="MIT (robosuite-models)",
        upstream="ARISE-Initiative robosuite_models; PSYONIC ability-hand-api",
    ),
    loader=_load,
    root_body="base",
    fingers={"thumb": "th", "index": "ff", "middle": "mf", "ring": "rf", "pinky": "lf"},
    # fingertip sites where robosuite's *_tip sites are
    tip_sites={
        "th": SitePlacement("thumb_L2", (0.065, 0.016, 0.0)),
        **{rf: SitePlacement(f"{src}_L2", (0.035, -0.018, 0.0)) for rf, src in _FINGERS},
    },
    joint_sites={
        "thumb1": SitePlacement("thumb_L1"),  # CMC: rotator
        "thumb2": SitePlacement("thumb_L2"),  # MCP: flexor
        **{f"{src}1": SitePlacement(f"{src}_L1") for _, src in _FINGERS},  # MCP
        **{f"{src}2": SitePlacement(f"{src}_L2") for _, src in _FINGERS},  # PIP
    },
    wrist=WristAlignment(distal=(0.0, 0.0, 1.0), radial=(-1.0, 0.0, 0.0)),
    actuators=(
        ActuatorSpec("thumb_q1", KP, ctrlrange=THUMB_ROTATOR_RANGE, source=_PSYONIC),
        ActuatorSpec("thumb_q2", KP, ctrlrange=THUMB_FLEXOR_RANGE, source=_PSYONIC),
        *(
            ActuatorSpec(f"{src}_q1", KP, ctrlrange=MCP_RANGE, source=_PSYONIC)
            for _, src in _FINGERS
        ),
    ),
    couplings=tuple(
        JointCoupling(
            f"{src}_q2",
            f"{src}_q1",
            PIP_MULTIPLIER,
            PIP_OFFSET,
            source="psyonicinc/ability-hand-api URDF/mujoco/README.md",
        )
        for _, src in _FINGERS
    ),
    coupling_notes="PIP = 0.72349796 + 1.05851325 * MCP on index..little (joint equalities)",
    joint_ranges={
        "thumb_q1": THUMB_ROTATOR_RANGE,
        "thumb_q2": THUMB_FLEXOR_RANGE,
        **{f"{src}_q1": MCP_RANGE for _, src in _FINGERS},
    },
    joint_damping=DAMPING,
    joint_frictionloss=0.0,
    default_posture={},  # MCP 0 (PIP 0.72 by the coupling: finger straight), thumb 0
    # Measured: `retarget calibrate-wrist --hand ability --pairs 12`; the
    # frames lie a median 11.0° (90th percentile 23.0°) from the mean rotation.
    wrist_offset=WristOffset(
        rotvec=(0.0193, -0.1498, 0.1368),  # rad, |11.7°|
        translation=(0.0111, 0.0020, 0.0056),  # m
        source="retarget calibrate-wrist: 12 generated pairs of operator2 (seed 1), 3600 frames",
    ),
    # A third of the wrist-pose weights: the coupled fingers reach the human's fingertips
    # with the wrist's help. `python -m benchmarks.retarget_speed_quality --hands ability
    # --n-pairs 20`, 1 → 1/3: keypoint error 14.19 → 13.98 mm (dex-retargeting 11.81), strict
    # re-sim success 40 → 40 % (0: 14.10 mm, kinematic runs only).
    wrist_weight=1 / 3,
)
