"""Building and solving the per-iterate QP on the joint step ``Δq``.

``build_qp`` sums the objectives' ``(H, c)`` terms (plus Levenberg–Marquardt damping) and stacks
the limits' rows; ``solve_qp`` hands the problem to ``qpsolvers`` (``daqp`` by default). Keeping
the two apart lets tests inspect the problem, and a failed solve raises with the problem attached
instead of silently returning the previous pose.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError
from retarget.limits.base import Limit
from retarget.objectives.base import Objective
from retarget.state import RobotState


@dataclass
class QPProblem:
    """``min ½ Δqᵀ P Δq + qᵀ Δq  s.t.  G Δq ≤ h,  A Δq = b``."""

    P: np.ndarray
    q: np.ndarray
    G: np.ndarray
    h: np.ndarray
    A: np.ndarray
    b: np.ndarray


class QPSolveError(RetargetError):
    """The QP solver failed; ``.problem`` holds the problem for inspection."""

    def __init__(self, message: str, problem: QPProblem):
        super().__init__(message)
        self.problem = problem


def build_qp(
    state: RobotState,
    objectives: Sequence[Objective],
    limits: Sequence[Limit] = (),
    damping: float = 1e-6,
) -> QPProblem:
    """Assemble the QP at ``state`` (objectives' Gauss–Newton terms, limits' linear rows)."""
    nv = state.nv
    P = damping * np.eye(nv)
    c = np.zeros(nv)
    for obj in objectives:
        H, g = obj.qp_terms(state)
        P += H
        c += g
    Gs, hs, As, bs = [np.zeros((0, nv))], [np.zeros(0)], [np.zeros((0, nv))], [np.zeros(0)]
    for lim in limits:
        G, h = lim.inequalities(state)
        A, b = lim.equalities(state)
        Gs.append(G)
        hs.append(h)
        As.append(A)
        bs.append(b)
    return QPProblem(
        P=0.5 * (P + P.T),
        q=c,
        G=np.concatenate(Gs),
        h=np.concatenate(hs),
        A=np.concatenate(As),
        b=np.concatenate(bs),
    )


def solve_qp(problem: QPProblem, solver: str = "daqp") -> np.ndarray:
    """Solve with ``qpsolvers``; raise :class:`QPSolveError` (problem attached) on failure."""
    import qpsolvers

    if solver not in qpsolvers.available_solvers:
        raise RetargetError(
            f"QP solver {solver!r} is not installed; available: "
            f"{', '.join(qpsolvers.available_solvers)}"
        )
    G = problem.G if problem.G.shape[0] else None
    h = problem.h if problem.h.shape[0] else None
    A = problem.A if problem.A.shape[0] else None
    b = problem.b if problem.b.shape[0] else None
    x = qpsolvers.solve_qp(problem.P, problem.q, G, h, A, b, solver=solver)
    if x is None or not np.all(np.isfinite(x)):
        # Infeasible limits (e.g. a coupling that contradicts a bound): report, don't hide.
        raise QPSolveError(
            f"QP solver {solver!r} found no solution ({problem.G.shape[0]} inequality and "
            f"{problem.A.shape[0]} equality rows)",
            problem,
        )
    return x
