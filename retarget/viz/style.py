"""What every renderer shares: colours, sizes, the human skeleton's bones, the camera.

Both renderers (meshcat in a browser, MuJoCo offscreen) draw the same things with the same
colours from the same camera, so their pictures of one frame can be compared.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dexcanvas_core.keypoints import FINGERS, MANO21, MANO_JOINTS, MANO_PARENTS
from dexcanvas_core.trajectory import FORCE_GROUPS

RGBA = tuple[float, float, float, float]

GROUP_COLORS: dict[str, RGBA] = {
    # Per-finger colours (matplotlib's tab10, skipping its orange: the object is orange).
    "thumb": (0.839, 0.153, 0.157, 1.0),
    "index": (0.173, 0.627, 0.173, 1.0),
    "middle": (0.122, 0.467, 0.706, 1.0),
    "ring": (0.580, 0.404, 0.741, 1.0),
    "pinky": (0.890, 0.467, 0.761, 1.0),
    "palm": (0.498, 0.498, 0.498, 1.0),
}
"""Colour of each ``FORCE_GROUPS`` row (contact points, force arrows, plot lines)."""

ROBOT_RGBA: RGBA = (0.34, 0.38, 0.46, 1.0)
"""The robot hand (slate; one colour for every hand and renderer, so pictures compare)."""
OBJECT_RGBA: RGBA = (0.85, 0.45, 0.2, 1.0)
"""The object as simulated (the scene's orange, ``retarget.scene.add_object``)."""
REFERENCE_OBJECT_RGBA: RGBA = (0.85, 0.45, 0.2, 0.25)
"""The human's object (the reference trajectory), translucent."""
HUMAN_RGBA: RGBA = (0.96, 0.78, 0.62, 0.55)
"""The human hand (skin tone, translucent)."""
TABLE_RGBA: RGBA = (0.82, 0.82, 0.80, 1.0)
BACKGROUND_RGB: tuple[float, float, float] = (1.0, 1.0, 1.0)

HUMAN_JOINT_RADIUS = 0.0075  # [m] about a finger's half-thickness
HUMAN_BONE_RADIUS = 0.006  # [m]
CONTACT_POINT_RADIUS = 0.003  # [m]
ARROW_RADIUS = 0.0018  # [m] shaft radius
ARROW_HEAD_LENGTH = 0.01  # [m]
ARROW_HEAD_RADIUS = 0.004  # [m]
FORCE_SCALE_M_PER_N = 0.02
"""Force arrow length per newton [m/N] (2 cm per N)."""
ARROW_MAX_LENGTH = 0.12
"""Longest force arrow [m]; larger forces are clipped to it."""


def group_color(group: int) -> RGBA:
    """Colour of ``FORCE_GROUPS[group]``."""
    return GROUP_COLORS[FORCE_GROUPS[group]]


def rgb_hex(rgba: RGBA) -> int:
    """0xRRGGBB of an RGBA tuple in [0, 1]."""
    r, g, b = (round(255 * c) for c in rgba[:3])
    return (r << 16) | (g << 8) | b


def human_bones() -> list[tuple[int, int]]:
    """MANO21 keypoint index pairs ``(parent, child)`` of the hand skeleton's 20 bones."""
    bones = [(MANO_PARENTS[j], j) for j in range(1, len(MANO_JOINTS))]
    for f in FINGERS:
        bones.append((MANO21.index(f"{f}3"), MANO21.index(f"{f}_tip")))
    return bones


def arrow_length(force: np.ndarray) -> np.ndarray:
    """Arrow length [m] of forces ``(..., 3)`` [N]: proportional, clipped to the maximum."""
    return np.minimum(FORCE_SCALE_M_PER_N * np.linalg.norm(force, axis=-1), ARROW_MAX_LENGTH)


def rotation_y_to(direction: np.ndarray) -> np.ndarray:
    """(3, 3) rotation taking +y onto ``direction`` (meshcat cylinders lie along y)."""
    y = np.asarray(direction, dtype=np.float64)
    n = np.linalg.norm(y)
    if n < 1e-12:
        return np.eye(3)
    y = y / n
    helper = np.array([1.0, 0.0, 0.0]) if abs(y[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    x = np.cross(y, helper)
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    return np.column_stack([x, y, z])


@dataclass(frozen=True)
class CameraView:
    """A camera looking at ``lookat`` from ``distance`` (MuJoCo's free-camera convention).

    ``azimuth`` [deg] turns about +z (0: looking along +x); ``elevation`` [deg] is negative
    when looking down. ``fovy`` [deg] is the vertical field of view.
    """

    lookat: tuple[float, float, float]
    distance: float
    azimuth: float
    elevation: float
    fovy: float = 45.0

    @property
    def forward(self) -> np.ndarray:
        az, el = np.radians(self.azimuth), np.radians(self.elevation)
        return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])

    @property
    def eye(self) -> np.ndarray:
        """Camera position [m], world frame."""
        return np.asarray(self.lookat) - self.distance * self.forward


def view_direction(center: np.ndarray, wrist: np.ndarray | None) -> float:
    """Azimuth [deg] looking across the wrist → ``center`` line (the hand does not hide the
    object), from the table's ``-x, -y`` side when both sides qualify; 45° without a wrist."""
    if wrist is None:
        return 45.0
    w = np.asarray(wrist, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(center)[:2] - w.mean(axis=0)[:2]
    if np.linalg.norm(d) < 1e-3:
        return 45.0
    side = np.array([-d[1], d[0]])  # horizontal, perpendicular to the hand → object line
    if side @ np.array([1.0, 1.0]) < 0:
        side = -side
    return float(np.degrees(np.arctan2(side[1], side[0])))


def fit_distance(radius: float, fovy: float, aspect: float, margin: float = 1.2) -> float:
    """Camera distance [m] that keeps a sphere of ``radius`` [m] in view."""
    half = np.radians(fovy) / 2
    half_min = min(half, np.arctan(np.tan(half) * aspect))
    return float(margin * max(radius, 0.05) / np.sin(half_min))


def bounding_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    """A sphere around ``points`` (..., 3): the centre of their bounding box and the largest
    distance [m] of a point from it."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    center = 0.5 * (p.min(axis=0) + p.max(axis=0))
    return center, float(np.linalg.norm(p - center, axis=1).max())
