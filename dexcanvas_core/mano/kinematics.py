"""Rotations and the forward kinematics of a joint tree (torch, batched, differentiable).

Both MANO paths (the exact model and the built-in skeleton) share these two functions, so they
give the same joint locations for the same rest joints and pose by construction.

Conventions (MANO's, as in its reference implementation and in ``smplx``):

* each joint ``i`` carries a local rotation ``R_local[i]`` (axis-angle → Rodrigues) about its own
  rest location, expressed in its parent's frame; the rest orientation of every joint frame is the
  identity in the template frame;
* the root's rotation (global orientation) turns the hand about the root's rest location ``J[0]``;
* ``T_world[i] = T_world[parent] ∘ (R_local[i], J[i] - J[parent])`` and ``T_world[0] =
  (R_local[0], J[0])``, so the posed joint locations are the translations of ``T_world``.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from dexcanvas_core.errors import ValidationError

_SMALL_ANGLE_SQ = 1e-4
"""Below this squared angle [rad²] the Rodrigues coefficients use their Taylor series.

The series are truncated after the θ⁴ term, whose remainder is below θ⁶/5040 ≈ 2e-16 here, so the
switch is invisible in float64; in float32 it avoids dividing by a vanishing angle.
"""


def axis_angle_to_matrix(axis_angle: torch.Tensor) -> torch.Tensor:
    """Rotation matrices from axis-angle vectors (Rodrigues' formula).

    Args:
        axis_angle: ``(..., 3)`` rotation vectors: unit axis times angle [rad].

    Returns:
        ``(..., 3, 3)`` rotation matrices, same dtype and device. Exact and differentiable at the
        zero rotation (no ε added to the angle).

    ``R = I + a·K + b·K²`` with ``K`` the cross-product matrix of the rotation vector,
    ``a = sin θ / θ`` and ``b = (1 - cos θ) / θ² = ½ (sin(θ/2) / (θ/2))²`` (the second form has no
    cancellation for small θ).
    """
    theta_sq = (axis_angle * axis_angle).sum(-1, keepdim=True)  # (..., 1)
    small = theta_sq < _SMALL_ANGLE_SQ
    safe_sq = torch.where(small, torch.ones_like(theta_sq), theta_sq)
    theta = torch.sqrt(safe_sq)
    half = 0.5 * theta
    a_exact = torch.sin(theta) / theta
    b_exact = 0.5 * (torch.sin(half) / half) ** 2
    a_series = 1.0 - theta_sq / 6.0 + theta_sq * theta_sq / 120.0
    b_series = 0.5 - theta_sq / 24.0 + theta_sq * theta_sq / 720.0
    a = torch.where(small, a_series, a_exact)[..., None]  # (..., 1, 1)
    b = torch.where(small, b_series, b_exact)[..., None]

    x, y, z = axis_angle.unbind(-1)
    zero = torch.zeros_like(x)
    K = torch.stack((zero, -z, y, z, zero, -x, -y, x, zero), dim=-1).reshape(
        (*axis_angle.shape[:-1], 3, 3)
    )
    eye = torch.eye(3, dtype=axis_angle.dtype, device=axis_angle.device)
    return eye + a * K + b * (K @ K)


def forward_kinematics(
    R_local: torch.Tensor, J_rest: torch.Tensor, parents: Sequence[int]
) -> tuple[torch.Tensor, torch.Tensor]:
    """Chain local joint rotations down a kinematic tree.

    Args:
        R_local: ``(B, J, 3, 3)`` local rotation of each joint (index 0 = root = global
            orientation), in its parent's frame.
        J_rest: ``(B, J, 3)`` or ``(J, 3)`` rest joint locations in the template frame [m].
        parents: parent index of each joint, ``-1`` for the root; every parent must come before
            its children (true for MANO's ``kintree_table``).

    Returns:
        ``(R_world, p_world)``: ``(B, J, 3, 3)`` rotation of each joint frame relative to the
        template frame, and ``(B, J, 3)`` posed joint locations [m] (no translation added).
    """
    n_joints = len(parents)
    if J_rest.dim() == 2:
        J_rest = J_rest.expand(R_local.shape[0], -1, -1)
    R_world: list[torch.Tensor] = [R_local[:, 0]]
    p_world: list[torch.Tensor] = [J_rest[:, 0]]
    for i in range(1, n_joints):
        p = parents[i]
        if not 0 <= p < i:
            raise ValidationError(
                f"parents must list each parent before its child; joint {i} has parent {p}",
                field="parents",
            )
        offset = J_rest[:, i] - J_rest[:, p]  # (B, 3), in the template frame
        R_world.append(R_world[p] @ R_local[:, i])
        p_world.append(p_world[p] + (R_world[p] @ offset[..., None])[..., 0])
    return torch.stack(R_world, dim=1), torch.stack(p_world, dim=1)
