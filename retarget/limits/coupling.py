"""Kinematic couplings of the robot model as linearised equality constraints.

MuJoCo expresses couplings as equality constraints: ``mjEQ_JOINT`` (``q₁ = poly(q₂)``, e.g.
mimic joints and linkages) and ``mjEQ_TENDON`` between fixed tendons (``L₁ = poly(L₂)``,
``L = Σ cᵢ qᵢ``). Each becomes one row ``A Δq = b`` that also pulls a violated coupling back.
"""

from __future__ import annotations

import mujoco
import numpy as np

from retarget.limits.base import Limit
from retarget.state import RobotState


def _poly(c: np.ndarray, x: float) -> tuple[float, float]:
    """``(p(x), p'(x))`` for ``p = c0 + c1 x + … + c4 x⁴``."""
    val = sum(c[k] * x**k for k in range(5))
    der = sum(k * c[k] * x ** (k - 1) for k in range(1, 5))
    return float(val), float(der)


class CouplingLimit(Limit):
    """Equality rows ``a₁ᵀΔq − p'(s₂) a₂ᵀΔq = −(s₁ − p(s₂))`` with ``sᵢ = aᵢᵀq``."""

    name = "coupling"

    def __init__(self, rows: list[tuple[np.ndarray, np.ndarray, np.ndarray]]):
        """``rows``: (a1 (nv,), a2 (nv,) or zeros for a constant, polycoef (5,))."""
        self.rows = rows

    @classmethod
    def from_mjmodel(cls, m: mujoco.MjModel) -> CouplingLimit:
        rows = []
        for e in range(m.neq):
            if not m.eq_active0[e]:
                continue
            typ = int(m.eq_type[e])
            coef = np.asarray(m.eq_data[e, :5], dtype=np.float64)
            a1, a2 = np.zeros(m.nv), np.zeros(m.nv)
            if typ == mujoco.mjtEq.mjEQ_JOINT:
                a1[m.jnt_dofadr[m.eq_obj1id[e]]] = 1.0
                if m.eq_obj2id[e] >= 0:
                    a2[m.jnt_dofadr[m.eq_obj2id[e]]] = 1.0
            elif typ == mujoco.mjtEq.mjEQ_TENDON:
                a1 = _fixed_tendon_coefficients(m, int(m.eq_obj1id[e]))
                if m.eq_obj2id[e] >= 0:
                    a2 = _fixed_tendon_coefficients(m, int(m.eq_obj2id[e]))
            else:
                continue  # connect/weld constraints do not couple a hand's joints
            rows.append((a1, a2, coef))
        return cls(rows)

    def equalities(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        if not self.rows:
            return np.zeros((0, state.nv)), np.zeros(0)
        A, b = [], []
        for a1, a2, coef in self.rows:
            s1, s2 = float(a1 @ state.q), float(a2 @ state.q)
            # MuJoCo's joint/tendon equality is relative to the reference configuration; with
            # qpos0 = 0 for the hands, the offsets vanish.
            p, dp = _poly(coef, s2)
            A.append(a1 - dp * a2)
            b.append(-(s1 - p))
        return np.array(A), np.array(b)


def _fixed_tendon_coefficients(m: mujoco.MjModel, tendon: int) -> np.ndarray:
    a = np.zeros(m.nv)
    adr, num = int(m.tendon_adr[tendon]), int(m.tendon_num[tendon])
    for w in range(adr, adr + num):
        if m.wrap_type[w] != mujoco.mjtWrap.mjWRAP_JOINT:
            raise ValueError(f"tendon {tendon} is not a fixed (joint) tendon")
        a[m.jnt_dofadr[m.wrap_objid[w]]] += m.wrap_prm[w]
    return a
