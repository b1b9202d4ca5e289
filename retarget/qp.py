"""Building and solving the per-iterate QP on the joint step ``Δq``.

``build_qp`` sums the objectives' ``(H, c)`` terms (``Objective.accumulate``; plus
Levenberg–Marquardt damping), stacks the limits' rows and intersects their box bounds (joint
ranges, velocity: ``lb ≤ Δq ≤ ub``, which the solver treats as simple bounds instead of ``2 nv``
general rows); ``solve_qp`` calls DAQP directly (the default) or any other solver through
``qpsolvers``. Keeping the two apart lets tests inspect the problem, and a failed solve raises
with the problem attached instead of silently returning the previous pose.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from retarget import _kernels
from retarget.errors import RetargetError
from retarget.limits.base import Limit
from retarget.objectives.base import Objective
from retarget.state import RobotState


@dataclass
class QPProblem:
    """``min ½ Δqᵀ P Δq + qᵀ Δq  s.t.  G Δq ≤ h,  A Δq = b,  lb ≤ Δq ≤ ub``."""

    P: np.ndarray
    q: np.ndarray
    G: np.ndarray
    h: np.ndarray
    A: np.ndarray
    b: np.ndarray
    lb: np.ndarray | None = None
    """(nv,) lower bounds (``-inf``: none); ``None``: no bounds at all."""
    ub: np.ndarray | None = None
    """(nv,) upper bounds (``inf``: none); ``None``: no bounds at all."""


class QPSolveError(RetargetError):
    """The QP solver failed; ``.problem`` holds the problem for inspection."""

    def __init__(self, message: str, problem: QPProblem):
        super().__init__(message)
        self.problem = problem


_EYE: dict[tuple[int, float], np.ndarray] = {}


def _damping_matrix(nv: int, damping: float) -> np.ndarray:
    """A fresh ``damping · I`` (nv, nv), copied from a memoised one (``damping * np.eye``
    costs 5× as much on 30 dofs: 3.3 against 0.7 µs)."""
    key = (nv, damping)
    D = _EYE.get(key)
    if D is None:
        if len(_EYE) > 32:
            _EYE.clear()
        D = _EYE[key] = damping * np.eye(nv)
    return D.copy()


def build_qp(
    state: RobotState,
    objectives: Sequence[Objective],
    limits: Sequence[Limit] = (),
    damping: float = 1e-6,
) -> QPProblem:
    """Assemble the QP at ``state`` (objectives' Gauss–Newton terms, limits' linear rows)."""
    nv = state.nv
    P = _damping_matrix(nv, damping)
    c = np.zeros(nv)
    for obj in objectives:
        obj.accumulate(state, P, c)  # (P += JᵀWJ, c += JᵀWe)
    Gs, hs, As, bs = [np.zeros((0, nv))], [np.zeros(0)], [np.zeros((0, nv))], [np.zeros(0)]
    lb = ub = None
    for lim in limits:
        kind = type(lim)
        if kind.bounds is not Limit.bounds:  # (the base's methods add nothing: skipped)
            box = lim.bounds(state)
            if box is not None:
                lo, hi = box
                lb = lo if lb is None else np.maximum(lb, lo)
                ub = hi if ub is None else np.minimum(ub, hi)
        if kind.inequalities is not Limit.inequalities:
            G, h = lim.inequalities(state)
            if G.shape[0]:
                Gs.append(G)
                hs.append(h)
        if kind.equalities is not Limit.equalities:
            A, b = lim.equalities(state)
            if A.shape[0]:
                As.append(A)
                bs.append(b)
    _kernels.symmetrize(P)  # (½ (P + Pᵀ) in place)
    return QPProblem(
        P=P,
        q=c,
        G=np.concatenate(Gs) if len(Gs) > 2 else Gs[-1],
        h=np.concatenate(hs) if len(hs) > 2 else hs[-1],
        A=np.concatenate(As) if len(As) > 2 else As[-1],
        b=np.concatenate(bs) if len(bs) > 2 else bs[-1],
        lb=lb,
        ub=ub,
    )


_DAQP_INF = 1e30  # DAQP's "no bound"
_NONE = (np.zeros(0), np.zeros(0))  # (no box: daqp_arrays reads no bounds)


def _bound(x: np.ndarray | None, default: float, nv: int) -> np.ndarray:
    """A box side as ``(nv,)`` float64 (``default`` where ``None``)."""
    if x is None:
        return np.full(nv, default)
    x = np.asarray(x, dtype=np.float64)
    return x if x.shape == (nv,) else np.broadcast_to(x, (nv,))


def _solve_daqp(problem: QPProblem) -> np.ndarray | None:
    """DAQP called directly: box bounds as its simple bounds, then ``G``, then ``A`` (equal)."""
    try:
        import daqp
    except ImportError:
        raise RetargetError("QP solver 'daqp' is not installed (pip install daqp)") from None
    nv = problem.q.shape[0]
    box = problem.lb is not None or problem.ub is not None
    lb, ub = (_bound(problem.lb, -np.inf, nv), _bound(problem.ub, np.inf, nv)) if box else _NONE
    M, upper, lower, sense = _kernels.daqp_arrays(
        problem.G, problem.h, problem.A, problem.b, lb, ub, box, _DAQP_INF
    )
    x, _, exitflag, _ = daqp.solve(problem.P, problem.q, M, upper, lower, sense)
    return x if exitflag > 0 else None


def solve_qp(problem: QPProblem, solver: str = "daqp") -> np.ndarray:
    """Solve (DAQP directly, any other ``qpsolvers`` solver by name); raise
    :class:`QPSolveError` (problem attached) on failure."""
    if solver == "daqp":
        x = _solve_daqp(problem)
    else:
        import qpsolvers

        if solver not in qpsolvers.available_solvers:
            raise RetargetError(
                f"QP solver {solver!r} is not installed; available: daqp, "
                f"{', '.join(qpsolvers.available_solvers)}"
            )
        G = problem.G if problem.G.shape[0] else None
        h = problem.h if problem.h.shape[0] else None
        A = problem.A if problem.A.shape[0] else None
        b = problem.b if problem.b.shape[0] else None
        x = qpsolvers.solve_qp(
            problem.P, problem.q, G, h, A, b, lb=problem.lb, ub=problem.ub, solver=solver
        )
    if x is None or not np.isfinite(x).all():
        # Infeasible limits (e.g. a coupling that contradicts a bound): report, don't hide.
        raise QPSolveError(
            f"QP solver {solver!r} found no solution ({problem.G.shape[0]} inequality and "
            f"{problem.A.shape[0]} equality rows)",
            problem,
        )
    return x
