"""The hand marker model: markers and keypoints as functions of the MANO parameters.

Fit parameters per frame, ``x = [global_orient (3), transl (3), hand_pose (45)]`` (axis-angle [rad],
[m], MANO joint order), exactly ``mano_global_rot_aa``, ``mano_global_pos`` and
``mano_hand_pose[:, 3:]`` of a DexCanvas row. The skeleton is a subject's
:class:`~dexcanvas_core.mano.HandSkeleton` (rest keypoints); each marker is carried by one MANO
joint frame at a constant offset from the joint (template frame, see ``layout``). Forward
kinematics follows ``mano.kinematics`` (MANO's semantics) but is evaluated level by level (root,
then the five fingers' first, second and third joints at once), which is what makes the batched
fit fast.

Jacobians are analytic. A local axis-angle ``ω`` changes the joint's rotation as
``R(ω + δ) ≈ R(ω) exp([J_r(ω) δ]×)`` (``J_r``: right Jacobian of SO(3)), so a point ``m`` carried
by the joint (or a descendant) moves by ``dm = (R_world J_r δ) × (m − p_joint)``. Each marker
depends on the 6 root parameters and the 3–9 parameters of its own finger, so the normal
equations have an arrowhead structure: a 6 × 6 root block, five 9 × 9 finger blocks and their
6 × 9 couplings (``NormalEquations``), solved by a Schur complement.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import MANO_FINGER_ORDER, MANO_JOINTS
from dexcanvas_core.mano.skeleton import TIP_PARENTS

N_PARAMS = 51
"""Parameters per frame: 3 global orientation + 3 translation + 45 finger axis-angles."""

_LEVEL_JOINTS = np.array([[1 + 3 * f + lev for f in range(5)] for lev in range(3)])
"""(3, 5): MANO joint index of each finger (MANO order) at each level (MCP/CMC, PIP/MCP, DIP/IP)."""


def skew(v: torch.Tensor) -> torch.Tensor:
    """``(..., 3, 3)`` cross-product matrices of ``(..., 3)`` vectors."""
    x, y, z = v.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack((o, -z, y, z, o, -x, -y, x, o), dim=-1).reshape((*v.shape[:-1], 3, 3))


def right_jacobian(aa: torch.Tensor) -> torch.Tensor:
    """``(..., 3, 3)`` right Jacobian of SO(3) at axis-angles ``(..., 3)``:
    ``J_r = I − (1 − cos θ)/θ² K + (θ − sin θ)/θ³ K²`` (series below θ² = 1e-6)."""
    th2 = (aa * aa).sum(-1, keepdim=True)[..., None]
    small = th2 < 1e-6
    th = torch.sqrt(torch.where(small, torch.ones_like(th2), th2))
    a = torch.where(small, 0.5 - th2 / 24.0, (1.0 - torch.cos(th)) / (th * th))
    b = torch.where(small, 1.0 / 6.0 - th2 / 120.0, (th - torch.sin(th)) / (th * th * th))
    K = skew(aa)
    eye = torch.eye(3, dtype=aa.dtype, device=aa.device)
    return eye - a * K + b * (K @ K)


def rotation_and_jacobian(aa: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Rotation matrices ``R = exp([ω]×)`` and right Jacobians ``J_r(ω)`` of ``(..., 3)``
    axis-angles, sharing one evaluation of the trigonometric coefficients:
    ``R = I + a K + b K²``, ``J_r = I − b K + c K²`` with ``a = sin θ/θ``,
    ``b = (1 − cos θ)/θ²``, ``c = (θ − sin θ)/θ³`` (Taylor series below θ² = 1e-4)."""
    th2 = (aa * aa).sum(-1, keepdim=True)[..., None]
    small = th2 < 1e-4
    safe = torch.where(small, torch.ones_like(th2), th2)
    th = torch.sqrt(safe)
    s, c = torch.sin(th), torch.cos(th)
    a = torch.where(small, 1.0 - th2 / 6.0 + th2 * th2 / 120.0, s / th)
    b = torch.where(small, 0.5 - th2 / 24.0 + th2 * th2 / 720.0, (1.0 - c) / safe)
    cc = torch.where(small, 1.0 / 6.0 - th2 / 120.0 + th2 * th2 / 5040.0, (th - s) / (safe * th))
    K = skew(aa)
    K2 = K @ K
    eye = torch.eye(3, dtype=aa.dtype, device=aa.device)
    return eye + a * K + b * K2, eye - b * K + cc * K2


@dataclass
class PoseState:
    """Forward kinematics of a batch of frames (torch)."""

    x: torch.Tensor  # (B, 51)
    R_world: torch.Tensor  # (B, 16, 3, 3) joint frames, MANO joint order
    p_world: torch.Tensor  # (B, 16, 3) joint positions [m] (translation included)
    markers: torch.Tensor  # (B, M, 3) [m]
    J_r: torch.Tensor | None = None  # (B, 16, 3, 3) right Jacobians of the local axis-angles


@dataclass
class NormalEquations:
    """Gauss–Newton normal equations ``H δ = −g`` in arrowhead blocks, plus the cost."""

    H_rr: torch.Tensor  # (B, 6, 6)
    H_rf: torch.Tensor  # (B, 5, 6, 9)
    H_ff: torch.Tensor  # (B, 5, 9, 9)
    g_r: torch.Tensor  # (B, 6)
    g_f: torch.Tensor  # (B, 5, 9)
    cost: torch.Tensor  # (B,) ½ Σ r²
    residual: torch.Tensor  # (B, M, 3) model − observation [m] (unweighted, 0 where unseen)


class HandMarkerModel:
    """Markers and keypoints of one subject's hand as functions of the fit parameters.

    Args:
        rest_keypoints: ``(21, 3)`` [m] the subject's rest skeleton (MANO21, template frame).
        marker_offsets: ``(M, 3)`` [m] marker minus parent joint at rest (template frame).
        marker_parents: ``(M,)`` parent joint of each marker (index into ``MANO_JOINTS``).
        dtype: torch dtype of the computation (float64 by default).
    """

    def __init__(
        self,
        rest_keypoints: np.ndarray,
        marker_offsets: np.ndarray,
        marker_parents: np.ndarray,
        dtype: torch.dtype = torch.float64,
    ):
        kp = np.asarray(rest_keypoints, dtype=np.float64)
        off = np.asarray(marker_offsets, dtype=np.float64)
        par = np.asarray(marker_parents, dtype=np.int64)
        if kp.shape != (21, 3):
            raise ValidationError(f"rest_keypoints must be (21, 3), got {kp.shape}")
        if off.ndim != 2 or off.shape[1] != 3 or par.shape != (off.shape[0],):
            raise ValidationError(
                f"marker_offsets (M, 3) and marker_parents (M,) disagree: {off.shape}, {par.shape}"
            )
        if par.min() < 0 or par.max() >= len(MANO_JOINTS):
            raise ValidationError("marker_parents must index MANO_JOINTS (0..15)")
        self.dtype = dtype
        self.num_markers = off.shape[0]
        t = lambda a: torch.tensor(np.array(a, dtype=np.float64), dtype=dtype)  # noqa: E731
        J = kp[:16]
        self.rest_keypoints = kp
        self.J0 = t(J[0])
        self.bone = [
            t(J[_LEVEL_JOINTS[0]] - J[0]),
            t(J[_LEVEL_JOINTS[1]] - J[_LEVEL_JOINTS[0]]),
            t(J[_LEVEL_JOINTS[2]] - J[_LEVEL_JOINTS[1]]),
        ]  # (5, 3) each: rest bone vectors entering each level
        self.tip_offsets = t(kp[16:] - kp[list(TIP_PARENTS)])  # (5, 3) thumb..pinky
        self.tip_parents = torch.as_tensor(TIP_PARENTS)
        self.offsets = t(off)
        self.parents = torch.as_tensor(par)
        # finger markers: finger (MANO order) and level (1..3) of the parent joint
        fing = par > 0
        self.root_idx = torch.as_tensor(np.flatnonzero(~fing))
        self.fin_idx = torch.as_tensor(np.flatnonzero(fing))
        self.fin_finger = torch.as_tensor((par[fing] - 1) // 3)
        level = (par[fing] - 1) % 3 + 1
        self.fin_mask = t((np.arange(1, 4)[None, :] <= level[:, None]).astype(np.float64))
        finger_of = (par[fing] - 1) // 3
        slot = np.array([int(np.sum(finger_of[:i] == finger_of[i])) for i in range(len(finger_of))])
        self.fin_slot = torch.as_tensor(slot, dtype=torch.int64)
        self.slots = int(slot.max()) + 1 if slot.size else 1
        self.finger_names = MANO_FINGER_ORDER

    # -- forward ----------------------------------------------------------------------------

    def forward(self, x: torch.Tensor) -> PoseState:
        """Joint frames, joint positions and markers of ``x (B, 51)``."""
        B = x.shape[0]
        aa = torch.cat([x[:, :3], x[:, 6:]], dim=1).reshape(B, 16, 3)
        R_all, J_r = rotation_and_jacobian(aa)
        R0 = R_all[:, 0]  # (B, 3, 3)
        R_loc = R_all[:, 1:].reshape(B, 5, 3, 3, 3)  # finger, level
        p0 = self.J0 + x[:, 3:6]  # (B, 3)
        Rp = R0[:, None].expand(B, 5, 3, 3)
        pp = p0[:, None].expand(B, 5, 3)
        Rs, ps = [], []
        for lev in range(3):
            pp = pp + (Rp @ self.bone[lev][..., None])[..., 0]
            Rp = Rp @ R_loc[:, :, lev]
            Rs.append(Rp)
            ps.append(pp)
        R_fin = torch.stack(Rs, dim=2).reshape(B, 15, 3, 3)  # MANO joint order 1..15
        p_fin = torch.stack(ps, dim=2).reshape(B, 15, 3)
        R_world = torch.cat([R0[:, None], R_fin], dim=1)
        p_world = torch.cat([p0[:, None], p_fin], dim=1)
        markers = (
            p_world[:, self.parents] + (R_world[:, self.parents] @ self.offsets[..., None])[..., 0]
        )
        return PoseState(x, R_world, p_world, markers, J_r)

    def keypoints(self, state: PoseState) -> torch.Tensor:
        """``(B, 21, 3)`` [m] MANO21 keypoints (16 joints, then the thumb…pinky tips)."""
        R_tip = state.R_world[:, self.tip_parents]
        tips = state.p_world[:, self.tip_parents] + (R_tip @ self.tip_offsets[..., None])[..., 0]
        return torch.cat([state.p_world, tips], dim=1)

    # -- linearisation ----------------------------------------------------------------------

    @staticmethod
    def _jr(state: PoseState) -> torch.Tensor:
        if state.J_r is not None:
            return state.J_r
        B = state.x.shape[0]
        aa = torch.cat([state.x[:, :3], state.x[:, 6:]], dim=1).reshape(B, 16, 3)
        return right_jacobian(aa)

    def normal_equations(
        self, state: PoseState, observed: torch.Tensor, weight: torch.Tensor
    ) -> NormalEquations:
        """Gauss–Newton blocks of ``½ Σ_k w_k² |m_k(x) − o_k|²``.

        Args:
            state: ``forward(x)``.
            observed: ``(B, M, 3)`` [m] observed markers (any finite value where unseen).
            weight: ``(B, M)`` ``w_k`` = 1/σ_k [1/m], 0 for unseen markers.
        """
        x = state.x
        B = x.shape[0]
        m = state.markers
        seen = (weight > 0)[..., None]
        res = torch.where(seen, m - torch.where(seen, observed, m), torch.zeros_like(m))
        rw = res * weight[..., None]  # (B, M, 3)
        cost = 0.5 * (rw * rw).sum(dim=(1, 2))

        # root columns: rotation (B, M, 3 xyz, 3) and translation (identity)
        A_all = state.R_world @ self._jr(state)  # (B, 16, 3, 3)
        A0 = A_all[:, 0]
        d0 = m - state.p_world[:, None, 0]  # (B, M, 3)
        # column c of the block: A0[:, c] × d
        cols = torch.linalg.cross(A0.transpose(-1, -2)[:, None], d0[:, :, None, :], dim=-1)
        J_rot = cols.transpose(-1, -2)  # (B, M, 3, 3)
        w = weight[..., None, None]
        J_rot_w = J_rot * w
        eye_w = torch.eye(3, dtype=x.dtype) * w  # (B, M, 3, 3) translation block, weighted
        J_root_w = torch.cat([J_rot_w, eye_w], dim=-1)  # (B, M, 3, 6)

        M = m.shape[1]
        Jr_flat = J_root_w.reshape(B, 3 * M, 6)
        Jr_t = Jr_flat.transpose(1, 2)
        H_rr = Jr_t @ Jr_flat
        g_r = (Jr_t @ rw.reshape(B, 3 * M, 1))[..., 0]

        # finger columns for the finger markers
        fi = self.fin_idx
        p_f = state.p_world[:, 1:].reshape(B, 5, 3, 3)
        A_f = A_all[:, 1:].reshape(B, 5, 3, 3, 3)  # (B, 5, 3 lev, 3, 3)
        A_sel = A_f[:, self.fin_finger]  # (B, Mf, 3, 3, 3)
        d_f = m[:, fi, None, :] - p_f[:, self.fin_finger]  # (B, Mf, 3 lev, 3)
        cols_f = torch.linalg.cross(A_sel.transpose(-1, -2), d_f[:, :, :, None, :], dim=-1)
        cols_f = cols_f * self.fin_mask[None, :, :, None, None]  # (B, Mf, lev, col, xyz)
        J_f_w = cols_f.permute(0, 1, 4, 2, 3).reshape(B, -1, 3, 9) * weight[:, fi, None, None]

        # pad the finger markers into (finger, slot) so each finger's blocks are one matmul
        K = self.slots
        Jf = torch.zeros(B, 5, K, 3, 9, dtype=x.dtype)
        Jf[:, self.fin_finger, self.fin_slot] = J_f_w
        Jrf = torch.zeros(B, 5, K, 3, 6, dtype=x.dtype)
        Jrf[:, self.fin_finger, self.fin_slot] = J_root_w[:, fi]
        rf = torch.zeros(B, 5, K, 3, dtype=x.dtype)
        rf[:, self.fin_finger, self.fin_slot] = rw[:, fi]
        Jf = Jf.reshape(B, 5, 3 * K, 9)
        Jf_t = Jf.transpose(-1, -2)
        H_ff = Jf_t @ Jf
        H_rf = Jrf.reshape(B, 5, 3 * K, 6).transpose(-1, -2) @ Jf
        g_f = (Jf_t @ rf.reshape(B, 5, 3 * K, 1))[..., 0]
        return NormalEquations(H_rr, H_rf, H_ff, g_r, g_f, cost, res)

    def jacobian(self, state: PoseState) -> torch.Tensor:
        """``(B, M, 3, 51)`` dense Jacobian of the markers w.r.t. ``x`` (unweighted)."""
        x = state.x
        B = x.shape[0]
        M = self.num_markers
        m = state.markers
        A_all = state.R_world @ self._jr(state)
        A0 = A_all[:, 0]
        d0 = m - state.p_world[:, None, 0]
        J_rot = torch.linalg.cross(A0.transpose(-1, -2)[:, None], d0[:, :, None, :], dim=-1)
        out = torch.zeros(B, M, 3, N_PARAMS, dtype=x.dtype)
        out[..., :3] = J_rot.transpose(-1, -2)
        out[..., 3:6] = torch.eye(3, dtype=x.dtype)
        fi = self.fin_idx
        p_f = state.p_world[:, 1:].reshape(B, 5, 3, 3)
        A_sel = A_all[:, 1:].reshape(B, 5, 3, 3, 3)[:, self.fin_finger]
        d_f = m[:, fi, None, :] - p_f[:, self.fin_finger]
        cols_f = torch.linalg.cross(A_sel.transpose(-1, -2), d_f[:, :, :, None, :], dim=-1)
        cols_f = cols_f * self.fin_mask[None, :, :, None, None]
        J_f = cols_f.permute(0, 1, 4, 2, 3).reshape(B, -1, 3, 9)
        for k in range(fi.numel()):
            f = int(self.fin_finger[k])
            out[:, int(fi[k]), :, 6 + 9 * f : 15 + 9 * f] = J_f[:, k]
        return out
