"""The table the demonstrations are performed on: a box of finite extent in the world frame.

The table top is a rectangle at height ``top_z_m``; the table is a box below it, ``thickness_m``
thick. Beyond its edges there is nothing: a hand or object that goes lower than the top there is
not held up (physics) and is not kept above it (retargeting and the demonstration generator keep
their table clearance only over the top, :meth:`Table.over`).

A trajectory may carry its own table (``Trajectory.table``, stored in the Lance column ``table``);
without one, :data:`DEFAULT_TABLE` applies. Every scene builder takes the table as an argument.

The default, :data:`DEFAULT_TABLE`, is a 1.2 m × 0.8 m top at z = 0 (the height the object
catalogue's rest poses and every built-in demonstration are expressed against), centred under
the built-in demonstrations' objects (x = 0.42 m, y = 0; their start positions are drawn within
±3 cm in x and ±5 cm in y of it, ``dexcanvas_core.demos.demo.generate_demo``), long side along
x, so the built-in demonstrations' hands and objects stay well inside its edges. The size is
that of a common lab bench, not a measured property of the DexCanvas capture table, whose
dimensions the paper does not give.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

from dexcanvas_core.errors import ValidationError


@dataclass(frozen=True)
class Table:
    """A table of finite extent (world frame, z up).

    All lengths in metres, the yaw in radians.
    """

    top_z_m: float = 0.0
    """Height of the table top [m]."""
    size_x_m: float = 1.2
    """Length of the top along the table's own x axis [m] (> 0)."""
    size_y_m: float = 0.8
    """Width of the top along the table's own y axis [m] (> 0)."""
    thickness_m: float = 0.05
    """Thickness of the table box below the top [m] (> 0)."""
    center_x_m: float = 0.42
    """World x of the top's centre [m]."""
    center_y_m: float = 0.0
    """World y of the top's centre [m]."""
    yaw_rad: float = 0.0
    """Rotation of the table's x axis from the world's x axis, about z [rad]."""

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, int | float | np.floating | np.integer):
                raise ValidationError(
                    f"table {f.name} must be a number, got {v!r}", field=f"table.{f.name}"
                )
            if not math.isfinite(float(v)):
                raise ValidationError(
                    f"table {f.name} must be finite, got {v!r}", field=f"table.{f.name}"
                )
            object.__setattr__(self, f.name, float(v))
        for name in ("size_x_m", "size_y_m", "thickness_m"):
            if getattr(self, name) <= 0.0:
                raise ValidationError(
                    f"table {name} must be > 0 [m], got {getattr(self, name)!r}",
                    field=f"table.{name}",
                )

    # -- geometry -----------------------------------------------------------------------------
    @property
    def half_size(self) -> tuple[float, float, float]:
        """Half extents [m] of the table box (MuJoCo's box ``size``)."""
        return (0.5 * self.size_x_m, 0.5 * self.size_y_m, 0.5 * self.thickness_m)

    @property
    def box_center(self) -> tuple[float, float, float]:
        """World position [m] of the table box's centre (half a thickness below the top)."""
        return (self.center_x_m, self.center_y_m, self.top_z_m - 0.5 * self.thickness_m)

    @property
    def quat_wxyz(self) -> tuple[float, float, float, float]:
        """The box's orientation in the world (the yaw about z), scalar first."""
        h = 0.5 * self.yaw_rad
        return (math.cos(h), 0.0, 0.0, math.sin(h))

    def local_xy(self, points_world) -> np.ndarray:
        """``(..., 2)`` coordinates [m] of world points ``(..., 2 or 3)`` in the top's frame
        (origin at its centre, axes along its sides)."""
        p = np.asarray(points_world, dtype=np.float64)
        dx = p[..., 0] - self.center_x_m
        dy = p[..., 1] - self.center_y_m
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)

    def over(self, points_world, margin_m: float = 0.0) -> np.ndarray:
        """``(...)`` bool: whether world points ``(..., 2 or 3)`` lie over (or under) the top,
        its rectangle grown by ``margin_m`` [m] on every side (negative: shrunk)."""
        local = np.abs(self.local_xy(points_world))
        return (local[..., 0] <= 0.5 * self.size_x_m + margin_m) & (
            local[..., 1] <= 0.5 * self.size_y_m + margin_m
        )

    def edge_distance(self, points_world) -> np.ndarray:
        """``(...)`` horizontal distance [m] of world points from the top's rectangle: negative
        inside (minus the distance to the nearest edge), positive outside."""
        local = np.abs(self.local_xy(points_world))
        q = local - np.array([0.5 * self.size_x_m, 0.5 * self.size_y_m])
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
        return outside + np.minimum(np.max(q, axis=-1), 0.0)

    def height_above(self, points_world, margin_m: float = 0.0) -> np.ndarray:
        """``(...)`` height [m] of world points ``(..., 3)`` above the top where they lie over
        it (its rectangle grown by ``margin_m``), ``+inf`` beyond its edges (nothing there to
        keep clear of or to rest on)."""
        p = np.asarray(points_world, dtype=np.float64)
        return np.where(self.over(p, margin_m), p[..., 2] - self.top_z_m, np.inf)

    def corners_world(self) -> np.ndarray:
        """``(4, 3)`` corners [m] of the top, counter-clockwise seen from above."""
        hx, hy = 0.5 * self.size_x_m, 0.5 * self.size_y_m
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
        xy = local @ np.array([[c, s], [-s, c]]) + (self.center_x_m, self.center_y_m)
        return np.concatenate([xy, np.full((4, 1), self.top_z_m)], axis=1)

    # -- serialisation ------------------------------------------------------------------------
    def to_dict(self) -> dict[str, float]:
        """The fields as a plain dict (the Lance ``table`` struct's children)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> Table:
        """A table from :meth:`to_dict`'s keys; missing keys take the defaults.

        Raises:
            ValidationError: an unknown key, or a value that is not a finite number (sizes and
                thickness > 0).
        """
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValidationError(
                f"unknown table field(s) {', '.join(map(repr, unknown))}; "
                f"known: {', '.join(sorted(known))}",
                field="table",
            )
        return cls(**{k: v for k, v in d.items() if v is not None})


DEFAULT_TABLE = Table()
"""The table of a trajectory that names none (module docstring)."""


def table_of(traj) -> Table:
    """The table of a trajectory (``traj.table``), :data:`DEFAULT_TABLE` when it names none."""
    t = getattr(traj, "table", None)
    return DEFAULT_TABLE if t is None else t
