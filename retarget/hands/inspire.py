"""Inspire RH56 dexterous hand (right), authored in ``robots/inspire/inspire_right.xml``.

No package ships an Inspire model that loads offline, so the model is authored here
(``robots/inspire/derive.py`` writes it from the published URDF kinematics; sources and
derivation steps in ``robots/inspire/README.md``).

Kinematics (Inspire RH56DFX): 12 joints, 6 actuators — thumb rotation (``th_cmc_yaw``), thumb
bend (``th_cmc_pitch``), and one per finger (``*_mcp``). Linkages drive the rest; the model file
holds them as joint equality constraints with the URDF's mimic ratios:
``th_mcp = 1.334 th_cmc_pitch``, ``th_ip = 0.667 th_cmc_pitch``,
``*_pip = 1.06399 *_mcp - 0.04545``.

Frame: the URDF's ``hand_base_link``: fingers -y, thumb side -z, MCP axes ≈ -z so fingers flex
towards -x: distal = -y, radial = -z, volar = -x. Wrist point: the origin (the wrist flange).
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
from retarget.hands.sources import robots_dir

# Force limits from measured fingertip forces (Correll lab, correlllab/rh56_controller README:
# index ≈ 7.06 N, middle ≈ 6.47 N, thumb bend ≈ 12.93 N at the maximum force setting) times the
# MCP→fingertip distance of the model (index 0.077 m, thumb pitch axis → tip 0.103 m):
FINGER_TORQUE = 7.06 * 0.077  # ≈ 0.54 N·m (used for all four fingers)
THUMB_BEND_TORQUE = 12.93 * 0.103  # ≈ 1.33 N·m
THUMB_ROTATION_TORQUE = FINGER_TORQUE  # not measured; assumed equal to a finger's
# Design values (no published simulation gains): 2 N·m/rad servos with 0.05 N·m·s/rad damping.
KP = 2.0
KV = 0.05


def _load():
    import mujoco

    return mujoco.MjSpec.from_file(str(robots_dir() / "inspire" / "inspire_right.xml"))


def _act(joint: str, torque: float) -> ActuatorSpec:
    return ActuatorSpec(
        joint, KP, kv=KV, forcerange=(-torque, torque),
        source="force: Correll-lab fingertip force x model lever; kp, kv: design",
    )  # fmt: skip


HAND = HandModel(
    name="inspire",
    description="Inspire RH56 dexterous hand (right), 6 actuators, 12 linkage-coupled joints",
    source=ModelSource(
        kind="robots",
        location="robots/inspire/inspire_right.xml",
        licence="Apache-2.0 (this project); kinematics from dex-urdf's Inspire URDF",
        upstream="Inspire Robots RH56DFX; dexsuite/dex-urdf inspire_hand_right.urdf",
    ),
    loader=_load,
    root_body="base",
    fingers={"thumb": "th", "index": "ff", "middle": "mf", "ring": "rf", "pinky": "lf"},
    tip_sites={"th": None, "ff": None, "mf": None, "rf": None, "lf": None},
    joint_sites={
        "thumb1": SitePlacement("th_proximal"),  # CMC: th_cmc_pitch
        "thumb2": SitePlacement("th_middle"),  # MCP: th_mcp
        "thumb3": SitePlacement("th_distal"),  # IP: th_ip
        **{
            f"{h}1": SitePlacement(f"{f}_proximal")
            for h, f in (("index", "ff"), ("middle", "mf"), ("ring", "rf"), ("pinky", "lf"))
        },
        **{
            f"{h}2": SitePlacement(f"{f}_distal")
            for h, f in (("index", "ff"), ("middle", "mf"), ("ring", "rf"), ("pinky", "lf"))
        },
    },
    wrist=WristAlignment(distal=(0.0, -1.0, 0.0), radial=(0.0, 0.0, -1.0)),
    actuators=(
        _act("th_cmc_yaw", THUMB_ROTATION_TORQUE),
        _act("th_cmc_pitch", THUMB_BEND_TORQUE),
        *(_act(f"{f}_mcp", FINGER_TORQUE) for f in ("ff", "mf", "rf", "lf")),
    ),
    coupling_notes=(
        "linkages as joint equalities in the model file: th_mcp = 1.334 th_cmc_pitch, "
        "th_ip = 0.667 th_cmc_pitch, *_pip = 1.06399 *_mcp - 0.04545"
    ),
    default_posture={},  # all 0: fingers straight (PIP -0.045 by the coupling), thumb open
    # Measured: `retarget calibrate-wrist --hand inspire --pairs 12`; the
    # frames lie a median 9.3° (90th percentile 19.0°) from the mean rotation.
    wrist_offset=WristOffset(
        rotvec=(-0.1359, -0.2631, 0.2720),  # rad, |23.0°|
        translation=(0.0239, 0.0337, 0.0168),  # m
        source="retarget calibrate-wrist: 12 generated pairs of operator2 (seed 1), 3600 frames",
    ),
    # A third of the wrist-pose weights: the coupled fingers reach the human's fingertips
    # with the wrist's help. `python -m benchmarks.retarget_speed_quality --hands inspire
    # --n-pairs 20`, 1 → 1/3: keypoint error 17.76 → 17.46 mm (dex-retargeting 15.45), strict
    # re-sim success 25 → 30 % (0: 17.90 mm, kinematic runs only).
    wrist_weight=1 / 3,
)
