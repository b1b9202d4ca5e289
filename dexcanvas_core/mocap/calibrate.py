"""Subject calibration: hand size (or bone lengths) and marker offsets, held fixed afterwards.

A capture starts with a *calibration segment* (by default the first second; or a designated
frame range). From the frames of that segment in which the hand markers are visible, the
calibration estimates jointly, by Gauss–Newton/Levenberg–Marquardt:

* the per-frame hand parameters (wrist SE(3) + 45-D pose, as in ``fit``), and
* the **subject** parameters shared by all frames:

  - ``mode="scale"`` (default): one size factor ``s`` of MANO's mean hand (bone lengths
    ``s · L₀``; the wrist joint stays MANO's J0), or
  - ``mode="bones"``: the 20 bone lengths (``mano.skeleton.BONE_NAMES``), regularised towards a
    common scale (σ = 10 % per bone), which needs a segment with finger motion, or
  - ``mode="none"``: MANO's mean hand,

  and, with ``offsets=True``, a correction of every marker's offset from its bone (σ = 3 mm
  prior around the layout; identifiable only from a segment with varied poses).

The joint problem has per-frame blocks and a few shared columns; each step eliminates the
frames (51 × 51 solves) and solves the Schur complement for the shared parameters. Derivatives
with respect to the shared parameters are finite differences (they enter only through the
rest skeleton and the marker offsets), those with respect to the per-frame parameters are the
analytic ones of ``model``. The result, a :class:`SubjectCalibration`, is then held fixed for
the whole capture, and can be saved as JSON and reused for other captures of the subject.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.mano.skeleton import BONE_NAMES, HandSkeleton
from dexcanvas_core.mocap.fit import HandFitter, SolverOptions, _Priors
from dexcanvas_core.mocap.layout import (
    HAND_MARKER_NAMES,
    hand_marker_offsets,
    hand_marker_parents,
    hand_marker_rest_positions,
)
from dexcanvas_core.mocap.model import N_PARAMS, HandMarkerModel, NormalEquations
from dexcanvas_core.mocap.sequence import fit_sequence
from dexcanvas_core.safe_io import atomic_write_text

log = logging.getLogger(__name__)

CalibrationMode = Literal["scale", "bones", "none"]
CALIBRATION_MODES: tuple[str, ...] = ("scale", "bones", "none")


class CalibrationError(ValidationError):
    """The calibration segment cannot calibrate the subject (too few usable frames)."""


@dataclass(frozen=True)
class SubjectCalibration:
    """A subject's hand: bone lengths and marker offsets (fixed for a capture)."""

    side: str
    bone_lengths_m: tuple[float, ...]
    """20 bone lengths [m], ``mano.skeleton.BONE_NAMES`` order."""
    marker_offsets_m: tuple[tuple[float, float, float], ...]
    """14 marker offsets [m] from their parent joint, template frame (``layout`` order)."""
    scale: float = 1.0
    """Geometric-mean size relative to MANO's mean hand."""
    mode: str = "none"
    frames: tuple[int, ...] = ()
    """Frames the calibration used."""
    residual_mm: float = float("nan")
    """RMS marker residual [mm] over the calibration frames."""
    extras: dict[str, Any] = field(default_factory=dict, compare=False)

    def skeleton(self) -> HandSkeleton:
        return HandSkeleton.from_bone_lengths(np.array(self.bone_lengths_m), side=self.side)

    def model(self, dtype: torch.dtype = torch.float64) -> HandMarkerModel:
        """The fitter's marker model for this subject."""
        return HandMarkerModel(
            self.skeleton().rest_keypoints,
            np.array(self.marker_offsets_m),
            hand_marker_parents(),
            dtype=dtype,
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "side": self.side,
            "bone_names": list(BONE_NAMES),
            "bone_lengths_m": list(self.bone_lengths_m),
            "marker_names": list(HAND_MARKER_NAMES),
            "marker_offsets_m": [list(o) for o in self.marker_offsets_m],
            "scale": self.scale,
            "mode": self.mode,
            "frames": list(self.frames),
            "residual_mm": self.residual_mm,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SubjectCalibration:
        try:
            lengths = tuple(float(v) for v in d["bone_lengths_m"])
            offsets = tuple(tuple(float(c) for c in o) for o in d["marker_offsets_m"])
            side = str(d.get("side", "right"))
        except (KeyError, TypeError, ValueError) as e:
            raise ValidationError(f"calibration data is incomplete or malformed ({e})") from e
        if len(lengths) != len(BONE_NAMES) or len(offsets) != len(HAND_MARKER_NAMES):
            raise ValidationError(
                f"calibration needs {len(BONE_NAMES)} bone lengths and {len(HAND_MARKER_NAMES)} "
                f"marker offsets, got {len(lengths)} and {len(offsets)}"
            )
        return cls(
            side=side,
            bone_lengths_m=lengths,
            marker_offsets_m=offsets,  # type: ignore[arg-type]
            scale=float(d.get("scale", 1.0)),
            mode=str(d.get("mode", "file")),
            frames=tuple(int(f) for f in d.get("frames", ())),
            residual_mm=float(d.get("residual_mm", float("nan"))),
        )

    def save(self, path: str | Path) -> Path:
        return atomic_write_text(path, json.dumps(self.to_dict(), indent=2))

    @classmethod
    def load(cls, path: str | Path) -> SubjectCalibration:
        p = Path(path)
        try:
            d = json.loads(p.read_text())
        except (OSError, json.JSONDecodeError) as e:
            raise ValidationError(f"cannot read calibration file {p}: {e}") from e
        return cls.from_dict(d)


def _build(side: str, L: np.ndarray, delta: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    sk = HandSkeleton.from_bone_lengths(L, side=side)
    off = hand_marker_offsets(sk.rest_keypoints, side)
    if delta is not None:
        off = off + delta
    return sk.rest_keypoints, off


def nominal_calibration(side: str = "right", scale: float = 1.0) -> SubjectCalibration:
    """MANO's mean hand scaled by ``scale``, markers on the layout's landmarks."""
    L = HandSkeleton.default(side).bone_lengths() * scale
    _, off = _build(side, L, None)
    return SubjectCalibration(
        side=side,
        bone_lengths_m=tuple(map(float, L)),
        marker_offsets_m=tuple(tuple(map(float, o)) for o in off),  # type: ignore[arg-type]
        scale=float(scale),
        mode="none",
    )


def select_calibration_frames(
    hand_markers: np.ndarray,
    frames: Any = None,
    max_frames: int = 60,
    default_span: int = 120,
) -> np.ndarray:
    """Frames of the calibration segment usable for calibration.

    Args:
        hand_markers: ``(T, 14, 3)`` raw hand markers (NaN = missing).
        frames: ``None`` (the first ``default_span`` frames), a ``(start, stop)`` range, or
            an explicit array of frame indices.
        max_frames: at most this many frames are used (evenly spread over the segment).
        default_span: length [frames] of the default segment.

    Frames with all 14 markers are preferred; if fewer than 3 exist, frames with ≥ 11 markers
    including ≥ 3 palm markers are taken.

    Raises:
        CalibrationError: no usable frame.
    """
    T = hand_markers.shape[0]
    if frames is None:
        cand = np.arange(min(T, default_span))
    elif (
        isinstance(frames, tuple | list) and len(frames) == 2 and not hasattr(frames[0], "__len__")
    ):
        a, b = int(frames[0]), int(frames[1])
        if not (0 <= a < b <= T):
            raise CalibrationError(f"calibration range [{a}, {b}) is outside frames 0..{T}")
        cand = np.arange(a, b)
    else:
        cand = np.unique(np.asarray(frames, dtype=np.int64))
        if cand.size == 0 or cand.min() < 0 or cand.max() >= T:
            raise CalibrationError(f"calibration frames must lie in 0..{T - 1}")
    vis = np.isfinite(hand_markers[cand]).all(-1)
    full = cand[vis.all(1)]
    if full.size < 3:
        palm = vis[:, :4].sum(1) >= 3
        full = cand[(vis.sum(1) >= 11) & palm]
    if full.size == 0:
        raise CalibrationError(
            f"no frame of the calibration segment (frames {int(cand[0])}..{int(cand[-1])}) shows "
            "at least 11 of the 14 hand markers with 3 palm markers; choose another segment "
            "(calibration_frames) or pass a saved calibration"
        )
    if full.size > max_frames:
        full = full[np.round(np.linspace(0, full.size - 1, max_frames)).astype(np.int64)]
    return full


def calibrate_subject(
    hand_markers_m: np.ndarray,
    times: np.ndarray,
    *,
    side: str = "right",
    frames: Any = None,
    mode: CalibrationMode = "scale",
    offsets: bool = False,
    max_frames: int = 12,
    options: SolverOptions | None = None,
    max_iterations: int = 6,
    x_init: np.ndarray | None = None,
) -> SubjectCalibration:
    """Calibrate a subject from the calibration segment (see the module docstring).

    Args:
        hand_markers_m: ``(T, 14, 3)`` hand markers [m], world frame, NaN where missing.
        times: ``(T,)`` [s].
        side: hand side.
        frames: calibration segment (see :func:`select_calibration_frames`).
        mode: ``"scale"``, ``"bones"`` or ``"none"``.
        offsets: also estimate the marker offsets.
        options: solver weights (the marker σ, the priors).
        x_init: ``(T, 51)`` hand parameters of every frame from an earlier fit (e.g. with a
            provisional hand size), used as the starting poses; default: fitted here.
    """
    if mode not in CALIBRATION_MODES:
        raise ValidationError(
            f"unknown calibration mode {mode!r}; expected one of {', '.join(CALIBRATION_MODES)}",
            field="calibrate",
        )
    opts = options or SolverOptions()
    sel = select_calibration_frames(hand_markers_m, frames, max_frames)
    obs = hand_markers_m[sel]
    w = np.isfinite(obs).all(-1).astype(np.float64)
    L0 = HandSkeleton.default(side).bone_lengths()
    nominal = nominal_calibration(side)
    if mode == "none" and not offsets:
        fitter = HandFitter(nominal.model(), side, opts)
        x0 = None if x_init is None else np.asarray(x_init)[sel]
        sf = fit_sequence(fitter, obs, w, times[sel], stride=4, x_init=x0)
        rms = float(np.sqrt(np.nanmean(sf.stats.residual_m**2)) * 1000)
        worst = np.nanmax(sf.stats.residual_m, axis=1) * 1000
        return _result(side, L0, nominal.marker_offsets_m, 1.0, mode, sel, rms, worst)

    n_len = {"scale": 1, "bones": 20, "none": 0}[mode]
    n_off = 3 * len(HAND_MARKER_NAMES) if offsets else 0
    C = n_len + n_off

    # start: scale from the palm markers' spread, then a pose fit with it
    c = np.zeros(C)
    if n_len:
        c[:n_len] = math.log(palm_scale(obs, side))

    def unpack(cv: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        L = L0 * np.exp(cv[:n_len]) if n_len == 20 else L0 * math.exp(cv[0] if n_len else 0.0)
        delta = cv[n_len:].reshape(-1, 3) if n_off else None
        return L, delta

    def model_for(cv: np.ndarray) -> HandMarkerModel:
        kp, off = _build(side, *unpack(cv))
        return HandMarkerModel(kp, off, hand_marker_parents())

    if x_init is None:
        fitter = HandFitter(model_for(c), side, opts)
        x = fit_sequence(fitter, obs, w, times[sel], stride=4).x
    else:
        x = np.array(x_init, dtype=np.float64)[sel]
    dt = torch.float64
    priors = _Priors(side, opts, dt)
    # shared-parameter prior: bones towards their common scale, offsets towards the layout
    sig_bone, sig_off = 0.10, 0.003

    def shared_prior(cv: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        g = np.zeros(C)
        H = np.zeros((C, C))
        cost = 0.0
        if n_len == 20:
            P = np.eye(20) - 1.0 / 20
            r = P @ cv[:20]
            H[:20, :20] += P.T @ P / sig_bone**2
            g[:20] += P.T @ r / sig_bone**2
            cost += 0.5 * float(r @ r) / sig_bone**2
        if n_off:
            d = cv[n_len:]
            H[n_len:, n_len:] += np.eye(n_off) / sig_off**2
            g[n_len:] += d / sig_off**2
            cost += 0.5 * float(d @ d) / sig_off**2
        return g, H, cost

    obs_t = torch.as_tensor(np.nan_to_num(obs), dtype=dt)
    w_t = torch.as_tensor(w / opts.marker_sigma_m, dtype=dt)

    def evaluate(cv: np.ndarray, xv: np.ndarray, need_jac: bool):
        model = model_for(cv)
        xt = torch.as_tensor(xv, dtype=dt)
        st = model.forward(xt)
        ne = model.normal_equations(st, obs_t, w_t)
        priors.add(ne, xt, None)
        g_c, H_c, cost_c = shared_prior(cv)
        total = float(ne.cost.sum()) + cost_c
        if not need_jac:
            return total, None
        Jx = model.jacobian(st).reshape(len(sel), -1, N_PARAMS)  # (N, 3M, 51)
        # shared Jacobian by forward differences (markers are nearly linear in the shared
        # parameters: bone lengths enter the rest skeleton and the offsets linearly)
        Jc = torch.zeros(len(sel), Jx.shape[1], C, dtype=dt)
        m0 = st.markers
        for j in range(C):
            h = 1e-6 if j < n_len else 1e-7
            cp = cv.copy()
            cp[j] += h
            mp = model_for(cp).forward(xt).markers
            Jc[:, :, j] = ((mp - m0) / h).reshape(len(sel), -1)
        return total, (ne, Jx, Jc, g_c, H_c)

    lam = 1e-3
    total, lin = evaluate(c, x, True)
    for _ in range(max_iterations):
        ne, Jx, Jc, g_c, H_c = lin
        wr = w_t.repeat_interleave(3, dim=1)[..., None]  # (N, 3M, 1)
        Jxw, Jcw = Jx * wr, Jc * wr
        rw = (ne.residual.reshape(len(sel), -1) * wr[..., 0])[..., None]
        A = _dense(ne)  # (N, 51, 51): markers + per-frame priors
        Bm = Jxw.transpose(1, 2) @ Jcw  # (N, 51, C)
        Cm = (Jcw.transpose(1, 2) @ Jcw).sum(0) + torch.as_tensor(H_c, dtype=dt)
        g_x = _dense_g(ne)  # (N, 51)
        gc = (Jcw.transpose(1, 2) @ rw)[..., 0].sum(0) + torch.as_tensor(g_c, dtype=dt)
        idx = torch.arange(N_PARAMS)
        A_d = A.clone()
        A_d[:, idx, idx] += lam * (A_d[:, idx, idx] + 1e-6)
        C_d = Cm.clone()
        ic = torch.arange(C)
        C_d[ic, ic] += lam * (C_d[ic, ic] + 1e-6)
        Y = torch.linalg.solve(A_d, torch.cat([Bm, g_x[..., None]], dim=-1))
        S = C_d - (Bm.transpose(1, 2) @ Y[..., :C]).sum(0)
        s = gc - (Bm.transpose(1, 2) @ Y[..., C:]).sum(0)[:, 0]
        dc = -torch.linalg.solve(S, s)
        dx = -(Y[..., C] + (Y[..., :C] @ dc[:, None])[..., 0])
        c_new = c + dc.numpy()
        x_new = x + dx.numpy()
        new_total, _ = evaluate(c_new, x_new, False)
        log.debug(
            "calibration step: cost %.6g -> %.6g, c %s, lam %.1e", total, new_total, c_new[:3], lam
        )
        if new_total < total:
            drop = total - new_total
            gain = drop / max(total, 1e-30)
            c, x, total = c_new, x_new, new_total
            lam = max(lam * 0.3, 1e-9)
            if gain < 1e-6 or drop < opts.abs_tolerance:
                break
            total, lin = evaluate(c, x, True)
        else:
            lam *= 8.0
            if lam > 1e8:
                break
    model = model_for(c)
    st = model.forward(torch.as_tensor(x, dtype=dt))
    d = np.linalg.norm(st.markers.numpy() - obs, axis=-1)
    d = np.where(w > 0, d, np.nan)
    rms = float(np.sqrt(np.nanmean(d**2)) * 1000)
    worst = np.nanmax(d, axis=1) * 1000
    L, _ = unpack(c)
    _, off = _build(side, *unpack(c))
    scale = float(np.exp(np.mean(np.log(L / L0))))
    cal = _result(side, L, off, scale, mode + ("+offsets" if offsets else ""), sel, rms, worst)
    log.info(
        "calibration (%s): scale %.4f, residual %.3f mm over %d frames", mode, scale, rms, len(sel)
    )
    return cal


def _result(side, L, off, scale, mode, sel, rms, worst) -> SubjectCalibration:
    return SubjectCalibration(
        side=side,
        bone_lengths_m=tuple(float(v) for v in L),
        marker_offsets_m=tuple(tuple(float(c) for c in o) for o in np.asarray(off)),  # type: ignore[arg-type]
        scale=float(scale),
        mode=mode,
        frames=tuple(int(f) for f in sel),
        residual_mm=float(rms),
        extras={"frame_worst_residual_mm": [float(v) for v in worst]},
    )


def palm_scale(obs: np.ndarray, side: str = "right") -> float:
    """Hand size relative to MANO's mean hand from the palm markers' mutual distances
    (``obs``: ``(T, 14, 3)`` hand markers [m]; median over frames and marker pairs)."""
    rest = HandSkeleton.default(side).rest_keypoints

    P = hand_marker_rest_positions(rest, side)[:4]
    ratios = []
    for i in range(4):
        for j in range(i + 1, 4):
            d = np.linalg.norm(obs[:, i] - obs[:, j], axis=-1)
            d = d[np.isfinite(d)]
            if d.size:
                ratios.append(np.median(d) / np.linalg.norm(P[i] - P[j]))
    return float(np.median(ratios)) if ratios else 1.0


def _dense(ne: NormalEquations) -> torch.Tensor:
    B = ne.H_rr.shape[0]
    H = torch.zeros(B, N_PARAMS, N_PARAMS, dtype=ne.H_rr.dtype)
    H[:, :6, :6] = ne.H_rr
    for f in range(5):
        s = slice(6 + 9 * f, 15 + 9 * f)
        H[:, :6, s] = ne.H_rf[:, f]
        H[:, s, :6] = ne.H_rf[:, f].transpose(-1, -2)
        H[:, s, s] = ne.H_ff[:, f]
    return H


def _dense_g(ne: NormalEquations) -> torch.Tensor:
    return torch.cat([ne.g_r, ne.g_f.reshape(ne.g_r.shape[0], 45)], dim=1)
