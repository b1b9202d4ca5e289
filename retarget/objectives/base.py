"""Objective base: a weighted least-squares term ``‖e(q) + J(q) Δq‖²_W`` of the per-frame QP."""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from retarget.objectives._kernels import weighted_gram
from retarget.state import RobotState


class Objective(ABC):
    """A residual ``e(q)`` with Jacobian ``J = ∂e/∂q``; the QP minimises ``Σ w ‖e + J Δq‖²``.

    Subclasses implement :meth:`error` and :meth:`jacobian`; :meth:`qp_terms` turns them into
    the QP's ``(H, c)`` contribution so value and gradient never disagree.
    """

    name: str = "objective"

    def __init__(self, weight: float | np.ndarray = 1.0):
        self.weight = weight

    @abstractmethod
    def error(self, state: RobotState) -> np.ndarray:
        """(m,) residual at ``state``."""

    @abstractmethod
    def jacobian(self, state: RobotState) -> np.ndarray:
        """(m, nv) derivative of :meth:`error` with respect to ``q``."""

    def weights(self, m: int) -> np.ndarray:
        w = self.weight
        if np.ndim(w) == 0:
            return np.full(m, float(w))
        return np.broadcast_to(np.asarray(w, dtype=np.float64), (m,))

    def qp_terms(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        """``(H, c)`` with ``H = Jᵀ W J`` and ``c = Jᵀ W e``."""
        e = self.error(state)
        if e.size == 0:
            return np.zeros((state.nv, state.nv)), np.zeros(state.nv)
        J = self.jacobian(state)
        JW = J.T * self._weight_vector(e.shape[0])
        return JW @ J, JW @ e

    def accumulate(self, state: RobotState, P: np.ndarray, c: np.ndarray) -> None:
        """Add :meth:`qp_terms`' ``(H, c)`` to ``P`` (nv, nv) and ``c`` (nv,) in place: what
        ``build_qp`` calls (one compiled pass instead of four array operations; subclasses
        with a cheaper form override it)."""
        e = self.error(state)
        if e.size:
            J = np.ascontiguousarray(self.jacobian(state))
            weighted_gram(J, self._weight_vector(e.shape[0]), e, P, c)

    memo_weights: bool = True
    """:meth:`weights` depends on ``weight`` and ``m`` only, so its vectors are memoised (the
    per-iterate cost of building them is a sizeable part of a frame's solve time)."""

    def _weight_vector(self, m: int) -> np.ndarray:
        if not self.memo_weights:
            return self.weights(m)
        w = self.weight
        key = (m, w.tobytes()) if isinstance(w, np.ndarray) else (m, w)
        memo = self.__dict__.setdefault("_weights_memo", {})
        out = memo.get(key)
        if out is None:
            if len(memo) > 64:
                memo.clear()
            out = memo[key] = np.array(self.weights(m), dtype=np.float64)
        return out

    def cost(self, state: RobotState) -> float:
        """``Σ w e²`` at ``state`` (for logging and line search)."""
        e = self.error(state)
        return float(np.sum(self.weights(e.shape[0]) * e * e)) if e.size else 0.0
