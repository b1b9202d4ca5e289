"""Scripted motions: a demonstration as a timeline of minimum-jerk phases at 120 Hz.

Every phase moves the wrist, the fingers and the object from the current state to a target with
the minimum-jerk profile ``s(τ) = 10τ³ − 15τ⁴ + 6τ⁵`` (Flash & Hogan 1985, the usual model of
smooth point-to-point human arm movements; Smeets & Brenner 1999 model grasping digits the same
way). Phase durations are human-like (a 25–35 cm reach in about a second gives a peak wrist
speed of ~0.5 m/s) and jittered by the seed.

Scripts (all start and end with the hand still, away from the object):

* **grasps** — reach while pre-shaping the hand, approach along the palm normal, close the
  fingers onto the object, lift it 10 cm, carry it 6–15 cm across the table while turning it up
  to ±20° about the vertical, put it down, open the hand, retreat;
* **rolling** — fingers on top of a sphere or lying cylinder roll it on the table: the object's
  centre follows the hand and it turns by (displacement / radius) about the horizontal axis
  perpendicular to the motion (rolling without slip on the table);
* **sliding** — fingers press on the object from above and slide it along the table, turning it
  a little about the vertical;
* **rotation** — a lifted object is turned and back about an axis between the fingers (a
  cylinder's own axis, a sphere's axis through the thumb contact and its centre, otherwise the
  thumb's contact normal through the thumb's contact point), the wrist following half of the
  turn, the finger postures re-solved along it;
* **finger transfer** — a lifted object held by thumb, index, middle and ring: the index lets
  go, thumb, middle and ring move the object 6–10 mm towards the little-finger side and turn it
  10° in the hand (finger angles re-solved at key frames), the index takes hold again.

The object moves only rigidly with the hand while opposing contacts hold it, or on the table
under the fingers; everything else is left to the plausibility checks to confirm.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dexcanvas_core.demos.timeline import (
    State,
    Timeline,
    interp_keys,
    keyed_duration,
    min_jerk,
    relaxed_posture,
)
from dexcanvas_core.mano.hand_model import FINGER_DOF_INDEX, HandModel, rodrigues
from dexcanvas_core.objects.geometry import ObjectGeometry


@dataclass
class ScriptContext:
    """What a script needs: the hand, the object, the solved grasp and random draws."""

    hand: HandModel
    geom: ObjectGeometry
    R_obj_wrist: np.ndarray
    p_obj_wrist: np.ndarray
    q_grasp: np.ndarray
    closing: list[np.ndarray]
    """Finger key postures from the open pre-shape (first) to the grasp (last)."""
    palm_dir_obj: np.ndarray
    parts: tuple[str, ...]
    """Contact parts the script holds on the object (capsule names / ``"palm"``)."""
    R_o0: np.ndarray
    p_o0: np.ndarray
    rng: np.random.Generator
    approach_m: float = 0.08
    approach_wrist: np.ndarray | None = None
    """Approach direction in the wrist frame (set by ``begin``; the retreat reverses it)."""
    reopen: Callable[[State], list[np.ndarray]] | None = None
    """Key postures opening the hand from the current in-hand state (default: the closing
    path reversed); scripts that change the grasp in the hand set it."""

    @property
    def q_pre(self) -> np.ndarray:
        return self.closing[0]

    def dur(self, seconds: float) -> float:
        """A phase duration jittered by ±12 %."""
        return seconds * float(self.rng.uniform(0.88, 1.12))


def _grasp_pose_world(ctx: ScriptContext) -> tuple[np.ndarray, np.ndarray]:
    return ctx.R_o0 @ ctx.R_obj_wrist, ctx.R_o0 @ ctx.p_obj_wrist + ctx.p_o0


def begin(ctx: ScriptContext) -> Timeline:
    """Start still, away from the object, then reach, pre-shape, approach and close."""
    R_wg, p_wg = _grasp_pose_world(ctx)
    palm_world = ctx.R_o0 @ ctx.palm_dir_obj
    ctx.approach_wrist = R_wg.T @ palm_world
    p_pre = p_wg - palm_world * ctx.approach_m
    offset = np.array([-0.20, -0.12, 0.10]) * ctx.rng.uniform(0.85, 1.15, 3)
    p_start = p_pre + offset
    p_start[2] = max(p_start[2], p_pre[2] + 0.05)
    R_start = rodrigues(np.array([0.0, 0.0, -0.3]) + ctx.rng.normal(0.0, 0.05, 3)) @ R_wg
    tl = Timeline([State(R_start, p_start, relaxed_posture(), ctx.R_o0.copy(), ctx.p_o0.copy())])
    tl.hold("still", ctx.dur(0.25))
    tl.move_hand("reach", ctx.dur(1.0), R_w=R_wg, p_w=p_pre, q=ctx.q_pre)
    tl.move_hand("approach", ctx.dur(0.5), p_w=p_wg)
    tl.move_fingers("close", ctx.dur(0.4), ctx.closing[1:])
    tl.contact_on(ctx.parts)
    tl.hold("settle", ctx.dur(0.15))
    return tl


def finish(ctx: ScriptContext, tl: Timeline) -> Timeline:
    """Open the hand (back to the pre-shape), retreat along the palm normal, end still."""
    tl.hold("settle", ctx.dur(0.1))
    tl.contact_off_all()
    keys = ctx.reopen(tl.now) if ctx.reopen else ctx.closing[-2::-1]
    tl.move_fingers("release", ctx.dur(0.4), keys)
    # back out the way the hand came in (the approach direction, carried by the wrist)
    away = -(tl.now.R_w @ ctx.approach_wrist)
    back = tl.now.p_w + away * ctx.approach_m
    tl.move_hand("retreat", ctx.dur(0.45), p_w=back)
    up = back + 0.04 * away + np.array([-0.05, -0.03, 0.08])
    tl.move_hand("withdraw", ctx.dur(0.5), p_w=up, q=relaxed_posture())
    tl.hold("still", ctx.dur(0.2))
    return tl


def _upright_on_table(geom: ObjectGeometry, R_o: np.ndarray, p_o: np.ndarray) -> np.ndarray:
    """Object position lowered (or raised) so that it rests on the table with rotation ``R_o``."""
    low = float(geom.lowest_z(R_o, p_o))
    return p_o - np.array([0.0, 0.0, low])


def pick_and_place(ctx: ScriptContext) -> Timeline:
    """Grasp, lift 10 cm, carry across the table with a turn, put down, release."""
    tl = begin(ctx)
    rng = ctx.rng
    lift = 0.10 * rng.uniform(0.9, 1.1)
    a = tl.now
    tl.move_object("lift", ctx.dur(0.6), a.R_o, a.p_o + np.array([0.0, 0.0, lift]))
    heading = rng.uniform(-np.pi, np.pi)
    dist = rng.uniform(0.06, 0.15)
    d = dist * np.array([math.cos(heading) * 0.6, math.sin(heading), 0.0])
    yaw = rng.uniform(-0.35, 0.35)
    a = tl.now
    R_end = rodrigues(np.array([0.0, 0.0, yaw])) @ a.R_o
    tl.notes["lift_mm"] = round(lift * 1e3, 1)
    tl.notes["transport_mm"] = round(float(np.linalg.norm(d)) * 1e3, 1)
    tl.move_object("transport", ctx.dur(0.9), R_end, a.p_o + d)
    a = tl.now
    tl.move_object("place", ctx.dur(0.6), a.R_o, _upright_on_table(ctx.geom, a.R_o, a.p_o))
    return finish(ctx, tl)


def rolling(ctx: ScriptContext, axis_obj: np.ndarray | None, radius: float) -> Timeline:
    """Roll a sphere (``axis_obj`` None) or a lying cylinder (axis in the object frame) on the
    table under the fingers, forward then part of the way back."""
    tl = begin(ctx)
    rng = ctx.rng
    if axis_obj is None:
        heading = rng.uniform(-0.6, 0.6) + (0.0 if rng.uniform() < 0.5 else np.pi)
        u = np.array([math.cos(heading), math.sin(heading), 0.0])
    else:
        a = ctx.R_o0 @ axis_obj
        u = np.cross([0.0, 0.0, 1.0], a)
        u /= np.linalg.norm(u)
        u *= 1.0 if rng.uniform() < 0.5 else -1.0
    dist = rng.uniform(0.05, 0.08)
    tl.notes["roll_mm"] = round(dist * 1e3, 1)
    tl.notes["roll_deg"] = round(math.degrees(dist / radius), 1)
    tl.roll("roll", ctx.dur(1.1), u * dist, radius)
    tl.hold("pause", ctx.dur(0.15))
    tl.roll("roll_back", ctx.dur(0.8), -u * dist * rng.uniform(0.3, 0.6), radius)
    return finish(ctx, tl)


def sliding(ctx: ScriptContext) -> Timeline:
    """Press on the object and slide it along the table, turning it a little."""
    tl = begin(ctx)
    rng = ctx.rng
    heading = rng.uniform(-np.pi, np.pi)
    d = rng.uniform(0.07, 0.12) * np.array([math.cos(heading) * 0.6, math.sin(heading), 0.0])
    a = tl.now
    R_end = rodrigues(np.array([0.0, 0.0, rng.uniform(-0.3, 0.3)])) @ a.R_o
    tl.notes["slide_mm"] = round(float(np.linalg.norm(d)) * 1e3, 1)
    tl.move_object("slide", ctx.dur(1.3), R_end, a.p_o + d)
    return finish(ctx, tl)


FingerSolver = Callable[
    [np.ndarray, np.ndarray, np.ndarray, tuple[str, ...], dict], tuple[np.ndarray, float]
]
"""``(R_obj_wrist, p_obj_wrist, q_start, holding parts, clear) → (q, error [m])``: fingers
re-solved with the wrist fixed relative to the object; the error is the worst contact distance
or penetration (or large when force closure is lost)."""

FingerCheck = Callable[[np.ndarray, np.ndarray, np.ndarray, tuple[str, ...]], float]
"""``(R_obj_wrist, p_obj_wrist, q, holding parts) → error [m]`` of a posture, not re-solved."""

KEY_TOL_M = 1.0e-3
"""Largest error [m] accepted at a re-solved in-hand key posture (the checks allow 1.5 mm)."""
MID_TOL_M = 1.2e-3
"""Largest error [m] accepted halfway between two key postures before another key is added."""
MAX_KEY_STEP = 0.35
"""Largest change of any finger angle [rad] between neighbouring key postures; more means the
re-solved postures jumped to another solution (the motion is then made smaller)."""


def _in_wrist(st: State) -> tuple[np.ndarray, np.ndarray]:
    """The wrist pose in the object frame ``(R_obj_wrist, p_obj_wrist)``."""
    return st.R_o.T @ st.R_w, st.R_o.T @ (st.p_w - st.p_o)


def keyed_postures(
    state_at: Callable[[float], State],
    q0: np.ndarray,
    solve: FingerSolver,
    check: FingerCheck,
    holding: tuple[str, ...],
    clear: dict,
    keys: int = 4,
    depth: int = 3,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Finger postures along an in-hand motion: ``state_at(s)`` gives the wrist and object at
    progress ``s ∈ [0, 1]``; postures are solved at ``keys`` evenly spaced points and, where
    the straight interpolation halfway between two of them misses by more than ``MID_TOL_M``,
    at the midpoint too (``depth`` rounds). Returns ``(grid (K,), postures (K, 22))`` starting
    with ``(0, q0)``, or ``None`` when a key cannot keep its contacts or neighbouring keys
    jump by more than ``MAX_KEY_STEP``."""
    pts = [(0.0, q0)]
    q = q0
    for k in range(1, keys + 1):
        s = k / keys
        q, err = solve(*_in_wrist(state_at(s)), q, holding, clear)
        if err > KEY_TOL_M:
            return None
        pts.append((s, q))
    for _ in range(depth):
        if max(np.abs(b[1] - a[1]).max() for a, b in itertools.pairwise(pts)) > MAX_KEY_STEP:
            return None  # the solutions jump between postures: no smooth motion through them
        refined, added = [pts[0]], False
        for (s0, q_a), (s1, q_b) in itertools.pairwise(pts):
            sm, qm = 0.5 * (s0 + s1), 0.5 * (q_a + q_b)
            if check(*_in_wrist(state_at(sm)), qm, holding) > MID_TOL_M:
                qm, err = solve(*_in_wrist(state_at(sm)), qm, holding, clear)
                if err > KEY_TOL_M:
                    return None
                refined.append((sm, qm))
                added = True
            refined.append((s1, q_b))
        pts = refined
        if not added:
            break
    if max(np.abs(b[1] - a[1]).max() for a, b in itertools.pairwise(pts)) > MAX_KEY_STEP:
        return None
    return np.array([p[0] for p in pts]), np.stack([p[1] for p in pts])


def rotation(
    ctx: ScriptContext,
    axis_obj: np.ndarray,
    solve: FingerSolver | None = None,
    check: FingerCheck | None = None,
    pivot_obj: np.ndarray | None = None,
) -> Timeline:
    """Lift, turn the object about ``axis_obj`` through ``pivot_obj`` (object frame; default
    its centre) and back, the wrist following half the angle; put it back down. With
    ``solve`` and ``check``, the fingers are re-solved along the turn to stay on the turning
    surfaces; if they cannot, the turn is made smaller (down to about a fifth)."""
    tl = begin(ctx)
    rng = ctx.rng
    a = tl.now
    tl.move_object("lift", ctx.dur(0.5), a.R_o, a.p_o + np.array([0.0, 0.0, 0.07]))
    a = tl.now
    axis = a.R_o @ axis_obj
    axis /= np.linalg.norm(axis)
    c = a.p_o if pivot_obj is None else a.R_o @ pivot_obj + a.p_o
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    angle = math.radians(rng.uniform(30.0, 45.0)) * sign

    def turned(s: float, angle: float) -> State:
        Rw = rodrigues(axis * 0.5 * angle * s)
        Ro = rodrigues(axis * angle * s)
        return State(Rw @ a.R_w, Rw @ (a.p_w - c) + c, a.q, Ro @ a.R_o, Ro @ (a.p_o - c) + c)

    plan = None
    if solve is not None and check is not None:
        for _ in range(3):
            plan = keyed_postures(
                lambda s, angle=angle: turned(s, angle), a.q, solve, check, ctx.parts, {}
            )
            if plan is not None:
                break
            angle *= 0.6
    grid, keys = plan if plan is not None else (np.array([0.0, 1.0]), np.stack([a.q, a.q]))
    tl.notes["rotation_deg"] = round(math.degrees(abs(angle)), 1)
    tl.notes["fingers_resolved"] = float(plan is not None)
    tl.turn("rotate", ctx.dur(0.9), axis, angle, 0.5 * angle, grid, keys, pivot=c)
    tl.hold("pause", ctx.dur(0.15))
    tl.turn(
        "rotate_back", ctx.dur(0.9), axis, -angle, -0.5 * angle, 1.0 - grid[::-1], keys[::-1],
        pivot=c,
    )  # fmt: skip
    a = tl.now
    tl.move_object("place", ctx.dur(0.5), a.R_o, _upright_on_table(ctx.geom, a.R_o, a.p_o))
    return finish(ctx, tl)


def finger_transfer(ctx: ScriptContext, solve: FingerSolver, check: FingerCheck) -> Timeline:
    """Lift; the index lets go; thumb, middle and ring shift the object towards the little
    finger and turn it about the vertical; the index takes hold again; put the object down.

    The finger postures are re-solved along the shift; if they cannot keep the contacts, the
    shift is made smaller (down to a plain let-go and re-grasp)."""
    tl = begin(ctx)
    rng = ctx.rng
    a = tl.now
    tl.move_object("lift", ctx.dur(0.5), a.R_o, a.p_o + np.array([0.0, 0.0, 0.07]))
    holding = tuple(p for p in ctx.parts if not p.startswith("index"))
    released = tuple(p for p in ctx.parts if p.startswith("index"))
    a = tl.now
    index_dofs = list(FINGER_DOF_INDEX["index"])

    def with_index(q_base: np.ndarray, q_index: np.ndarray) -> np.ndarray:
        # fingers are separate chains: only the index moves, the others keep their hold
        out = q_base.copy()
        out[index_dofs] = q_index[index_dofs]
        return out

    q1 = with_index(a.q, solve(*_in_wrist(a), a.q, holding, {"index": 0.01})[0])
    ulnar = a.R_w @ np.array([0.0, 0.0, -1.0])
    ulnar[2] = 0.0
    ulnar /= max(np.linalg.norm(ulnar), 1e-9)
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    dist = rng.uniform(0.006, 0.010)

    def shifted(s: float, amount: float) -> State:
        w = np.array([0.0, 0.0, math.radians(10.0) * sign * amount])
        return State(a.R_w, a.p_w, q1, rodrigues(w * s) @ a.R_o, a.p_o + s * amount * dist * ulnar)

    plan, amount = None, 1.0
    for _ in range(4):
        keyed = keyed_postures(
            lambda s, amount=amount: shifted(s, amount), q1, solve, check, holding,
            {"index": 0.01},
        )  # fmt: skip
        if keyed is not None:
            end = _in_wrist(shifted(1.0, amount))
            q3 = with_index(keyed[1][-1], solve(*end, keyed[1][-1], ctx.parts, {})[0])
            if check(*end, q3, ctx.parts) <= KEY_TOL_M:
                plan = (amount, *keyed, q3)
                break
        amount *= 0.5
    if plan is None:  # hold still in the hand: let go with the index and take hold again
        q3 = with_index(q1, solve(*_in_wrist(a), q1, ctx.parts, {})[0])
        plan = (0.0, np.array([0.0, 1.0]), np.stack([q1, q1]), q3)
    amount, grid, keys, q3 = plan
    tl.notes["transfer_shift_mm"] = round(amount * dist * 1e3, 1)
    tl.notes["transfer_turn_deg"] = round(10.0 * amount, 1)
    tl.contact_off(released)
    tl.move_fingers("let_go", ctx.dur(0.35), [q1])
    # the wrist stays still; the object moves in the hand, the fingers through the key postures
    start = tl.frame
    n = max(1, round(keyed_duration(ctx.dur(0.9), grid, keys) * tl.fps))
    for i in range(1, n + 1):
        s = float(min_jerk(i / n))
        st = shifted(s, amount)
        st.q = interp_keys(s, grid, keys)
        tl.states.append(st)
    tl.phases.append(("shift", start, tl.frame))
    if amount > 0.0:
        tl.moves.append([start, tl.frame])
    tl.move_fingers("take_hold", ctx.dur(0.35), [q3])
    tl.contact_on(released)
    tl.hold("settle", ctx.dur(0.1))
    a = tl.now
    tl.move_object("place", ctx.dur(0.5), a.R_o, _upright_on_table(ctx.geom, a.R_o, a.p_o))
    return finish(ctx, tl)
