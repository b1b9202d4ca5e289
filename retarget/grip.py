"""The position command's grip (``q_command = q + Δq``): the weight-aware grip
(``grip.mode="wrench"``), the depth squeeze (``grip.mode="depth"``) and force matching's
squeeze, each turned into joint offsets through the servo gains."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from dexcanvas_core.rotations import aa_to_matrix, aa_to_quat_wxyz
from dexcanvas_core.sim.physics import GRAVITY, capture_acceleration, carried_load
from dexcanvas_core.table import DEFAULT_TABLE
from dexcanvas_core.trajectory import FORCE_GROUPS, Trajectory
from retarget._checks import check_choice, check_range
from retarget.errors import RetargetError
from retarget.force_matching import distribute, servo_gains, squeeze_offsets
from retarget.limits.coupling import servo_follower_map

GripMode = Literal["wrench", "depth"]


@dataclass(frozen=True, kw_only=True)
class GripConfig:
    """How the position command (``q_command``) presses the object where the human touches it
    (force matching, ``ForceMatchingConfig``, replaces the grip). Chosen on the retargeting
    benchmark; docs/method.md#2-pressing-the-grip-and-force-matching."""

    mode: GripMode = "wrench"
    """``wrench``: contact forces from the object's weight and motion where the hand carries
    it (the force QP, ``retarget.force_matching.distribute``), plus ``force_n`` between
    opposed fingers, applied through the servo gains; ``depth``: every contacting finger
    pressed ``squeeze_depth`` into the surface. Default ``wrench``."""
    squeeze_depth: float = 0.01
    """``mode="depth"``: how far [m] the command presses each contacting finger into the
    surface (0: off). Default 0.01."""
    force_n: float = 3.0
    """``mode="wrench"``: normal force [N] each opposed contact presses with on top of what the
    object's weight and motion need. Default 3."""
    lead_s: float = 0.15
    """``mode="wrench"``: the weight is carried from this long [s] before the object leaves the
    table (``dexcanvas_core.sim.physics.carried_load``). Default 0.15."""
    surface_normals: bool = True
    """``mode="wrench"``: press each contacting link along the object's normal where it touches
    (when within 45° of the human contact's normal) instead of the human contact's normal.
    Default True."""
    mu: float = 0.8
    """Friction coefficient of the force QP's (linearised, inner) cones (also force
    matching's). Default 0.8."""

    def __post_init__(self):
        check_choice(self, "mode", GripMode)
        check_range(self, "force_n", unit="N")
        check_range(self, "lead_s", unit="s")


class GripAssembly:
    """The :class:`retarget.retargeter.Retargeter`'s grip and force matching (a mixin: it reads
    the retargeter's scene, kinematics, config and contact objective)."""

    def _servo_gains(self) -> tuple[np.ndarray, np.ndarray]:
        """``(kp, tau_max)`` per hand joint (:func:`retarget.force_matching.servo_gains`)."""
        return servo_gains(self.scene.model, self.nq)

    def _object_com(self) -> np.ndarray:
        return self.geometry.com

    def _grip_targets(self, traj: Trajectory) -> dict:
        """Per-frame object wrench the hand must supply: ``λ m (a + g ẑ)`` and no torque about
        the centre of mass, with ``a`` the object's captured acceleration (50 ms smoothing) and
        ``λ`` the share of the weight the hand carries (the force pipeline's
        ``sim.physics.carried_load``: 0 while the object rests on the table, 1 off it, built up
        over the ``grip.lead_s`` before lift-off: the grip must be there when the table stops
        helping)."""
        T, F = traj.num_frames, len(self.tip_sites)
        kp, tau_max = self._servo_gains()
        R = aa_to_matrix(traj.object.rot_aa.astype(np.float64))
        p = traj.object.pos.astype(np.float64)
        load = carried_load(
            self.geometry, p, aa_to_quat_wxyz(traj.object.rot_aa), traj.fps,
            lead_s=self.cfg.grip.lead_s, table=self.table or DEFAULT_TABLE,
        )  # fmt: skip
        acc = capture_acceleration(p, traj.fps)
        W = np.zeros((T, 6))
        W[:, :3] = (load * self.geometry.mass_kg)[:, None] * (acc + np.array([0.0, 0.0, GRAVITY]))
        return {
            "mode": "grip",
            "kp": kp,
            "tau_max": tau_max,
            "human_force": None,
            "wrench": W,
            "com_local": self._object_com(),
            "robot_force": np.zeros((T, F, 3)),
            "shortfall": np.zeros(T),
            "R_obj": R,
            "p_obj": p,
        }

    def human_finger_forces(self, traj: Trajectory) -> np.ndarray:
        """(T, F, 3) [N, world]: the human's summed contact force on the object of the human
        finger each robot fingertip stands for (``tip_human`` order; a gripper's merged finger
        repeats), from the force pipeline's contact records."""
        c = traj.contacts
        if c is None or c.num_records == 0 or traj.object_wrench_world is None:
            raise RetargetError(
                f"force matching needs the human's contact forces, and trajectory {traj.uuid} "
                "has none: run it through the force pipeline first (dexcanvas simulate), or use "
                "retarget run --forces, which does"
            )
        groups = c.finger_totals().astype(np.float64)  # (T, 6, 3) on the object, world
        return np.stack([groups[:, FORCE_GROUPS.index(f)] for f in self.tip_human], axis=1)

    def _force_targets(self, traj: Trajectory) -> dict:
        """Per-frame human forces of the robot's fingers and the object wrench to reproduce."""
        human = self.human_finger_forces(traj)
        kp, tau_max = self._servo_gains()
        T, F = traj.num_frames, len(self.tip_sites)
        return {
            "mode": "human",
            "kp": kp,
            "tau_max": tau_max,
            "human_force": human,
            "wrench": traj.object_wrench_world.astype(np.float64),
            "com_local": self._object_com(),
            "robot_force": np.zeros((T, F, 3)),
            "shortfall": np.zeros(T),
            "R_obj": aa_to_matrix(traj.object.rot_aa.astype(np.float64)),
            "p_obj": traj.object.pos.astype(np.float64),
        }

    def _force_squeeze(self, q: np.ndarray, t: int, tg: dict, fm: dict) -> np.ndarray:
        """Joint offsets that make the servos press with the force QP's contact forces."""
        W = fm["wrench"][t]
        normals = tg["contact_normals"][t]
        if fm["mode"] == "human":
            f_des = self.cfg.force_matching.scale * fm["human_force"][t]
            active = tg["contact_active"][t] & (np.linalg.norm(f_des, axis=1) > 1e-3)
        else:
            # No human forces: the wrench the object needs, plus a light squeeze between
            # fingers that push against each other (an unopposed finger is not pressed).
            active = tg["contact_active"][t]
            opp = opposed_contacts(active, normals)
            f_des = -self.cfg.grip.force_n * normals * opp[:, None]
            if not W.any():
                active = opp
        # A finger the captured hand touches with while the human's presses nothing is backed
        # off the surface (``force_matching.idle_contact_clearance``) instead of pressed by
        # the servo.
        idle = np.zeros_like(active)
        if fm["mode"] == "human" and self.cfg.force_matching.idle_contact_clearance is not None:
            idle = tg["contact_active"][t] & ~active
        if not active.any():
            fm["shortfall"][t] = float(np.linalg.norm(W[:3]))
            if not idle.any():
                return np.zeros(self.nq)
        self.kin.forward(q)
        idx = np.flatnonzero(active | idle)
        pressed = active[idx]
        fingers = np.isfinite(fm["kp"])
        bodies, P, gap = self.contacts.nearest_of(q, idx)
        Jall = self.kin.point_jacobians(bodies, P)[:, :, : self.nq]
        # Over the servoed joints, each carrying the joints its linkage drives (a coupled
        # distal joint moves with its servo, and its share of the load is the servo's: τ =
        # (J C)ᵀ f); the wrist has no column (it does not squeeze).
        C = self._servo_follower_map(q)
        Jall = Jall @ C
        dq = np.zeros(self.nq)
        # The robot link presses where it touches, along the object's normal there
        # (``grip.surface_normals``), which is not the human's where the robot's link meets
        # the object elsewhere (a larger hand's fingertip on an apple's upper side, the
        # human's on its equator). Force matching keeps the human's normals: its forces are
        # the human's own vectors, their cones the human's.
        normals = normals.copy()
        if self.cfg.grip.surface_normals and fm["mode"] != "human":
            normals[idx] = self._surface_normals(q, idx, normals[idx])
            f_des = -self.cfg.grip.force_n * normals * opp[:, None]
        if pressed.any():
            ia = idx[pressed]
            J = list(Jall[pressed])
            com = fm["p_obj"][t] + fm["R_obj"][t] @ fm["com_local"]
            dist = distribute(
                P[pressed],
                normals[ia],
                f_des[ia],
                W,
                com,
                mu=self.cfg.grip.mu,
                jacobians=[Ji[:, fingers] for Ji in J],
                tau_max=np.minimum(fm["tau_max"][fingers], 1e3),
            )
            fm["robot_force"][t, ia] = dist.forces
            fm["shortfall"][t] = dist.force_shortfall_n
            dq = squeeze_offsets(J, dist.forces, np.where(fingers, fm["kp"], np.inf))
        # K⁻¹Jᵀf presses from the surface: a finger the kinematic solution leaves short of it
        # (non-penetration margin, contact error) first closes that gap, else a light force
        # is spent in the air (Allegro on cube2h/tripod: 3.6 mm mean contact error, 0.2 N
        # reached instead of the human's ~2 N, the cube dropped); one the solution leaves
        # inside it (up to the 2 mm penetration margin) backs out to it, else it presses that
        # depth's servo force on top of the plan's (k·d with k = kp/L², e.g. 1.5 N for
        # Allegro's 10 N·m/rad at a 0.1 m lever and 1.5 mm). An idle finger goes out to its
        # clearance where it is nearer. The two groups take a damped step each: one step for
        # both solves them jointly through the joints they share (Shadow's WRJ0/1, SVH's
        # spread), which the force benchmark's (d) measured worse (five-finger correlation on
        # the same 61 successful runs 0.739 → 0.732, SVH cube2/sliding 0.83 → 0.63).
        # The idle fingers' clearance is a distance: it grows along the surface normal at the
        # finger's nearest point (the distance's gradient), which is not the human contact's
        # where the robot finger sits on an edge the human touched beside.
        target = np.where(pressed, 0.0, self.cfg.force_matching.idle_contact_clearance or 0.0)
        # A finger point inside the object (the solution's penetration margin) has no such
        # gradient to trust near an edge (the nearest face from inside may not be the one it
        # went through): it keeps the human contact's normal (a pressed one: the normal where
        # it touches with ``grip.surface_normals``).
        step_normals = normals[idx].copy()
        if (~pressed).any() and self.geometry is not None:
            R_o, p_o = fm["R_obj"][t], fm["p_obj"][t]
            d_loc, n_loc = self.geometry.sdf_and_normal((P[~pressed] - p_o) @ R_o)
            idle = np.flatnonzero(~pressed)[d_loc > 0.0]
            step_normals[idle] = n_loc[d_loc > 0.0] @ R_o.T
        for group in (pressed, ~pressed & (gap < target)):
            err = (gap - target)[group]
            if err.any():
                delta = -(err[:, None] * step_normals[group]).reshape(-1)
                dq = dq + _damped_step(Jall[group].reshape(-1, self.nq), delta)
        return self._within_limits(q + C @ dq) - q

    def _surface_normals(self, q: np.ndarray, idx: np.ndarray, human: np.ndarray) -> np.ndarray:
        """(k, 3) for the contacting fingers ``idx`` at ``q``: the object's outward normal
        [world] where each finger's contact link is nearest it (the direction in which the
        link–object distance grows, from the contact term's distance query: the gradient of
        the object's signed distance at that point), where the link is outside the surface or
        within the penetration margin + 0.5 mm of it and that normal is within 45° of the
        human contact's (``human`` (k, 3)): the link touches the face the human's phalanx
        does. Elsewhere the human's normal: deeper, the nearest face from inside need not be
        the one the link touches; beyond 45°, the link's nearest point is on an edge or
        another face (a fingertip over a cube's edge), where pressing along that normal does
        not squeeze the object as the human does."""
        out = np.array(human, dtype=np.float64, copy=True)
        _, _, gap = self.contacts.nearest_of(q, idx)
        n = self.contacts.nearest_directions(q, idx)
        use = (gap > -(self.cfg.collision.penetration_margin + 5e-4)) & (
            np.einsum("ki,ki->k", n, out) > np.cos(np.radians(45.0))
        )
        out[use] = n[use]
        return out

    def _servo_follower_map(self, q: np.ndarray) -> np.ndarray:
        """``(nq, nq)`` map from a displacement of the servoed finger joints to every joint's,
        the unservoed finger joints following through the model's couplings
        (``CouplingLimit.follower_map``; Ability's and Inspire's distal joints, SVH's 11 mimic
        joints, Shadow's distal J0): zero columns for the wrist and the followers. Cached when
        the couplings are linear (every hand here)."""
        if self._servo_map is not None:
            return self._servo_map
        C = servo_follower_map(self.scene.model, q, self.nq, self._coupling)
        C[:, :6] = 0.0  # the wrist's servos do not squeeze
        if self._coupling.linear:
            self._servo_map = C
        return C

    def _squeeze(self, q: np.ndarray, active: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """``grip.mode="depth"``: joint offset pressing each contacting finger ``squeeze_depth``
        into the surface.

        ``Δq = C (J C)ᵀ (J C (J C)ᵀ + λ I)⁻¹ δ`` with ``δ = −depth · n`` per active contact,
        ``J`` the contact points' Jacobians and ``C`` the servoed finger joints' follower map
        (the wrist does not move; coupled joints follow their servo).
        """
        dq = np.zeros(self.nq)
        if self.contacts is None or self.cfg.grip.squeeze_depth <= 0 or not active.any():
            return dq
        self.kin.forward(q)
        idx = np.flatnonzero(active)
        bodies, P, _ = self.contacts.nearest_of(q, idx)
        J = self.kin.point_jacobians(bodies, P)[:, :, : self.nq]
        J = J.reshape(-1, self.nq)
        C = self._servo_follower_map(q)  # the servos move; coupled joints follow them
        delta = np.concatenate([-self.cfg.grip.squeeze_depth * normals[i] for i in idx])
        dq = C @ _damped_step(J @ C, delta)
        return self._within_limits(q + dq) - q

    def _within_limits(self, q: np.ndarray) -> np.ndarray:
        """``q`` clipped to the servo commands' joint ranges (``np.clip`` costs 2.3× as much on
        30 dofs: 3.2 against 1.4 µs)."""
        return np.minimum(np.maximum(q, self.lower), self.upper)


def opposed_contacts(active: np.ndarray, normals: np.ndarray, cos_max: float = -0.3) -> np.ndarray:
    """(F,) which active contacts have another active contact pushing back against them.

    A contact is opposed when some other active contact's surface normal points at least
    ~107° away from its own (``nᵢ·nⱼ < cos_max``): pressing both squeezes the object between
    them. An unopposed finger (the first finger to arrive, one resting on the top face while
    others grip the sides) pressed into the surface only pushes the object (Allegro on
    generated cylinder6/rotation: the index alone on the top face at 11 N, 7× the
    cylinder's weight, before the grasp closes)."""
    a = np.asarray(active, bool)
    n = np.asarray(normals, dtype=np.float64)
    dots = n @ n.T
    ok = (dots < cos_max) & a[None, :] & a[:, None]
    return a & ok.any(axis=1)


def _damped_step(J: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Least-norm joint step moving the points of Jacobian ``J`` by ``delta``:
    ``Jᵀ (J Jᵀ + λ I)⁻¹ δ`` with a small damping λ = 1e-6."""
    return J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(J.shape[0]), delta)
