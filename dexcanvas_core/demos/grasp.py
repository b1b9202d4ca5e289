"""Grasp synthesis: a small optimisation on the hand skeleton, per manipulation type.

For one (object, manipulation type, operator) the optimiser finds the wrist pose relative to the
object and the 22 driven finger angles (:mod:`.hand`) such that the type's **contact parts**
touch the object's surface and the hand does not penetrate the object or the table. It is a
bounded nonlinear least-squares problem (Levenberg–Marquardt, :mod:`.optimize`; joint limits
as bounds with a 2° margin; Jacobian by batched forward differences).

Residuals (distances in metres, weights in ``GraspWeights``):

* **contact** — for every contact part, the signed distance from its capsule's surface (within
  the pad zone) to the object, minus the target gap (0 for a grasp);
* **side** — the pad must face the object: the object's outward normal at the contact and the
  pad's volar (or radial) direction must be opposed within 60°; for table-supported types the
  contact normal must point upwards (the fingers press from above);
* **opposition** — a force-closure proxy: the mean of the horizontal unit vectors from the
  object's vertical centre line to the contacts stays below 0.25 (the contacts surround the
  object; two contacts end up nearly antipodal — smooth where face normals are not), and the
  contacts' mean normal does not tilt up or down by more than 0.2 (a ball pinched above its
  equator squeezes out);
* **normal balance** — the same on the true outward normals, which the positions alone do not
  pin down (a pad on a box's edge, or on a face at right angles to the opposing one, can sit
  where the positions oppose): the horizontal part of the contacts' mean normal stays below
  0.05 and no opposing pad's normal points up by more than 0.1 (it would push the object
  into the table); the result is accepted when ``checks.closure_margin`` of the contact normals
  shows force closure with margin and ``checks.lift_grip_ratio`` shows the normals lift the
  object with at most 1.5× the squeeze of a balanced grasp (``GRIP_RATIO_MAX``);
* **penetration** — a hinge on every capsule sample deeper than 0.3 mm in the object;
* **table** — a hinge keeping every capsule 0.5 mm above the table;

(hinges are smoothed over 0.5 mm — quadratic, then linear — so the steps do not stall on them)
* **clearance** — fingers that do not take part stay 4 mm off the object (and the palm 8 mm off
  it in precision grasps);
* **posture** — a weak pull towards the type's natural posture (non-contact fingers curled,
  extended or relaxed; thumb abducted or adducted), and towards the type's wrist approach
  direction (from above for precision grasps and low objects, from the side for power grasps of
  tall objects).

``solve_grasp`` returns a :class:`Grasp` with the measured contact distances; ``Grasp.ok`` tells
whether every required contact lies within ±1 mm, nothing penetrates deeper than 1.5 mm and
the contacts oppose and can lift the object (the demonstration checks allow ±1.5 mm and 2 mm).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Literal

import numpy as np

from dexcanvas_core.demos.checks import closure_margin, lift_grip_ratio
from dexcanvas_core.demos.geometry import ObjectGeometry, object_geometry
from dexcanvas_core.demos.hand import (
    CAPSULE_INDEX,
    CAPSULES,
    DOF_HIGH,
    DOF_LOW,
    N_DOF,
    HandModel,
    dof_index,
    rodrigues,
)
from dexcanvas_core.demos.optimize import least_squares_lm
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.taxonomy import MANIPULATION_TYPES

log = logging.getLogger(__name__)

Side = Literal["volar", "radial", "any", "up"]
Posture = Literal["curl", "extend", "relax"]
Approach = Literal["top", "side"]

LIMIT_MARGIN = math.radians(2.0)
"""Margin [rad] kept from every anatomical limit by the optimiser's bounds."""


@dataclass(frozen=True)
class ContactSpec:
    """One hand part that touches the object in a manipulation type.

    Attributes:
        capsule: name in ``hand.CAPSULES`` (``"index_dip"``, ``"thumb_ip"``…) or ``"palm"``
            (any of the palm's capsules).
        side: which side of the part faces the object: ``"volar"`` (the pad), ``"radial"``
            (thumb side of a finger, lateral pinches), ``"any"``, or ``"up"`` (table-supported
            types: the contact must be on the object's upper half, pressing down).
        zone: fraction range along the capsule where the contact may lie (``(0.3, 1.0)`` = the
            distal 70 %).
        required: required contacts are checked in every contact frame; optional ones (a
            supporting finger side, the palm in some power grasps) are pulled towards the
            surface but enter the contact schedule only when the grasp achieves them.
    """

    capsule: str
    side: Side = "volar"
    zone: tuple[float, float] = (0.3, 1.0)
    required: bool = True

    @property
    def finger(self) -> str:
        return self.capsule.split("_", 1)[0]


@dataclass(frozen=True)
class GraspSpec:
    """How a manipulation type holds an object (used by the optimiser and the scripts)."""

    type_name: str
    contacts: tuple[ContactSpec, ...]
    """The parts that touch the object (pads, sides, the palm)."""
    approach: Approach | Literal["auto"] = "auto"
    """Wrist approach: from above, from the side (subject's side), or ``auto`` (side for
    objects taller than wide, else top)."""
    palm: Literal["contact", "clear", "free"] = "free"
    """The palm touches the object (power), keeps 8 mm off it (precision) or is free."""
    posture: Posture = "relax"
    """Natural posture of the fingers that do not take part."""
    thumb: Literal["abducted", "adducted"] = "abducted"
    """Initial thumb posture (opposed, or along the index)."""
    opposition: bool = True
    """False for table-supported types (rolling, sliding): no force closure needed."""
    closure: float = 0.55
    """Initial flexion (0 open … 1 fist) of the contact fingers."""
    shape: tuple[float, float, float] | None = None
    """Initial (MCP, PIP, DIP) flexion [rad] of the contact fingers, overriding ``closure``."""


def _pads(*fingers: str, side: Side = "volar", required: bool = True) -> tuple[ContactSpec, ...]:
    return tuple(
        ContactSpec(f"{f}_ip" if f == "thumb" else f"{f}_dip", side, required=required)
        for f in fingers
    )


_PALM = (ContactSpec("palm", "any", (0.2, 1.0)),)
_PALM_OPT = (ContactSpec("palm", "any", (0.2, 1.0), required=False),)
_T, _I, _M, _R, _P = "thumb", "index", "middle", "ring", "pinky"

# fmt: off
GRASP_SPECS: dict[str, GraspSpec] = {s.type_name: s for s in (
    # power: the object rests against the palm
    GraspSpec("ring", (*_pads(_T, _I), *_PALM_OPT), "auto", "free", "curl", closure=0.7),
    GraspSpec("sphere_3_finger", (*_pads(_T, _I, _M), *_PALM), "top", "contact", "curl",
              closure=0.6),
    GraspSpec("sphere_4_finger", (*_pads(_T, _I, _M, _R), *_PALM), "top", "contact", "curl",
              closure=0.6),
    GraspSpec("large_diameter", (*_pads(_T, _I, _M, _R, _P), *_PALM), "auto", "contact",
              closure=0.7),
    GraspSpec("distal_type", (*_pads(_T, _M, _R, side="any"),
                              *_pads(_I, _P, side="any", required=False)),
              "top", "free", "relax", closure=0.5),
    GraspSpec("extension_type", _pads(_T, _I, _M, _R, _P), "top", "clear", "extend",
              shape=(1.0, 0.25, 0.1)),
    GraspSpec("adducted_thumb", (*_pads(_I, _M, _R, _P), *_pads(_T, side="any", required=False),
                                 *_PALM), "auto", "contact", thumb="adducted", closure=0.75),
    # intermediate
    GraspSpec("writing_tripod", (*_pads(_T, _I), ContactSpec("middle_dip", "radial",
                                                              required=False)),
              "top", "clear", "curl", closure=0.45),
    GraspSpec("tripod_variation", (*_pads(_T, _I), *_pads(_M, _R, required=False)),
              "top", "clear", "curl", closure=0.45),
    GraspSpec("lateral_pinch", (*_pads(_T), ContactSpec("index_pip", "radial", (0.0, 1.0))),
              "top", "clear", "curl", thumb="adducted", closure=0.8),
    GraspSpec("lateral_tripod", (*_pads(_T), ContactSpec("index_dip", "radial", (0.0, 1.0)),
                                 ContactSpec("middle_dip", "any", (0.0, 1.0))),
              "top", "clear", "curl", thumb="adducted", closure=0.6),
    # precision: fingertips only, palm off the object
    GraspSpec("palmar_pinch", _pads(_T, _I), "top", "clear", "curl", closure=0.45),
    GraspSpec("inferior_pincer", _pads(_T, _I), "top", "clear", "extend", closure=0.45),
    GraspSpec("tripod", _pads(_T, _I, _M), "top", "clear", "curl", closure=0.45),
    GraspSpec("quadpod", _pads(_T, _I, _M, _R), "top", "clear", "curl", closure=0.45),
    GraspSpec("precision_sphere", _pads(_T, _I, _M, _R, _P), "top", "clear", closure=0.45),
    GraspSpec("parallel_extension", _pads(_T, _I, _M, _R, _P), "top", "clear", "extend",
              thumb="adducted", shape=(1.2, 0.15, 0.1)),
    # in-hand manipulation: the grasp the motion starts from
    GraspSpec("rolling", _pads(_T, _I, side="up"), "top", "clear", "curl", opposition=False,
              closure=0.3),
    GraspSpec("sliding", _pads(_T, _I, _M, side="up"), "top", "clear", "curl",
              opposition=False, closure=0.3),
    GraspSpec("finger_transfer", _pads(_T, _I, _M, _R), "top", "clear", "curl", closure=0.45),
    GraspSpec("rotation", _pads(_T, _I, _M), "top", "clear", "curl", closure=0.45),
)}
# fmt: on

if set(GRASP_SPECS) != set(MANIPULATION_TYPES):  # pragma: no cover - catalogue consistency
    raise RuntimeError("GRASP_SPECS must cover the 21 manipulation types")


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


@dataclass
class Grasp:
    """A solved grasp in the object frame.

    Attributes:
        R_obj_wrist: ``(3, 3)`` wrist orientation in the object frame.
        p_obj_wrist: ``(3,)`` wrist joint (J0) position in the object frame [m].
        q: ``(22,)`` driven finger angles [rad] (``hand.DOF_NAMES``).
        contacts: contact specs of the grasp, with ``distance_m`` (signed, capsule surface to
            object surface), ``achieved`` and the object's outward ``normals`` (object frame)
            at each.
        max_penetration_m: deepest penetration of any capsule into the object [m] (≥ 0).
        min_table_clearance_m: lowest capsule surface height above the table at rest [m].
        ok: required contacts within ±1 mm, penetration ≤ 1.5 mm, contacts opposing.
        reason: why not ``ok``, else ``""``.
        seconds: optimisation time [s].
    """

    object_id: str
    type_name: str
    R_obj_wrist: np.ndarray
    p_obj_wrist: np.ndarray
    q: np.ndarray
    contacts: tuple[ContactSpec, ...]
    distance_m: np.ndarray
    achieved: np.ndarray
    normals: np.ndarray
    samples: np.ndarray
    """Capsule sample (``HandModel`` index) nearest to the object for each contact."""
    points: np.ndarray
    """That sample's position (a point on the capsule axis, object frame) [m]."""
    max_penetration_m: float
    min_table_clearance_m: float
    closure: float
    """Force-closure margin of the contact normals (``checks.closure_margin``; < sin(atan μ)
    holds against any force, 1.0 for a single contact)."""
    grip_ratio: float
    """Least total normal force that lifts the object, in weights (``checks.lift_grip_ratio``,
    μ = 0.5): 2 for normals that balance, more when part of the squeeze is spent on
    contacts that do not oppose, ``inf`` when they cannot lift it."""
    hold_ratio: float
    """The same with the torques balanced too (``lift_grip_ratio`` with the contact points,
    about the object frame's origin): pads off the centre of mass, or a squeeze whose two
    sides are not in line, cost more; ``inf`` when the contacts cannot hold it still."""
    ok: bool
    reason: str
    seconds: float
    cost: float = 0.0
    extra: dict = field(default_factory=dict)

    def schedule_parts(self) -> tuple[ContactSpec, ...]:
        """The contacts the scripts hold: required ones and achieved optional ones."""
        return tuple(c for c, a in zip(self.contacts, self.achieved, strict=True) if a)


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


# -- approach and initial posture ----------------------------------------------------------------


def choose_approach(geom: ObjectGeometry, spec: GraspSpec) -> Approach:
    """Top or side approach: power grasps of objects taller than wide come from the side."""
    if spec.approach != "auto":
        return spec.approach
    hx, hy, hz = geom.aabb_half
    return "side" if hz > 0.8 * max(hx, hy) and hz > 0.035 else "top"


def approach_frame(approach: Approach) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Desired palm normal and finger direction (object frame) and the initial ``R_obj_wrist``.

    Top: palm down, fingers pointing away from the subject (+x). Side: palm facing +x (the
    subject sits at -x), thumb up, fingers to the right (-y) — a right hand reaching forward.
    The template frame has fingers along -x, the palm facing -y and the thumb on +z.
    """
    if approach == "top":
        palm, fingers, thumb = np.array([0, 0, -1.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    else:
        palm, fingers, thumb = np.array([1.0, 0, 0]), np.array([0, -1.0, 0]), np.array([0, 0, 1.0])
    # columns: images of the template axes x = -fingers, y = -palm, z = thumb
    R = np.stack([-fingers, -palm, thumb], axis=1)
    return palm, fingers, R


def natural_posture(spec: GraspSpec, rng: np.random.Generator | None = None) -> np.ndarray:
    """``(22,)`` initial/prior driven angles [rad] for a type (before touching the object)."""
    q = np.zeros(N_DOF)
    fingers_in = {c.finger for c in spec.contacts}
    c = spec.closure
    rest = {"curl": (1.2, 1.3, 0.7), "extend": (0.1, 0.1, 0.05), "relax": (0.5, 0.6, 0.3)}
    for f in ("index", "middle", "ring", "pinky"):
        if f in fingers_in:
            mcp, pip, dip = spec.shape or (0.9 * c + 0.1, 1.1 * c + 0.1, 0.6 * c + 0.05)
        else:
            mcp, pip, dip = rest[spec.posture]
        q[dof_index(f"{f}1_flex")] = mcp
        q[dof_index(f"{f}2_flex")] = pip
        q[dof_index(f"{f}3_flex")] = dip
    spread = {"index": 0.08, "middle": 0.0, "ring": -0.06, "pinky": -0.12}
    for f, a in spread.items():
        q[dof_index(f"{f}1_abd")] = a if spec.posture != "extend" else 0.3 * a
    if spec.thumb == "abducted":
        th = {"flex": 0.6, "abd": -0.4, "twist": -0.3, "2flex": 0.2, "2abd": 0.0, "3flex": 0.3}
    else:
        th = {"flex": 0.2, "abd": -0.5, "twist": 0.0, "2flex": 0.3, "2abd": 0.0, "3flex": 0.3}
    q[dof_index("thumb1_flex")] = th["flex"]
    q[dof_index("thumb1_abd")] = th["abd"]
    q[dof_index("thumb1_twist")] = th["twist"]
    q[dof_index("thumb2_flex")] = th["2flex"]
    q[dof_index("thumb2_abd")] = th["2abd"]
    q[dof_index("thumb3_flex")] = th["3flex"]
    if rng is not None:
        q = q + rng.normal(0.0, math.radians(3.0), N_DOF)
    return np.clip(q, DOF_LOW + LIMIT_MARGIN, DOF_HIGH - LIMIT_MARGIN)


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


def grasp_site(geom: ObjectGeometry, spec: GraspSpec, approach: Approach) -> np.ndarray:
    """Where the palm centre goes (object frame) before optimising, and its weak prior.

    Above the object's centre for top approaches (a little towards the subject, so that the
    fingertips reach the far side), level with it on the subject's side (-x) for side
    approaches; YCB items name their graspable part (the drill's handle, the scissors' loops,
    the bowl's rim).
    """
    half = geom.aabb_half
    named = {p.name: np.asarray(p.pos) for p in geom.primitives}
    if approach == "top":
        lift = 0.002 if spec.palm == "contact" else 0.035
        site = np.array([-0.015, 0.0, half[2] + lift])
        if geom.object_id == "bowl":
            site = np.array([-half[0] + 0.01, 0.0, half[2] + 0.03])
        elif geom.object_id == "scissor":
            loops = [p.pos for p in geom.primitives if p.name.endswith("loop")]
            c = np.mean(loops, axis=0)
            site = np.array([c[0], c[1], half[2] + 0.03])
        return site
    gap = 0.002 if spec.palm == "contact" else 0.03
    z = 0.0
    if geom.object_id == "powerdrill":
        z = float(named["handle"][2])
    # the palm centre at least 45 mm above the table so the little finger clears it
    z = max(z, 0.045 - geom.rest_z)
    # first surface met along +x at that height (the side facing the subject)
    xs = np.arange(-half[0] - 0.01, half[0] + 0.01, 0.001)
    d = geom.signed_distance(np.stack([xs, np.zeros_like(xs), np.full_like(xs, z)], axis=1))
    hit = np.flatnonzero(d <= 0.0)
    x_surf = xs[hit[0]] if hit.size else -half[0]
    return np.array([x_surf - gap, 0.0, z])


# -- the solver ----------------------------------------------------------------------------------


ATTEMPTS = 10
"""Starts tried per grasp: the type's natural start, then deterministic variations of it."""

_ATTEMPT_YAW_DEG = (0.0, 40.0, -40.0, 80.0, 20.0, -20.0, 60.0, -60.0, 100.0, -80.0)
"""Hand turn about the approach direction of each start [deg] (thumb on another side)."""


def solve_grasp(
    object_id: str,
    type_name: str,
    hand: HandModel,
    *,
    seed: int = 0,
    weights: GraspWeights = GraspWeights(),
    max_iter: int = 60,
    attempts: int = ATTEMPTS,
) -> Grasp:
    """Optimise a grasp of ``object_id`` with manipulation type ``type_name`` for ``hand``.

    ``seed`` perturbs the posture prior and the approach direction slightly (posture variation
    across demonstrations); the result is deterministic for a seed. When a start ends in a local
    minimum that misses a contact, up to ``attempts`` starts are tried (the approach tilted, the
    palm shifted, the fingers more or less closed) and the first acceptable grasp — else the one
    with the smallest contact error — is returned.
    """
    if attempts < 1:
        raise ValidationError(f"attempts must be ≥ 1, got {attempts}", field="attempts")
    t0 = time.perf_counter()
    geom = object_geometry(object_id)
    spec = GRASP_SPECS[type_name]
    approach = choose_approach(geom, spec)
    palm_dir, finger_dir, R_nominal = approach_frame(approach)
    site_nominal = grasp_site(geom, spec, approach)
    best = None
    for attempt in range(attempts):
        rng = np.random.default_rng([seed, attempt, 7919])
        amount = 0.0 if (seed == 0 and attempt == 0) else 1.0
        yaw = math.radians(_ATTEMPT_YAW_DEG[attempt % len(_ATTEMPT_YAW_DEG)])
        R_yaw = rodrigues(-palm_dir * yaw)  # turn the hand about its approach direction
        tilt = rodrigues(rng.normal(0.0, math.radians(4.0), 3) * amount)
        R0 = tilt @ R_yaw @ R_nominal
        start_spec = spec
        if attempt:
            start_spec = replace(
                spec, closure=float(np.clip(spec.closure + rng.normal(0, 0.2), 0.1, 0.9))
            )
        q0 = natural_posture(start_spec, rng if amount else None)
        shift = rng.normal(0.0, 0.006, 3) * (attempt > 0)
        site = site_nominal + shift - palm_dir * (palm_dir @ shift)
        p0 = site - R0 @ _palm_centre(hand)
        prob = HandObjectProblem(
            hand, geom, spec, R0=R0, p0=p0, q_prior=q0, palm_dir=palm_dir,
            finger_dir=finger_dir, weights=weights, site=site_nominal,
        )  # fmt: skip
        x, cost = prob.solve(np.r_[np.zeros(6), q0], max_iter=max_iter)
        grasp = _make_grasp(prob, x, cost, object_id, type_name, 0.0)
        grasp.extra["attempt"] = attempt
        if best is None or grasp_badness(grasp) < grasp_badness(best):
            best = grasp
        if grasp.ok:
            break
    if not best.ok:
        log.debug(
            "grasp %s/%s (hand scale %.2f, seed %d) not acceptable after %d starts: %s",
            object_id, type_name, hand.scale, seed, attempts, best.reason,
        )  # fmt: skip
    best.seconds = time.perf_counter() - t0
    best.extra["approach"] = approach
    best.extra["palm_dir"] = palm_dir
    best.extra["finger_dir"] = finger_dir
    return best


def grasp_badness(g: Grasp) -> float:
    """How far a grasp is from acceptable (0 when its contacts are exact; metres of contact
    error or penetration, plus small terms for weak opposition): ranks the starts."""
    req = np.array([c.required for c in g.contacts])
    err = np.abs(g.distance_m[req]).max() if req.any() else 0.0
    bad = max(err, g.max_penetration_m, -min(g.min_table_clearance_m, 0.0))
    if GRASP_SPECS[g.type_name].opposition:
        bad += 0.01 * max(0.0, g.closure - CLOSURE_MAX)
        bad += 1e-4 * min(max(0.0, g.grip_ratio - GRIP_RATIO_MAX), 10.0)
        bad += 1e-5 * min(max(0.0, g.hold_ratio - HOLD_RATIO_MAX), 50.0)
    return float(bad)


def _make_grasp(
    prob: HandObjectProblem, x: np.ndarray, cost: float, object_id: str, type_name: str, secs: float
) -> Grasp:
    e = prob.evaluate(x[None])
    R, p, q = e["R"][0], e["p"][0], e["q"][0]
    cd = e["cd"][0]
    spec = prob.spec
    achieved = np.array(
        [c.required or abs(d) <= OPTIONAL_TOL_M for c, d in zip(prob.contacts, cd, strict=True)]
    )
    pen = float(max(0.0, -e["d"][0].min()))
    z = e["S"][0][:, 2] + prob.geom.rest_z - prob.hand.s_r
    problems = []
    for c, d in zip(prob.contacts, cd, strict=True):
        if c.required and abs(d) > CONTACT_TOL_M:
            problems.append(f"{c.capsule} contact off by {d * 1e3:+.1f} mm")
    if pen > PENETRATION_TOL_M:
        problems.append(f"penetration {pen * 1e3:.1f} mm")
    held = np.array([c.required or a for c, a in zip(prob.contacts, achieved, strict=True)])
    closure = float(closure_margin(e["cn"][:, held], np.ones((1, int(held.sum())), bool))[0])
    grip = hold = math.inf
    if spec.opposition:
        grip = lift_grip_ratio(e["cn"][0, held])
        hold = lift_grip_ratio(e["cn"][0, held], prob.geom.closest_point(e["cp"][0, held]))
    if spec.opposition and closure > CLOSURE_MAX:
        problems.append(f"contacts do not oppose (closure margin {closure:.2f} > {CLOSURE_MAX})")
    elif spec.opposition and grip > GRIP_RATIO_MAX:
        problems.append(f"lifting needs {grip:.1f} weights of squeeze (> {GRIP_RATIO_MAX})")
    elif spec.opposition and hold > HOLD_RATIO_MAX:
        problems.append(f"holding still needs {hold:.1f} weights of squeeze (> {HOLD_RATIO_MAX})")
    if z.min() < 0.0:
        problems.append(f"hand {-z.min() * 1e3:.1f} mm below the table")
    return Grasp(
        object_id=object_id,
        type_name=type_name,
        R_obj_wrist=R,
        p_obj_wrist=p,
        q=q,
        contacts=tuple(prob.contacts),
        distance_m=cd,
        achieved=achieved,
        normals=e["cn"][0],
        samples=e["ci"][0],
        points=e["cp"][0],
        max_penetration_m=pen,
        min_table_clearance_m=float(z.min()),
        closure=closure,
        grip_ratio=grip,
        hold_ratio=hold,
        ok=not problems,
        reason="; ".join(problems),
        seconds=secs,
        cost=cost,
    )


@lru_cache(maxsize=512)
def cached_grasp(object_id: str, type_name: str, scale: float, seed: int) -> Grasp:
    """``solve_grasp`` memoised per (object, type, hand scale, seed)."""
    from dexcanvas_core.demos.hand import hand_model

    return solve_grasp(object_id, type_name, hand_model(scale), seed=seed)


# -- finger-only problems: pre-shape and in-hand re-grasps ---------------------------------------


def _fingers_only(prob: HandObjectProblem) -> HandObjectProblem:
    prob.free[:6] = False
    return prob


def solve_preshape(
    grasp: Grasp,
    hand: HandModel,
    *,
    gap: float = 0.015,
    approach_m: float | None = 0.08,
    q_init: np.ndarray | None = None,
    dense_sweep: bool = False,
) -> np.ndarray:
    """``(22,)`` finger angles with the wrist at the grasp pose and each holding pad backed
    ``gap`` [m] off its grasp contact along the surface normal (the hand opened, or partly
    closed on the way to the grasp).

    Fingers that hold nothing keep their grasp posture. Every finger stays clear of the object
    (5 mm, or half the gap) and above the table; with ``approach_m``, also all along the
    approach line (that far back along the palm normal, checked at 3 points, or 12 with
    ``dense_sweep``) so the open hand can move in.
    """
    geom = object_geometry(grasp.object_id)
    spec = GRASP_SPECS[grasp.type_name]
    palm_dir = grasp.extra["palm_dir"]
    held = [k for k, c in enumerate(grasp.contacts) if grasp.achieved[k] and c.capsule != "palm"]
    idx = grasp.samples[held]
    pts = grasp.points[held] + gap * grasp.normals[held]
    sweep = None
    if approach_m:
        sweep = np.array([-palm_dir * o for o in (0.012, 0.035, approach_m)])
        if dense_sweep:
            sweep = np.array([-palm_dir * o for o in np.linspace(0.004, approach_m, 12)])
    spec_pre = replace(spec, contacts=(), opposition=False)
    prob = HandObjectProblem(
        hand, geom, spec_pre, R0=grasp.R_obj_wrist, p0=grasp.p_obj_wrist, q_prior=grasp.q,
        palm_dir=palm_dir, finger_dir=grasp.extra["finger_dir"], sweep=sweep,
        clear={f: min(0.005, 0.5 * gap) for f in FINGERS}, targets=(idx, pts),
        weights=replace(GraspWeights(), posture=0.01, contact=2.0),
    )  # fmt: skip
    start = grasp.q if q_init is None else q_init
    x, _ = _fingers_only(prob).solve(np.r_[np.zeros(6), start], max_iter=15)
    return x[6:]


def posture_violation(
    grasp: Grasp, hand: HandModel, Q: np.ndarray, offset: np.ndarray | None = None
) -> np.ndarray:
    """``(K,)`` worst penetration into the object or below the table [m] (≥ 0) of finger
    postures ``Q (K, 22)`` with the wrist at the grasp pose (object resting), shifted by
    ``offset`` (object frame) if given."""
    geom = object_geometry(grasp.object_id)
    K = Q.shape[0]
    p = grasp.p_obj_wrist if offset is None else grasp.p_obj_wrist + offset
    kp, _ = hand.forward(Q, np.repeat(grasp.R_obj_wrist[None], K, 0), np.repeat(p[None], K, 0))
    S = hand.samples(kp)
    pen = -(geom.signed_distance(S) - hand.s_r).min(axis=1)
    below = -(S[..., 2] + geom.rest_z - hand.s_r).min(axis=1)
    return np.maximum(0.0, np.maximum(pen, below))


def closing_path(grasp: Grasp, hand: HandModel, tol: float = 1e-3) -> list[np.ndarray]:
    """Key finger postures from the open pre-shape (first) to the grasp (last).

    Keys: the pads backed 15 mm (up to 35 mm if the open hand must clear the object on its
    approach) and 6 mm off their contacts along the normals, then touching. Where a straight
    interpolation between two neighbouring keys would cut more than ``tol`` [m] into the
    object or the table, a key at the intermediate gap is inserted (twice at most per
    segment)."""
    gaps = [0.015, 0.006, 0.0]
    keys = [solve_preshape(grasp, hand, gap=0.015)]
    palm_dir = grasp.extra["palm_dir"]
    along = -palm_dir[None, :] * np.linspace(0.0, 0.08, 17)[:, None]

    def swept(q: np.ndarray) -> float:
        return max(posture_violation(grasp, hand, q[None], o)[0] for o in along)

    for wider in (0.015, 0.025, 0.035):
        if swept(keys[0]) <= tol:
            break
        # the approach sweeps the open hand through the object: check densely, open wider
        keys[0] = solve_preshape(grasp, hand, gap=wider, q_init=keys[0], dense_sweep=True)
    keys.append(solve_preshape(grasp, hand, gap=0.006, approach_m=None, q_init=grasp.q))
    keys.append(grasp.q.copy())
    s = np.linspace(0.0, 1.0, 7)[1:-1, None]
    for _ in range(2):
        k = 0
        inserted = False
        while k < len(keys) - 1:
            Q = keys[k] + s * (keys[k + 1] - keys[k])
            if posture_violation(grasp, hand, Q).max() > tol and gaps[k] - gaps[k + 1] > 0.002:
                gap = 0.5 * (gaps[k] + gaps[k + 1])
                mid = solve_preshape(grasp, hand, gap=gap, approach_m=None,
                                     q_init=0.5 * (keys[k] + keys[k + 1]))  # fmt: skip
                keys.insert(k + 1, mid)
                gaps.insert(k + 1, gap)
                inserted = True
                k += 2
            else:
                k += 1
        if not inserted:
            break
    return keys


def solve_fingers(
    hand: HandModel,
    object_id: str,
    type_name: str,
    R_obj_wrist: np.ndarray,
    p_obj_wrist: np.ndarray,
    q_start: np.ndarray,
    contacts: tuple[ContactSpec, ...],
    *,
    clear: dict[str, float] | None = None,
    table: bool = False,
    max_iter: int = 40,
) -> tuple[np.ndarray, float, float]:
    """Re-solve the fingers with the wrist fixed (in-hand motions): the given contacts touch
    the object, fingers in ``clear`` keep that gap; returns ``(q, worst contact error or
    penetration beyond 0.5 mm [m], closure margin)``."""
    geom = object_geometry(object_id)
    spec = replace(GRASP_SPECS[type_name], contacts=contacts)
    prob = HandObjectProblem(
        hand, geom, spec, R0=R_obj_wrist, p0=p_obj_wrist, q_prior=q_start,
        palm_dir=-R_obj_wrist[:, 1], finger_dir=-R_obj_wrist[:, 0], table=table, clear=clear,
        weights=replace(GraspWeights(), posture=0.01),
    )  # fmt: skip
    x, _ = _fingers_only(prob).solve(np.r_[np.zeros(6), q_start], max_iter=max_iter)
    return (x[6:], *_in_hand_measures(prob, x))


def _in_hand_measures(prob: HandObjectProblem, x: np.ndarray) -> tuple[float, float]:
    e = prob.evaluate(x[None])
    err = float(np.abs(e["cd"][0]).max()) if e["cd"].size else 0.0
    err = max(err, float(-e["d"][0].min()) - 5e-4)  # penetration beyond half a millimetre
    closure = float(closure_margin(e["cn"], np.ones(e["cn"].shape[:2], bool))[0])
    return err, closure


def in_hand_error(
    hand: HandModel,
    object_id: str,
    type_name: str,
    R_obj_wrist: np.ndarray,
    p_obj_wrist: np.ndarray,
    q: np.ndarray,
    contacts: tuple[ContactSpec, ...],
) -> tuple[float, float]:
    """``(worst contact error or penetration [m], closure margin)`` of a posture, unsolved."""
    geom = object_geometry(object_id)
    spec = replace(GRASP_SPECS[type_name], contacts=contacts)
    prob = HandObjectProblem(
        hand, geom, spec, R0=R_obj_wrist, p0=p_obj_wrist, q_prior=q,
        palm_dir=-R_obj_wrist[:, 1], finger_dir=-R_obj_wrist[:, 0], table=False,
    )  # fmt: skip
    return _in_hand_measures(prob, np.r_[np.zeros(6), q])
