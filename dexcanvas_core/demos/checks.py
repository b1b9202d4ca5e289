"""Physical plausibility checks of a demonstration, computed from the stored trajectory.

The checks read what a dataset row holds — ``mano_hand_pose``, ``mano_joint_pos`` and the object
track — plus the object's geometry and the script's contact schedule, so a trajectory edited
after generation (or one from elsewhere, given a schedule) is judged on its own data:

* **joint limits** — every finger joint's anatomical angles inside ``mano.limits`` [rad];
* **contact** — at every frame where the script says a part holds the object, the distance
  from that part's pad (its capsule surface in the pad zone) to the object surface is within
  ±1.5 mm;
* **penetration** — no hand capsule deeper than 2 mm in the object, at any frame;
* **hand–table** — no hand capsule more than 2 mm below the table top where it is over the
  table (the trajectory's, else the default; beyond its edges nothing is there);
* **support** — the object never moves (or hangs in the air) unless held by opposing contacts
  or resting on the table (lowest point within 1.5 mm of it) and touched by the hand; it never
  sinks into the table. *Opposing contacts*: the hand parts within 2 mm of the surface push
  along their friction cones (μ = 0.8) and together can resist a force in any direction, i.e.
  no direction ``u`` has ``u·n ≥ sin(atan μ)`` for every contact's outward normal ``n`` (force
  closure without torques; two contacts need normals ≥ 103° apart);
* **speed** — peak wrist speed ≤ 1.5 m/s and peak finger-joint speed ≤ 10 rad/s: generous
  bounds on human movement (reach-to-grasp peak wrist speeds are typically 0.5–1.2 m/s, finger
  joints in grasping move at a few rad/s; these limits catch teleports and glitches, not fast
  humans).

The hand's capsules are rebuilt from the keypoints (``hand.CAPSULES``), with radii scaled by the
hand size measured from the keypoints' bone lengths.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.mano.hand_model import CAPSULE_INDEX, CAPSULES, hand_model
from dexcanvas_core.mano.limits import anatomical_angles, limit_violation
from dexcanvas_core.mano.skeleton import HandSkeleton, measure_bone_lengths
from dexcanvas_core.objects.geometry import ObjectGeometry, object_geometry
from dexcanvas_core.rotations import aa_to_matrix
from dexcanvas_core.table import Table, table_of
from dexcanvas_core.trajectory import Trajectory


@dataclass(frozen=True)
class CheckLimits:
    """Thresholds of the plausibility checks."""

    joint_limit_rad: float = 1e-3
    """Largest allowed anatomical-limit violation [rad] (storage rounding only)."""
    contact_mm: float = 1.5
    """Pad-to-surface distance tolerance at scripted contact frames [mm]."""
    penetration_mm: float = 2.0
    """Deepest allowed hand-object penetration [mm]."""
    table_mm: float = 2.0
    """Deepest allowed hand-table penetration [mm]."""
    touch_mm: float = 2.0
    """A part within this distance of the surface touches the object (support check) [mm]."""
    friction: float = 0.8
    """Skin–object friction coefficient of the force-closure test (dry fingertip skin on
    plastics and metals measures about 0.5–1.2: Derler & Gerhardt 2012, "Tribology of skin",
    Tribology Letters 45)."""
    table_rest_mm: float = 1.5
    """The object rests on the table when its lowest point is within this height [mm]."""
    still_m: float = 1e-4
    """Object translation per frame below which it does not move [m]."""
    still_rad: float = 1e-3
    """Object rotation per frame below which it does not move [rad]."""
    wrist_speed_m_s: float = 1.5
    joint_speed_rad_s: float = 10.0


@dataclass(frozen=True)
class ContactInterval:
    """The script holds ``capsule`` (a ``hand.CAPSULES`` name or ``"palm"``) on the object from
    ``start`` to ``end`` (frames, inclusive); the pad is the capsule's ``zone`` (fractions)."""

    capsule: str
    start: int
    end: int
    zone: tuple[float, float] = (0.3, 1.0)

    @property
    def part(self) -> str:
        """DexCanvas contact part name (``index_dip``, ``thumb_ip``, ``palm``)."""
        return "palm" if self.capsule == "palm" else CAPSULES[CAPSULE_INDEX[self.capsule]].part


@dataclass
class CheckResult:
    """One check: pass/fail, the measured value and the limit it was held to."""

    name: str
    passed: bool
    value: float | list[float]
    limit: float | list[float]
    unit: str
    detail: str = ""


@dataclass
class PlausibilityReport:
    """Per-check results of one demonstration (see the module docstring)."""

    checks: dict[str, CheckResult] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks.values())

    @property
    def failed(self) -> list[str]:
        return [n for n, c in self.checks.items() if not c.passed]

    def _v(self, name: str):
        return self.checks[name].value

    @property
    def max_joint_limit_violation_rad(self) -> float:
        return float(self._v("joint_limits"))

    @property
    def contact_error_range_mm(self) -> tuple[float, float]:
        lo, hi = self._v("contact")
        return float(lo), float(hi)

    @property
    def max_penetration_mm(self) -> float:
        return float(self._v("penetration"))

    @property
    def unsupported_motion_frames(self) -> int:
        return int(self._v("support"))

    @property
    def peak_wrist_speed_m_s(self) -> float:
        return float(self._v("wrist_speed"))

    @property
    def peak_joint_speed_rad_s(self) -> float:
        return float(self._v("joint_speed"))

    def summary(self) -> str:
        """One line: ``passed`` or the failed checks with their values."""
        if self.passed:
            return "passed"
        return "; ".join(f"{n}: {self.checks[n].detail}" for n in self.failed)

    def to_dict(self) -> dict:
        return {"passed": self.passed, "checks": {n: asdict(c) for n, c in self.checks.items()}}


def _hand_scale(joint_pos: np.ndarray) -> float:
    """Hand size relative to the default skeleton, from the keypoints' bone lengths."""
    ref = HandSkeleton.default("right").bone_lengths()
    measured = measure_bone_lengths(joint_pos[:: max(1, len(joint_pos) // 20)])
    return float(np.median(measured / ref))


def _object_frames(traj: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    R = aa_to_matrix(traj.object.rot_aa.astype(np.float64))
    return R, traj.object.pos.astype(np.float64)


def check_trajectory(
    traj: Trajectory,
    schedule: list[ContactInterval] | tuple[ContactInterval, ...] = (),
    *,
    geometry: ObjectGeometry | None = None,
    limits: CheckLimits = CheckLimits(),
) -> PlausibilityReport:
    """Run every plausibility check on a one-hand, one-object trajectory.

    Args:
        traj: the demonstration (``mano_joint_pos`` required).
        schedule: the frames where the script holds each part on the object.
        geometry: the object's geometry; default ``object_geometry(traj.scene)``.
        limits: thresholds.
    """
    h = traj.hand
    if h.joint_pos is None:
        raise ValidationError("check_trajectory needs mano_joint_pos", field="mano_joint_pos")
    geom = geometry if geometry is not None else object_geometry(traj.scene or traj.object.name)
    T = traj.num_frames
    fps = float(traj.fps)
    kp = h.joint_pos.astype(np.float64)  # (T, 21, 3) world
    hm = hand_model(round(_hand_scale(kp), 4))
    S = hm.samples(kp)  # (T, Ns, 3) world
    R_o, p_o = _object_frames(traj)
    S_obj = (S - p_o[:, None, :]) @ R_o  # rows: R^T (S - p)
    # Samples far from the object (beyond its bounding sphere + 2 cm) get the bounding
    # sphere's distance, a lower bound that is enough for every check; the rest exact values.
    bound = float(np.linalg.norm(geom.aabb_half))
    radial = np.linalg.norm(S_obj, axis=-1) - bound
    near = radial < 0.02
    d = radial.copy()
    n_obj = np.zeros_like(S_obj)
    n_obj[..., 2] = 1.0
    if near.any():
        d[near], n_obj[near] = geom.sdf_and_normal(S_obj[near])
    d = d - hm.s_r  # capsule surface distance [m]
    n_world = n_obj @ np.transpose(R_o, (0, 2, 1))  # rows: R n
    report = PlausibilityReport()

    # joint limits
    viol = limit_violation(h.hand_pose[:, 3:].astype(np.float64))
    worst = float(viol.max()) if viol.size else 0.0
    report.checks["joint_limits"] = CheckResult(
        "joint_limits", worst <= limits.joint_limit_rad, worst, limits.joint_limit_rad, "rad",
        f"max anatomical-limit violation {math.degrees(worst):.2f}°",
    )  # fmt: skip

    # contact distances at scripted contact frames
    lo, hi = (math.inf, ""), (-math.inf, "")
    for c in schedule:
        idx = _zone_samples(hm, c)
        frames = np.arange(max(c.start, 0), min(c.end, T - 1) + 1)
        if frames.size == 0:
            continue
        dist = d[frames][:, idx].min(axis=1) * 1e3
        k_lo, k_hi = int(np.argmin(dist)), int(np.argmax(dist))
        if dist[k_lo] < lo[0]:
            lo = (float(dist[k_lo]), f"{c.part} at frame {int(frames[k_lo])}")
        if dist[k_hi] > hi[0]:
            hi = (float(dist[k_hi]), f"{c.part} at frame {int(frames[k_hi])}")
    if not math.isfinite(lo[0]):  # no scripted contact frame
        lo, hi = (0.0, ""), (0.0, "")
    ok = -limits.contact_mm <= lo[0] and hi[0] <= limits.contact_mm
    detail = f"pad-surface distance {lo[0]:+.2f}…{hi[0]:+.2f} mm"
    if not ok:
        detail += f" (worst: {hi[1] if hi[0] > -lo[0] else lo[1]})"
    report.checks["contact"] = CheckResult(
        "contact", ok, [lo[0], hi[0]], [-limits.contact_mm, limits.contact_mm], "mm", detail
    )

    # penetration
    depth = -d.min(axis=1) * 1e3  # (T,)
    pen = float(max(0.0, depth.max()))
    f_pen = int(np.argmax(depth))
    cap = CAPSULES[hm.s_cap[int(np.argmin(d[f_pen]))]].name
    report.checks["penetration"] = CheckResult(
        "penetration", pen <= limits.penetration_mm, pen, limits.penetration_mm, "mm",
        f"deepest {pen:.2f} mm ({cap} at frame {f_pen})",
    )  # fmt: skip

    # hand below the table top, where it is over the table (beyond its edges nothing is there)
    table = table_of(traj)
    low = (table.height_above(S) - hm.s_r).min(axis=1)  # (T,) inf: the hand beyond the edges
    below = float(max(0.0, -low.min() * 1e3))
    f_low = int(np.argmin(low))
    report.checks["hand_table"] = CheckResult(
        "hand_table", below <= limits.table_mm, below, limits.table_mm, "mm",
        f"hand {below:.2f} mm below the table surface (frame {f_low})",
    )  # fmt: skip

    # support
    bad = _unsupported_frames(geom, hm, d, n_world, R_o, p_o, limits, table)
    report.checks["support"] = CheckResult(
        "support", len(bad) == 0, len(bad), 0, "frames",
        "object always held or resting on the table" if not bad else
        f"{len(bad)} frames where the object moves or floats unsupported "
        f"(first {bad[0][0]}: {bad[0][1]})",
    )  # fmt: skip

    # speeds
    if T > 1:
        v = np.linalg.norm(np.diff(kp[:, 0], axis=0), axis=1) * fps
        ang = anatomical_angles(h.hand_pose[:, 3:].astype(np.float64))
        w = np.abs(np.diff(ang, axis=0)).max(axis=(1, 2)) * fps
        v_max, w_max = float(v.max()), float(w.max())
        f_v, f_w = int(np.argmax(v)) + 1, int(np.argmax(w)) + 1
    else:
        v_max = w_max = 0.0
        f_v = f_w = 0
    report.checks["wrist_speed"] = CheckResult(
        "wrist_speed", v_max <= limits.wrist_speed_m_s, v_max, limits.wrist_speed_m_s, "m/s",
        f"peak wrist speed {v_max:.2f} m/s (frame {f_v})",
    )  # fmt: skip
    report.checks["joint_speed"] = CheckResult(
        "joint_speed", w_max <= limits.joint_speed_rad_s, w_max, limits.joint_speed_rad_s,
        "rad/s", f"peak finger-joint speed {w_max:.2f} rad/s (frame {f_w})",
    )  # fmt: skip
    return report


def _zone_samples(hm, c: ContactInterval) -> np.ndarray:
    names = [k.name for k in CAPSULES if k.part == "palm"] if c.capsule == "palm" else [c.capsule]
    out = []
    for name in names:
        idx = hm.cap_slices[CAPSULE_INDEX[name]]
        n = len(idx)
        lo, hi = int(np.floor(c.zone[0] * (n - 1))), int(np.ceil(c.zone[1] * (n - 1)))
        out.append(idx[lo : hi + 1])
    return np.concatenate(out)


_DIRECTIONS: np.ndarray | None = None


def _sphere_directions(n: int = 400) -> np.ndarray:
    """``(n, 3)`` near-uniform unit vectors (Fibonacci sphere), cached."""
    global _DIRECTIONS
    if _DIRECTIONS is None or len(_DIRECTIONS) != n:
        k = np.arange(n) + 0.5
        z = 1.0 - 2.0 * k / n
        phi = k * math.pi * (3.0 - math.sqrt(5.0))
        r = np.sqrt(1.0 - z * z)
        _DIRECTIONS = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return _DIRECTIONS


def closure_margin(normals: np.ndarray, touching: np.ndarray) -> np.ndarray:
    """``max_u min_i u·n_i`` over unit directions ``u`` and the touching contacts ``i``.

    ``normals (T, P, 3)`` outward surface normals, ``touching (T, P)`` bool. A frictional grasp
    resists every force direction iff this is below ``sin(atan μ)``; 1 with one contact, ≤ 0
    when the normals surround the origin. ``+inf`` where nothing touches.
    """
    U = _sphere_directions()
    dots = U @ np.transpose(normals, (0, 2, 1))  # (T, U, P)
    dots = np.where(touching[:, None, :], dots, np.inf)
    return dots.min(axis=2).max(axis=1)


LIFT_MU = 0.5
"""Friction coefficient of the lift test (:func:`lift_grip_ratio`): below the skin–object
values (0.5–1.2) so that a grasp passing it keeps a margin for soft, slipping contacts."""
LIFT_TORSION_M = 0.0025
"""Torsional friction [m] of a pad in the lift test: half the simulated hand's 5 mm
(``sim.hand``), the same margin as ``LIFT_MU``."""


def _cone_edges(normal: np.ndarray, mu: float, k: int = 8) -> np.ndarray:
    """``(k, 3)`` edge directions of the friction pyramid inscribed in the cone of a contact
    pushing on the object (along ``-normal``, the outward normal's opposite); one edge points
    straight up the tangent plane (the direction that lifts), so a contact's best lift is
    exact and the others are conservative."""
    n = normal / np.linalg.norm(normal)
    up = np.array([0.0, 0.0, 1.0]) - n[2] * n
    if np.linalg.norm(up) < 1e-6:  # a horizontal face: any tangent
        up = np.cross(n, [1.0, 0.0, 0.0])
    t1 = up / np.linalg.norm(up)
    t2 = np.cross(n, t1)
    th = 2.0 * math.pi * np.arange(k) / k
    tang = np.cos(th)[:, None] * t1 + np.sin(th)[:, None] * t2
    return -n + mu * tang


def lift_grip_ratio(
    normals: np.ndarray,
    points: np.ndarray | None = None,
    centre: np.ndarray | None = None,
    mu: float = LIFT_MU,
    torsion_m: float = LIFT_TORSION_M,
) -> float:
    """Least total normal force [in units of the object's weight] with which contacts of
    outward normals ``normals (P, 3)`` (object frame, z up) can hold the object still against
    gravity, each force inside its friction cone (an inscribed 8-sided pyramid of ``mu``).

    With the contact ``points (P, 3)`` [m] the torques balance too, about the object's centre
    of mass ``centre`` (default the origin): each contact is a soft finger that also resists a
    twist about its normal of up to ``torsion_m`` × its normal force (MuJoCo's condim-4
    torsional friction, a pad's contact patch), so a pinch far from the centre of mass
    needs a hard squeeze to keep the object from swinging about the pinch line.

    ``1/μ`` for an antipodal horizontal pinch through the centre of mass or any grasp whose
    normals balance, 1 for a contact under the object, larger when normals do not oppose or the
    contacts are off-centre (part of the squeeze is spent balancing them), ``inf`` when the
    contacts cannot hold the object at all.

    A linear programme (``scipy.optimize.linprog``, HiGHS) over the friction pyramid's edge
    weights and the torsion.
    """
    from scipy.optimize import linprog

    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    if normals.shape[0] == 0 or not np.all(np.isfinite(normals)):
        return math.inf
    n_unit = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    cols, cost = [], []
    for i, n in enumerate(n_unit):
        for e in _cone_edges(n, mu):
            cols.append((i, e, np.zeros(3)))
        if points is not None and torsion_m > 0:
            for sgn in (1.0, -1.0):  # a push along -n with a twist about n
                cols.append((i, -n, sgn * torsion_m * n))
        cost.extend([1.0] * (len(cols) - len(cost)))
    rows = 3 if points is None else 6
    A = np.zeros((rows, len(cols)))
    c0 = np.zeros(3) if centre is None else np.asarray(centre, dtype=float)
    for j, (i, f, m) in enumerate(cols):
        A[:3, j] = f
        if points is not None:
            A[3:, j] = np.cross(np.asarray(points[i], dtype=float) - c0, f) + m
    b = np.zeros(rows)
    b[2] = 1.0
    res = linprog(np.array(cost), A_eq=A, b_eq=b, bounds=(0, None), method="highs")
    return float(res.fun) if res.status == 0 else math.inf


def _unsupported_frames(geom, hm, d, n_world, R_o, p_o, limits: CheckLimits, table: Table):
    """Frames ``(t, why)`` where the object moves or floats without support (the table holds
    it only where its origin is over the table)."""
    T = d.shape[0]
    parts = sorted({c.part for c in CAPSULES})
    part_idx = [np.flatnonzero([CAPSULES[k].part == p for k in hm.s_cap]) for p in parts]
    # per part: min distance and the normal there
    dmin = np.stack([d[:, idx].min(axis=1) for idx in part_idx], axis=1)  # (T, P)
    arg = [idx[np.argmin(d[:, idx], axis=1)] for idx in part_idx]
    normals = np.stack([n_world[np.arange(T), a] for a in arg], axis=1)  # (T, P, 3)
    touch = dmin <= limits.touch_mm * 1e-3
    touched = touch.any(axis=1)
    lowest = geom.lowest_z(R_o, p_o)
    low = table.height_above(np.concatenate([p_o[:, :2], lowest[:, None]], axis=1)) * 1e3  # mm
    resting = np.abs(low) <= limits.table_rest_mm
    step = np.zeros(T)
    turn = np.zeros(T)
    if T > 1:
        step[1:] = np.linalg.norm(np.diff(p_o, axis=0), axis=1)
        rel = np.einsum("tji,tjk->tik", R_o[:-1], R_o[1:])
        turn[1:] = np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0))
    moving = (step > limits.still_m) | (turn > limits.still_rad)
    # force closure only where it decides: moving or off the table, and not (resting + touched)
    need = (moving | ~resting) & ~(resting & touched)
    held = np.zeros(T, bool)
    if need.any():
        margin = closure_margin(normals[need], touch[need])
        held[need] = margin < math.sin(math.atan(limits.friction))
    bad = []
    for t in range(T):
        if low[t] < -limits.table_rest_mm:
            bad.append((t, f"object {-low[t]:.1f} mm inside the table"))
        elif moving[t] and not (held[t] or (resting[t] and touched[t])):
            why = "resting but untouched" if resting[t] else "not held by opposing contacts"
            bad.append((t, f"moves {step[t] * 1e3:.1f} mm, {why}"))
        elif not moving[t] and not resting[t] and not held[t]:
            where = (
                f"floats {low[t]:.1f} mm above the table"
                if np.isfinite(low[t])
                else "is beyond the table's edge"
            )
            bad.append((t, f"{where}, not held"))
    return bad
