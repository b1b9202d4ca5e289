"""The five built-in operators: hand sizes that span adult hands.

An operator is the default MANO-compatible skeleton (``HandSkeleton.default``, MANO's mean hand,
wrist-to-middle-fingertip ≈ 176 mm) scaled uniformly about the wrist. The five scales
0.90, 0.95, 1.00, 1.05, 1.10 cover roughly the 5th-percentile woman to the 95th-percentile man:
adult hand length has a coefficient of variation of about 5 % within each sex and the sexes'
means differ by about 8 % (US Army anthropometry: ANSUR II, Gordon et al. 2014, NATICK/TR-15/007,
hand length ≈ 19 cm for men and ≈ 18 cm for women with ≈ 1 cm standard deviations — values as
recalled, not re-read; the same spread as ``mano.skeleton.BETA0_SCALE_PER_UNIT``'s derivation).

``Operator.betas`` expresses the size in the skeleton path's shape convention (β₀ only:
``scale = exp(BETA0_SCALE_PER_UNIT · β₀)``), so a ``ManoLayer`` without model files fed these
betas reproduces the operator's keypoints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dexcanvas_core.errors import UnknownNameError
from dexcanvas_core.mano.skeleton import BETA0_SCALE_PER_UNIT, HandSkeleton


@dataclass(frozen=True)
class Operator:
    """One built-in demonstrator.

    Attributes:
        name: ``"operator1"`` … ``"operator5"``.
        scale: hand size relative to the default skeleton (uniform, about the wrist).
        description: who the size stands for.
    """

    name: str
    scale: float
    description: str = ""

    def skeleton(self) -> HandSkeleton:
        """The operator's right-hand skeleton."""
        return HandSkeleton.default("right").scaled(self.scale)

    @property
    def hand_length_m(self) -> float:
        """Wrist joint to middle fingertip at rest [m]."""
        kp = self.skeleton().rest_keypoints
        return float(np.linalg.norm(kp[18] - kp[0]))

    @property
    def betas(self) -> np.ndarray:
        """``(10,)`` MANO shape in the skeleton path's convention (β₀ sets the size)."""
        b = np.zeros(10)
        b[0] = math.log(self.scale) / BETA0_SCALE_PER_UNIT
        return b


OPERATORS: dict[str, Operator] = {
    o.name: o
    for o in (
        Operator("operator1", 0.90, "small hand (≈ 5th-percentile adult woman)"),
        Operator("operator2", 0.95, "smaller than average"),
        Operator("operator3", 1.00, "MANO's mean hand"),
        Operator("operator4", 1.05, "larger than average"),
        Operator("operator5", 1.10, "large hand (≈ 95th-percentile adult man)"),
    )
}
"""The five built-in operators by name."""


def operator(name: str | Operator) -> Operator:
    """Look an operator up by name (``"operator3"``) or return it unchanged."""
    if isinstance(name, Operator):
        return name
    try:
        return OPERATORS[name]
    except (KeyError, TypeError):
        raise UnknownNameError("operator", name, OPERATORS) from None
