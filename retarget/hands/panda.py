"""Franka Emika Panda parallel gripper, from example-robot-data's URDF.

Source: ``cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf``
(example-robot-data; Apache-2.0, upstream frankaemika ``franka_description``). The URDF describes
the whole arm; MuJoCo loads it with ``fusestatic="false"`` (so ``panda_hand`` stays a body),
``discardvisual="true"`` (the visual meshes are COLLADA, which MuJoCo does not read) and
``meshdir`` = the package's ``meshes/collision``; only the ``panda_hand`` subtree is kept.

Kinematics: two prismatic fingers, ``panda_finger_joint2`` mimics ``panda_finger_joint1``
(URDF ``<mimic>``; MuJoCo's URDF importer turns it into a joint equality constraint, kept here).
One actuator drives ``panda_finger_joint1`` [m], 0 (closed) … 0.04 (open) per finger.

Correspondence: the thumb drives the left finger (``panda_leftfinger``, +y), index and middle
drive the right finger; ring and little are dropped.

Frame: ``panda_hand``, origin at the flange; fingers along +z, the left finger opens towards +y.
distal = +z, radial (thumb side) = +y, "volar" = radial × distal = +x. Wrist point: the flange.
"""

from __future__ import annotations

from retarget.hands.base import ActuatorSpec, ModelSource, SitePlacement, WristAlignment
from retarget.hands.model import HandModel
from retarget.hands.sources import example_robot_data_path, urdf_with_mujoco_compiler

# panda.urdf: panda_finger_joint1 <limit effort="100" upper="0.04"/>
FINGER_EFFORT = 100.0  # [N]
FINGER_OPEN = 0.04  # [m]
# Design value: 500 N/m servo on the finger slide (10 N for 2 cm of squeeze); with the added
# 0.01 kg armature (the gripper drive's reflected mass) it stays well inside the stable range at
# a 2 ms timestep.
FINGER_KP = 500.0  # [N/m]
FINGER_ARMATURE = 0.01  # [kg]
# panda.urdf rubber fingertip pad: box centred (0, ±7.58e-3, 45.25e-3) in the finger frame; the
# pad's inner (gripping) face is the y = 0 plane of the finger frame.
PAD_CENTRE_Z = 0.04525  # [m]


def _load():
    import mujoco

    root = example_robot_data_path("panda_description")
    text = (root / "urdf" / "panda.urdf").read_text()
    text = urdf_with_mujoco_compiler(
        text,
        balanceinertia="true",
        discardvisual="true",
        fusestatic="false",
        strippath="true",
        meshdir=str(root / "meshes" / "collision"),
    )
    return mujoco.MjSpec.from_string(text)


HAND = HandModel(
    name="panda",
    description="Franka Emika Panda parallel gripper (2 mimic-coupled fingers)",
    source=ModelSource(
        kind="package",
        location="example-robot-data: share/example-robot-data/robots/panda_description/urdf/"
        "panda.urdf",
        licence="Apache-2.0 (panda_description)",
        upstream="frankaemika franka_description",
    ),
    loader=_load,
    root_body="panda_hand",
    fingers={"thumb": "left", "index": "right", "middle": "right", "ring": None, "pinky": None},
    tip_sites={
        "left": SitePlacement("panda_leftfinger", (0.0, 0.0, PAD_CENTRE_Z)),
        "right": SitePlacement("panda_rightfinger", (0.0, 0.0, PAD_CENTRE_Z)),
    },
    joint_sites={},
    wrist=WristAlignment(distal=(0.0, 0.0, 1.0), radial=(0.0, 1.0, 0.0)),
    actuators=(
        ActuatorSpec(
            "panda_finger_joint1",
            FINGER_KP,
            kv=10.0,  # [N·s/m] design value: ~critical damping of kp 500 on ~0.05 kg
            forcerange=(-FINGER_EFFORT, FINGER_EFFORT),
            source="force limit: panda.urdf effort; kp, kv: design values",
        ),
    ),
    coupling_notes="panda_finger_joint2 = panda_finger_joint1 (URDF <mimic>, joint equality)",
    default_posture={"panda_finger_joint1": FINGER_OPEN, "panda_finger_joint2": FINGER_OPEN},
    joint_armature=FINGER_ARMATURE,
    # No wrist term: a gripper's wrist has no pose that matches the human wrist's (the
    # calibration's mean offset is 36.7° with a 35.1° median scatter, `retarget
    # calibrate-wrist --hand panda --pairs 12`), so its two pads and the contacts place it.
    # python -m benchmarks.retarget_speed_quality --hands panda --n-pairs 20, 1 → 0:
    # keypoint error 40.92 → 19.34 mm (dex-retargeting 20.58), strict re-sim success 7 → 7 %.
    wrist_weight=0.0,
)
