"""LEAP Hand (right), authored in ``robots/leap/leap_right.xml`` from published kinematics.

No package ships a LEAP model that loads offline, so the model is authored here
(``robots/leap/derive.py`` writes it from the numbers of the official LEAP_Hand_Sim URDF and the
dex-urdf description; sources and derivation steps in ``robots/leap/README.md``).

Kinematics (Shaw et al., RSS 2023): 16 joints, 16 actuators, 4 fingers. Each of index, middle
and ring: MCP flexion (``*_mcp``, in the palm), the "universal" abduction joint (``*_abd``), PIP,
DIP; thumb: ``th_cmc``, ``th_axl``, ``th_mcp``, ``th_ip``. No couplings. The little finger is
dropped.

Frame: LEAP's ``palm_lower`` frame: fingers +x, index side +y, MCP axes +y so fingers flex
towards -z: distal = +x, radial = +y, volar = -z. Wrist point: the palm's proximal edge
(x = -0.100, the dex-urdf palm box at x = -0.098 is 4 mm thick) on the middle finger's centreline
(y = -0.0369, from the derivation) at the palm's mid-thickness (z = -0.0115, the dex-urdf palm
boxes' centre).
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

# LEAP_Hand_Sim leapsim/cfg/task/LeapHandRot.yaml: controller pgain 3, dgain 0.1
KP = 3.0  # [N·m/rad]
KV = 0.1  # [N·m·s/rad]
# LEAP_Hand_Sim assets/leap_hand/robot.urdf: <limit effort="0.95"/> (Dynamixel XC330-M288-T)
EFFORT = 0.95  # [N·m]

_JOINTS = (
    *(f"{f}_{j}" for f in ("ff", "mf", "rf") for j in ("mcp", "abd", "pip", "dip")),
    "th_cmc",
    "th_axl",
    "th_mcp",
    "th_ip",
)


def _load():
    import mujoco

    return mujoco.MjSpec.from_file(str(robots_dir() / "leap" / "leap_right.xml"))


def _chain(human: str, f: str) -> dict[str, SitePlacement]:
    return {
        f"{human}1": SitePlacement(f"{f}_base"),  # MCP flexion axis
        f"{human}2": SitePlacement(f"{f}_middle"),  # PIP
        f"{human}3": SitePlacement(f"{f}_distal"),  # DIP
    }


HAND = HandModel(
    name="leap",
    description="LEAP Hand (right), 4 fingers x 4 joints, Dynamixel-driven",
    source=ModelSource(
        kind="robots",
        location="robots/leap/leap_right.xml",
        licence="Apache-2.0 (this project); kinematics from LEAP_Hand_Sim (MIT) and dex-urdf",
        upstream="Shaw, Agarwal, Pathak, LEAP Hand, RSS 2023; leap-hand/LEAP_Hand_Sim",
    ),
    loader=_load,
    root_body="palm",
    fingers={"thumb": "th", "index": "ff", "middle": "mf", "ring": "rf", "pinky": None},
    tip_sites={"th": None, "ff": None, "mf": None, "rf": None},  # in leap_right.xml
    joint_sites={
        "thumb1": SitePlacement("th_base"),  # CMC: th_cmc
        "thumb2": SitePlacement("th_middle"),  # MCP: th_mcp
        "thumb3": SitePlacement("th_distal"),  # IP: th_ip
        **_chain("index", "ff"),
        **_chain("middle", "mf"),
        **_chain("ring", "rf"),
    },
    wrist=WristAlignment(
        distal=(1.0, 0.0, 0.0), radial=(0.0, 1.0, 0.0), wrist_point=(-0.100, -0.0369, -0.0115)
    ),
    actuators=tuple(
        ActuatorSpec(
            j,
            KP,
            kv=KV,
            forcerange=(-EFFORT, EFFORT),
            source="LEAP_Hand_Sim LeapHandRot.yaml gains; URDF effort",
        )
        for j in _JOINTS
    ),
    default_posture={},  # all 0: the flat open hand of the URDF
    # Measured: `retarget calibrate-wrist --hand leap --pairs 12`; the
    # frames lie a median 8.1° (90th percentile 13.1°) from the mean rotation.
    wrist_offset=WristOffset(
        rotvec=(-0.0351, 0.0061, -0.2743),  # rad, |15.8°|
        translation=(-0.0125, -0.0162, -0.0034),  # m
        source="retarget calibrate-wrist: 12 generated pairs of operator2 (seed 1), 3600 frames",
    ),
)
