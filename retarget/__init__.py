"""retarget: the robot side of dexcanvas-retarget.

QP retargeting of human demonstrations onto robot hands, re-simulation validation, metrics and
visualisation. Builds on ``dexcanvas_core`` (data flows one way: this package imports it, never
the reverse).
"""

from retarget.errors import RetargetError

__version__ = "0.1.0"
__all__ = ["RetargetError"]
