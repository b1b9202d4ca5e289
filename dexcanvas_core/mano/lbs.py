"""Exact MANO forward pass: shape blend shapes, pose correctives, joint regression, skinning.

Implements the SMPL-family model of Romero, Tzionas & Black (2017), "Embodied Hands: Modeling and
Capturing Hands and Bodies Together" (MANO), for one batch of parameters, in torch:

1. ``v_shaped = v_template + shapedirs · β``                           (shape blend shapes)
2. ``J = J_regressor · v_shaped``                                      (16 rest joints)
3. ``v_posed = v_shaped + posedirs · vec(R_i - I, i = 1..15)``          (pose correctives; the
   feature is the row-major flattening of each non-root joint's local rotation minus identity)
4. forward kinematics of the 16 joints (``kinematics.forward_kinematics``);
5. linear blend skinning: ``v = Σ_k w_vk (R_k v_posed + p_k - R_k J_k)``.

Translation is added by the caller.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from dexcanvas_core.mano.kinematics import forward_kinematics


def mano_lbs(
    betas: torch.Tensor,
    R_local: torch.Tensor,
    v_template: torch.Tensor,
    shapedirs: torch.Tensor,
    posedirs: torch.Tensor,
    J_regressor: torch.Tensor,
    weights: torch.Tensor,
    parents: Sequence[int],
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Posed MANO vertices and joints in the template frame (no translation).

    Args:
        betas: ``(B, S)`` shape coefficients.
        R_local: ``(B, J, 3, 3)`` local joint rotations (index 0: global orientation).
        v_template: ``(V, 3)`` mean template [m].
        shapedirs: ``(V, 3, S)`` shape blend shapes [m].
        posedirs: ``(V, 3, 9·(J-1))`` pose corrective blend shapes [m].
        J_regressor: ``(J, V)`` joint regressor (rows sum to 1).
        weights: ``(V, J)`` skinning weights (rows sum to 1).
        parents: parent of each joint, root ``-1``.

    Returns:
        ``(vertices (B, V, 3), joints (B, J, 3), R_world (B, J, 3, 3))``, template frame [m].
    """
    B, J = R_local.shape[:2]
    V = v_template.shape[0]
    v_shaped = v_template + torch.einsum("bs,vcs->bvc", betas, shapedirs)  # (B, V, 3)
    J_rest = torch.einsum("jv,bvc->bjc", J_regressor, v_shaped)  # (B, J, 3)

    eye = torch.eye(3, dtype=R_local.dtype, device=R_local.device)
    pose_feature = (R_local[:, 1:] - eye).reshape(B, 9 * (J - 1))  # (B, 135)
    pose_offsets = pose_feature @ posedirs.reshape(V * 3, -1).T  # (B, V·3)
    v_posed = v_shaped + pose_offsets.reshape(B, V, 3)

    R_world, p_world = forward_kinematics(R_local, J_rest, parents)
    # Rigid transform of each joint relative to its rest placement: x ↦ R x + (p - R J_rest).
    t_rel = p_world - (R_world @ J_rest[..., None])[..., 0]  # (B, J, 3)
    R_blend = torch.einsum("vj,bjkl->bvkl", weights, R_world)  # (B, V, 3, 3)
    t_blend = torch.einsum("vj,bjk->bvk", weights, t_rel)  # (B, V, 3)
    vertices = (R_blend @ v_posed[..., None])[..., 0] + t_blend
    return vertices, p_world, R_world
