"""Markers → ``Trajectory``: the whole fit of one capture, and ``run_fit`` (``dexcanvas fit``).

``fit_markers(stream)`` runs, in order:

1. **World frame**: every marker goes through the stream's fixed mocap → MANO world transform
   (``MocapFrame``: axes, origin, unit).
2. **Object** (when the stream has ``obj1`` … ``obj4``): per-frame rigid registration with
   label-swap repair and outlier rejection (``rigid.register_object``) on the raw markers; the
   cleaned markers are gap-filled and low-passed and registered again. Frames with fewer than 3
   markers get a pose interpolated from their neighbours (slerp) and are flagged; an object that
   never shows 3 markers is an error.
3. **Hand, pass 1** on the raw markers (palm swaps repaired by rigid registration first), with a
   provisional hand size from the palm markers' spread: ``sequence.fit_sequence`` — wrist from the
   palm markers, key frames fitted from cold starts, every frame warm-started from them.
4. **Hand marker repair**: in frames with a marker residual above its threshold (``outlier_mm``,
   or 5 σ of that marker's pass-1 residuals if larger), swapping suspect labels pairwise and
   dropping the worst marker are tried (batched re-solves); a swap that brings every residual
   under its threshold is applied, else such a removal; both are flagged.
5. **Subject calibration** (``calibrate``) on the calibration segment (default: the first
   second) of the cleaned markers, starting from the pass-1 poses; then held fixed. If the
   segment has no usable frame the whole capture is tried, and failing that the palm-marker
   size estimate is kept (mode ``"palm"``, logged).
6. **Gaps and noise**: short gaps (≤ ``max_gap_frames``) are spline-filled, longer ones flagged;
   every contiguous run is low-passed (zero-phase Butterworth, ``lowpass_hz``) when the noise
   estimated from pass 1 is at least ``lowpass_min_noise_mm``.
7. **Hand, pass 2** on the cleaned markers with the calibrated hand, warm-started from pass 1
   (where a finger marker is inside a long gap, the finger's start and temporal prior are
   interpolated across the gap). Frames left with fewer than 3 usable hand markers get
   parameters interpolated from their neighbours and are flagged.

The output trajectory has one ``object_move`` segment: the frames in which the object is
displaced from its initial pose (``move_threshold_mm`` / ``move_threshold_deg``).

Per-frame quality flags (:class:`FitFlags`) travel with the result and are stored in the written
dataset as one extra column ``fit_quality`` (a struct of per-frame lists); the calibration and
the settings go to the column ``mocap_fit``. Nothing is dropped: the output has one frame per
input frame, and every frame whose values are not a direct fit says so.
"""

from __future__ import annotations

import json
import logging
import math
import time
import warnings
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pyarrow as pa
import torch

from dexcanvas_core.errors import DexCanvasError, ValidationError
from dexcanvas_core.io import write_dataset
from dexcanvas_core.mano.skeleton import BETA0_SCALE_PER_UNIT
from dexcanvas_core.mocap.calibrate import (
    CALIBRATION_MODES,
    CalibrationError,
    CalibrationMode,
    SubjectCalibration,
    calibrate_subject,
    nominal_calibration,
    palm_scale,
)
from dexcanvas_core.mocap.fit import HandFitter, SolverOptions
from dexcanvas_core.mocap.gaps import fill_gaps, lowpass, runs
from dexcanvas_core.mocap.layout import (
    DORSUM_MARKERS,
    HAND_MARKER_NAMES,
    OBJECT_MARKER_NAMES,
    object_marker_positions,
)
from dexcanvas_core.mocap.readers import read_markers
from dexcanvas_core.mocap.rigid import kabsch, register_object
from dexcanvas_core.mocap.sequence import fit_sequence, interpolate_params, root_from_markers
from dexcanvas_core.mocap.stream import MarkerStream
from dexcanvas_core.rotations import matrix_to_aa, rotation_angle_between_aa, slerp_aa
from dexcanvas_core.taxonomy import object_spec
from dexcanvas_core.trajectory import HandTrack, ObjectMove, ObjectTrack, Trajectory

log = logging.getLogger(__name__)

FIT_QUALITY_COLUMN = "fit_quality"
"""Name of the extra dataset column holding the per-frame :class:`FitFlags`."""
FIT_INFO_COLUMN = "mocap_fit"
"""Name of the extra dataset column holding the calibration and fit settings (JSON)."""


class MarkerDataError(DexCanvasError, ValueError):
    """Marker data that cannot give a fit (no object pose ever, no hand markers, …)."""


# -- options ------------------------------------------------------------------------------------


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


@contextmanager
def _torch_threads(n: int):
    old = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(old)


# -- object -------------------------------------------------------------------------------------


def _rms_mm(d_m: np.ndarray) -> np.ndarray:
    """Row-wise RMS [mm] of distances [m] ignoring NaN; NaN for rows without any value."""
    seen = np.isfinite(d_m)
    n = seen.sum(1)
    sq = np.where(seen, d_m, 0.0) ** 2
    return np.where(n > 0, np.sqrt(sq.sum(1) / np.maximum(n, 1)) * 1000, np.nan)


def _interp_pose_runs(
    times: np.ndarray, valid: np.ndarray, max_gap: int
) -> tuple[np.ndarray, np.ndarray]:
    """Masks of invalid frames inside short (≤ max_gap, bounded) and long/open runs."""
    short = np.zeros(valid.shape, bool)
    long = np.zeros(valid.shape, bool)
    T = valid.shape[0]
    for a, b in runs(~valid):
        if a > 0 and b < T and b - a <= max_gap:
            short[a:b] = True
        else:
            long[a:b] = True
    return short, long


def _fit_object(
    obj_world: np.ndarray, object_id: str, times: np.ndarray, fps: float, opts: FitOptions
) -> dict[str, np.ndarray]:
    P = object_marker_positions(object_id)
    vis = np.isfinite(obj_world).all(-1)
    n_vis = vis.sum(1)
    if n_vis.max(initial=0) < 3:
        present = [OBJECT_MARKER_NAMES[k] for k in range(4) if vis[:, k].any()]
        most = int(n_vis.max(initial=0))
        raise MarkerDataError(
            f"object {object_id!r} never has 3 visible markers (at most {most} in any frame; "
            f"markers ever seen: {present or 'none'}); a 6-DoF pose needs 3"
        )
    # outlier threshold: the floor, or 5 σ of the residuals of a plain registration
    R0, t0 = kabsch(P, obj_world)
    d0 = np.linalg.norm(np.einsum("tij,kj->tki", R0, P) + t0[:, None] - obj_world, axis=-1)
    d0 = d0[np.isfinite(d0)]
    sig = float(np.median(d0)) / 1.538 if d0.size else 0.0
    thr = max(opts.object_outlier_mm * 1e-3, 5.0 * sig)
    reg1 = register_object(P, obj_world, outlier_m=thr, repair_swaps=opts.repair_swaps)
    T = obj_world.shape[0]
    clean = np.where(reg1.used[..., None], reg1.corrected, np.nan)
    filled = fill_gaps(clean, opts.max_gap_frames, times)
    rms1 = reg1.residual_m[np.isfinite(reg1.residual_m)]
    noise_mm = float(np.median(rms1)) * 1000 if rms1.size else 0.0
    cutoff = opts.object_lowpass_hz if noise_mm >= opts.lowpass_min_noise_mm else None
    smooth = lowpass(filled.positions, fps, cutoff)
    R, t = kabsch(P, smooth)
    ok = np.isfinite(t).all(1)
    res = np.full(T, np.nan)
    if ok.any():
        pred = np.einsum("tij,kj->tki", R[ok], P) + t[ok][:, None]
        res[ok] = _rms_mm(np.linalg.norm(pred - clean[ok], axis=-1))
    short, long = _interp_pose_runs(times, ok, opts.max_gap_frames)
    aa = np.zeros((T, 3))
    aa[ok] = matrix_to_aa(R[ok])
    pos = t.copy()
    if not ok.all():
        known = np.flatnonzero(ok)
        tk = times[known]
        tq = np.clip(times, tk[0], tk[-1])
        aa = slerp_aa(tk, aa[known], tq) if known.size > 1 else np.tile(aa[known[0]], (T, 1))
        pos = np.stack([np.interp(tq, tk, t[known, d]) for d in range(3)], axis=1)
    return {
        "pos": pos,
        "rot_aa": aa,
        "visible": n_vis,
        "residual_mm": res,
        "swapped": reg1.swapped,
        "outliers": reg1.outliers,
        "marker_interp": filled.interpolated.any(1),
        "marker_long": filled.long_gap.any(1),
        "pose_short": short,
        "pose_long": long,
        "lowpass_hz": cutoff,
    }


# -- hand ---------------------------------------------------------------------------------------


def _repair_palm(
    model, hand: np.ndarray, opts: FitOptions
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Swap repair (and, with a fourth marker, outlier rejection) of the palm markers, which
    move as one rigid body with MANO's root."""
    idx = [HAND_MARKER_NAMES.index(n) for n in DORSUM_MARKERS]
    rest = model.rest_keypoints[0] + model.offsets.numpy()[idx]
    reg = register_object(
        rest, hand[:, idx], outlier_m=opts.outlier_mm * 1e-3, repair_swaps=opts.repair_swaps
    )
    out = hand.copy()
    out[:, idx] = np.where(reg.used[..., None], reg.corrected, np.nan)
    return out, reg.swapped, reg.outliers


def _repair_hand_markers(
    fitter: HandFitter,
    obs: np.ndarray,
    x: np.ndarray,
    residual_m: np.ndarray,
    cost: np.ndarray,
    thr_m: np.ndarray,
    rounds: int = 2,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Repair label swaps and drop outliers in frames with a residual above ``thr_m``
    (``(M,)`` [m], one threshold per marker).

    For each such frame, candidate relabellings (each suspect marker swapped with another
    suspect or with one of its two nearest markers, or moved onto the hidden label predicted
    nearest to it) and the removal of the worst marker are
    re-solved from the frame's solution; a candidate is taken only if it brings every residual
    under ``thr_m`` and lowers the cost (swaps first). Frames nothing fixes stay as they are
    (their residual flags them).

    Returns the cleaned markers, ``x`` updated on repaired frames, and per-frame swap flags and
    outlier counts.
    """
    T = obs.shape[0]
    obs = obs.copy()
    x = x.copy()
    swapped = np.zeros(T, bool)
    outliers = np.zeros(T, np.int64)
    res = residual_m.copy()
    cost_f = np.asarray(cost, dtype=np.float64).copy()
    for _ in range(rounds):
        ratio = np.where(np.isfinite(res), res, 0.0) / thr_m
        bad = np.flatnonzero(ratio.max(1) > 1.0)
        if bad.size == 0:
            break
        cand_f, cand_obs, cand_kind = [], [], []
        with torch.no_grad():
            pred_bad = fitter.model.forward(torch.as_tensor(x[bad])).markers.numpy()
        for b_i, f in enumerate(bad):
            seen = np.flatnonzero(np.isfinite(obs[f]).all(-1))
            hidden = np.setdiff1d(np.arange(obs.shape[1]), seen)
            r = ratio[f]
            suspects = [int(k) for k in np.argsort(-r)[:3] if r[k] > 1.0]
            pairs = set()
            for i in suspects:
                d = np.linalg.norm(obs[f, seen] - obs[f, i], axis=-1)
                for j in seen[np.argsort(d)[1:3]]:
                    pairs.add(tuple(sorted((i, int(j)))))
                for j in suspects:
                    if j != i:
                        pairs.add(tuple(sorted((i, j))))
            for i, j in sorted(pairs):
                o = obs[f].copy()
                o[[i, j]] = o[[j, i]]
                cand_f.append(f)
                cand_obs.append(o)
                cand_kind.append(("swap", i, j))
            # a marker that took the label of a hidden one: move it to the hidden label
            # whose predicted position is nearest, if nearer than its own
            pred = pred_bad[b_i]
            for i in suspects:
                if hidden.size == 0:
                    break
                d = np.linalg.norm(pred[hidden] - obs[f, i], axis=-1)
                j = int(hidden[np.argmin(d)])
                if d.min() < np.linalg.norm(pred[i] - obs[f, i]):
                    o = obs[f].copy()
                    o[j], o[i] = o[i], np.nan
                    cand_f.append(f)
                    cand_obs.append(o)
                    cand_kind.append(("swap", i, j))
            o = obs[f].copy()
            o[suspects[0]] = np.nan
            cand_f.append(f)
            cand_obs.append(o)
            cand_kind.append(("drop", suspects[0], -1))
        cf = np.array(cand_f)
        co = np.array(cand_obs)
        w = np.isfinite(co).all(-1).astype(np.float64)
        xs, st = fitter.solve(co, w, x[cf], x[cf], max_iterations=8)
        worst_c = (np.where(np.isfinite(st.residual_m), st.residual_m, 0.0) / thr_m).max(1)
        changed = False
        for f in bad:
            sel = np.flatnonzero(cf == f)
            ok = [s for s in sel if worst_c[s] <= 1.0 and st.cost[s] < cost_f[f]]
            swaps = [s for s in ok if cand_kind[s][0] == "swap"]
            drops = [s for s in ok if cand_kind[s][0] == "drop"]
            if swaps:
                s = min(swaps, key=lambda s: st.cost[s])
                swapped[f] = True
            elif drops:
                s = drops[0]
                outliers[f] += 1
            else:
                continue
            obs[f] = co[s]
            x[f] = xs[s]
            res[f] = st.residual_m[s]
            cost_f[f] = st.cost[s]
            changed = True
        if not changed:
            break
    return obs, x, swapped, outliers


def _bridge_long_gaps(x: np.ndarray, long_gap: np.ndarray, model, times: np.ndarray) -> np.ndarray:
    """Start and temporal-prior targets for pass 2: where a finger has a marker inside a long
    gap, its 9 parameters are interpolated from the frames in which all its markers are seen
    (so the directions the remaining markers leave free follow the motion across the gap
    instead of relaxing to the priors)."""
    out = x.copy()
    fingers = model.fin_finger.numpy()
    idx = model.fin_idx.numpy()
    for f in range(5):
        cols = slice(6 + 9 * f, 15 + 9 * f)
        gap = long_gap[:, idx[fingers == f]].any(1)
        if gap.any() and (~gap).any():
            known = np.flatnonzero(~gap)
            for c in range(cols.start, cols.stop):
                out[gap, c] = np.interp(times[gap], times[known], x[known, c])
    return out


def _hand_fit(
    hand_world: np.ndarray,
    times: np.ndarray,
    fps: float,
    side: str,
    opts: FitOptions,
    calibration: SubjectCalibration | None,
) -> dict[str, Any]:
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    sopts = opts.solver
    if sopts.marker_sigma_m != opts.marker_sigma_mm * 1e-3:
        sopts = replace(sopts, marker_sigma_m=opts.marker_sigma_mm * 1e-3)
    T = hand_world.shape[0]
    raw_vis = np.isfinite(hand_world).all(-1)
    if calibration is not None and calibration.side != side:
        raise ValidationError(
            f"the calibration is for a {calibration.side} hand, the capture is {side}",
            field="calibration",
        )

    # pass 1 on raw markers (palm repaired as a rigid body), with a provisional hand size
    if calibration is None:
        provisional = nominal_calibration(side, palm_scale(hand_world, side))
    else:
        provisional = calibration
    model = provisional.model()
    fitter = HandFitter(model, side, sopts)
    hand1, palm_swapped, palm_out = _repair_palm(model, hand_world, opts)
    w1 = np.isfinite(hand1).all(-1).astype(np.float64)
    _, root_ok = root_from_markers(model, hand1)
    if not root_ok.any():
        raise MarkerDataError(
            f"no frame shows 3 of the palm markers {', '.join(DORSUM_MARKERS)}: the wrist pose "
            "cannot be initialised"
        )
    s1 = fit_sequence(
        fitter,
        hand1,
        w1,
        times,
        stride=opts.stride,
        rel_tolerance=1e-3,
        abs_tolerance=0.1,
        max_iterations=6,
        repair_rounds=0,
    )
    timings["pass1"] = time.perf_counter() - t0
    t0 = time.perf_counter()

    # marker repair: label swaps and outliers
    res = s1.stats.residual_m
    finite = res[np.isfinite(res)]
    sigma_hat = float(np.median(finite)) / 1.538 if finite.size else 0.0
    # per-marker thresholds: markers with less redundancy have smaller residuals
    with warnings.catch_warnings():  # markers never seen: all-NaN columns
        warnings.simplefilter("ignore", RuntimeWarning)
        sig_k = np.nanmedian(res, axis=0) / 1.538
    sig_k = np.where(np.isfinite(sig_k), sig_k, sigma_hat)
    thr = np.maximum(opts.outlier_mm * 1e-3, 5.0 * sig_k)
    if opts.repair_swaps:
        hand2, x1, swapped, outl = _repair_hand_markers(
            fitter, hand1, s1.x, res, s1.stats.cost, thr
        )
    else:
        hand2, x1 = hand1, s1.x
        swapped = np.zeros(T, bool)
        outl = np.zeros(T, np.int64)
    swapped |= palm_swapped
    outl = outl + palm_out
    timings["repair"] = time.perf_counter() - t0
    t0 = time.perf_counter()

    # subject calibration on the cleaned markers, starting from the pass-1 poses
    if calibration is None:
        cal_frames = opts.calibration_frames or (0, min(T, max(round(fps), 1)))
        cal = None
        for frames in (cal_frames, (0, T)):
            try:
                cal = calibrate_subject(
                    hand2,
                    times,
                    side=side,
                    frames=frames,
                    mode=opts.calibrate,
                    offsets=opts.calibrate_offsets,
                    options=sopts,
                    x_init=x1,
                )
                break
            except CalibrationError as e:
                log.warning("calibration on frames %s failed: %s", frames, e)
        if cal is None:
            log.warning(
                "no usable calibration frame anywhere: keeping the hand size %.3f estimated "
                "from the palm markers (calibration mode 'palm')",
                provisional.scale,
            )
            cal = replace(provisional, mode="palm")
        model = cal.model()
        fitter = HandFitter(model, side, sopts)
    else:
        cal = calibration
    timings["calibration"] = time.perf_counter() - t0
    t0 = time.perf_counter()

    # gaps and low-pass, then pass 2 from pass 1
    filled = fill_gaps(hand2, opts.max_gap_frames, times)
    cutoff = opts.lowpass_hz if sigma_hat * 1000 >= opts.lowpass_min_noise_mm else None
    smooth = lowpass(filled.positions, fps, cutoff)
    w2 = np.isfinite(smooth).all(-1).astype(np.float64)
    x_ref = _bridge_long_gaps(x1, filled.long_gap, model, times)
    # the temporal prior matters where markers are missing; elsewhere it only biases
    ref_w = np.where((w2 == 0.0).any(1), 1.0, opts.ref_weight_complete)
    s2 = fit_sequence(
        fitter,
        smooth,
        w2,
        times,
        x_init=x_ref,
        max_iterations=8,
        rel_tolerance=1e-4,
        ref_weight=ref_w,
    )
    timings["pass2"] = time.perf_counter() - t0
    x = s2.x
    n_used = (w2 > 0).sum(1)
    hand_lost = n_used < 3
    short = np.zeros(T, bool)
    long = np.zeros(T, bool)
    if hand_lost.any():
        known = np.flatnonzero(~hand_lost)
        if known.size == 0:
            raise MarkerDataError("no frame has 3 usable hand markers")
        x = x.copy()
        x[hand_lost] = interpolate_params(times, known, x[known])[hand_lost]
        short, long = _interp_pose_runs(times, ~hand_lost, opts.max_gap_frames)

    # residuals against the cleaned (unfiltered, not interpolated) markers
    with torch.no_grad():
        state = model.forward(torch.as_tensor(x, dtype=model.dtype))
        pred = state.markers.numpy()
        keypoints = model.keypoints(state).numpy()
    d = np.linalg.norm(pred - hand2, axis=-1)  # NaN where unseen or rejected
    rms = _rms_mm(d)
    mx = np.where(np.isfinite(d).any(1), np.max(np.nan_to_num(d, nan=0.0), axis=1) * 1000, np.nan)
    return {
        "x": x,
        "keypoints": keypoints,
        "calibration": cal,
        "visible": raw_vis.sum(1),
        "residual_mm": rms,
        "max_residual_mm": mx,
        "swapped": swapped,
        "outliers": outl,
        "marker_interp": filled.interpolated.any(1),
        "marker_long": filled.long_gap.any(1),
        "hand_lost": hand_lost,
        "pose_short": short,
        "pose_long": long,
        "sigma_hat_mm": sigma_hat * 1000,
        "threshold_mm": (thr * 1000).tolist(),
        "lowpass_hz": cutoff,
        "iterations": s1.stats.iterations + s2.stats.iterations,
        "timings": timings,
    }


# -- the whole capture --------------------------------------------------------------------------


def fit_markers(
    stream: MarkerStream,
    *,
    options: FitOptions | None = None,
    object_id: str | None = None,
    uuid: str | None = None,
    operator: str = "",
    gesture: str = "",
) -> MocapFit:
    """Fit a capture: object poses, subject calibration, hand parameters, quality flags.

    Args:
        stream: the labelled markers (``readers.read_markers`` or ``render_markers``).
        options: fit settings (``FitOptions``).
        object_id: catalogue id of the object (overrides ``stream.object_id``).
        uuid, operator, gesture: identity fields of the output trajectory.

    Raises:
        MarkerDataError: the object never shows 3 markers, object markers without an object
            id, an object id without object markers, or a hand that is never observable.
    """
    opts = (options or FitOptions()).validate()
    t_start = time.perf_counter()
    T = stream.num_frames
    times = stream.times
    fps = stream.fps
    obj_id = object_id or stream.object_id
    if stream.has_object_markers and obj_id is None:
        raise MarkerDataError(
            "the stream has object markers (obj1..obj4) but no object id; pass object_id "
            "(e.g. 'cube2') or set \"object\" in the mapping file"
        )
    if obj_id is not None:
        obj_id = object_spec(obj_id).id
        if not stream.has_object_markers:
            raise MarkerDataError(
                f"object {obj_id!r} was given but the stream has none of the object markers "
                f"{', '.join(OBJECT_MARKER_NAMES)}"
            )
    present = [n for n in HAND_MARKER_NAMES if n in stream.labels]
    if not present:
        raise MarkerDataError(
            f"the stream has none of the 14 hand markers ({', '.join(HAND_MARKER_NAMES)})"
        )
    absent = [n for n in HAND_MARKER_NAMES if n not in stream.labels]
    if absent:
        log.warning("hand markers absent from the capture (fitted without them): %s", absent)
    world_all = stream.positions_world()
    nan_frame = ~np.isfinite(world_all).all(-1).any(1)
    hand_world = stream.hand_world()

    with _torch_threads(opts.threads), torch.no_grad():
        obj = None
        t_obj = time.perf_counter()
        if obj_id is not None:
            obj = _fit_object(stream.object_world(), obj_id, times, fps, opts)
        t_obj = time.perf_counter() - t_obj
        hand = _hand_fit(hand_world, times, fps, stream.side, opts, opts.calibration)
    fit_seconds = time.perf_counter() - t_start

    x = hand["x"]
    obj_vis = obj["visible"] if obj else np.zeros(T, np.int64)
    n_layout = len(HAND_MARKER_NAMES) + (len(OBJECT_MARKER_NAMES) if obj else 0)
    false = np.zeros(T, bool)
    flags = FitFlags(
        residual_mm=hand["residual_mm"],
        max_residual_mm=hand["max_residual_mm"],
        object_residual_mm=obj["residual_mm"] if obj else np.full(T, np.nan),
        hand_markers_visible=hand["visible"],
        object_markers_visible=obj_vis,
        missing_markers=n_layout - hand["visible"] - obj_vis,
        interpolated=hand["marker_interp"]
        | hand["pose_short"]
        | (obj["marker_interp"] | obj["pose_short"] if obj else false),
        long_gap=hand["marker_long"]
        | hand["pose_long"]
        | (obj["marker_long"] | obj["pose_long"] if obj else false),
        hand_interpolated=hand["hand_lost"],
        object_interpolated=(obj["pose_short"] | obj["pose_long"]) if obj else false,
        swapped=hand["swapped"] | (obj["swapped"] if obj else false),
        outliers=hand["outliers"] + (obj["outliers"] if obj else 0),
        nan_frame=nan_frame,
    )
    cal: SubjectCalibration = hand["calibration"]
    betas = np.zeros(10, np.float32)
    betas[0] = math.log(cal.scale) / BETA0_SCALE_PER_UNIT
    side = stream.side
    track = HandTrack(
        name=side,
        global_pos=x[:, 3:6],
        global_rot_aa=x[:, :3],
        hand_pose=np.concatenate([x[:, :3], x[:, 6:]], axis=1),
        joint_pos=hand["keypoints"],
        betas=betas,
    )
    objects = [ObjectTrack(obj_id, obj["pos"], obj["rot_aa"])] if obj else []
    moves = _object_moves(obj_id, obj["pos"], obj["rot_aa"], opts) if obj else []
    info = {
        "source": stream.source,
        "mocap_frame": stream.frame.to_dict(),
        "ignored_labels": list(stream.ignored_labels),
        "absent_markers": absent,
        "object_id": obj_id,
        "calibration": cal.to_dict(),
        "options": opts.to_dict(),
        "noise_sigma_estimate_mm": hand["sigma_hat_mm"],
        "lowpass_hz": {"hand": hand["lowpass_hz"], "object": obj["lowpass_hz"] if obj else None},
        "outlier_threshold_mm": hand["threshold_mm"],
        "fit_seconds": fit_seconds,
        "mean_iterations": float(np.mean(hand["iterations"])),
        "timings_s": {"object": t_obj, **hand["timings"]},
    }
    if uuid:
        uid = uuid
    elif stream.source.startswith("render:"):
        uid = "mocap-" + stream.source.split(":", 1)[1]
    else:
        uid = "mocap-" + (Path(stream.source).stem or "capture")
    traj = Trajectory(
        uuid=uid,
        timestamp=times.copy(),
        fps=float(fps),
        hands=[track],
        objects=objects,
        gesture=gesture,
        operator=operator,
        scene=obj_id or "",
        object_move=moves,
        cap_machine="dexcanvas-mocap-fit",
        is_generated=False,
        extras={
            FIT_QUALITY_COLUMN: flags.to_arrow(),
            FIT_INFO_COLUMN: pa.scalar(json.dumps(info, default=_json_default)),
        },
    )
    traj.validate()
    log.info(
        "fitted %d frames in %.2f s (%.0f frames/s); %s",
        T,
        fit_seconds,
        T / max(fit_seconds, 1e-9),
        flags.summary(),
    )
    return MocapFit(traj, flags, cal, obj_id, fit_seconds, info)


def _object_moves(
    obj_id: str, pos: np.ndarray, rot_aa: np.ndarray, opts: FitOptions
) -> list[ObjectMove]:
    """The ``object_move`` segment: from the first to the last frame in which the object is
    displaced from its initial pose by more than ``move_threshold_mm`` or ``move_threshold_deg``
    (no segment if it never is)."""
    d = np.linalg.norm(pos - pos[0], axis=-1) * 1000
    a = np.rad2deg(rotation_angle_between_aa(rot_aa, np.tile(rot_aa[0], (len(rot_aa), 1))))
    moving = np.flatnonzero((d > opts.move_threshold_mm) | (a > opts.move_threshold_deg))
    if moving.size == 0:
        return []
    return [ObjectMove(obj_id, int(moving[0]), int(moving[-1]))]


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    return str(o)


def fit_flags(traj: Trajectory) -> FitFlags:
    """The per-frame flags of a fitted trajectory (e.g. read back with ``open_dataset``)."""
    if FIT_QUALITY_COLUMN not in traj.extras:
        raise ValidationError(
            f"trajectory {traj.uuid!r} has no {FIT_QUALITY_COLUMN!r} column (not a mocap fit)",
            field=FIT_QUALITY_COLUMN,
        )
    return FitFlags.from_arrow(traj.extras[FIT_QUALITY_COLUMN])


# -- run_fit (the CLI's entry point) -------------------------------------------------------------


@dataclass(frozen=True)
class FitConfig:
    """``dexcanvas fit MARKERS --out PATH``: what to read, how to fit, where to write."""

    markers: Path
    """Marker file (``.c3d`` or ``.csv``)."""
    out: Path
    """Output Lance dataset (a directory, conventionally ``*.lance``)."""
    format: Literal["auto", "c3d", "csv"] = "auto"
    """File format; ``auto`` takes it from the extension."""
    mapping: Path | None = None
    """Marker-name mapping file (JSON or CSV); see ``readers``."""
    object_id: str | None = None
    """Catalogue object carrying ``obj1`` … ``obj4`` (or ``"object"`` in the mapping)."""
    fps: float | None = None
    """Frame rate [Hz], overriding the file's."""
    units: str | None = None
    """Length unit of the file (``mm``, ``cm``, ``m``), overriding the file's."""
    up: Literal["y", "z"] = "y"
    """Vertical axis of the mocap frame."""
    origin_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """World position [m] of the mocap origin."""
    side: Literal["right", "left"] | None = None
    """Hand side (default: the mapping's, else right)."""
    overwrite: bool = False
    """Replace an existing output dataset."""
    uuid: str | None = None
    operator: str = ""
    gesture: str = ""
    calibration_file: Path | None = None
    """A saved ``SubjectCalibration`` (JSON) to use instead of calibrating."""
    save_calibration: Path | None = None
    """Write the calibration used to this JSON file."""
    options: FitOptions = field(default_factory=FitOptions)

    def validate(self) -> FitConfig:
        if not Path(self.markers).exists():
            raise ValidationError(f"marker file {self.markers} does not exist", field="markers")
        if Path(self.out).exists() and not self.overwrite:
            raise ValidationError(
                f"{self.out} already exists; pass overwrite=True (--overwrite) to replace it",
                field="out",
            )
        if self.fps is not None and not (math.isfinite(self.fps) and self.fps > 0):
            raise ValidationError(f"fps must be > 0, got {self.fps}", field="fps")
        self.options.validate()
        return self


@dataclass
class FitReport:
    """What ``run_fit`` did."""

    out: Path
    frames: int
    fps: float
    fit_seconds: float
    frames_per_second: float
    object_id: str | None
    calibration: dict[str, Any]
    flags: dict[str, Any]
    ignored_labels: list[str]
    absent_markers: list[str]

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["out"] = str(self.out)
        return d


def run_fit(cfg: FitConfig) -> FitReport:
    """Read a marker file, fit it and write a one-row Trajectory dataset with the flags."""
    cfg.validate()
    stream = read_markers(
        cfg.markers,
        format=cfg.format,
        mapping=cfg.mapping,
        fps=cfg.fps,
        units=cfg.units,
        up=cfg.up,
        origin_m=cfg.origin_m,
        object_id=cfg.object_id,
        side=cfg.side,
    )
    opts = cfg.options
    if cfg.calibration_file is not None:
        opts = replace(opts, calibration=SubjectCalibration.load(cfg.calibration_file))
    result = fit_markers(
        stream,
        options=opts,
        object_id=cfg.object_id,
        uuid=cfg.uuid or f"mocap-{Path(cfg.markers).stem}",
        operator=cfg.operator,
        gesture=cfg.gesture,
    )
    if cfg.save_calibration is not None:
        result.calibration.save(cfg.save_calibration)
    write_dataset([result.trajectory], cfg.out, mode="overwrite" if cfg.overwrite else "create")
    return FitReport(
        out=Path(cfg.out),
        frames=result.flags.num_frames,
        fps=stream.fps,
        fit_seconds=result.fit_seconds,
        frames_per_second=result.frames_per_second,
        object_id=result.object_id,
        calibration=result.calibration.to_dict(),
        flags=result.flags.summary(),
        ignored_labels=list(stream.ignored_labels),
        absent_markers=result.info["absent_markers"],
    )
