"""Settings of the marker fit (:class:`FitOptions`): gaps, filters, outliers, calibration,
solver."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.mocap.calibrate import (
    CALIBRATION_MODES,
    CalibrationMode,
    SubjectCalibration,
)
from dexcanvas_core.mocap.fit import SolverOptions


@dataclass(frozen=True)
class FitOptions:
    """Settings of ``fit_markers`` (all have working defaults)."""

    max_gap_frames: int = 10
    """Longest marker gap [frames] filled by interpolation; longer gaps are flagged."""
    lowpass_hz: float | None = 10.0
    """Cut-off [Hz] of the zero-phase low-pass applied to the hand markers (``None``: off)."""
    object_lowpass_hz: float | None = 6.0
    """Cut-off [Hz] for the object markers (objects move more slowly than fingers)."""
    lowpass_min_noise_mm: float = 0.2
    """Markers are low-passed only if their noise σ, estimated from the residuals of a fit to
    the raw markers, is at least this [mm]: on (nearly) exact data a filter only distorts fast
    motion."""
    marker_sigma_mm: float = 1.0
    """σ [mm] the solver weights marker residuals with (balance with the priors)."""
    outlier_mm: float = 5.0
    """Smallest residual [mm] that makes a marker a swap/outlier suspect (each marker's
    threshold also grows with the noise: 5 × the σ of its pass-1 residuals)."""
    object_outlier_mm: float = 5.0
    """Smallest residual [mm] that makes an object marker an outlier or swap suspect (the
    threshold also grows with the noise: 5 × the σ estimated from a plain registration)."""
    repair_swaps: bool = True
    """Try label permutations on suspect frames (object and hand)."""
    calibrate: CalibrationMode = "scale"
    """Subject calibration: ``scale`` (hand size), ``bones`` (20 lengths) or ``none``."""
    calibrate_offsets: bool = False
    """Also estimate every marker's offset from its bone (needs varied poses)."""
    calibration_frames: tuple[int, int] | None = None
    """Calibration segment ``(start, stop)`` [frames]; default the first second."""
    calibration: SubjectCalibration | None = None
    """A ready calibration (e.g. ``SubjectCalibration.load``); skips calibrating."""
    stride: int = 8
    """Frames between the cold-started key frames of pass 1."""
    move_threshold_mm: float = 5.0
    """``object_move`` spans the frames where the object is displaced from its initial pose by
    more than this [mm] …"""
    move_threshold_deg: float = 3.0
    """… or rotated by more than this [deg]."""
    ref_weight_complete: float = 0.01
    """Weight (relative) of the temporal prior in frames where every hand marker is measured or
    gap-filled (where a marker is missing it has full weight)."""
    threads: int = 1
    """torch intra-op threads during the fit (per-frame tensors are small: 1 is fastest)."""
    solver: SolverOptions = field(default_factory=SolverOptions)

    def validate(self) -> FitOptions:
        if self.max_gap_frames < 0:
            raise ValidationError(f"max_gap_frames must be >= 0, got {self.max_gap_frames}")
        for name in ("lowpass_hz", "object_lowpass_hz"):
            v = getattr(self, name)
            if v is not None and not v >= 0:
                raise ValidationError(f"{name} must be >= 0 [Hz] or None, got {v}", field=name)
        for name in ("marker_sigma_mm", "outlier_mm", "object_outlier_mm"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValidationError(f"{name} must be > 0 [mm], got {v}", field=name)
        if self.calibrate not in CALIBRATION_MODES:
            raise ValidationError(
                f"unknown calibrate mode {self.calibrate!r}; expected "
                f"{', '.join(CALIBRATION_MODES)}",
                field="calibrate",
            )
        if self.stride < 1 or self.threads < 1:
            raise ValidationError("stride and threads must be >= 1")
        return self

    def to_dict(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d["solver"] = asdict(self.solver)
        d["calibration"] = None if self.calibration is None else "given"
        return d
