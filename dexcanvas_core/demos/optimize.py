"""A small bounded Levenberg–Marquardt solver for the generator's least-squares problems.

The grasp and posture problems have ~30 unknowns and a few hundred residuals. SciPy's
``least_squares`` solves them well, but its SVDs go through multi-threaded BLAS, which on a
shared two-core machine can run 20× slower than single-threaded. This solver forms the 30 × 30
normal equations with ``einsum`` (single-threaded C loops), damps them (scaled by the
diagonal, Nielsen's damping schedule) and keeps the iterate inside box bounds by projection.
Deterministic for given inputs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass
class LMResult:
    x: np.ndarray
    cost: float
    """½‖r‖² at ``x``."""
    iterations: int
    evaluations: int


def least_squares_lm(
    fun: Callable[[np.ndarray], np.ndarray],
    jac: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    x0: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    *,
    max_iter: int = 60,
    rtol: float = 1e-4,
    patience: int = 3,
) -> LMResult:
    """Minimise ``½‖fun(x)‖²`` subject to ``lo ≤ x ≤ hi``.

    Args:
        fun: residuals ``(m,)`` at ``x``.
        jac: ``(r, J)`` at ``x``: the residuals and their Jacobian ``(m, n)``.
        x0: start (projected onto the bounds).
        max_iter: Jacobian evaluations at most.
        rtol: stop when ``patience`` accepted steps in a row each lower the cost by less than
            this fraction.
    """
    x = np.clip(np.asarray(x0, dtype=float), lo, hi)
    evals = 0
    r, J = jac(x)
    evals += 1
    cost = 0.5 * float(np.einsum("i,i->", r, r))
    H = np.einsum("ij,ik->jk", J, J)
    mu = 1e-3 * float(np.max(np.diag(H)))  # damping (Nielsen's schedule)
    nu = 2.0
    it = 0
    slow = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - reported in the result
        g = np.einsum("ij,i->j", J, r)
        H = np.einsum("ij,ik->jk", J, J)
        scale = np.diag(H).copy() + 1e-12
        accepted = False
        for _ in range(10):
            try:
                step = np.linalg.solve(H + mu * np.diag(scale / scale.max()), -g)
            except np.linalg.LinAlgError:
                mu *= nu
                nu *= 2.0
                continue
            x_new = np.clip(x + step, lo, hi)
            step = x_new - x
            r_new = fun(x_new)
            evals += 1
            cost_new = 0.5 * float(np.einsum("i,i->", r_new, r_new))
            # gain ratio: actual vs predicted decrease of the linearised model
            predicted = -(g @ step) - 0.5 * (step @ H @ step)
            rho = (cost - cost_new) / predicted if predicted > 0 else -1.0
            if cost_new < cost and rho > 0:
                mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                nu = 2.0
                accepted = True
                break
            mu *= nu
            nu *= 2.0
        if not accepted:
            break
        drop = (cost - cost_new) / max(cost, 1e-300)
        x = x_new
        cost = cost_new
        slow = slow + 1 if drop < rtol else 0
        if slow >= patience or cost < 1e-16:
            break
        r, J = jac(x)
        evals += 1
    return LMResult(x=x, cost=cost, iterations=it, evaluations=evals)
