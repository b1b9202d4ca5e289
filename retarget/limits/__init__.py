"""QP limits: joint and velocity bounds, couplings, collision avoidance."""

from retarget.limits.base import Limit
from retarget.limits.collision import CollisionLimit
from retarget.limits.coupling import CouplingLimit
from retarget.limits.joints import FrameSpeedLimit, JointLimit, VelocityLimit
from retarget.limits.sweep import ContactSweep

__all__ = [
    "CollisionLimit",
    "ContactSweep",
    "CouplingLimit",
    "FrameSpeedLimit",
    "JointLimit",
    "Limit",
    "VelocityLimit",
]
