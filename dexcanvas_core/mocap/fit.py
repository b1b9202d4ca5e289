"""Per-frame hand fit: wrist SE(3) + 45-D MANO pose from markers, batched Levenberg–Marquardt.

For every frame the fitter minimises

    ½ Σ_k (|m_k(x) − o_k| / σ_m)²                         markers (seen ones only)
  + ½ Σ_j,c ((a_jc(x) − μ_jc) / σ_jc)²                     anatomical prior
  + ½ Σ_j,c (viol_jc(x) / σ_lim)²                          soft joint limits
  + ½ Σ_i ((x_i − x_ref,i) / σ_ref,i)²                     temporal prior (warm start)

over ``x = [global_orient, transl, hand_pose]`` (``model`` module), where ``a_j = F_j r_j`` are the
anatomical angles (flex, abd, twist) of finger joint ``j`` (``mano.limits.anatomical_angles``) and
``viol`` is ``mano.limits.limit_violation`` (zero inside the range of motion).

* **Anatomical prior** (``AnatomicalPrior``): axial twist of the finger joints and abduction of
  the PIP/DIP (thumb IP) joints are not active degrees of freedom; they are held near zero
  (σ ≈ 3°), which makes PIP/DIP hinges (see ``layout``). Everything the layout measures is left
  free: flexion (σ 10 rad, a mere tie-breaker), MCP abduction (σ 1 rad), the thumb's CMC and
  MCP (σ 10 rad). On generated demonstrations, tighter priors on these only added bias — with
  exact markers the free fit recovers the keypoints to ~0.01 mm, with a 0.5-rad thumb prior the
  thumb joints were off by ~0.5 mm — and did not reduce the error under noise.
* **DIP–PIP coupling** (optional, off by default): ``DIP ≈ κ · PIP`` for index…pinky, the
  classical coupling of unloaded finger flexion (κ ≈ ⅔, e.g. Rijpkema & Girard 1991, "Computer
  animation of knowledge-based human grasping"). The middle-phalanx marker makes DIP and PIP
  observable, so the default leaves it off: on grasps that do not follow it, it only biases.
* **Joint limits**: ``σ_lim`` = 0.02 rad turns the range-of-motion bounds into stiff walls; the
  violation is ``mano.limits.limit_violation`` (the same bounds and anatomical frames), written
  out here with its piecewise-linear Jacobian.
* **Temporal prior**: ``x_ref`` is the warm start (a neighbouring frame's solution, or the
  previous pass); weak (σ 0.5 rad, 50 mm), it decides only the directions the markers leave free
  — a finger whose markers are missing follows its motion across the gap instead of relaxing
  to the priors. The pipeline weights it per frame (``ref_weight``): full where a marker is
  missing, 1 % where every marker is measured or gap-filled.

Solver: Gauss–Newton with Levenberg–Marquardt damping ``λ (diag H + ε)``, per-frame accept/reject
and per-frame λ, all frames of a batch at once (torch, float64, chunks of ``chunk_frames``). The
normal equations have the arrowhead structure of ``model.NormalEquations``; each step factors
the five 9 × 9 finger blocks (Cholesky), forms the 6 × 6 Schur complement of the root and
back-substitutes. Frames leave the batch when converged (cost change below ``rel_tolerance`` or
``abs_tolerance`` χ²). Every residual's Jacobian is analytic (``model``); the priors are linear
in ``x``.

Whole sequences: :mod:`.sequence`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import torch

from dexcanvas_core.mano.limits import HIGH, LOW, joint_frames
from dexcanvas_core.mocap.model import N_PARAMS, HandMarkerModel, NormalEquations

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class AnatomicalPrior:
    """σ [rad] of the anatomical angles (flex, abd, twist) per joint level; μ = 0."""

    finger_mcp: tuple[float, float, float] = (10.0, 1.0, 0.06)
    """Index…pinky MCP: flexion free, abduction loose, twist held."""
    finger_pip: tuple[float, float, float] = (10.0, 0.05, 0.05)
    finger_dip: tuple[float, float, float] = (10.0, 0.05, 0.05)
    thumb_cmc: tuple[float, float, float] = (10.0, 10.0, 10.0)
    """Thumb CMC: flexion, abduction and axial rotation (opposition) free."""
    thumb_mcp: tuple[float, float, float] = (10.0, 10.0, 0.05)
    thumb_ip: tuple[float, float, float] = (10.0, 0.05, 0.05)
    dip_pip_ratio: float = 0.67
    """κ of the optional DIP–PIP flexion coupling prior ``DIP ≈ κ · PIP`` (index…pinky)."""
    dip_pip_sigma: float = 0.0
    """σ [rad] of the coupling prior; 0 (default) or inf: off."""

    def sigma(self) -> np.ndarray:
        """``(15, 3)`` σ per MANO finger joint (index, middle, pinky, ring, thumb × 3 levels)."""
        finger = [self.finger_mcp, self.finger_pip, self.finger_dip]
        thumb = [self.thumb_cmc, self.thumb_mcp, self.thumb_ip]
        rows = [*finger * 4, *thumb]
        return np.array(rows, dtype=np.float64)


@dataclass(frozen=True)
class SolverOptions:
    """Weights and stopping rules of the per-frame fit."""

    marker_sigma_m: float = 0.001
    """σ_m [m]: marker noise the residuals are scaled by (sets the balance with the priors)."""
    prior: AnatomicalPrior = field(default_factory=AnatomicalPrior)
    limit_sigma_rad: float = 0.02
    """σ_lim [rad]: stiffness of the joint-limit walls."""
    ref_sigma_rot_rad: float = 0.5
    """Temporal prior on the global orientation [rad]."""
    ref_sigma_transl_m: float = 0.05
    """Temporal prior on the translation [m]."""
    ref_sigma_pose_rad: float = 0.5
    """Temporal prior on each finger axis-angle component [rad]."""
    max_iterations: int = 30
    """LM iterations at most per frame."""
    rel_tolerance: float = 1e-7
    """Stop a frame when an accepted step lowers its cost by less than this fraction…"""
    abs_tolerance: float = 1e-2
    """… or by less than this much (the cost is a χ² in units of σ: 0.01 is nothing)."""
    lambda_init: float = 1e-3
    chunk_frames: int = 512
    """Frames solved together at most (larger batches are split)."""


@dataclass
class SolveStats:
    """What the solver did for each frame of a batch."""

    iterations: np.ndarray  # (B,) accepted + rejected steps taken
    cost: np.ndarray  # (B,) final total cost (dimensionless)
    marker_rms_m: np.ndarray  # (B,) RMS distance of the seen markers [m] (NaN if none)
    residual_m: np.ndarray  # (B, M) per-marker distance [m] (NaN if unseen)


class _Priors:
    """Constant prior terms in the finger blocks (torch), shared by all frames."""

    def __init__(self, side: str, opts: SolverOptions, dtype: torch.dtype):
        F = joint_frames(side)  # (15, 3, 3) rows: flex, abd, twist
        w_anat = 1.0 / opts.prior.sigma()  # (15, 3)
        self.F = torch.tensor(np.array(F), dtype=dtype).reshape(5, 3, 3, 3)  # finger, level
        self.Ft = self.F.transpose(-1, -2).contiguous()
        self.w2_anat = torch.tensor(w_anat**2, dtype=dtype).reshape(5, 3, 3)
        H = np.zeros((5, 9, 9))
        for f in range(5):
            for lev in range(3):
                j = 3 * f + lev
                blk = F[j].T @ np.diag(w_anat[j] ** 2) @ F[j]
                H[f, 3 * lev : 3 * lev + 3, 3 * lev : 3 * lev + 3] = blk
        # DIP-PIP coupling: u_f · r_f = DIP flex - κ PIP flex for index, middle, pinky, ring
        U = np.zeros((5, 9))
        sc = opts.prior.dip_pip_sigma
        if sc and np.isfinite(sc):
            for f in range(4):
                U[f, 3:6] = -opts.prior.dip_pip_ratio * F[3 * f + 1][0] / sc
                U[f, 6:9] = F[3 * f + 2][0] / sc
        H += np.einsum("fi,fj->fij", U, U)
        self.U = torch.tensor(U, dtype=dtype)
        self.H_anat = torch.tensor(H, dtype=dtype)
        self.low = torch.tensor(LOW, dtype=dtype).reshape(5, 3, 3)
        self.high = torch.tensor(HIGH, dtype=dtype).reshape(5, 3, 3)
        self.w2_lim = 1.0 / opts.limit_sigma_rad**2
        w_ref = np.concatenate(
            [
                np.full(3, 1.0 / opts.ref_sigma_rot_rad),
                np.full(3, 1.0 / opts.ref_sigma_transl_m),
                np.full(45, 1.0 / opts.ref_sigma_pose_rad),
            ]
        )
        self.w2_ref = torch.tensor(w_ref**2, dtype=dtype)

    def add(
        self,
        ne: NormalEquations,
        x: torch.Tensor,
        x_ref: torch.Tensor | None,
        ref_weight: torch.Tensor | None = None,
    ) -> None:
        """Add the prior terms at ``x`` to ``ne`` in place (H, g and cost)."""
        B = x.shape[0]
        r = x[:, 6:].reshape(B, 5, 3, 3)  # finger, level, xyz
        a = (self.F @ r[..., None])[..., 0]  # (B, 5, 3, 3) anatomical angles
        wa = self.w2_anat * a
        ne.g_f += (self.Ft @ wa[..., None]).reshape(B, 5, 9)
        ne.H_ff += self.H_anat
        cost = 0.5 * (wa * a).sum(dim=(1, 2, 3))
        rc = (x[:, 6:].reshape(B, 5, 9) * self.U).sum(-1)  # (B, 5)
        ne.g_f += rc[..., None] * self.U
        cost = cost + 0.5 * (rc * rc).sum(-1)
        over = torch.relu(a - self.high)
        under = torch.relu(self.low - a)
        viol = over + under
        active = (viol > 0).to(x.dtype)
        if bool(active.any()):
            signed = over - under
            ne.g_f += self.w2_lim * (self.Ft @ signed[..., None]).reshape(B, 5, 9)
            blk = self.w2_lim * torch.einsum("flcx,bflc,flcy->bflxy", self.F, active, self.F)
            for lev in range(3):
                ne.H_ff[:, :, 3 * lev : 3 * lev + 3, 3 * lev : 3 * lev + 3] += blk[:, :, lev]
            cost = cost + 0.5 * self.w2_lim * (viol * viol).sum(dim=(1, 2, 3))
        if x_ref is not None:
            dx = x - x_ref
            w2 = self.w2_ref if ref_weight is None else self.w2_ref * ref_weight[:, None]
            wdx = w2 * dx
            ne.g_r += wdx[:, :6]
            ne.g_f += wdx[:, 6:].reshape(B, 5, 9)
            w2 = w2.expand(B, N_PARAMS)
            ne.H_rr.diagonal(dim1=-2, dim2=-1).add_(w2[:, :6])
            ne.H_ff.diagonal(dim1=-2, dim2=-1).add_(w2[:, 6:].reshape(B, 5, 9))
            cost = cost + 0.5 * (wdx * dx).sum(dim=1)
        ne.cost = ne.cost + cost


def _solve(ne: NormalEquations, lam: torch.Tensor) -> torch.Tensor:
    """LM step ``δ (B, 51)`` of the damped arrowhead system by a Schur complement."""
    B = lam.shape[0]
    H_rr = ne.H_rr.clone()
    H_ff = ne.H_ff.clone()
    d_rr = H_rr.diagonal(dim1=-2, dim2=-1)
    d_rr.add_(lam[:, None] * (d_rr + 1e-6))
    d_ff = H_ff.diagonal(dim1=-2, dim2=-1)
    d_ff.add_(lam[:, None, None] * (d_ff + 1e-6))
    L, info = torch.linalg.cholesky_ex(H_ff)
    if bool((info > 0).any()):  # not positive definite: add a ridge where it failed
        bad = info > 0
        H_ff[bad] += (
            1e-3
            * torch.eye(9, dtype=H_ff.dtype)
            * H_ff[bad]
            .diagonal(dim1=-2, dim2=-1)
            .abs()
            .max(-1)
            .values[:, None, None]
            .clamp_min(1.0)
        )
        L, _ = torch.linalg.cholesky_ex(H_ff)
    rhs = torch.cat([ne.H_rf.transpose(-1, -2), ne.g_f[..., None]], dim=-1)  # (B, 5, 9, 7)
    X = torch.cholesky_solve(rhs, L)
    Xh, Xg = X[..., :6], X[..., 6]
    HX = ne.H_rf @ X  # (B, 5, 6, 7)
    HX = HX.sum(1)
    S = H_rr - HX[..., :6]
    s = ne.g_r - HX[..., 6]
    d_r = -torch.linalg.solve(S, s)
    d_f = -Xg - (Xh @ d_r[:, None, :, None])[..., 0]
    return torch.cat([d_r, d_f.reshape(B, 45)], dim=1)


def _wrap_root(x: torch.Tensor) -> torch.Tensor:
    """Keep the global axis-angle's norm ≤ π (same rotation)."""
    aa = x[:, :3]
    th = aa.norm(dim=1, keepdim=True)
    over = th > np.pi
    if bool(over.any()):
        scale = torch.where(over, 1.0 - 2.0 * np.pi / th.clamp_min(1e-12), torch.ones_like(th))
        x = torch.cat([aa * scale, x[:, 3:]], dim=1)
    return x


class HandFitter:
    """Batched LM fit of the hand parameters to markers for one subject.

    Args:
        model: the subject's ``HandMarkerModel`` (calibrated skeleton and marker offsets).
        side: ``'right'`` or ``'left'`` (anatomical frames of the priors).
        options: weights and stopping rules.
    """

    def __init__(self, model: HandMarkerModel, side: str, options: SolverOptions | None = None):
        self.model = model
        self.side = side
        self.options = options or SolverOptions()
        self.dtype = model.dtype
        self.priors = _Priors(side, self.options, self.dtype)

    def _linearize(
        self,
        x: torch.Tensor,
        obs: torch.Tensor,
        w: torch.Tensor,
        x_ref: torch.Tensor | None,
        ref_weight: torch.Tensor | None = None,
    ) -> NormalEquations:
        state = self.model.forward(x)
        ne = self.model.normal_equations(state, obs, w)
        self.priors.add(ne, x, x_ref, ref_weight)
        return ne

    def solve(
        self,
        observed_m: np.ndarray | torch.Tensor,
        weight: np.ndarray | torch.Tensor,
        x0: np.ndarray | torch.Tensor,
        x_ref: np.ndarray | torch.Tensor | None = None,
        max_iterations: int | None = None,
        rel_tolerance: float | None = None,
        ref_weight: np.ndarray | None = None,
        abs_tolerance: float | None = None,
    ) -> tuple[np.ndarray, SolveStats]:
        """Fit a batch of frames independently.

        Args:
            observed_m: ``(B, M, 3)`` [m] markers in the world frame (NaN where unseen).
            weight: ``(B, M)`` relative weight of each marker (1 = σ_m, 0 = unseen; NaN
                markers get 0 regardless).
            x0: ``(B, 51)`` initial parameters.
            x_ref: ``(B, 51)`` temporal-prior targets, or ``None`` for no temporal prior.
            max_iterations: override of ``options.max_iterations``.
            rel_tolerance: override of ``options.rel_tolerance``.
            ref_weight: ``(B,)`` per-frame multiplier of the temporal prior's weight.
            abs_tolerance: override of ``options.abs_tolerance``.

        Returns:
            ``(x (B, 51), SolveStats)``.

        Batches larger than ``options.chunk_frames`` are solved chunk by chunk (bounded memory,
        cache-sized tensors); frames are independent, so the result is the same.
        """
        B_all = int(np.shape(x0)[0])
        chunk = self.options.chunk_frames
        if B_all > chunk:
            parts = []
            for a in range(0, B_all, chunk):
                sl = slice(a, min(a + chunk, B_all))
                parts.append(
                    self.solve(
                        np.asarray(observed_m)[sl],
                        np.asarray(weight)[sl],
                        np.asarray(x0)[sl],
                        None if x_ref is None else np.asarray(x_ref)[sl],
                        max_iterations,
                        rel_tolerance,
                        None if ref_weight is None else np.asarray(ref_weight)[sl],
                        abs_tolerance,
                    )
                )
            xs = np.concatenate([p[0] for p in parts])
            stats = SolveStats(
                *(np.concatenate([getattr(p[1], f) for p in parts]) for f in _STAT_FIELDS)
            )
            return xs, stats
        dt = self.dtype
        opts = self.options
        obs = torch.as_tensor(np.asarray(observed_m, dtype=np.float64), dtype=dt)
        seen = torch.isfinite(obs).all(-1)
        obs = torch.nan_to_num(obs, nan=0.0)
        w = torch.as_tensor(np.asarray(weight, dtype=np.float64), dtype=dt)
        w = torch.where(seen, w, torch.zeros_like(w)) / opts.marker_sigma_m
        x = torch.as_tensor(np.asarray(x0, dtype=np.float64), dtype=dt).clone()
        ref = None if x_ref is None else torch.as_tensor(np.asarray(x_ref), dtype=dt)
        rw = None if ref_weight is None else torch.as_tensor(np.asarray(ref_weight), dtype=dt)
        B = x.shape[0]
        n_iter = opts.max_iterations if max_iterations is None else max_iterations
        tol = opts.rel_tolerance if rel_tolerance is None else rel_tolerance
        abs_tol = opts.abs_tolerance if abs_tolerance is None else abs_tolerance
        iters = torch.zeros(B, dtype=torch.int64)
        lam = torch.full((B,), opts.lambda_init, dtype=dt)
        active = torch.arange(B)
        ne_all = self._linearize(x, obs, w, ref, rw)
        cost = ne_all.cost.clone()
        # per-frame normal equations of the active set
        ne = ne_all
        for _ in range(n_iter):
            if active.numel() == 0:
                break
            xa = x[active]
            step = _solve(ne, lam[active])
            x_new = _wrap_root(xa + step)
            ref_a = None if ref is None else ref[active]
            rw_a = None if rw is None else rw[active]
            ne_new = self._linearize(x_new, obs[active], w[active], ref_a, rw_a)
            c_old = cost[active]
            accept = ne_new.cost < c_old
            iters[active] += 1
            gain = (c_old - ne_new.cost) / c_old.clamp_min(1e-30)
            x[active] = torch.where(accept[:, None], x_new, xa)
            cost[active] = torch.where(accept, ne_new.cost, c_old)
            la = lam[active]
            lam[active] = torch.where(accept, (la * 0.3).clamp_min(1e-9), (la * 8.0))
            drop = c_old - ne_new.cost
            done = (accept & ((gain < tol) | (drop < abs_tol))) | (lam[active] > 1e8)
            done |= step.abs().amax(dim=1) < 1e-10
            ne = _merge(ne_new, ne, accept)
            keep = ~done
            active = active[keep]
            ne = _select(ne, keep)
        state = self.model.forward(x)
        res = (state.markers - obs).norm(dim=-1)
        res = torch.where(seen, res, torch.full_like(res, float("nan")))
        n_seen = seen.sum(1)
        rms = torch.sqrt(torch.nan_to_num(res, nan=0.0).pow(2).sum(1) / n_seen.clamp_min(1))
        rms = torch.where(n_seen > 0, rms, torch.full_like(rms, float("nan")))
        stats = SolveStats(
            iterations=iters.numpy(),
            cost=cost.numpy(),
            marker_rms_m=rms.numpy(),
            residual_m=res.numpy(),
        )
        return x.numpy(), stats


_STAT_FIELDS = ("iterations", "cost", "marker_rms_m", "residual_m")


def _merge(new: NormalEquations, old: NormalEquations, accept: torch.Tensor) -> NormalEquations:
    if bool(accept.all()):
        return new
    if not bool(accept.any()):
        return old

    def pick(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        shape = (-1,) + (1,) * (a.dim() - 1)
        return torch.where(accept.reshape(shape), a, b)

    return NormalEquations(
        pick(new.H_rr, old.H_rr),
        pick(new.H_rf, old.H_rf),
        pick(new.H_ff, old.H_ff),
        pick(new.g_r, old.g_r),
        pick(new.g_f, old.g_f),
        pick(new.cost, old.cost),
        pick(new.residual, old.residual),
    )


def _select(ne: NormalEquations, keep: torch.Tensor) -> NormalEquations:
    if bool(keep.all()):
        return ne
    return NormalEquations(
        ne.H_rr[keep],
        ne.H_rf[keep],
        ne.H_ff[keep],
        ne.g_r[keep],
        ne.g_f[keep],
        ne.cost[keep],
        ne.residual[keep],
    )
