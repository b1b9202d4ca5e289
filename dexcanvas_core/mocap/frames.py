"""The fixed transform between a mocap system's frame and the MANO world frame.

Mocap systems write marker coordinates in their own frame and unit: often y up (OptiTrack,
Qualisys' default for animation), sometimes z up (Vicon), in millimetres. The DexCanvas world
frame is z up, in metres. A :class:`MocapFrame` holds the rigid transform and the unit scale::

    p_world [m] = R_world_mocap @ (unit_m * p_mocap) + t_world_mocap_m

It is fixed for a capture session (calibrated once, like the mocap volume itself); the fitter
applies it to every marker before fitting, and ``render_markers`` applies its inverse.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dexcanvas_core.errors import ValidationError

UNITS_M: dict[str, float] = {"mm": 0.001, "cm": 0.01, "m": 1.0}
"""Metres per unit for the unit names C3D/CSV files use."""

_Y_UP = ((1.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0))
"""Mocap y-up → world z-up: world x = mocap x, world y = −mocap z, world z = mocap y."""
_Z_UP = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


@dataclass(frozen=True)
class MocapFrame:
    """Mocap frame and unit → MANO world frame [m] (z up)."""

    R_world_mocap: tuple[tuple[float, float, float], ...] = _Y_UP
    """Rotation (3 × 3, row-major) from mocap axes to world axes."""
    t_world_mocap_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Position [m] of the mocap origin in the world frame."""
    unit_m: float = 0.001
    """Metres per mocap unit (0.001 for millimetres)."""
    name: str = field(default="y_up_mm", compare=False)
    """Label for reports."""

    def __post_init__(self) -> None:
        R = np.asarray(self.R_world_mocap, dtype=np.float64)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
            raise ValidationError(
                f"MocapFrame.R_world_mocap must be a 3 × 3 rotation matrix, got {R.tolist()}",
                field="R_world_mocap",
            )
        if np.linalg.det(R) < 0:
            raise ValidationError(
                "MocapFrame.R_world_mocap is a reflection (det = -1): a left-handed mocap frame "
                "needs an axis flipped explicitly",
                field="R_world_mocap",
            )
        t = np.asarray(self.t_world_mocap_m, dtype=np.float64)
        if t.shape != (3,) or not np.isfinite(t).all():
            raise ValidationError(
                f"MocapFrame.t_world_mocap_m must be 3 finite numbers [m], got {t.tolist()}",
                field="t_world_mocap_m",
            )
        if not (math.isfinite(self.unit_m) and self.unit_m > 0):
            raise ValidationError(
                f"MocapFrame.unit_m must be > 0 [m per unit], got {self.unit_m}", field="unit_m"
            )
        object.__setattr__(self, "R_world_mocap", tuple(tuple(map(float, r)) for r in R))
        object.__setattr__(self, "t_world_mocap_m", tuple(map(float, t)))

    @classmethod
    def y_up(cls, unit: str = "mm", origin_world_m: Any = (0.0, 0.0, 0.0)) -> MocapFrame:
        """A y-up mocap frame (x shared with the world) in ``unit``; its origin at
        ``origin_world_m`` [m] in the world."""
        return cls(_Y_UP, tuple(origin_world_m), _unit(unit), name=f"y_up_{unit}")

    @classmethod
    def z_up(cls, unit: str = "mm", origin_world_m: Any = (0.0, 0.0, 0.0)) -> MocapFrame:
        """A z-up mocap frame (axes shared with the world) in ``unit``."""
        return cls(_Z_UP, tuple(origin_world_m), _unit(unit), name=f"z_up_{unit}")

    @property
    def R(self) -> np.ndarray:
        return np.asarray(self.R_world_mocap, dtype=np.float64)

    @property
    def t(self) -> np.ndarray:
        return np.asarray(self.t_world_mocap_m, dtype=np.float64)

    def with_unit(self, unit_m: float) -> MocapFrame:
        """The same axes and origin with another unit (e.g. the unit a C3D file declares)."""
        return MocapFrame(self.R_world_mocap, self.t_world_mocap_m, float(unit_m), self.name)

    def to_world(self, p_mocap: np.ndarray) -> np.ndarray:
        """``(..., 3)`` mocap coordinates [unit] → world [m] (NaN stays NaN)."""
        p = np.asarray(p_mocap, dtype=np.float64)
        return (self.unit_m * p) @ self.R.T + self.t

    def to_mocap(self, p_world: np.ndarray) -> np.ndarray:
        """``(..., 3)`` world [m] → mocap coordinates [unit]."""
        p = np.asarray(p_world, dtype=np.float64)
        return ((p - self.t) @ self.R) / self.unit_m

    def to_dict(self) -> dict[str, Any]:
        return {
            "R_world_mocap": [list(r) for r in self.R_world_mocap],
            "t_world_mocap_m": list(self.t_world_mocap_m),
            "unit_m": self.unit_m,
            "name": self.name,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> MocapFrame:
        unknown = set(d) - {"R_world_mocap", "t_world_mocap_m", "unit_m", "name", "up", "unit"}
        if unknown:
            raise ValidationError(
                f"unknown mocap frame keys {sorted(unknown)}; expected R_world_mocap, "
                "t_world_mocap_m, unit_m (or up: 'y'|'z' and unit: 'mm'|'cm'|'m')",
                field="mocap_frame",
            )
        if "up" in d:
            up = d["up"]
            if up not in ("y", "z"):
                raise ValidationError(f"mocap frame 'up' must be 'y' or 'z', got {up!r}")
            maker = cls.y_up if up == "y" else cls.z_up
            return maker(d.get("unit", "mm"), d.get("t_world_mocap_m", (0.0, 0.0, 0.0)))
        return cls(
            tuple(tuple(r) for r in d.get("R_world_mocap", _Y_UP)),
            tuple(d.get("t_world_mocap_m", (0.0, 0.0, 0.0))),
            float(d.get("unit_m", 0.001)),
            name=str(d.get("name", "custom")),
        )


def _unit(unit: str) -> float:
    key = str(unit).strip().lower()
    if key not in UNITS_M:
        raise ValidationError(
            f"unknown length unit {unit!r}; expected one of {', '.join(UNITS_M)}", field="unit"
        )
    return UNITS_M[key]
