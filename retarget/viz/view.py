"""What a picture shows and from where: :class:`SceneOptions` and the camera framing.

Both renderers use the same :class:`Framing`: one viewing direction for the whole trajectory;
for stills the camera's target and distance fit the frame's content (``Framing.at(t)``), for
the animation the whole trajectory (``Framing.whole``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from retarget.viz import style
from retarget.viz.data import SceneData
from retarget.viz.errors import VizError

EXTENT_MARGIN_M = 0.03
"""Added to every radius [m]: fingertips and object surfaces reach past the drawn points."""


@dataclass(frozen=True)
class SceneOptions:
    """What the scene shows and how."""

    layout: Literal["overlay", "side_by_side"] = "side_by_side"
    """``side_by_side``: the human demonstration (hand, its object, its contacts) beside the
    robot, to the camera's left; ``overlay``: drawn over the robot (a larger robot hand then
    hides the human hand)."""
    side_offset_m: float = 0.25
    """Distance [m] between the robot and the human group in ``side_by_side``."""
    show_human: bool = True
    show_contacts: bool = True
    show_reference_object: bool = True
    """Draw the human's object (translucent) besides the simulated one."""
    show_table: bool = True
    width: int = 800
    """Picture width [px] (sets the camera's aspect ratio)."""
    height: int = 600
    """Picture height [px]."""
    camera: style.CameraView | None = None
    """A fixed camera for every frame; None: fitted to the data (:func:`frame_scene`)."""
    elevation_deg: float = -30.0
    """Camera elevation [deg] when fitted (negative: looking down)."""
    azimuth_deg: float | None = None
    """Camera azimuth [deg] when fitted; None: across the hand–object line."""

    def validate(self) -> SceneOptions:
        if self.layout not in ("overlay", "side_by_side"):
            raise VizError(f"layout must be 'overlay' or 'side_by_side', got {self.layout!r}")
        if not (16 <= self.width <= 8192 and 16 <= self.height <= 8192):
            raise VizError(f"picture size {self.width}×{self.height} px outside 16…8192")
        if not -90.0 <= self.elevation_deg <= 90.0:
            raise VizError(f"elevation {self.elevation_deg}° outside -90…90")
        return self

    def human_offset(self, azimuth_deg: float) -> np.ndarray:
        """(3,) [m] translation of everything human (hand, reference object, contacts): to the
        left of a camera at ``azimuth_deg`` in ``side_by_side``, none in ``overlay``."""
        if self.layout != "side_by_side":
            return np.zeros(3)
        az = np.radians(azimuth_deg)
        left = np.array([-np.sin(az), np.cos(az), 0.0])  # forward × up, negated
        return self.side_offset_m * left


@dataclass(frozen=True)
class Framing:
    """Camera for the whole trajectory, and per frame one fitted to that frame's content
    (same viewing direction)."""

    whole: style.CameraView
    human_offset: np.ndarray
    """(3,) [m] translation of the human group (``SceneOptions.human_offset``)."""
    lookat: np.ndarray
    """(T, 3) [m] camera target per frame."""
    distance: np.ndarray
    """(T,) [m] camera distance per frame."""

    def at(self, t: int) -> style.CameraView:
        return replace(
            self.whole,
            lookat=tuple(float(c) for c in self.lookat[t]),
            distance=float(self.distance[t]),
        )


def robot_body_positions(model, qpos: np.ndarray) -> np.ndarray:
    """(T, nbody - 1, 3) [m] positions of the model's bodies (not the world) per frame."""
    import mujoco

    d = mujoco.MjData(model)
    out = np.zeros((qpos.shape[0], model.nbody - 1, 3))
    for t, q in enumerate(qpos):
        d.qpos[: q.shape[0]] = q
        mujoco.mj_kinematics(model, d)
        out[t] = d.xpos[1:]
    return out


def frame_scene(data: SceneData, options: SceneOptions, robot_points: np.ndarray) -> Framing:
    """Fit the camera to the robot's body positions ``robot_points`` (T, B, 3), the objects
    and the human keypoints (``options`` decides what is shown and where)."""
    T = data.num_frames
    wrist = data.robot_qpos[:, :3]
    if data.human_keypoints is not None:
        wrist = data.human_keypoints[:, 0]
    if options.camera is not None:
        azimuth = options.camera.azimuth
    elif options.azimuth_deg is not None:
        azimuth = options.azimuth_deg
    else:
        azimuth = style.view_direction(data.object_pos.mean(axis=0), wrist)
    off = options.human_offset(azimuth)
    parts = [robot_points, data.object_pos[:, None]]
    show_ref = options.show_reference_object or options.layout == "side_by_side"
    if show_ref:
        parts.append(data.ref_object_pos[:, None] + off)
    if options.show_human and data.human_keypoints is not None:
        parts.append(data.human_keypoints + off)
    pts = np.concatenate([np.asarray(p, dtype=np.float64).reshape(T, -1, 3) for p in parts], 1)
    aspect = options.width / options.height
    if options.camera is not None:
        cam = options.camera
        return Framing(
            whole=cam,
            human_offset=off,
            lookat=np.tile(np.asarray(cam.lookat), (T, 1)),
            distance=np.full(T, cam.distance),
        )
    center, radius = style.bounding_sphere(pts)
    fovy = 45.0
    whole = style.CameraView(
        lookat=tuple(float(c) for c in center),
        distance=style.fit_distance(radius + EXTENT_MARGIN_M, fovy, aspect),
        azimuth=float(azimuth),
        elevation=float(options.elevation_deg),
        fovy=fovy,
    )
    lookat = np.zeros((T, 3))
    distance = np.zeros(T)
    for t in range(T):
        lookat[t], radius = style.bounding_sphere(pts[t])
        distance[t] = style.fit_distance(radius + EXTENT_MARGIN_M, fovy, aspect)
    return Framing(whole=whole, human_offset=off, lookat=lookat, distance=distance)
