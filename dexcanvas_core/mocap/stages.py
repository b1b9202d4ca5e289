"""The fitting stages of ``fit_markers`` (see :mod:`.pipeline` for the order): the object's
rigid registration with repair, gap filling and low-pass (:func:`fit_object`), and the hand's
two passes with marker repair and subject calibration (:func:`fit_hand`)."""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import replace
from typing import Any

import numpy as np
import torch

from dexcanvas_core.errors import DexCanvasError, ValidationError
from dexcanvas_core.mocap.calibrate import (
    CalibrationError,
    SubjectCalibration,
    calibrate_subject,
    nominal_calibration,
    palm_scale,
)
from dexcanvas_core.mocap.fit import HandFitter
from dexcanvas_core.mocap.gaps import fill_gaps, lowpass, runs
from dexcanvas_core.mocap.layout import (
    DORSUM_MARKERS,
    HAND_MARKER_NAMES,
    OBJECT_MARKER_NAMES,
    object_marker_positions,
)
from dexcanvas_core.mocap.options import FitOptions
from dexcanvas_core.mocap.rigid import kabsch, register_object
from dexcanvas_core.mocap.sequence import fit_sequence, interpolate_params, root_from_markers
from dexcanvas_core.rotations import matrix_to_aa, slerp_aa

log = logging.getLogger(__name__)


class MarkerDataError(DexCanvasError, ValueError):
    """Marker data that cannot give a fit (no object pose ever, no hand markers, …)."""


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


def fit_object(
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


def fit_hand(
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
