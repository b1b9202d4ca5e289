"""What a marker fit returns: per-frame quality flags (:class:`FitFlags`, stored as the dataset
column ``fit_quality``), the fit itself (:class:`MocapFit`), and the flags read back from a
fitted trajectory (:func:`fit_flags`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyarrow as pa

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.mocap.calibrate import SubjectCalibration
from dexcanvas_core.trajectory import Trajectory

FIT_QUALITY_COLUMN = "fit_quality"
"""Name of the extra dataset column holding the per-frame :class:`FitFlags`."""
FIT_INFO_COLUMN = "mocap_fit"
"""Name of the extra dataset column holding the calibration and fit settings (JSON)."""


# -- flags --------------------------------------------------------------------------------------

_FLAG_TYPES: dict[str, pa.DataType] = {
    "residual_mm": pa.float32(),
    "max_residual_mm": pa.float32(),
    "object_residual_mm": pa.float32(),
    "hand_markers_visible": pa.int8(),
    "object_markers_visible": pa.int8(),
    "missing_markers": pa.int8(),
    "interpolated": pa.bool_(),
    "long_gap": pa.bool_(),
    "hand_interpolated": pa.bool_(),
    "object_interpolated": pa.bool_(),
    "swapped": pa.bool_(),
    "outliers": pa.int8(),
    "nan_frame": pa.bool_(),
}


@dataclass
class FitFlags:
    """Per-frame quality of a fit (every field ``(T,)``)."""

    residual_mm: np.ndarray
    """RMS distance [mm] between the fitted and the measured hand markers (NaN: none seen)."""
    max_residual_mm: np.ndarray
    """Largest hand-marker distance [mm]."""
    object_residual_mm: np.ndarray
    """RMS residual [mm] of the object registration (NaN: pose not measured)."""
    hand_markers_visible: np.ndarray
    """Hand markers in the raw frame (of 14)."""
    object_markers_visible: np.ndarray
    """Object markers in the raw frame (of 4; 0 without an object)."""
    missing_markers: np.ndarray
    """Layout markers absent from the raw frame (hand + object)."""
    interpolated: np.ndarray
    """A marker or a pose of this frame was interpolated across a short gap."""
    long_gap: np.ndarray
    """A marker of this frame is inside a gap too long to fill, or a pose was interpolated
    across such a gap (less reliable)."""
    hand_interpolated: np.ndarray
    """The hand had < 3 usable markers: its parameters are interpolated from neighbours."""
    object_interpolated: np.ndarray
    """The object had < 3 usable markers: its pose is interpolated from neighbours."""
    swapped: np.ndarray
    """A label swap was detected and repaired in this frame."""
    outliers: np.ndarray
    """Markers rejected as outliers in this frame."""
    nan_frame: np.ndarray
    """The raw frame had no valid marker at all."""

    def to_arrow(self) -> pa.StructScalar:
        """One struct scalar of per-frame lists (the ``fit_quality`` column value)."""
        typ = pa.struct([pa.field(k, pa.list_(t)) for k, t in _FLAG_TYPES.items()])
        value = {}
        for k, t in _FLAG_TYPES.items():
            a = np.asarray(getattr(self, k))
            value[k] = pa.array(a.astype(t.to_pandas_dtype()), type=t)
        return pa.scalar(value, type=typ)

    @classmethod
    def from_arrow(cls, scalar: Any) -> FitFlags:
        d = scalar.as_py() if hasattr(scalar, "as_py") else dict(scalar)
        missing = [k for k in _FLAG_TYPES if k not in d]
        if missing:
            raise ValidationError(f"fit_quality lacks fields {missing}", field=FIT_QUALITY_COLUMN)
        out = {}
        for k, t in _FLAG_TYPES.items():
            vals = [np.nan if v is None else v for v in d[k]]
            out[k] = np.asarray(vals, dtype=t.to_pandas_dtype())
        return cls(**out)

    @property
    def num_frames(self) -> int:
        return len(self.residual_mm)

    def summary(self) -> dict[str, Any]:
        r = self.residual_mm[np.isfinite(self.residual_mm)]
        return {
            "frames": self.num_frames,
            "residual_mm_mean": float(r.mean()) if r.size else float("nan"),
            "residual_mm_p95": float(np.percentile(r, 95)) if r.size else float("nan"),
            "frames_interpolated": int(self.interpolated.sum()),
            "frames_long_gap": int(self.long_gap.sum()),
            "frames_hand_interpolated": int(self.hand_interpolated.sum()),
            "frames_object_interpolated": int(self.object_interpolated.sum()),
            "frames_swapped": int(self.swapped.sum()),
            "outlier_markers": int(self.outliers.sum()),
            "nan_frames": int(self.nan_frame.sum()),
        }


@dataclass
class MocapFit:
    """Result of :func:`fit_markers`."""

    trajectory: Trajectory
    flags: FitFlags
    calibration: SubjectCalibration
    object_id: str | None
    fit_seconds: float
    """Wall time [s] of the fit (calibration, object, hand; not reading or writing)."""
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def frames_per_second(self) -> float:
        return self.flags.num_frames / max(self.fit_seconds, 1e-9)


def fit_flags(traj: Trajectory) -> FitFlags:
    """The per-frame flags of a fitted trajectory (e.g. read back with ``open_dataset``)."""
    if FIT_QUALITY_COLUMN not in traj.extras:
        raise ValidationError(
            f"trajectory {traj.uuid!r} has no {FIT_QUALITY_COLUMN!r} column (not a mocap fit)",
            field=FIT_QUALITY_COLUMN,
        )
    return FitFlags.from_arrow(traj.extras[FIT_QUALITY_COLUMN])
