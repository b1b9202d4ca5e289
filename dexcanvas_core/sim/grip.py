"""Contact-aware grip: joint-target offsets that make position-controlled fingers press.

A position-controlled finger whose target lies exactly on the object surface touches it with
(almost) no force, so a reference replayed in physics drops what the human lifted. For every
finger whose reference pad is near the object, the grip offsets move the finger's joint targets
*into* the object by exactly as much as makes its actuators push with a chosen force once the
surface stops it (the "squeeze", ``Δq = K⁻¹ Jᵀ f``):

* the pad point is the point of the finger's distal capsule axis closest to the object surface,
  ``n`` the object's outward normal there (both at the reference pose);
* ``f_k = −n_k · w_k · F_k``. The pad forces are *internal* forces: they must not push the object
  (the reference already moves it), so the magnitudes ``F_k ≥ 0`` minimise
  ``‖Σ_k F_k n_k + F_palm n_palm‖² + λ Σ_k (F_k − F_hold)²`` — balanced against each other and
  against the palm when it touches (``F_palm ≥ 0`` free: the wrist carries it) — with
  ``F_hold = F_min + λ · s · m·g / (μ · n_fingers)``: a contact-keeping force plus enough
  friction to carry ``s`` times the object's weight shared by the fingers near it (``additive``;
  otherwise the larger of the two, the earlier model, under which a heavy object got barely more
  than a light one: 4.6 vs 4 N per pad for ``cylinder1h``/``cylinder1``). ``w`` ∈ [0, 1] ramps
  with the pad's distance to the surface (``grip_weights``) and is smoothed in time;
* ``λ`` ∈ [0, 1] (:func:`~dexcanvas_core.sim.physics.carried_load`) is the share of the weight
  the hand carries: 0 while the reference object rests on the table, 1 once it is lifted,
  built up ahead of lift-off (grip force–load force coupling: people raise the grip *before*
  the object leaves the table).
  Without it the first finger to reach a resting object got the whole weight-sized force
  (``n_fingers`` = 1, 14 N for a 0.47 kg cylinder) and pushed or tipped the object before the
  others arrived — the lift-off drops of heavy objects on the force-pipeline benchmark;
* ``J`` is the pad point's translational Jacobian over that finger's hinges, ``K`` the hinges'
  position gains: at equilibrium against the surface ``K (q_target − q) = Jᵀ f``;
* optionally (``max_gap_m`` > 0, off by default) a pad that the reference holds short of the
  surface by ``g`` is first moved onto it: ``Δq += J⁺ (−n · min(g, max_gap_m))`` (damped
  pseudo-inverse). Measured on the 57 built-in demonstrations with the open-loop tracker it
  lowered success (27 vs 30 with 5 mm, 18 vs 30 with 10 mm): closing fingers the human held
  clear pushes the object before the grasp holds.
"""

from __future__ import annotations

import mujoco
import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.sim.hand import FINGER_HINGES, HAND_JOINTS
from dexcanvas_core.sim.physics import GRAVITY


def finger_columns() -> list[np.ndarray]:
    """Per finger (thumb … pinky): indices into ``HAND_JOINTS`` of its hinges."""
    return [
        np.array([HAND_JOINTS.index(n) for n in FINGER_HINGES if n.startswith(f)]) for f in FINGERS
    ]


def distal_geoms(scene) -> list[int]:
    """The distal capsule geom of each finger (thumb … pinky)."""
    part = {"thumb": "thumb_ip", **{f: f"{f}_dip" for f in FINGERS[1:]}}
    by_part = {p: g for g, p in scene.hand.geom_part.items()}
    return [by_part[part[f]] for f in FINGERS]


def squeeze_offsets(
    scene,
    ctrl_ref: np.ndarray,
    object_pos: np.ndarray,
    object_quat: np.ndarray,
    weights: np.ndarray,
    *,
    force_min_n: float,
    safety: float,
    friction: float,
    palm_contact_m: float = 0.01,
    balance: bool = True,
    max_gap_m: float = 0.0,
    load: np.ndarray | None = None,
    additive: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """``(T, 51)`` joint-target offsets and ``(T, 5)`` the commanded pad forces [N].

    Args:
        scene: the ``SimScene``.
        ctrl_ref: ``(T, 51)`` reference actuator targets (the pose the pads are measured in).
        object_pos, object_quat: ``(T, 3)``, ``(T, 4)`` reference object pose.
        weights: ``(T, 5)`` grip weights in [0, 1] per finger.
        balance: balance the pad forces (module docstring); ``False``: every pad gets
            ``F_hold`` (e.g. one finger pressing a fixed object).
        load: ``(T,)`` share ``λ`` ∈ [0, 1] of the weight the hand carries
            (:func:`carried_load`); ``None``: the whole weight at every frame.
        additive: ``F_hold = F_min + F_load`` (module docstring); ``False``: the larger of the
            two.
    """
    m = scene.model
    d = mujoco.MjData(m)
    hand = scene.hand
    geoms = distal_geoms(scene)
    cols = finger_columns()
    kp = m.actuator_gainprm[hand.actuator, 0]
    mass = scene.mass_kg
    T = ctrl_ref.shape[0]
    load = np.ones(T) if load is None else np.asarray(load, dtype=np.float64)
    if load.shape != (T,) or not np.all((load >= 0.0) & (load <= 1.0)):
        raise ValidationError(f"load must be ({T},) values in [0, 1]", field="load")
    out = np.zeros((T, len(HAND_JOINTS)))
    force = np.zeros((T, len(FINGERS)))
    jacp = np.zeros((3, m.nv))
    s = np.linspace(0.0, 1.0, 9)
    oa = scene.object_qpos_adr
    palm = [g for g, p in hand.geom_part.items() if p == "palm"]
    for t in range(T):
        w = weights[t]
        if not (w > 0).any():
            continue
        d.qpos[hand.qpos_adr] = ctrl_ref[t]
        d.qpos[oa : oa + 3] = object_pos[t]
        d.qpos[oa + 3 : oa + 7] = object_quat[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        R_o = d.xmat[scene.object_body].reshape(3, 3)
        p_o = d.xpos[scene.object_body]
        n_near = max(1.0, float((w > 0.5).sum()))
        F_load = load[t] * safety * mass * GRAVITY / (friction * n_near)
        F_hold = force_min_n + F_load if additive else max(force_min_n, F_load)
        act = [k for k in range(len(geoms)) if w[k] > 0]
        pts_k, n_k, J_k, gaps = [], [], [], []
        for k in act:
            g = geoms[k]
            p, n_w = _closest_on_axis(scene, d, g, s, R_o, p_o)
            sd, _ = scene.geometry.sdf_and_normal(((p - p_o) @ R_o)[None])
            gaps.append(min(float(sd[0]) - m.geom_size[g, 0], max_gap_m))
            mujoco.mj_jac(m, d, jacp, None, p, m.geom_bodyid[g])
            pts_k.append(p)
            n_k.append(n_w)
            J_k.append(jacp[:, hand.dof_adr[cols[k]]].copy())
        # the palm, if it touches: a free balancing contact
        n_p = []
        for g in palm:
            p, n_w = _closest_on_axis(scene, d, g, s, R_o, p_o)
            sd, _ = scene.geometry.sdf_and_normal(((p - p_o) @ R_o)[None])
            if sd[0] - m.geom_size[g, 0] < palm_contact_m:
                n_p.append(n_w)
        if balance:
            F = balanced_forces(np.array(n_k), np.array(n_p).reshape(-1, 3), F_hold)
        else:
            F = np.full(len(act), F_hold)
        for i, k in enumerate(act):
            f = -n_k[i] * w[k] * F[i]
            dq = (J_k[i].T @ f) / kp[cols[k]]
            if gaps[i] > 0 and w[k] > 0.99:  # close the gap first: move the pad onto the surface
                J = J_k[i]
                dq += w[k] * J.T @ np.linalg.solve(J @ J.T + 1e-4 * np.eye(3), -n_k[i] * gaps[i])
            out[t, cols[k]] = dq
            force[t, k] = w[k] * F[i]
    return out, force


def contact_keeping_force(
    mass_kg: float, force_n: float, floor_n: float | None, weight_k: float
) -> float:
    """The contact-keeping part ``F_min`` [N] of each pad's grip force for an object of
    ``mass_kg``: ``weight_k · m·g`` clipped to [``floor_n``, ``force_n``]; ``force_n`` when
    ``floor_n`` is ``None``.

    A fixed 4 N suits objects of 150 g and more; on lighter ones it is many times the weight
    and, where the pads are not opposed along one line (a thumb pressing from above, fingers on
    the side), its resultant pushes the object about. Measured on the force-pipeline suite's
    mocap-fitted demonstrations: 2 N everywhere lifted the 82–85 g scissor and cylinder5 that
    4 N dropped, and dropped three 150–510 g objects that 4 N held.
    """
    if floor_n is None:
        return float(force_n)
    if not (0.0 < floor_n <= force_n) or weight_k < 0.0:
        raise ValidationError(
            f"contact-keeping force needs 0 < floor ≤ force and k ≥ 0, got floor {floor_n}, "
            f"force {force_n}, k {weight_k}",
            field="grip_force_floor_n",
        )
    return float(np.clip(weight_k * mass_kg * GRAVITY, floor_n, force_n))


def _closest_on_axis(scene, d, g, s, R_o, p_o) -> tuple[np.ndarray, np.ndarray]:
    """Point of capsule ``g``'s axis closest to the object surface, and the outward normal
    there (world)."""
    m = scene.model
    c = d.geom_xpos[g]
    axis = d.geom_xmat[g].reshape(3, 3)[:, 2]
    half = m.geom_size[g, 1]
    pts = c + np.outer((2 * s - 1) * half, axis)
    sdf, nrm = scene.geometry.sdf_and_normal((pts - p_o) @ R_o)
    i = int(np.argmin(sdf))
    return pts[i], R_o @ nrm[i]


def balanced_forces(
    normals: np.ndarray, palm_normals: np.ndarray, F_hold: float, lam: float = 1.0
) -> np.ndarray:
    """Pad force magnitudes ``(k,)`` ≥ 0, near ``F_hold``, whose net force (with free,
    non-negative palm forces along ``palm_normals``) is as small as possible (module docstring).
    Solved as a bounded least-squares problem (``scipy.optimize.lsq_linear``)."""
    from scipy.optimize import lsq_linear

    k = normals.shape[0]
    if k == 0:
        return np.zeros(0)
    N = np.concatenate([normals, palm_normals], axis=0).T  # (3, k + p)
    p = palm_normals.shape[0]
    reg = np.sqrt(lam) * np.concatenate([np.eye(k), np.zeros((k, p))], axis=1)
    A = np.concatenate([N, reg], axis=0)
    b = np.concatenate([np.zeros(3), np.sqrt(lam) * np.full(k, F_hold)])
    sol = lsq_linear(A, b, bounds=(0.0, np.inf))
    return sol.x[:k]
