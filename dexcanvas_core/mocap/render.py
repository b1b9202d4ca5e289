"""Render the marker stream a mocap system would deliver for a demonstration.

``render_markers(traj)`` places the 14 hand markers of ``layout`` on the demonstration's hand
(its skeleton is measured from ``mano_joint_pos``, so markers sit on the same bones the keypoints
come from) and the 4 object markers on its object, moves them with the MANO parameters and the
object pose, and then corrupts the stream the way optical capture does, all seeded:

* **noise**: isotropic Gaussian, ``noise_mm`` standard deviation per axis [mm];
* **dropouts**: every marker sample is missing with probability ``dropout`` (single-frame
  losses: reflections, a marker at the edge of the camera views);
* **occlusion gaps**: a gap starts on a marker at a frame with probability ``gap_rate`` and
  lasts a uniformly drawn ``gap_frames`` span (a finger hidden by the object or the palm);
* **label swaps**: with probability ``swap_rate`` per frame, a marker and its nearest
  neighbour of the same body (hand or object) exchange labels for 1–15 frames (the classic
  auto-labelling error between adjacent markers);
* **placement error** (``placement_mm``): each marker sits off its nominal landmark by a fixed
  random offset — what subject calibration with ``offsets=True`` estimates (0 by default).

The stream is returned in a mocap frame (``frame``, y up, millimetres by default); the fitter
undoes that transform. ``stream.truth`` keeps the clean world positions and what was corrupted.
"""

from __future__ import annotations

import logging

import numpy as np
import torch

from dexcanvas_core.errors import UnknownNameError, ValidationError
from dexcanvas_core.mano.skeleton import BETA0_SCALE_PER_UNIT, HandSkeleton, measure_bone_lengths
from dexcanvas_core.mocap.frames import MocapFrame
from dexcanvas_core.mocap.layout import (
    HAND_MARKER_NAMES,
    OBJECT_MARKER_NAMES,
    hand_marker_offsets,
    hand_marker_parents,
    object_marker_positions,
)
from dexcanvas_core.mocap.model import HandMarkerModel
from dexcanvas_core.mocap.stream import MarkerStream, MarkerTruth
from dexcanvas_core.rotations import aa_to_matrix
from dexcanvas_core.taxonomy import object_spec
from dexcanvas_core.trajectory import Trajectory

log = logging.getLogger(__name__)

SWAP_FRAMES = (1, 15)
"""Range [frames] of a label swap's duration."""


def demo_skeleton(traj: Trajectory) -> HandSkeleton:
    """The skeleton of a demonstration's first hand: bone lengths measured from its keypoints
    (``mano_joint_pos``), or MANO's mean hand scaled by β₀ when it has none."""
    h = traj.hand
    side = h.name if h.name in ("right", "left") else "right"
    if h.joint_pos is not None:
        return HandSkeleton.from_bone_lengths(measure_bone_lengths(h.joint_pos), side=side)
    scale = float(np.exp(BETA0_SCALE_PER_UNIT * float(h.betas[0])))
    return HandSkeleton.default(side).scaled(scale)


def clean_markers_world(
    traj: Trajectory, placement_mm: float = 0.0, seed: int = 0
) -> tuple[np.ndarray, tuple[str, ...], str | None]:
    """Noise-free marker centres [m] in the world frame: ``(T, M, 3)``, labels, object id."""
    h = traj.hand
    side = h.name if h.name in ("right", "left") else "right"
    sk = demo_skeleton(traj)
    off = hand_marker_offsets(sk.rest_keypoints, side)
    rng = np.random.default_rng([seed, 7])
    if placement_mm > 0:
        off = off + rng.normal(scale=placement_mm * 1e-3, size=off.shape)
    model = HandMarkerModel(sk.rest_keypoints, off, hand_marker_parents())
    x = np.concatenate([h.global_rot_aa, h.global_pos, h.hand_pose[:, 3:]], axis=1)
    with torch.no_grad():
        state = model.forward(torch.as_tensor(x, dtype=torch.float64))
        hand = state.markers.numpy()
        if h.joint_pos is not None:
            kp = model.keypoints(state).numpy()
            dev = float(np.abs(kp - h.joint_pos).max())
            if dev > 1e-3:
                log.warning(
                    "render_markers(%s): keypoints from the MANO parameters differ from "
                    "mano_joint_pos by up to %.1f mm; markers follow the parameters",
                    traj.uuid,
                    dev * 1000,
                )
    labels: tuple[str, ...] = HAND_MARKER_NAMES
    object_id = None
    parts = [hand]
    if traj.objects:
        obj = traj.object

        for candidate in (obj.name, traj.scene):
            try:
                object_id = object_spec(candidate).id
                break
            except (UnknownNameError, ValidationError):
                continue
        if object_id is None:
            raise ValidationError(
                f"render_markers: object {obj.name!r} of trajectory {traj.uuid!r} is not in the "
                "catalogue, so it has no marker layout",
                field="objects",
            )
        P = object_marker_positions(object_id)
        R = aa_to_matrix(obj.rot_aa.astype(np.float64))
        parts.append(np.einsum("tij,kj->tki", R, P) + obj.pos.astype(np.float64)[:, None])
        labels = (*labels, *OBJECT_MARKER_NAMES)
    return np.concatenate(parts, axis=1), labels, object_id


def render_markers(
    traj: Trajectory,
    *,
    noise_mm: float = 1.0,
    dropout: float = 0.1,
    gap_rate: float = 0.0005,
    gap_frames: tuple[int, int] = (3, 30),
    swap_rate: float = 0.0005,
    placement_mm: float = 0.0,
    frame: MocapFrame | None = None,
    seed: int = 0,
) -> MarkerStream:
    """The marker stream of a demonstration (see the module docstring).

    Args:
        traj: demonstration with one hand (``joint_pos`` recommended) and usually one object.
        noise_mm: per-axis Gaussian noise σ [mm].
        dropout: probability that a marker sample is missing.
        gap_rate: probability per marker and frame that an occlusion gap starts.
        gap_frames: (shortest, longest) gap [frames].
        swap_rate: probability per frame that two neighbouring markers swap labels.
        placement_mm: σ [mm] of each marker's fixed offset from its landmark.
        frame: mocap frame to express the stream in (default: y up, millimetres).
        seed: random seed; the same seed gives the same stream.
    """
    for name, v, hi in (
        ("noise_mm", noise_mm, 100.0),
        ("dropout", dropout, 1.0),
        ("gap_rate", gap_rate, 1.0),
        ("swap_rate", swap_rate, 1.0),
        ("placement_mm", placement_mm, 100.0),
    ):
        if not (np.isfinite(v) and 0.0 <= v <= hi):
            raise ValidationError(
                f"render_markers: {name} must be in [0, {hi}], got {v}", field=name
            )
    lo_gap, hi_gap = int(gap_frames[0]), int(gap_frames[1])
    if not 1 <= lo_gap <= hi_gap:
        raise ValidationError(
            f"gap_frames must be (min, max) with 1 <= min <= max, got {gap_frames}"
        )
    frame = frame or MocapFrame()
    clean, labels, object_id = clean_markers_world(traj, placement_mm, seed)
    T, M, _ = clean.shape
    rng = np.random.default_rng([seed, 1])
    n_hand = len(HAND_MARKER_NAMES)
    groups = [np.arange(n_hand), np.arange(n_hand, M)]

    # label swaps (applied to the clean positions first: labels, not positions, are wrong)
    labelled = clean.copy()
    swapped = np.zeros((T, M), bool)
    for t0 in np.flatnonzero(rng.random(T) < swap_rate):
        g = groups[int(rng.integers(len(groups)))] if M > n_hand else groups[0]
        if g.size < 2:
            continue
        i = int(rng.choice(g))
        others = g[g != i]
        d = np.linalg.norm(clean[t0, others] - clean[t0, i], axis=-1)
        j = int(others[np.argmin(d)])
        t1 = min(T, t0 + int(rng.integers(SWAP_FRAMES[0], SWAP_FRAMES[1] + 1)))
        labelled[t0:t1, i], labelled[t0:t1, j] = clean[t0:t1, j], clean[t0:t1, i]
        swapped[t0:t1, [i, j]] = True

    noisy = labelled + rng.normal(scale=noise_mm * 1e-3, size=labelled.shape)

    occluded = np.zeros((T, M), bool)
    starts = rng.random((T, M)) < gap_rate
    for t0, k in zip(*np.nonzero(starts), strict=True):
        n = int(rng.integers(lo_gap, hi_gap + 1))
        occluded[t0 : t0 + n, k] = True
    drop = rng.random((T, M)) < dropout
    missing = occluded | drop
    noisy[missing] = np.nan

    truth = MarkerTruth(
        positions_world=clean,
        dropout=drop,
        occluded=occluded,
        swapped=swapped & ~missing,
        noise_mm=float(noise_mm),
    )
    return MarkerStream(
        labels=labels,
        positions=frame.to_mocap(noisy),
        fps=float(traj.fps),
        frame=frame,
        timestamp=traj.timestamp.copy(),
        object_id=object_id,
        side=traj.hand.name if traj.hand.name in ("right", "left") else "right",
        source=f"render:{traj.uuid}",
        truth=truth,
    )
