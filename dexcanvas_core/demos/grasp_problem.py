"""The grasp as a least-squares problem on the hand skeleton (:class:`HandObjectProblem`): its
residuals, tolerances and acceptance thresholds; the residuals are described in :mod:`.grasp`,
which builds and solves it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dexcanvas_core.demos.grasp_specs import ContactSpec, GraspSpec
from dexcanvas_core.demos.optimize import least_squares_lm
from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.mano.hand_model import (
    CAPSULE_INDEX,
    CAPSULES,
    DOF_HIGH,
    DOF_LOW,
    N_DOF,
    HandModel,
    rodrigues,
)
from dexcanvas_core.objects.geometry import ObjectGeometry

LIMIT_MARGIN = math.radians(2.0)
"""Margin [rad] kept from every anatomical limit by the optimiser's bounds."""


@dataclass(frozen=True)
class GraspWeights:
    """Residual weights; distances are in metres, so with ``contact = 10`` a residual of 0.01
    is 1 mm of contact error."""

    contact: float = 10.0
    """Required contact distances [1/m]."""
    optional: float = 3.0
    """Optional contact distances [1/m]."""
    side: float = 0.3
    """Pad facing the object (cosine hinge)."""
    opposition: float = 0.3
    """Force-closure proxy (unit-vector hinge)."""
    normals: float = 0.3
    """Balance of the contacts' outward normals (unit-vector hinge)."""
    penetration: float = 20.0
    """Capsule depth in the object [1/m]."""
    table: float = 20.0
    """Capsule depth below the table clearance [1/m]."""
    clearance: float = 5.0
    """Gap shortfall of non-contact fingers (and of the palm in precision grasps) [1/m]."""
    posture: float = 0.004
    """Finger angles from the type's natural posture [1/rad]."""
    wrist: float = 0.01
    """Palm normal and finger direction from the type's approach (unit vectors)."""
    site: float = 0.05
    """Palm centre from the grasp site, across the approach direction [1/m]."""


DEFAULT_WEIGHTS = GraspWeights()
"""The residual weights every grasp is solved with unless told otherwise."""


TABLE_CLEARANCE_M = 5e-4
"""Height [m] every capsule keeps above the table while the object rests on it."""

OPPOSITION_SLACK = 0.25
"""Net contact direction (mean of unit vectors) tolerated before the opposition term acts."""
NORMAL_SLACK = 0.05
"""Horizontal part of the contacts' mean outward normal tolerated before the normal-balance
term acts."""
NORMAL_UP_MAX = 0.1
"""Upward component of an opposing contact's outward normal tolerated (about 6° above the
horizontal) before the normal-balance term acts."""

CONTACT_TOL_M = 1e-3
"""Grasp acceptance: required contact distances within ± this [m]."""
PENETRATION_TOL_M = 1.5e-3
"""Grasp acceptance: deepest penetration [m]."""
OPTIONAL_TOL_M = 1.0e-3
"""An optional contact counts as achieved within ± this [m]."""
CLOSURE_MAX = 0.5
"""Grasp acceptance: closure margin below this (the check allows sin(atan 0.8) ≈ 0.62)."""
HOLD_RATIO_MAX = 6.0
"""Grasp acceptance: ``Grasp.hold_ratio`` at most this. On the same suite (its 30 tracked
pairs after the grip-ratio change): 7 of the 9 grasps dropped were above it, 3 of the 21 held
(pinches whose flat pads, line contacts in the simulation, twist less than the model's soft
point contacts)."""
GRIP_RATIO_MAX = 3.0
"""Grasp acceptance: ``Grasp.grip_ratio`` at most this (1.5 × a balanced grasp's 2).
Measured on the force-pipeline suite (32 pairs, MPC tracker): 9 of the 12 grasps the simulated
hand dropped at the lift were above 3.4, 1 of the 18 it lifted."""


def _hinge(x: np.ndarray, tau: float) -> np.ndarray:
    """Smoothed ``max(0, x)``: 0 below 0, ``x²/2τ`` up to ``τ``, then ``x - τ/2`` (C¹, so the
    damped Gauss–Newton steps see a gradient that does not jump at the constraint)."""
    return np.where(x <= 0.0, 0.0, np.where(x < tau, x * x / (2.0 * tau), x - 0.5 * tau))


def contact_samples(hand: HandModel, c: ContactSpec) -> np.ndarray:
    """Indices of the capsule samples where contact ``c`` may lie (``"palm"``: the whole palm)."""
    names = [k.name for k in CAPSULES if k.part == "palm"] if c.capsule == "palm" else [c.capsule]
    out = []
    for name in names:
        idx = hand.cap_slices[CAPSULE_INDEX[name]]
        n = len(idx)
        lo, hi = int(np.floor(c.zone[0] * (n - 1))), int(np.ceil(c.zone[1] * (n - 1)))
        out.append(idx[lo : hi + 1])
    return np.concatenate(out)


class HandObjectProblem:
    """Residuals of a hand posed relative to an object (the grasp optimiser's core).

    The decision vector is ``x = (ω (3), δ (3), q (22))``: the wrist orientation
    ``R = R0 · exp(ω)`` and position ``p = p0 + δ`` in the object frame, and the driven angles.
    Parts of it can be frozen (``free`` mask), e.g. the wrist when re-solving the fingers only.
    """

    def __init__(
        self,
        hand: HandModel,
        geom: ObjectGeometry,
        spec: GraspSpec,
        *,
        R0: np.ndarray,
        p0: np.ndarray,
        q_prior: np.ndarray,
        palm_dir: np.ndarray,
        finger_dir: np.ndarray,
        weights: GraspWeights = GraspWeights(),
        table: bool = True,
        sweep: np.ndarray | None = None,
        site: np.ndarray | None = None,
        clear: dict[str, float] | None = None,
        targets: tuple[np.ndarray, np.ndarray] | None = None,
    ):
        self.hand, self.geom, self.spec, self.w = hand, geom, spec, weights
        self.R0, self.p0 = np.asarray(R0, float), np.asarray(p0, float)
        self.q_prior = np.asarray(q_prior, float)
        self.palm_dir, self.finger_dir = np.asarray(palm_dir, float), np.asarray(finger_dir, float)
        self.table = table  # keep the hand above the table, the object resting on it
        self.sweep = None if sweep is None else np.asarray(sweep, float)
        self.site = None if site is None else np.asarray(site, float)
        self.targets = targets  # (sample indices (K,), target points (K, 3)) or None
        a = self.palm_dir / np.linalg.norm(self.palm_dir)
        self.site_proj = np.eye(3) - np.outer(a, a)
        self.palm_local = _palm_centre(hand)
        self.contacts = list(spec.contacts)
        self.c_samples = []
        self.c_joint = []
        for c in self.contacts:
            self.c_samples.append(contact_samples(hand, c))
            self.c_joint.append(
                0 if c.capsule == "palm" else CAPSULES[CAPSULE_INDEX[c.capsule]].joint
            )
        self.c_joint = np.array(self.c_joint, dtype=int)
        self.opp_mask = np.array([c.capsule != "palm" for c in self.contacts], dtype=bool)
        self._no_samples = np.zeros(hand.num_samples, bool)
        self.is_contact_sample = np.zeros(hand.num_samples, bool)
        for idx in self.c_samples:
            self.is_contact_sample[idx] = True
        self.opp_centre = opposition_centre(geom)
        self.c_weight = np.array(
            [weights.contact if c.required else weights.optional for c in self.contacts]
        )
        # clearance: fingers without any contact, and the palm when it must stay clear;
        # ``clear`` raises the gap of named fingers ("palm" for the palm) [m]
        fingers_in = {c.finger for c in self.contacts}
        gaps: dict[str, float] = {}
        for f in FINGERS:
            if f not in fingers_in:
                gaps[f] = 0.004
        if spec.palm == "clear":
            gaps["palm"] = 0.008
        for f, g in (clear or {}).items():
            gaps[f] = max(gaps.get(f, 0.0), g)
        clear_idx, clear_gap = [], []
        for i, cap in enumerate(CAPSULES):
            owner = cap.name.split("_", 1)[0]
            if owner in gaps:
                clear_idx.append(hand.cap_slices[i])
                clear_gap.append(np.full(len(hand.cap_slices[i]), gaps[owner]))
        self.clear_idx = np.concatenate(clear_idx) if clear_idx else np.zeros(0, int)
        self.clear_gap = np.concatenate(clear_gap) if clear_gap else np.zeros(0)
        self.free = np.ones(6 + N_DOF, bool)
        self.lo = np.r_[np.full(6, -np.inf), DOF_LOW + LIMIT_MARGIN]
        self.hi = np.r_[np.full(6, np.inf), DOF_HIGH - LIMIT_MARGIN]

    # -- decision vector ---------------------------------------------------------------------

    def unpack(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        X = np.atleast_2d(X)
        R = self.R0 @ rodrigues(X[:, :3])
        p = self.p0 + X[:, 3:6]
        return R, p, X[:, 6:]

    # -- residuals ---------------------------------------------------------------------------

    def evaluate(self, X: np.ndarray) -> dict[str, np.ndarray]:
        """Everything the residuals and reports need, batched over rows of ``X``."""
        R, p, q = self.unpack(X)
        kp, Rj = self.hand.forward(q, R, p)
        S = self.hand.samples(kp)  # (B, Ns, 3)
        d, n = self._sdf(S)
        d = d - self.hand.s_r
        B = S.shape[0]
        rows = np.arange(B)
        cd, cn, cp, ci = [], [], [], []
        for idx in self.c_samples:
            dc = d[:, idx]
            k = np.argmin(dc, axis=1)
            cd.append(dc[rows, k])
            cn.append(n[:, idx][rows, k])
            cp.append(S[:, idx][rows, k])
            ci.append(idx[k])
        return {
            "R": R,
            "p": p,
            "q": q,
            "kp": kp,
            "Rj": Rj,
            "S": S,
            "d": d,
            "n": n,
            "cd": np.stack(cd, 1) if cd else np.zeros((B, 0)),
            "cn": np.stack(cn, 1) if cn else np.zeros((B, 0, 3)),
            "cp": np.stack(cp, 1) if cp else np.zeros((B, 0, 3)),
            "ci": np.stack(ci, 1) if ci else np.zeros((B, 0), int),
        }

    def _sdf(
        self, S: np.ndarray, always: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Signed distances of a batch of sample sets; rows after the first that differ from
        it only in some samples (a finger's finite-difference step) reuse the rest."""
        if S.shape[0] == 1:
            return self.geom.sdf_and_normal(S)
        changed = np.any(S != S[:1], axis=-1)  # (B, Ns)
        # finite-difference rows: samples far from the object (> 3 cm) have flat residuals
        # unless they carry a contact; keep the base row's values for them
        d0, _ = self.geom.sdf_and_normal(S[0])
        changed &= (d0 < 0.03) | (self.is_contact_sample if always is None else always)
        changed[0] = True
        d = np.broadcast_to(np.empty(S.shape[1]), S.shape[:2]).copy()
        n = np.empty(S.shape)
        dd, nn = self.geom.sdf_and_normal(S[changed])
        d[changed], n[changed] = dd, nn
        keep = ~changed
        d[keep] = np.broadcast_to(d[:1], d.shape)[keep]
        n[keep] = np.broadcast_to(n[:1], n.shape)[keep]
        return d, n

    def residuals_batch(self, X: np.ndarray) -> np.ndarray:
        w = self.w
        e = self.evaluate(X)
        d, S, q, R = e["d"], e["S"], e["q"], e["R"]
        parts = []
        # contacts
        if self.contacts:
            parts.append(self.c_weight * e["cd"])
            side_res = []
            for k, c in enumerate(self.contacts):
                nk = e["cn"][:, k]
                if c.side in ("volar", "radial"):
                    sd = self.hand.directions(e["Rj"], self.c_joint[k : k + 1], c.side)[:, 0]
                    side_res.append(_hinge(np.sum(nk * sd, -1) + math.cos(math.pi / 3), 0.05))
                elif c.side == "up":
                    side_res.append(_hinge(0.5 - nk[:, 2], 0.05))
                else:
                    side_res.append(np.zeros(nk.shape[0]))
            parts.append(w.side * np.stack(side_res, 1))
            if self.spec.opposition and self.opp_mask.any():
                # force-closure proxy: horizontal directions from the object's vertical centre
                # line to the contacts cancel (smooth, unlike face normals that are constant
                # on a face); the palm is left out (it sits above the centre in many grasps)
                v = (e["cp"] - self.opp_centre)[:, self.opp_mask]
                v[..., 2] = 0.0
                v = v / np.sqrt(np.sum(v * v, axis=-1, keepdims=True) + 0.005**2)
                wts = self.c_weight[self.opp_mask] / self.c_weight[self.opp_mask].sum()
                net = np.einsum("k,bki->bi", wts, v)
                size = np.linalg.norm(net, axis=-1, keepdims=True)
                excess = _hinge(size - OPPOSITION_SLACK, 0.05) / np.maximum(size, 1e-9)
                parts.append(w.opposition * excess * net)
                # the true normals must not all tilt up (a ball pinched above its equator
                # squeezes out): their mean vertical component stays small
                nz = np.einsum("k,bk->b", wts, e["cn"][:, self.opp_mask, 2])
                parts.append(w.opposition * _hinge(np.abs(nz) - 0.2, 0.05)[:, None])
                # the true normals' horizontal parts cancel too (the positions above can
                # surround the centre with a pad on an edge or a face at right angles): normals
                # that do not balance spend squeeze, and the grasp needs more friction to lift
                nh = np.einsum("k,bki->bi", wts, e["cn"][:, self.opp_mask, :2])
                size = np.linalg.norm(nh, axis=-1, keepdims=True)
                excess = _hinge(size - NORMAL_SLACK, 0.05) / np.maximum(size, 1e-9)
                parts.append(w.normals * excess * nh)
                # and no single pad presses down from above the object's edge or equator
                # (its squeeze pushes the object into the table instead of holding it up)
                up = e["cn"][:, self.opp_mask, 2]
                parts.append(w.normals * _hinge(up - NORMAL_UP_MAX, 0.05))
        # penetration (object) and table
        parts.append(w.penetration * _hinge(-d - 3e-4, 5e-4))
        if self.table:
            z = S[..., 2] + self.geom.rest_z
            parts.append(w.table * _hinge(TABLE_CLEARANCE_M + self.hand.s_r - z, 5e-4))
        if self.clear_idx.size:
            parts.append(w.clearance * _hinge(self.clear_gap - d[:, self.clear_idx], 5e-4))
        if self.sweep is not None:
            # the pre-shaped hand must clear the object all along its approach line
            for off in self.sweep:
                dd = self._sdf(S + off, always=self._no_samples)[0] - self.hand.s_r
                parts.append(w.clearance * _hinge(0.004 - dd, 5e-4))
        if self.targets is not None:
            idx, pts = self.targets
            parts.append(w.contact * (S[:, idx] - pts).reshape(S.shape[0], -1))
        parts.append(w.posture * (q - self.q_prior))
        if self.site is not None:
            palm = np.einsum("bij,j->bi", R, self.palm_local) + e["p"]
            parts.append(w.site * (palm - self.site) @ self.site_proj.T)
        parts.append(w.wrist * (-R[:, :, 1] - self.palm_dir))
        parts.append(0.5 * w.wrist * (-R[:, :, 0] - self.finger_dir))
        return np.concatenate(parts, axis=1)

    # -- solve -------------------------------------------------------------------------------

    def solve(self, x0: np.ndarray, max_iter: int = 60) -> tuple[np.ndarray, float]:
        """Minimise the residuals from ``x0`` over the free entries; returns ``(x, cost)``."""
        free = np.flatnonzero(self.free)
        base = np.clip(np.array(x0, dtype=float), self.lo, self.hi)
        h = 1e-6

        def full(z: np.ndarray) -> np.ndarray:
            x = base.copy()
            x[free] = z
            return x

        def fun(z: np.ndarray) -> np.ndarray:
            return self.residuals_batch(full(z)[None])[0]

        def jac(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            X = np.repeat(full(z)[None], len(free) + 1, axis=0)
            X[np.arange(1, len(free) + 1), free] += h
            r = self.residuals_batch(X)
            return r[0], ((r[1:] - r[0]) / h).T

        sol = least_squares_lm(
            fun, jac, base[free], self.lo[free], self.hi[free], max_iter=max_iter
        )
        return full(sol.x), sol.cost


def _palm_centre(hand: HandModel) -> np.ndarray:
    """Palm centre on its volar surface, wrist frame at rest [m]."""
    kp = hand.rest
    c = kp[[0, 1, 4, 7, 10]].mean(axis=0)
    return c + np.array([0.0, -0.0125 * hand.scale, 0.0])


def opposition_centre(geom: ObjectGeometry) -> np.ndarray:
    """Point (object frame) whose vertical line the contacts should surround: the object's
    centre, or its graspable part (the drill's handle, between the scissors' loops, the bowl's
    near rim)."""
    named = {p.name: np.asarray(p.pos) for p in geom.primitives}
    if geom.object_id == "bowl":
        return np.array([-geom.aabb_half[0] + 0.003, 0.0, 0.0])
    if geom.object_id == "scissor":
        loops = [p.pos for p in geom.primitives if p.name.endswith("loop")]
        return np.mean(loops, axis=0)
    if "handle" in named and geom.object_id == "powerdrill":
        return named["handle"]
    return np.zeros(3)
