"""The per-frame human targets of the retargeting QP (``Retargeter.human_targets``): the
wrist, the scaled keypoints, the fingertip vectors and the contacts (which human phalanges
touch the object where), with the per-frame weights and margins derived from them."""

from __future__ import annotations

import mujoco
import numpy as np

from dexcanvas_core.keypoints import MANO21
from dexcanvas_core.mano import ManoLayer
from dexcanvas_core.rotations import aa_to_matrix
from dexcanvas_core.trajectory import Trajectory
from retarget.errors import RetargetError


class HumanTargets:
    """The :class:`retarget.retargeter.Retargeter`'s targets (a mixin: it reads the
    retargeter's hand, geometry, config, scene, sites and contact objective)."""

    def _contact_links(self, hand, m) -> list[list[list[int]]]:
        """Per robot finger, the collision geoms of the links that stand for the human's
        distal, middle and proximal phalanx (thumb: distal, proximal, metacarpal): the tip
        site's link, then the links towards the palm that have geoms (at most three; a
        two-link finger's proximal link takes both the middle and the proximal phalanx).

        A link is a rigid group of bodies (MuJoCo's ``body_weldid``): a jointless body welded
        to its parent belongs to the parent's link. Allegro's fingertips are such bodies
        (``link_3.0_tip`` on ``link_3.0``); counted as links of their own, the distal
        phalanx stood for the human's middle one, and on a fingertip contact the
        non-contact clearance held it 2 mm off the object, the tip short of the surface
        (built-in cube2/tripod: the middle finger 4 mm off the cube, 10 mm from its contact
        point)."""
        chains = hand.hand_parts(m)
        weld = m.body_weldid
        geoms_of = lambda w: [g for g in self.scene.hand_geoms if weld[m.geom_bodyid[g]] == w]  # noqa: E731
        out = []
        for f, site in zip(self.tip_human, self.tip_sites, strict=True):
            link = weld[m.site_bodyid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, site)]]
            geoms = geoms_of(link)
            if not geoms:
                raise RetargetError(f"hand {hand.name!r}: no collision geom on {site}'s link")
            parts = [geoms]
            robot_finger = hand.fingers[f]
            # A robot finger several human fingers drive (a gripper's) keeps its tip only.
            shared = sum(v == robot_finger for v in hand.fingers.values()) > 1
            links: list[int] = []  # the finger's links, palm to tip
            for b in chains.get(robot_finger, []):
                w = int(weld[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b)])
                if w not in links:
                    links.append(w)
            if not shared and link in links:
                for w in reversed(links[: links.index(link)]):
                    g = geoms_of(w)
                    if g:
                        parts.append(g)
                    if len(parts) == 3:
                        break
            if len(parts) == 2:  # two links: the proximal one takes both phalanges
                parts.append(parts[1])
            out.append(parts)
        return out

    def human_targets(self, traj: Trajectory) -> dict[str, np.ndarray]:
        """Per-frame targets in world coordinates (see the module docstring)."""
        h = traj.hand
        if h.joint_pos is None:
            layer = ManoLayer(h.name)
            h_kp = layer.forward_numpy(
                betas=h.betas[None], global_orient=h.global_rot_aa, hand_pose=h.finger_pose,
                transl=h.global_pos,
            ).keypoints  # fmt: skip
        else:
            h_kp = h.joint_pos.astype(np.float64)
        if not np.all(np.isfinite(h_kp)):
            raise RetargetError(f"trajectory {traj.uuid}: human keypoints contain NaN")
        R_wrist = aa_to_matrix(h.global_rot_aa.astype(np.float64))
        scaled = self._scaled_keypoints(traj, h_kp)  # (T, 21, 3)
        wrist_p = scaled[:, 0]
        if self.cfg.wrist.use_offset and self.hand.wrist_offset is not None:
            R_wrist, wrist_p = self.hand.wrist_offset.apply(R_wrist, wrist_p)
        kp = scaled[:, self.kp_index]
        vec = (
            np.stack([scaled[:, a] - scaled[:, b] for a, b in self.vec_human], axis=1)
            if self.vec_human
            else np.zeros((traj.num_frames, 0, 3))
        )
        out = {"wrist_p": wrist_p, "wrist_R": R_wrist, "keypoints": kp, "vectors": vec}
        T, F = traj.num_frames, len(self.tip_sites)
        active = np.zeros((T, F), bool)
        parts = np.zeros((T, F), int)
        by_part = np.zeros((T, F, 3), bool)
        points = np.zeros((T, F, 3))
        normals = np.zeros((T, F, 3))
        if self.geometry is not None and traj.objects:
            R_obj = aa_to_matrix(traj.object.rot_aa.astype(np.float64))
            p_obj = traj.object.pos.astype(np.float64)
            tips_world = h_kp[:, self.tip_index]  # (T, F, 3)
            tips_obj = np.einsum("tji,tfj->tfi", R_obj, tips_world - p_obj[:, None])
            sdf, n_obj = self.geometry.sdf_and_normal(tips_obj.reshape(-1, 3))
            sdf = sdf.reshape(T, F)
            n_obj = n_obj.reshape(T, F, 3)
            surf_obj = tips_obj - sdf[..., None] * n_obj  # surface point under the fingertip
            records = traj.contacts is not None and self.cfg.contacts.source == "records"
            if records:
                by_part = self._parts_from_records(traj)
            else:
                by_part = np.zeros((T, F, 3), bool)
                by_part[..., 0] = sdf < self.cfg.contacts.threshold_m
            # A finger whose tip keypoint does not touch may touch with its distal pad, else its
            # middle, else its proximal phalanx: that link's contact replaces the tip's
            # (lateral pinch, power grasps).
            n_parts = np.array([len(p) for p in self.contacts.part_geoms])[None]
            active = by_part[..., 0].copy()
            for k in (0, 1, 2) if self.cfg.contacts.link_contacts else ():
                seg = self._segment_rows(k)
                a, b = h_kp[:, seg[:, 0]], h_kp[:, seg[:, 1]]  # (T, F, 3) segment ends
                u = np.linspace(0.0, 1.0, 5)[:, None, None, None]
                pts = (1 - u) * a[None] + u * b[None]  # (5, T, F, 3)
                pts_obj = np.einsum("tji,stfj->stfi", R_obj, pts - p_obj[None, :, None])
                d, n = self.geometry.sdf_and_normal(pts_obj.reshape(-1, 3))
                d, n = d.reshape(5, T, F), n.reshape(5, T, F, 3)
                j = d.argmin(axis=0)  # (T, F) the sample nearest the surface
                dk = np.take_along_axis(d, j[None], 0)[0]
                nk = np.take_along_axis(n, j[None, ..., None], 0)[0]
                pk = np.take_along_axis(pts_obj, j[None, ..., None], 0)[0]
                if not records:
                    by_part[..., k] = dk < self.cfg.contacts.link_threshold_m
                # (k = 0: the distal phalanx's pad touches while the tip keypoint, at the end
                # of the finger, is farther than contact_threshold: a lateral pinch's thumb)
                use = by_part[..., k] & ~active & (n_parts > k)
                surf_obj[use] = (pk - dk[..., None] * nk)[use]
                n_obj[use] = nk[use]
                parts[use] = k
                active |= use
            points = np.einsum("tij,tfj->tfi", R_obj, surf_obj) + p_obj[:, None]
            normals = np.einsum("tij,tfj->tfi", R_obj, n_obj)
        out.update(
            contact_active=active, contact_points=points, contact_normals=normals,
            contact_part=parts, contact_by_part=by_part,
        )  # fmt: skip
        return out

    def _scaled_keypoints(self, traj: Trajectory, h_kp: np.ndarray) -> np.ndarray:
        """The human keypoints ``h_kp`` (T, 21, 3) [m, world] scaled to the robot hand's size.

        Without an object: about the wrist by ``scale``. With one, ``keypoints.scaling``:

        * ``uniform`` — about the object's centre by ``scale``;
        * ``surface`` — the same, then each keypoint moved along the surface normal until its
          distance to the surface is that of a robot-sized finger with the human's gap: with
          ``ρ = finger_radius_m`` and the human keypoint's distance ``d``, ``scale·d`` within
          ``ρ`` (touching), ``scale·ρ + (d − ρ)·g(d)`` beyond, the gap's scale ``g`` going
          from 1 to ``scale`` over ``keypoints.scale_blend_m`` (smoothstep; ``scale·d`` far
          away). Across the surface the keypoints keep the robot hand's spread (its fingers are
          wider apart); towards it, a keypoint that touches stays touching and one that keeps a
          gap keeps it.

        Scaled uniformly, a fingertip on the object is pushed ``(scale − 1)·r`` off the surface
        (``r`` its distance from the centre: ~9 mm on a 5 cm cube for Shadow's 1.37), so the
        keypoint and contact targets disagree on every contact frame and a contact switching on
        pulls the finger, and the wrist with it, across the gap (Shadow on generated
        cube2/tripod, operator2: the thumb 21.8 mm from its contact target after the onset
        frame's solve, the wrist dived 6.8 cm and came back while the human's stood still;
        with ``surface`` 2.6 mm and one 1.3 cm wrist step, no return)."""
        s = self.scale
        if self.geometry is None or not traj.objects:
            c = h_kp[:, :1]
            return c + s * (h_kp - c)
        c = traj.object.pos.astype(np.float64)[:, None]  # (T, 1, 3)
        u = c + s * (h_kp - c)
        if self.cfg.keypoints.scaling == "uniform":
            return u
        R_obj = aa_to_matrix(traj.object.rot_aa.astype(np.float64))  # (T, 3, 3) object → world
        d, _ = self.geometry.sdf_and_normal(np.einsum("tji,tkj->tki", R_obj, h_kp - c))
        d_u, n_u = self.geometry.sdf_and_normal(np.einsum("tji,tkj->tki", R_obj, u - c))
        rho = self.cfg.keypoints.finger_radius_m
        x = np.clip((d - rho) / self.cfg.keypoints.scale_blend_m, 0.0, 1.0)
        gap_scale = 1.0 + (s - 1.0) * x * x * (3.0 - 2.0 * x)
        d_target = np.where(d < rho, s * d, s * rho + (d - rho) * gap_scale)  # (T, 21) [m]
        n_world = np.einsum("tij,tkj->tki", R_obj, n_u)
        return u - (d_u - d_target)[..., None] * n_world

    def _frame_margins(self, by_part: np.ndarray) -> np.ndarray:
        """Per frame and hand–object pair, the margin [m] of its non-penetration row: the
        penetration margin where the pair's hand geom stands for a phalanx the human touches
        the object with (``by_part`` (..., F, 3)), or that is no finger part (palm), else the
        clearance ``−noncontact_clearance``; the table pairs keep theirs. Returns
        (..., pairs)."""
        lead = by_part.shape[:-2]
        margins = np.broadcast_to(self._base_margins, (*lead, self._base_margins.size)).copy()
        if self.cfg.collision.noncontact_clearance <= 0:
            return margins
        mask = self._pair_parts  # (pairs, F·3)
        flags = by_part.reshape(*lead, -1).astype(np.int64)
        allowed = flags @ mask.T.astype(np.int64) > 0  # (..., pairs)
        margins[mask.any(axis=1) & ~allowed] = -self.cfg.collision.noncontact_clearance
        return margins

    def _closing_parts(self, tg: dict, fps: float) -> np.ndarray | None:
        """(T, F, 3) factors in [0, 1] on ``closing.weight`` of the finger parts the human touches
        the object with besides each finger's contact part (the closing terms' links): 0 where
        not, rising from 0 to 1 over the ``closing.ramp_s`` after the part's touch began;
        ``None`` without closing terms."""
        if self.contacts is None or not (self.cfg.contacts.enabled and self.cfg.closing.weight > 0):
            return None
        on = np.asarray(tg["contact_by_part"], bool).copy()
        part = np.asarray(tg["contact_part"], int)
        np.put_along_axis(on, part[..., None], False, axis=-1)
        on &= np.asarray(tg["contact_active"], bool)[..., None]
        since = np.zeros(on.shape)  # frames each part has been touching, this one included
        run = np.zeros(on.shape[1:])
        for t in range(on.shape[0]):
            run = np.where(on[t], run + 1, 0)
            since[t] = run
        n = max(self.cfg.closing.ramp_s * fps, 1.0)
        return np.clip(since / n, 0.0, 1.0)

    def _segment_rows(self, k: int) -> np.ndarray:
        """(F, 2) MANO21 rows of each finger's phalanx ``k`` (0: distal, 1: middle,
        2: proximal; the thumb's 1: proximal, 2: metacarpal)."""
        end = lambda f: f"{f}_tip" if k == 0 else f"{f}{4 - k}"  # noqa: E731
        return np.array([[MANO21.index(f"{f}{3 - k}"), MANO21.index(end(f))]
                         for f in self.tip_human])  # fmt: skip

    def _parts_from_records(self, traj: Trajectory) -> np.ndarray:
        """(T, F, 3) bool: the force pipeline's contact records on each finger's distal,
        middle and proximal part (thumb: ip, mcp, cmc)."""
        T, F = traj.num_frames, len(self.tip_sites)
        out = np.zeros((T, F, 3), bool)
        names = {}
        for i, f in enumerate(self.tip_human):
            joints = ("ip", "mcp", "cmc") if f == "thumb" else ("dip", "pip", "mcp")
            for k, j in enumerate(joints):
                names[f"{f}_{j}"] = (i, k)
        c = traj.contacts
        for frame, part in zip(c.frame, c.joint_name, strict=True):
            hit = names.get(part)
            if hit is not None:
                out[frame, hit[0], hit[1]] = True
        return out


def contact_ramp(active: np.ndarray, frames: float) -> np.ndarray:
    """(T, F) weight factors in (0, 1] of contacts ``active`` (T, F): a contact's weight rises
    over its first ``frames`` frames and falls over its last ones (1 where inactive, unused)."""
    T, F = active.shape
    since = np.zeros((T, F))
    until = np.zeros((T, F))
    run = np.zeros(F)
    for t in range(T):
        run = np.where(active[t], run + 1, 0)
        since[t] = run
    run = np.zeros(F)
    for t in range(T - 1, -1, -1):
        run = np.where(active[t], run + 1, 0)
        until[t] = run
    n = max(float(frames), 1.0)
    return np.where(active, np.minimum(1.0, np.minimum(since, until) / n), 1.0)
