"""QP objectives: each a residual and its Jacobian (see ``base.Objective``)."""

from retarget.objectives.base import Objective
from retarget.objectives.contacts import SurfaceContactObjective
from retarget.objectives.keypoints import KeypointObjective, VectorObjective
from retarget.objectives.regularization import PostureObjective, SmoothnessObjective
from retarget.objectives.site_contacts import ContactObjective
from retarget.objectives.wrist import WristPoseObjective

__all__ = [
    "ContactObjective",
    "KeypointObjective",
    "Objective",
    "PostureObjective",
    "SmoothnessObjective",
    "SurfaceContactObjective",
    "VectorObjective",
    "WristPoseObjective",
]
