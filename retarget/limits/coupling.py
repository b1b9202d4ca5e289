"""Kinematic couplings of the robot model as linearised equality constraints.

MuJoCo expresses couplings as equality constraints: ``mjEQ_JOINT`` (``q₁ = poly(q₂)``, e.g.
mimic joints and linkages) and ``mjEQ_TENDON`` between fixed tendons (``L₁ = poly(L₂)``,
``L = Σ cᵢ qᵢ``). Each becomes one row ``A Δq = b`` that also pulls a violated coupling back.

Limited fixed tendons bound a joint combination, ``lo ≤ aᵀq ≤ hi``: a narrow range is a
coupling (Shadow's ``T_*J1c`` hold ``0.00705·J0 − 0.00805·J1`` within ±1 mm, so the distal
joint follows the middle one), a wide one bounds a sum. The simulator enforces both, so the
kinematic solution must too: two rows ``±aᵀΔq ≤ …`` each, or box bounds on the joint when the
tendon spans one joint only. (Without them the solver left
Shadow's distal joints straight while the middle ones flexed, 6 mm outside the ±1 mm
coupling, and the re-simulated fingertips landed elsewhere: J0 0.0 kinematic vs 0.47 rad
simulated on a lateral pinch.)
"""

from __future__ import annotations

import mujoco
import numpy as np

from retarget.limits import _kernels
from retarget.limits.base import Limit
from retarget.state import RobotState

COUPLING_TENDON_WIDTH_M = 2e-3
"""A limited fixed tendon over two or more joints whose range is at most this wide couples
them (Shadow's ``T_*J1c``, ±1 mm); a wider one only bounds their combination."""


class CouplingLimit(Limit):
    """Equality rows ``a₁ᵀΔq − p'(s₂) a₂ᵀΔq = −(s₁ − p(s₂))`` with ``sᵢ = aᵢᵀq``."""

    name = "coupling"

    def __init__(
        self,
        rows: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
        ranges: list[tuple[np.ndarray, float, float]] | None = None,
    ):
        """``rows``: (a1 (nv,), a2 (nv,) or zeros for a constant, polycoef (5,));
        ``ranges``: (a (nv,), lo, hi) for ``lo ≤ aᵀq ≤ hi`` (limited fixed tendons)."""
        self.rows = rows
        self.ranges = list(ranges or [])
        # A range on one joint (``lo ≤ c·q_j ≤ hi``: most of Shadow's 44, the tendons of its
        # antagonistic actuator pairs) is an interval of that joint: box bounds, which the QP
        # solver takes at a fraction of a row's cost (Shadow: 88 → 24 rows per QP). The
        # ranges on joint combinations stay rows.
        multi, self._box = [], None
        for a, lo, hi in self.ranges:
            (nz,) = np.nonzero(a)
            if nz.size != 1:
                multi.append((a, lo, hi))
                continue
            if self._box is None:
                self._box = (np.full(a.shape[0], -np.inf), np.full(a.shape[0], np.inf))
            j, c = int(nz[0]), float(a[nz[0]])
            q_lo, q_hi = (lo / c, hi / c) if c > 0 else (hi / c, lo / c)
            self._box[0][j] = max(self._box[0][j], q_lo)
            self._box[1][j] = min(self._box[1][j], q_hi)
        # The narrow multi-joint ranges tie joints as an equality would (``follower_map``).
        ties = [a for a, lo, hi in multi if hi - lo <= COUPLING_TENDON_WIDTH_M]
        self._ties = np.array(ties) if ties else None
        if multi:
            self._G = np.array([a for a, _, _ in multi])
            self._lo = np.array([lo for _, lo, _ in multi])
            self._hi = np.array([hi for _, _, hi in multi])
        self._multi = bool(multi)
        # The equality rows stacked, built in one compiled pass per iterate (a Python loop over
        # them took 7.6 % of SVH's solve time; its 11 rows 89 µs per call, 15.2 µs as NumPy
        # array operations, 2.6 µs compiled, timeit).
        if rows:
            self._A1 = np.array([a1 for a1, _, _ in rows])
            self._A2 = np.array([a2 for _, a2, _ in rows])
            C = np.array([c for _, _, c in rows])  # (k, 5)
            self._C = C
            self._dC = C[:, 1:] * np.arange(1, 5)  # p' coefficients (k, 4)
        self.linear = not self.rows or not self._dC[:, 1:].any()
        """Every equality is linear (``p'`` constant): :meth:`follower_map` does not depend
        on ``q``."""

    def __bool__(self) -> bool:
        return bool(self.rows or self.ranges)

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
        ranges = []
        for t in range(m.ntendon):
            adr, num = int(m.tendon_adr[t]), int(m.tendon_num[t])
            fixed = all(m.wrap_type[adr + k] == mujoco.mjtWrap.mjWRAP_JOINT for k in range(num))
            if fixed and m.tendon_limited[t]:
                lo, hi = (float(x) for x in m.tendon_range[t])
                ranges.append((_fixed_tendon_coefficients(m, t), lo, hi))
        return cls(rows, ranges)

    def bounds(self, state: RobotState) -> tuple[np.ndarray, np.ndarray] | None:
        """The one-joint ranges as ``q_lo − q ≤ Δq ≤ q_hi − q`` (a violated one pulls back,
        as its row did); ``None`` when there are none."""
        if self._box is None:
            return None
        nv = state.nv
        return self._box[0][:nv] - state.q, self._box[1][:nv] - state.q

    def inequalities(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        if not self._multi:
            return np.zeros((0, state.nv)), np.zeros(0)
        G = self._G[:, : state.nv]
        s = G @ state.q
        return np.concatenate([G, -G]), np.concatenate([self._hi - s, s - self._lo])

    def equalities(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        if not self.rows:
            return np.zeros((0, state.nv)), np.zeros(0)
        nv = state.nv
        # MuJoCo's joint/tendon equality is relative to the reference configuration; with
        # qpos0 = 0 for the hands, the offsets vanish.
        return _kernels.coupling_rows(self._A1[:, :nv], self._A2[:, :nv], self._C, state.q)

    def follower_map(self, q: np.ndarray, followers: np.ndarray) -> np.ndarray:
        """``(nv, nv)`` matrix ``C``: the joint displacement ``C Δq`` that a displacement ``Δq``
        of the other joints causes when the ``followers`` (bool ``(nv,)``, e.g. joints without
        a servo) move only through the couplings, linearised at ``q``.

        The couplings (equality rows, and the limited fixed tendons no wider than
        ``COUPLING_TENDON_WIDTH_M`` over two or more joints) read
        ``A_F Δq_F + A_O Δq_O = 0``, so ``Δq_F = −A_F⁺ A_O Δq_O``; ``C`` is the identity on the
        other joints and has zero columns for the followers. A follower no coupling names
        (a free passive joint) is not moved. Used where a servo's torque or offset must account
        for the joints it drives through a linkage: ``τ = (J C)ᵀ f``."""
        nv = q.shape[0]
        F = np.asarray(followers, bool)[:nv]
        rows = []
        if self.rows:
            A1, A2 = self._A1[:, :nv], self._A2[:, :nv]
            s2 = A2 @ q
            dp = np.add.reduce(self._dC * (s2[:, None] ** np.arange(4)), axis=1)
            rows.append(A1 - dp[:, None] * A2)
        if self._ties is not None:
            rows.append(self._ties[:, :nv])
        C = np.diag((~F).astype(np.float64))
        if not rows or not F.any():
            return C
        A = np.concatenate(rows)
        A = A[np.abs(A[:, F]).sum(axis=1) > 0]  # the rows that tie a follower
        if A.shape[0]:
            C[np.ix_(F, ~F)] = -np.linalg.pinv(A[:, F]) @ A[:, ~F]
        return C


def servo_follower_map(
    m: mujoco.MjModel, q: np.ndarray, hand_nv: int, coupling: CouplingLimit | None = None
) -> np.ndarray:
    """:meth:`CouplingLimit.follower_map` of ``m``'s couplings at ``q`` (``(hand_nv,)``) with
    the hand joints no joint actuator moves as the followers: ``(hand_nv, hand_nv)``, how a
    displacement of the servoed joints moves every hand joint (identity without couplings).
    ``coupling``: ``CouplingLimit.from_mjmodel(m)`` when the caller already has it."""
    followers = np.ones(hand_nv, bool)
    for a in range(m.nu):
        if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT:
            dof = int(m.jnt_dofadr[m.actuator_trnid[a, 0]])
            if dof < hand_nv:
                followers[dof] = False
    if coupling is None:
        coupling = CouplingLimit.from_mjmodel(m)
    if not coupling:
        return np.diag((~followers).astype(np.float64))
    return coupling.follower_map(np.asarray(q, dtype=np.float64)[:hand_nv], followers)


def _fixed_tendon_coefficients(m: mujoco.MjModel, tendon: int) -> np.ndarray:
    a = np.zeros(m.nv)
    adr, num = int(m.tendon_adr[tendon]), int(m.tendon_num[tendon])
    for w in range(adr, adr + num):
        if m.wrap_type[w] != mujoco.mjtWrap.mjWRAP_JOINT:
            raise ValueError(f"tendon {tendon} is not a fixed (joint) tendon")
        a[m.jnt_dofadr[m.wrap_objid[w]]] += m.wrap_prm[w]
    return a
