"""Finger-only problems on a solved grasp: the pre-shape before contact, the closing path onto
the object, and the in-hand re-grasps (finger transfer, rotation) with the wrist held fixed.

Each is the grasp's :class:`~dexcanvas_core.demos.grasp.HandObjectProblem` with the wrist's
six degrees of freedom frozen.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from dexcanvas_core.demos.checks import closure_margin
from dexcanvas_core.demos.grasp import Grasp
from dexcanvas_core.demos.grasp_problem import GraspWeights, HandObjectProblem
from dexcanvas_core.demos.grasp_specs import GRASP_SPECS, ContactSpec
from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.mano.hand_model import HandModel
from dexcanvas_core.objects.geometry import object_geometry


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
