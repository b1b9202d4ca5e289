"""Batched, differentiable forward kinematics of the robot hands in torch (pytorch-kinematics).

Training code computes robot keypoints and retargeting losses on any device:

    fk = TorchHandFK(get_hand("shadow"), device="cuda")
    p = fk.site_positions(q)            # (B, S, 3) for q (B, nq) in MuJoCo qpos order
    loss = ((p - targets) ** 2).sum()   # differentiable w.r.t. q

The chain is built from the same compiled ``MjModel`` as every other backend: it is exported to
a kinematic URDF (``retarget.urdf_export.export_urdf``, exact to double precision)
and loaded with ``pytorch_kinematics``; every joint is independent (couplings are the caller's
business, as for ``qpos``), and every MuJoCo site is a frame of the chain.
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from pathlib import Path

import torch

from dexcanvas_core.checks import check_type
from retarget.errors import RetargetError
from retarget.hands.model import HandModel
from retarget.urdf_export import export_urdf


class TorchHandFK:
    """Forward kinematics of one hand for ``(B, nq)`` joint tensors (MuJoCo ``qpos`` order).

    >>> from retarget import get_hand
    >>> fk = TorchHandFK(get_hand("shadow"))
    >>> q = torch.zeros(4, fk.nq, requires_grad=True)       # (B, nq), MuJoCo qpos order
    >>> p = fk.site_positions(q)                             # (B, S, 3)
    >>> p.shape[0], p.shape[2]
    (4, 3)
    >>> p.sum().backward(); q.grad.shape                     # differentiable w.r.t. q
    torch.Size([4, 30])
    """

    def __init__(
        self, hand, device: str | torch.device = "cpu", dtype: torch.dtype = torch.float32
    ):
        import pytorch_kinematics as pk

        check_type(
            "hand",
            hand,
            HandModel,
            hint="; get one with retarget.get_hand(NAME)",
            error=RetargetError,
        )
        model = hand.compile()
        with tempfile.TemporaryDirectory() as tmp:
            exp = export_urdf(model, Path(tmp) / f"{hand.name}.urdf", couplings=False)
            urdf = exp.path.read_text()
        self.hand = hand.name
        self.chain = pk.build_chain_from_urdf(urdf).to(dtype=dtype, device=device)
        self.joint_names: list[str] = list(exp.joint_names)  # MuJoCo qpos order
        chain_joints = self.chain.get_joint_parameter_names()
        missing = set(self.joint_names) - set(chain_joints)
        if missing:
            raise RetargetError(f"torch FK of {hand.name}: joints missing from the chain {missing}")
        # Chain joint i takes qpos column perm[i].
        self._perm = torch.tensor(
            [self.joint_names.index(j) for j in chain_joints], device=device, dtype=torch.long
        )
        self.site_links: dict[str, str] = dict(exp.site_links)
        self.nq = len(self.joint_names)
        self.device, self.dtype = torch.device(device), dtype

    def to(self, device: str | torch.device) -> TorchHandFK:
        self.chain = self.chain.to(device=device)
        self._perm = self._perm.to(device)
        self.device = torch.device(device)
        return self

    def _check(self, q: torch.Tensor) -> torch.Tensor:
        if q.ndim != 2 or q.shape[1] != self.nq:
            raise RetargetError(f"q must have shape (B, {self.nq}), got {tuple(q.shape)}")
        return q.index_select(1, self._perm)

    def link_poses(self, q: torch.Tensor) -> dict[str, torch.Tensor]:
        """Every link's world pose as ``(B, 4, 4)`` matrices (sites under their own names)."""
        tf = self.chain.forward_kinematics(self._check(q))
        return {name: t.get_matrix() for name, t in tf.items()}

    def site_positions(self, q: torch.Tensor, sites: Sequence[str] | None = None) -> torch.Tensor:
        """``(B, S, 3)`` world positions [m] of ``sites`` (default: every MuJoCo site)."""
        sites = list(self.site_links) if sites is None else list(sites)
        unknown = [s for s in sites if s not in self.site_links]
        if unknown:
            raise RetargetError(
                f"unknown site(s) {unknown}; {self.hand} has: {', '.join(sorted(self.site_links))}"
            )
        links = [self.site_links[s] for s in sites]
        tf = self.chain.forward_kinematics(
            self._check(q), frame_indices=self.chain.get_frame_indices(*links)
        )
        return torch.stack([tf[name].get_matrix()[:, :3, 3] for name in links], dim=1)
