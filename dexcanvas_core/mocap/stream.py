"""``MarkerStream``: labelled marker trajectories as a mocap system delivers them.

A stream holds ``T`` frames of ``M`` markers in the **mocap frame and unit** (see
:class:`~dexcanvas_core.mocap.frames.MocapFrame`), NaN where a marker is missing, with labels that
are names of the layout (``layout.MARKER_NAMES``). Readers build streams from C3D/CSV files
(mapping the capture's labels to layout names), ``render_markers`` builds them from a
demonstration and adds the ground truth of what it corrupted (``truth``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.mocap.frames import MocapFrame
from dexcanvas_core.mocap.layout import HAND_MARKER_NAMES, MARKER_NAMES, OBJECT_MARKER_NAMES


@dataclass
class MarkerTruth:
    """What ``render_markers`` did to a clean stream (for tests and benchmarks)."""

    positions_world: np.ndarray
    """(T, M, 3) [m]: noise-free marker centres in the world frame, correct labels."""
    dropout: np.ndarray
    """(T, M) bool: single-frame dropouts."""
    occluded: np.ndarray
    """(T, M) bool: frames inside an occlusion gap."""
    swapped: np.ndarray
    """(T, M) bool: the marker carries another marker's label at this frame."""
    noise_mm: float = 0.0


@dataclass
class MarkerStream:
    """Labelled marker positions over time (mocap frame, mocap unit, NaN = missing)."""

    labels: tuple[str, ...]
    """(M,) layout names (``layout.MARKER_NAMES``), one per column."""
    positions: np.ndarray
    """(T, M, 3) marker centres [mocap unit] in the mocap frame; NaN where missing."""
    fps: float
    """Capture rate [Hz]."""
    frame: MocapFrame = field(default_factory=MocapFrame)
    """Transform to the MANO world frame (and the unit of ``positions``)."""
    timestamp: np.ndarray | None = None
    """(T,) [s]; ``None`` means ``arange(T) / fps``."""
    object_id: str | None = None
    """Catalogue id of the object carrying ``obj1`` … ``obj4`` (``None``: no object)."""
    side: str = "right"
    """Hand side: ``'right'`` or ``'left'``."""
    source: str = ""
    """Where the stream came from (file path, ``render:<uuid>``)."""
    ignored_labels: tuple[str, ...] = ()
    """Capture labels the mapping file told the reader to drop (reported, not fitted)."""
    truth: MarkerTruth | None = None
    """Ground truth when the stream was rendered."""

    def __post_init__(self) -> None:
        self.labels = tuple(str(s) for s in self.labels)
        unknown = [s for s in self.labels if s not in MARKER_NAMES]
        if unknown:
            raise ValidationError(
                f"marker stream has labels that are not layout names: {unknown}; layout names "
                f"are {', '.join(MARKER_NAMES)}",
                field="labels",
            )
        dup = sorted({s for s in self.labels if self.labels.count(s) > 1})
        if dup:
            raise ValidationError(f"marker stream labels repeat: {dup}", field="labels")
        try:
            pos = np.asarray(self.positions, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise ValidationError(f"marker positions are not numeric ({e})") from e
        if pos.ndim != 3 or pos.shape[1:] != (len(self.labels), 3):
            raise ValidationError(
                f"marker positions must have shape (T, {len(self.labels)}, 3), got {pos.shape}",
                field="positions",
            )
        if pos.shape[0] == 0:
            raise ValidationError("marker stream has no frames", field="positions")
        if np.isinf(pos).any():
            raise ValidationError("marker positions contain inf", field="positions")
        self.positions = pos
        if not (math.isfinite(self.fps) and self.fps > 0):
            raise ValidationError(f"fps must be > 0, got {self.fps}", field="fps")
        if self.timestamp is not None:
            ts = np.asarray(self.timestamp, dtype=np.float64).reshape(-1)
            if ts.shape[0] != pos.shape[0] or not np.isfinite(ts).all():
                raise ValidationError(
                    f"timestamp must be {pos.shape[0]} finite values, got shape {ts.shape}",
                    field="timestamp",
                )
            if ts.shape[0] > 1 and np.any(np.diff(ts) <= 0):
                raise ValidationError("timestamps must be strictly increasing", field="timestamp")
            self.timestamp = ts
        if self.side not in ("right", "left"):
            raise ValidationError(f"side must be 'right' or 'left', got {self.side!r}")

    @property
    def num_frames(self) -> int:
        return self.positions.shape[0]

    @property
    def times(self) -> np.ndarray:
        """(T,) [s]."""
        if self.timestamp is not None:
            return self.timestamp
        return np.arange(self.num_frames) / self.fps

    def positions_world(self) -> np.ndarray:
        """(T, M, 3) [m] in the MANO world frame (NaN where missing)."""
        return self.frame.to_world(self.positions)

    def columns(self, names: tuple[str, ...]) -> np.ndarray:
        """(T, len(names), 3) world positions [m] in the order of ``names``; markers absent
        from the stream are all-NaN columns."""
        world = self.positions_world()
        out = np.full((self.num_frames, len(names), 3), np.nan)
        for i, n in enumerate(names):
            if n in self.labels:
                out[:, i] = world[:, self.labels.index(n)]
        return out

    def hand_world(self) -> np.ndarray:
        """(T, 14, 3) [m]: the hand markers in ``layout.HAND_MARKER_NAMES`` order."""
        return self.columns(HAND_MARKER_NAMES)

    def object_world(self) -> np.ndarray:
        """(T, 4, 3) [m]: the object markers ``obj1`` … ``obj4``."""
        return self.columns(OBJECT_MARKER_NAMES)

    @property
    def has_object_markers(self) -> bool:
        return any(n in self.labels for n in OBJECT_MARKER_NAMES)
