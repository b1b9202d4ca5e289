"""Shadow Dexterous Hand (right), from gymnasium-robotics' MuJoCo model.

Source: ``gymnasium_robotics/envs/assets/hand/`` (gymnasium-robotics, MIT; the Shadow hand assets
carry the Apache-2.0 notice of their ``LICENSE.md``), the model OpenAI published for its hand
environments. ``reach.xml`` ``<include>``s ``shared.xml`` (defaults, tendons, actuators),
``shared_asset.xml`` (meshes) and ``robot.xml`` (bodies); ``mujoco.MjSpec.from_file`` resolves the
includes, and the hand is taken from its ``robot0:wrist`` body (the forearm and the scene are
dropped; the ``robot0:`` namespace is stripped, the source's ``wrist`` body becomes
``wrist_link``).

Kinematics: 24 joints — wrist WRJ1/WRJ0, 4 per finger (J3 abduction, J2 MCP, J1 PIP, J0 DIP),
little finger +LFJ4 (metacarpal), thumb THJ4…THJ0 — and 20 actuators: each finger's J1 and J0 are
coupled by a fixed tendon (``T_FFJ1c`` etc.: ``0.00705·J0 − 0.00805·J1`` held within ±1 mm, i.e.
J0 ≈ 1.14·J1), the source's way of modelling Shadow's single-tendon distal joints; these tendons
are kept as they are and only J1 is actuated.

Frame: the root (source ``robot0:wrist``) has its origin on the WRJ1 wrist axis; fingers point
+z, the first finger and thumb are on the +x side, and the fingers flex towards -y (J2 axes +x):
distal = +z, radial = +x, volar = radial × distal = -y. Its wrist point is the origin (the wrist
joint).
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
from retarget.hands.sources import package_path

_SRC = "gymnasium-robotics envs/assets/hand/shared.xml <actuator>"

# (joint, kp [N·m/rad], force limit [N·m]) — the source's position actuators (shared.xml)
_GAINS = (
    ("WRJ1", 5.0, 4.785),
    ("WRJ0", 5.0, 2.175),
    *(
        (f"{f}J{j}", 1.0, lim)
        for f in ("FF", "MF", "RF")
        for j, lim in ((3, 0.9), (2, 0.9), (1, 0.7245))
    ),
    ("LFJ4", 1.0, 0.9),
    ("LFJ3", 1.0, 0.9),
    ("LFJ2", 1.0, 0.9),
    ("LFJ1", 1.0, 0.7245),
    ("THJ4", 1.0, 2.3722),
    ("THJ3", 1.0, 1.45),
    ("THJ2", 1.0, 0.99),
    ("THJ1", 1.0, 0.99),
    ("THJ0", 1.0, 0.81),
)


def _load():
    import re

    import mujoco

    folder = package_path("gymnasium_robotics", "envs", "assets", "hand",
                          pip_name="gymnasium-robotics")  # fmt: skip

    def read(name: str) -> str:
        # The source names everything "robot0:…"; drop that namespace (and rename the source's
        # "wrist" body, which would clash with the floating-wrist body).
        text = (folder / name).read_text()
        return text.replace('<body name="robot0:wrist"', '<body name="wrist_link"').replace(
            "robot0:", ""
        )

    def body(name: str) -> str:  # an included file's content, without its <mujoco> element
        text = read(name)
        return text[text.index(">", text.index("<mujoco")) + 1 : text.rindex("</mujoco>")]

    main = read("reach.xml")
    main = re.sub(r'<include file="([^"]+)"\s*(?:/>|></include>)', lambda m: body(m.group(1)), main)
    main = main.replace('meshdir="../stls/hand"', f'meshdir="{folder.parent / "stls" / "hand"}"')
    main = main.replace('texturedir="../textures"', f'texturedir="{folder.parent / "textures"}"')
    return mujoco.MjSpec.from_string(main)


def _finger_sites(f: str, prefix: str) -> dict[str, SitePlacement]:
    return {
        f"{f}1": SitePlacement(f"{prefix}knuckle"),  # MCP (J3/J2 axes)
        f"{f}2": SitePlacement(f"{prefix}middle"),  # PIP (J1)
        f"{f}3": SitePlacement(f"{prefix}distal"),  # DIP (J0)
    }


HAND = HandModel(
    name="shadow",
    description="Shadow Dexterous Hand E (right), 5 fingers, tendon-coupled distal joints",
    source=ModelSource(
        kind="package",
        location="gymnasium-robotics: gymnasium_robotics/envs/assets/hand/reach.xml",
        licence="MIT (gymnasium-robotics); Shadow assets Apache-2.0 (LICENSE.md)",
        upstream="OpenAI hand environments (Plappert et al. 2018), Farama Gymnasium-Robotics",
    ),
    loader=_load,
    root_body="wrist_link",
    fingers={"thumb": "th", "index": "ff", "middle": "mf", "ring": "rf", "pinky": "lf"},
    # fingertip sites where the source's S_*tip sites are (distal link +26 mm, thumb +27.5 mm)
    tip_sites={
        "th": SitePlacement("thdistal", (0.0, 0.0, 0.0275)),
        "ff": SitePlacement("ffdistal", (0.0, 0.0, 0.026)),
        "mf": SitePlacement("mfdistal", (0.0, 0.0, 0.026)),
        "rf": SitePlacement("rfdistal", (0.0, 0.0, 0.026)),
        "lf": SitePlacement("lfdistal", (0.0, 0.0, 0.026)),
    },
    joint_sites={
        "thumb1": SitePlacement("thbase"),  # CMC: THJ4/THJ3
        "thumb2": SitePlacement("thhub"),  # MCP: THJ2/THJ1
        "thumb3": SitePlacement("thdistal"),  # IP: THJ0
        **_finger_sites("index", "ff"),
        **_finger_sites("middle", "mf"),
        **_finger_sites("ring", "rf"),
        **_finger_sites("pinky", "lf"),
    },
    wrist=WristAlignment(distal=(0.0, 0.0, 1.0), radial=(1.0, 0.0, 0.0)),
    actuators=tuple(ActuatorSpec(j, kp, forcerange=(-f, f), source=_SRC) for j, kp, f in _GAINS),
    coupling_notes=(
        "distal joints: fixed tendons T_{FF,MF,RF,LF}J1c keep 0.00705*J0 - 0.00805*J1 within "
        "+-1 mm (J0 ~ 1.14*J1), kept from the source; only J1 is actuated"
    ),
    default_posture={},  # all joints 0: fingers straight, thumb in the palm plane
    # Measured: `retarget calibrate-wrist --hand shadow --pairs 12`, WRJ1 and
    # WRJ0 held at 0; the frames lie a median 6.8° (90th percentile 12.3°) from the mean rotation.
    wrist_offset=WristOffset(
        rotvec=(0.0885, -0.1423, -0.0161),  # rad, |9.6°|
        translation=(0.0295, -0.0051, 0.0071),  # m
        source="retarget calibrate-wrist: 12 generated pairs of operator2 (seed 1), 3600 frames",
    ),
)
