"""Robot hands: one module per hand, and the registry behind ``--hand``.

>>> from retarget.hands import get_hand
>>> hand = get_hand("shadow")
>>> model = hand.compile()                 # mujoco.MjModel: floating wrist + hand
>>> hand.keypoint_map["index_tip"]         # MANO21 keypoint -> robot site
'ff_tip_site'

Adding a hand is one module in this package that defines ``HAND = HandModel(...)``
(:mod:`retarget.hands.model`; see ``shadow.py`` for a package-sourced model, ``leap.py`` for one
authored in ``robots/``); the registry finds it by itself. Out-of-tree hands call :func:`register`
or declare an entry point in the ``dexcanvas_retarget.hands`` group.
"""

from retarget.hands.base import (
    HUMAN_FINGERS,
    WRIST_BODY,
    WRIST_JOINTS,
    WRIST_SITE,
    ActuatorSpec,
    ContactParams,
    JointCoupling,
    ModelSource,
    SitePlacement,
    WristAlignment,
    WristGains,
    WristOffset,
    wrist_qpos_from_mano,
)
from retarget.hands.model import HandModel
from retarget.hands.registry import (
    available_hands,
    get_hand,
    hands_table,
    register,
    unregister,
)

__all__ = [
    "HUMAN_FINGERS",
    "WRIST_BODY",
    "WRIST_JOINTS",
    "WRIST_SITE",
    "ActuatorSpec",
    "ContactParams",
    "HandModel",
    "JointCoupling",
    "ModelSource",
    "SitePlacement",
    "WristAlignment",
    "WristGains",
    "WristOffset",
    "available_hands",
    "get_hand",
    "hands_table",
    "register",
    "unregister",
    "wrist_qpos_from_mano",
]
