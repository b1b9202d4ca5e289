"""Fitting whole sequences (``fit_sequence``): the wrist of every frame from rigid registration of
the palm markers; every ``stride``-th frame fitted from two cold starts (open and half-closed
hand, the better kept); all frames then fitted from the time-interpolation of those key frames,
which is also their temporal prior (warm start in time). Frames stuck in a local minimum — cost
far above both neighbours' — are re-solved from their neighbours' solutions. The per-frame
solver is :class:`~dexcanvas_core.mocap.fit.HandFitter`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from dexcanvas_core.mano.limits import pose_from_anatomical
from dexcanvas_core.mocap.fit import HandFitter, SolveStats
from dexcanvas_core.mocap.model import N_PARAMS, HandMarkerModel
from dexcanvas_core.mocap.rigid import kabsch
from dexcanvas_core.rotations import matrix_to_aa, slerp_aa

log = logging.getLogger(__name__)


# -- whole sequences ----------------------------------------------------------------------------


def interpolate_params(times: np.ndarray, known: np.ndarray, x_known: np.ndarray) -> np.ndarray:
    """``(T, 51)`` parameters at every frame from those at frames ``known`` (sorted indices):
    global orientation by slerp, translation and finger axis-angles linearly; frames outside
    the known range hold the nearest known value."""
    T = times.shape[0]
    out = np.empty((T, x_known.shape[1]))
    tk = times[known]
    tq = np.clip(times, tk[0], tk[-1])
    out[:, :3] = slerp_aa(tk, x_known[:, :3], tq) if len(known) > 1 else x_known[0, :3]
    for j in range(3, x_known.shape[1]):
        out[:, j] = np.interp(tq, tk, x_known[:, j])
    return out


def root_from_markers(
    model: HandMarkerModel, observed_m: np.ndarray, weight: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Wrist pose by rigid registration of the palm (root-frame) markers.

    Returns ``(x_root (T, 6), ok (T,))``: global orientation and translation (MANO's
    ``global_orient``, ``transl``), and whether ≥ 3 palm markers were seen.
    """
    idx = model.root_idx.numpy()
    J0 = model.rest_keypoints[0]
    rest = J0 + model.offsets.numpy()[idx]
    Q = observed_m[:, idx]
    w = None if weight is None else weight[:, idx]
    R, t = kabsch(rest, Q, w)
    ok = np.isfinite(R).all(axis=(1, 2))
    x = np.full((observed_m.shape[0], 6), np.nan)
    if ok.any():
        x[ok, :3] = matrix_to_aa(R[ok])
        x[ok, 3:] = t[ok] + np.einsum("bij,j->bi", R[ok], J0) - J0
    return x, ok


@dataclass
class SequenceFit:
    """A hand fit over a whole capture."""

    x: np.ndarray
    """(T, 51) parameters per frame."""
    stats: SolveStats
    """Solver statistics of the final pass, per frame."""
    root_observed: np.ndarray
    """(T,) bool: the frame had ≥ 3 palm markers (else its wrist was interpolated first)."""
    repaired: np.ndarray
    """(T,) bool: the frame was re-solved from a neighbour's solution (local minimum)."""


def _half_closed_pose(side: str) -> np.ndarray:
    """``(45,)`` a half-closed hand (second cold start of the key frames)."""
    a = np.zeros((15, 3))
    for f in range(4):
        a[3 * f : 3 * f + 3, 0] = (0.6, 0.8, 0.5)
    a[12] = (0.3, -0.3, 0.0)
    a[13, 0] = 0.3
    a[14, 0] = 0.3
    return pose_from_anatomical(a, side)


def _normalized_cost(stats: SolveStats) -> np.ndarray:
    n = np.isfinite(stats.residual_m).sum(1)
    return stats.cost / np.maximum(n, 1)


def fit_sequence(
    fitter: HandFitter,
    observed_m: np.ndarray,
    weight: np.ndarray,
    times: np.ndarray,
    *,
    stride: int = 8,
    x_init: np.ndarray | None = None,
    max_iterations: int | None = None,
    rel_tolerance: float | None = None,
    repair_rounds: int = 1,
    ref_weight: np.ndarray | None = None,
    abs_tolerance: float | None = None,
) -> SequenceFit:
    """Fit every frame of a capture, warm-started in time.

    Without ``x_init`` (cold start): the wrist of every frame comes from the palm markers
    (``root_from_markers``; interpolated where fewer than 3 are seen); every ``stride``-th frame
    is fitted from a neutral finger pose; every frame is then fitted from the interpolation of
    those solutions, with that interpolation as the temporal prior. With ``x_init`` (e.g. a
    previous pass) all frames start from it and it is the temporal prior.

    After each pass, frames caught in a local minimum — normalised cost far above both
    neighbours' — are re-solved from their neighbours' solutions (``repair_rounds`` sweeps) and
    keep the better result.
    """
    T = observed_m.shape[0]
    repaired = np.zeros(T, bool)
    if x_init is None:
        root, ok = root_from_markers(fitter.model, observed_m, weight)
        if not ok.any():
            raise ValueError("no frame has 3 palm markers")
        x0 = np.zeros((T, N_PARAMS))
        x0[:, :6] = interpolate_params(times, np.flatnonzero(ok), root[ok])
        coarse = np.unique(np.concatenate([np.arange(0, T, max(stride, 1)), [T - 1]]))
        n = coarse.size
        # two starts per key frame (open hand, half-closed hand), the better one kept
        starts = np.concatenate([x0[coarse], x0[coarse]])
        starts[n:, 6:] = _half_closed_pose(fitter.side)
        obs2 = np.concatenate([observed_m[coarse], observed_m[coarse]])
        w2 = np.concatenate([weight[coarse], weight[coarse]])
        xs, st_s = fitter.solve(
            obs2,
            w2,
            starts,
            None,
            max_iterations=15,
            rel_tolerance=rel_tolerance,
            abs_tolerance=abs_tolerance,
        )
        second = st_s.cost[n:] < st_s.cost[:n]
        pick = np.where(second, np.arange(n, 2 * n), np.arange(n))
        xc = xs[pick]
        st_c = SolveStats(
            st_s.iterations[pick], st_s.cost[pick], st_s.marker_rms_m[pick], st_s.residual_m[pick]
        )
        xc, rep_c = _repair(fitter, observed_m[coarse], weight[coarse], xc, st_c, None, 1)
        repaired[coarse] = rep_c
        x_init = interpolate_params(times, coarse, xc)
        x_init[:, :6] = x0[:, :6]  # the measured wrist beats an interpolated one
        ref = x_init
    else:
        ok = np.ones(T, bool)
        ref = x_init
    x, st = fitter.solve(
        observed_m,
        weight,
        x_init,
        ref,
        max_iterations=max_iterations,
        rel_tolerance=rel_tolerance,
        ref_weight=ref_weight,
        abs_tolerance=abs_tolerance,
    )
    x, rep = _repair(
        fitter, observed_m, weight, x, st, ref, repair_rounds, stats_out=True, ref_weight=ref_weight
    )
    repaired |= rep[0]
    st = rep[1]
    return SequenceFit(x, st, ok, repaired)


def _repair(
    fitter: HandFitter,
    obs: np.ndarray,
    w: np.ndarray,
    x: np.ndarray,
    st: SolveStats,
    ref: np.ndarray | None,
    rounds: int,
    stats_out: bool = False,
    ref_weight: np.ndarray | None = None,
):
    """Re-solve frames whose normalised cost is far above their neighbours' from those
    neighbours' solutions; keep whichever result is better."""
    T = x.shape[0]
    repaired = np.zeros(T, bool)
    x = x.copy()
    st = SolveStats(
        st.iterations.copy(), st.cost.copy(), st.marker_rms_m.copy(), st.residual_m.copy()
    )
    for _ in range(rounds):
        q = _normalized_cost(st)
        if T < 2:
            break
        prev = np.concatenate([[np.inf], q[:-1]])
        nxt = np.concatenate([q[1:], [np.inf]])
        best_nb = np.minimum(prev, nxt)
        floor = 2.0 * np.median(q) + 1.0
        bad = np.flatnonzero((q > 3.0 * best_nb) & (q > floor))
        if bad.size == 0:
            break
        cand_frames, cand_init = [], []
        for f in bad:
            for nb in (f - 1, f + 1):
                if 0 <= nb < T:
                    cand_frames.append(f)
                    cand_init.append(x[nb])
        cf = np.array(cand_frames)
        ref_c = None if ref is None else ref[cf]
        rw_c = None if ref_weight is None else ref_weight[cf]
        xn, sn = fitter.solve(
            obs[cf], w[cf], np.array(cand_init), ref_c, max_iterations=8, ref_weight=rw_c
        )
        improved = False
        for i, f in enumerate(cf):
            if sn.cost[i] < st.cost[f] * 0.999:
                x[f] = xn[i]
                st.cost[f] = sn.cost[i]
                st.iterations[f] += sn.iterations[i]
                st.marker_rms_m[f] = sn.marker_rms_m[i]
                st.residual_m[f] = sn.residual_m[i]
                repaired[f] = True
                improved = True
        if not improved:
            break
    if stats_out:
        return x, (repaired, st)
    return x, repaired
