"""Grasp synthesis: a small optimisation on the hand skeleton, per manipulation type.

For one (object, manipulation type, operator) the optimiser finds the wrist pose relative to the
object and the 22 driven finger angles (:mod:`dexcanvas_core.mano.hand_model`) such that the
type's **contact parts** touch the object's surface and the hand does not penetrate the object or
the table. It is a bounded nonlinear least-squares problem (Levenberg–Marquardt,
:mod:`.optimize`; joint limits as bounds with a 2° margin; Jacobian by batched forward differences).

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

import numpy as np

from dexcanvas_core.demos.checks import closure_margin, lift_grip_ratio
from dexcanvas_core.demos.grasp_problem import (
    CLOSURE_MAX,
    CONTACT_TOL_M,
    DEFAULT_WEIGHTS,
    GRIP_RATIO_MAX,
    HOLD_RATIO_MAX,
    LIMIT_MARGIN,
    OPTIONAL_TOL_M,
    PENETRATION_TOL_M,
    GraspWeights,
    HandObjectProblem,
    _palm_centre,
)
from dexcanvas_core.demos.grasp_specs import GRASP_SPECS, Approach, ContactSpec, GraspSpec
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.mano.hand_model import (
    DOF_HIGH,
    DOF_LOW,
    N_DOF,
    HandModel,
    dof_index,
    hand_model,
    rodrigues,
)
from dexcanvas_core.objects.geometry import ObjectGeometry, object_geometry

log = logging.getLogger(__name__)


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
    weights: GraspWeights = DEFAULT_WEIGHTS,
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
    return solve_grasp(object_id, type_name, hand_model(scale), seed=seed)
