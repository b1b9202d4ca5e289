"""``ManoLayer``: one API for MANO hand kinematics, with or without the official model files.

* **Exact path** (``layer.exact is True``): when ``model_dir`` (or ``$MANO_MODEL_DIR``) holds
  ``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl``, the layer computes MANO itself (shape blend shapes, pose
  correctives, joint regression, skinning; ``lbs.mano_lbs``): 16 joints, 778 vertices, and the five
  fingertips taken from the mesh. This path is the reference.
* **Skeleton path** (``layer.exact is False``): without model files, a built-in MANO-compatible
  skeleton (``skeleton.HandSkeleton``: MANO's mean hand by default, or a subject's measured bone
  lengths) is posed with the same kinematic tree and the same axis-angle semantics. It gives
  joints and keypoints, no mesh.

Semantics shared by both paths (MANO's, identical to ``smplx.MANO``): ``hand_pose`` holds the
axis-angle [rad] of the 15 finger joints in MANO joint order (index, middle, pinky, ring, thumb;
three joints each), each a rotation about the joint's rest location in its parent's frame;
``global_orient`` rotates the whole hand about the (shaped) rest wrist joint J0; then ``transl``
[m] is added, so the posed wrist is at ``J0 + transl``. Outputs are in the frame the parameters
are expressed in (world frame for DexCanvas data).

Known quirk of the official files, kept for parity with ``smplx``: ``MANO_LEFT.pkl``'s
``shapedirs`` has the sign of its x component flipped relative to the right model (smplx issue
#48), so equal betas do not give mirror-image hands; some projects negate
``shapedirs[:, 0, :]`` of the left model. This layer uses the file as is.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS, MANO_JOINTS, MANO_PARENTS
from dexcanvas_core.mano.kinematics import axis_angle_to_matrix, forward_kinematics
from dexcanvas_core.mano.lbs import mano_lbs
from dexcanvas_core.mano.model_file import ManoModelData, load_mano_model, resolve_model_file
from dexcanvas_core.mano.pose import _MANO_HANDS_MEAN_RIGHT, mirror_axis_angle, split_full_pose
from dexcanvas_core.mano.skeleton import (
    BETA0_SCALE_PER_UNIT,
    TIP_PARENTS,
    HandSkeleton,
    Side,
    _check_side,
)

logger = logging.getLogger(__name__)

NUM_BETAS = 10
"""Number of shape coefficients the layer takes (MANO's released models have 10)."""

MANO_TIP_VERTEX_IDS: dict[str, int] = {
    "thumb": 744,
    "index": 320,
    "middle": 443,
    "ring": 554,
    "pinky": 671,
}
"""Mesh vertex of each fingertip on MANO's 778-vertex mesh (both sides share the topology).

Source: ``smplx.vertex_ids.VERTEX_IDS['mano']`` (vchoutas/smplx), the fingertips most MANO layers
use. Other public layers pick neighbouring vertices (e.g. minimal-hand 333/444/555/672/744), a
difference of about a millimetre.
"""


@dataclass
class ManoOutput:
    """Result of a ``ManoLayer`` forward pass (torch tensors, or numpy from ``forward_numpy``).

    Attributes:
        joints: ``(B, 16, 3)`` posed MANO joints [m], ``MANO_JOINTS`` order.
        keypoints: ``(B, 21, 3)`` joints then the thumb…pinky tips [m], ``MANO21`` order.
        vertices: ``(B, 778, 3)`` posed mesh [m] (exact path), else ``None``.
        joint_rotations: ``(B, 16, 3, 3)`` orientation of each joint frame relative to the
            template frame (rest orientation = identity), in the output frame.
    """

    joints: Any
    keypoints: Any
    vertices: Any | None
    joint_rotations: Any


def _shape_str(shape: tuple[Any, ...]) -> str:
    return "(" + ", ".join(str(s) for s in shape) + ")"


class ManoLayer(nn.Module):
    """MANO-compatible hand: (betas, global orientation, pose, translation) → joints, keypoints.

    Args:
        side: ``"right"`` or ``"left"``.
        model_dir: folder holding the official ``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl``. ``None``
            reads ``$MANO_MODEL_DIR``; if that is unset or lacks the file, the built-in skeleton
            is used. An explicit folder without the file is an error.
        bone_lengths: a subject's ``(20,)`` bone lengths [m] (``skeleton.BONE_NAMES`` order, e.g.
            ``measure_bone_lengths(mano_joint_pos)``) or a per-finger mapping; forces the
            skeleton path, and betas are then ignored (the lengths already are the subject's).
        flat_hand_mean: ``True`` (default, as DexCanvas and ``smplx(flat_hand_mean=True)``): a
            zero ``hand_pose`` is the flat hand. ``False``: MANO's mean pose ``hands_mean`` is
            added to ``hand_pose``.
        skeleton: a ready ``HandSkeleton`` for the skeleton path (exclusive with
            ``bone_lengths``; e.g. ``HandSkeleton.anthropometric(0.19)``); mirrored if built for
            the other side. Betas are ignored, as with ``bone_lengths``.
        beta0_scale_per_unit: skeleton path only; the hand is scaled about J0 by
            ``exp(beta0_scale_per_unit · β₀)`` and ``β₁…β₉`` are ignored — an approximation
            (see ``skeleton.BETA0_SCALE_PER_UNIT`` for its derivation); ``0`` ignores betas.
            The exact path is the reference for betas.

    Attributes:
        exact: ``True`` when the official model is used.
        skeleton: the ``HandSkeleton`` of the skeleton path (``None`` on the exact path).
        model: the loaded ``ManoModelData`` (``None`` on the skeleton path).

    >>> import numpy as np
    >>> from dexcanvas_core import ManoLayer
    >>> out = ManoLayer().forward_numpy(hand_pose=np.zeros((1, 45)))  # the flat hand
    >>> out.keypoints.shape, out.joints.shape
    ((1, 21, 3), (1, 16, 3))
    """

    def __init__(
        self,
        side: Side = "right",
        model_dir: str | Path | None = None,
        bone_lengths: Any = None,
        flat_hand_mean: bool = True,
        *,
        skeleton: HandSkeleton | None = None,
        beta0_scale_per_unit: float = BETA0_SCALE_PER_UNIT,
    ):
        super().__init__()
        _check_side(side)
        if bone_lengths is not None and skeleton is not None:
            raise ValidationError("give bone_lengths or skeleton, not both", field="bone_lengths")
        custom_skeleton = bone_lengths is not None or skeleton is not None
        if custom_skeleton and model_dir is not None:
            raise ValidationError(
                "bone_lengths/skeleton select the built-in skeleton; they cannot be combined with "
                f"model_dir={str(model_dir)!r} (the exact MANO model has its own shape)",
                field="bone_lengths",
            )
        self.side: Side = side
        self.flat_hand_mean = bool(flat_hand_mean)
        self.beta0_scale_per_unit = float(beta0_scale_per_unit)
        self.num_betas = NUM_BETAS
        self.model: ManoModelData | None = None
        self.skeleton: HandSkeleton | None = None
        self._use_betas = not custom_skeleton
        self._warned_betas = False

        model_path = None if custom_skeleton else resolve_model_file(side, model_dir)
        f64 = torch.float64
        if model_path is not None:
            model = load_mano_model(model_path)
            if model.num_betas < NUM_BETAS:
                raise ValidationError(
                    f"MANO model {model_path} has {model.num_betas} shape components, "
                    f"need {NUM_BETAS}",
                    field="shapedirs",
                )
            self.model = model
            self.register_buffer(
                "v_template", torch.as_tensor(model.v_template, dtype=f64), persistent=False
            )
            self.register_buffer(
                "shapedirs",
                torch.as_tensor(model.shapedirs[..., :NUM_BETAS], dtype=f64),
                persistent=False,
            )
            self.register_buffer(
                "posedirs", torch.as_tensor(model.posedirs, dtype=f64), persistent=False
            )
            self.register_buffer(
                "J_regressor", torch.as_tensor(model.J_regressor, dtype=f64), persistent=False
            )
            self.register_buffer(
                "lbs_weights", torch.as_tensor(model.weights, dtype=f64), persistent=False
            )
            hands_mean = model.hands_mean
            logger.info("ManoLayer(%s): exact MANO from %s", side, model_path)
        else:
            if skeleton is None:
                skeleton = (
                    HandSkeleton.default(side)
                    if bone_lengths is None
                    else HandSkeleton.from_bone_lengths(bone_lengths, side=side)
                )
            elif skeleton.side != side:
                skeleton = skeleton.mirrored()
            self.skeleton = skeleton
            self.register_buffer(
                "rest_keypoints",
                torch.tensor(skeleton.rest_keypoints, dtype=f64),
                persistent=False,
            )
            hands_mean = (
                _MANO_HANDS_MEAN_RIGHT
                if side == "right"
                else mirror_axis_angle(_MANO_HANDS_MEAN_RIGHT)
            )
            logger.debug("ManoLayer(%s): built-in skeleton (no MANO model file)", side)
        self.register_buffer("hands_mean", torch.tensor(hands_mean, dtype=f64), persistent=False)
        self._tip_vertex_ids = [MANO_TIP_VERTEX_IDS[f] for f in FINGERS]  # MANO21 tip order

    # -- properties ---------------------------------------------------------------------------

    @property
    def exact(self) -> bool:
        """``True`` when the official MANO model is used (vertices available)."""
        return self.model is not None

    @property
    def faces(self) -> np.ndarray | None:
        """``(1538, 3)`` mesh triangles (vertex indices) on the exact path, else ``None``."""
        return None if self.model is None else self.model.faces

    def extra_repr(self) -> str:
        source = f"model={self.model.path}" if self.model is not None else "skeleton"
        return (
            f"side={self.side!r}, exact={self.exact}, {source}, "
            f"flat_hand_mean={self.flat_hand_mean}"
        )

    # -- input handling -----------------------------------------------------------------------

    def _prepare(
        self, betas: Any, global_orient: Any, hand_pose: Any, transl: Any
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        named = {
            "betas": betas,
            "global_orient": global_orient,
            "hand_pose": hand_pose,
            "transl": transl,
        }
        tensors: dict[str, torch.Tensor] = {}
        for name, value in named.items():
            if value is None:
                continue
            if not isinstance(value, torch.Tensor):
                try:
                    value = torch.as_tensor(np.asarray(value, dtype=np.float64))
                except (TypeError, ValueError) as exc:
                    raise ValidationError(
                        f"{name} must be a numeric array, got {type(value).__name__}", field=name
                    ) from exc
            elif not value.is_floating_point():
                raise ValidationError(
                    f"{name} must be a floating-point tensor, got dtype {value.dtype}", field=name
                )
            tensors[name] = value

        if tensors:
            devices = {t.device for t in tensors.values()}
            if len(devices) > 1:
                listed = ", ".join(f"{n} on {t.device}" for n, t in tensors.items())
                raise ValidationError(f"inputs must share one device, got {listed}")
            dtype = tensors[next(iter(tensors))].dtype
            for t in tensors.values():
                dtype = torch.promote_types(dtype, t.dtype)
            device = devices.pop()
            tensors = {n: t.to(dtype) for n, t in tensors.items()}
        else:
            dtype, device = torch.get_default_dtype(), torch.device("cpu")

        pose = tensors.get("hand_pose")
        if pose is not None:
            if pose.dim() != 2 or pose.shape[1] not in (45, 48):
                raise ValidationError(
                    f"hand_pose must have shape (B, 45) or (B, 48), got {_shape_str(pose.shape)}",
                    field="hand_pose",
                )
            if pose.shape[1] == 48:
                if "global_orient" in tensors:
                    raise ValidationError(
                        "hand_pose has shape (B, 48) (global orientation included) but "
                        "global_orient is also given; pass (B, 45) or drop global_orient",
                        field="hand_pose",
                    )
                tensors["global_orient"], tensors["hand_pose"] = split_full_pose(pose)

        batch_sizes = {n: t.shape[0] for n, t in tensors.items() if t.dim() >= 1 and n != "betas"}
        b = tensors.get("betas")
        if b is not None and b.dim() == 2 and b.shape[0] != 1:
            batch_sizes["betas"] = b.shape[0]
        if len(set(batch_sizes.values())) > 1:
            listed = ", ".join(f"{n}: {s}" for n, s in batch_sizes.items())
            raise ValidationError(f"inputs disagree on the batch size B ({listed})")
        B = next(iter(batch_sizes.values())) if batch_sizes else 1

        expected = {"global_orient": (B, 3), "hand_pose": (B, 45), "transl": (B, 3)}
        for name, shape in expected.items():
            t = tensors.get(name)
            if t is None:
                tensors[name] = torch.zeros(shape, dtype=dtype, device=device)
            elif tuple(t.shape) != shape:
                raise ValidationError(
                    f"{name} must have shape (B, {shape[1]}) with B = {B}, "
                    f"got {_shape_str(t.shape)}",
                    field=name,
                )
        if b is None:
            b = torch.zeros((B, self.num_betas), dtype=dtype, device=device)
        else:
            given_shape = _shape_str(b.shape)
            if b.dim() == 1:
                b = b[None]
            if b.dim() != 2 or b.shape[1] != self.num_betas or b.shape[0] not in (1, B):
                raise ValidationError(
                    f"betas must have shape (B, {self.num_betas}), (1, {self.num_betas}) or "
                    f"({self.num_betas},) with B = {B}, got {given_shape}",
                    field="betas",
                )
            b = b.expand(B, -1)
        tensors["betas"] = b

        for name in ("betas", "global_orient", "hand_pose", "transl"):
            if not torch.isfinite(tensors[name]).all():
                raise ValidationError(f"{name} has NaN or inf values", field=name)
        return tensors["betas"], tensors["global_orient"], tensors["hand_pose"], tensors["transl"]

    # -- forward ------------------------------------------------------------------------------

    def forward(
        self,
        betas: Any = None,
        global_orient: Any = None,
        hand_pose: Any = None,
        transl: Any = None,
    ) -> ManoOutput:
        """Pose the hand (batched, differentiable through torch autograd).

        Args:
            betas: ``(B, 10)``, ``(1, 10)`` or ``(10,)`` shape coefficients; default zeros.
            global_orient: ``(B, 3)`` axis-angle [rad] of the hand about the rest wrist J0;
                default zeros.
            hand_pose: ``(B, 45)`` finger axis-angles [rad] in MANO joint order, or ``(B, 48)``
                = DexCanvas ``mano_hand_pose`` (3 global + 45) when ``global_orient`` is None;
                default zeros (the flat hand, or MANO's mean pose if ``flat_hand_mean=False``).
            transl: ``(B, 3)`` translation [m] added last; default zeros.

        Inputs may be tensors or array-likes; they are promoted to a common floating dtype and
        must share a device. Outputs have that dtype and device (with no inputs at all: B = 1,
        torch's default dtype, CPU).

        Returns:
            ``ManoOutput`` with ``joints (B, 16, 3)``, ``keypoints (B, 21, 3)`` (MANO21),
            ``vertices (B, 778, 3)`` or ``None``, ``joint_rotations (B, 16, 3, 3)``.

        Raises:
            ValidationError: wrong shapes, inconsistent batch sizes, NaN/inf values.
        """
        betas, global_orient, hand_pose, transl = self._prepare(
            betas, global_orient, hand_pose, transl
        )
        dtype, device = hand_pose.dtype, hand_pose.device
        B = hand_pose.shape[0]

        def buf(name: str) -> torch.Tensor:
            return getattr(self, name).to(device=device, dtype=dtype)

        if not self.flat_hand_mean:
            hand_pose = hand_pose + buf("hands_mean")
        axis_angle = torch.cat([global_orient, hand_pose], dim=-1).reshape(B, len(MANO_JOINTS), 3)
        R_local = axis_angle_to_matrix(axis_angle)  # (B, 16, 3, 3)

        vertices = None
        if self.model is not None:
            vertices, joints, R_world = mano_lbs(
                betas,
                R_local,
                buf("v_template"),
                buf("shapedirs"),
                buf("posedirs"),
                buf("J_regressor"),
                buf("lbs_weights"),
                MANO_PARENTS,
            )
            tips = vertices[:, self._tip_vertex_ids]
        else:
            rest = buf("rest_keypoints")  # (21, 3)
            n_joints = len(MANO_JOINTS)
            tip_offsets = rest[n_joints:] - rest[list(TIP_PARENTS)]  # (5, 3)
            if self._use_betas and self.beta0_scale_per_unit != 0.0:
                self._warn_ignored_betas(betas)
                scale = torch.exp(self.beta0_scale_per_unit * betas[:, :1])[..., None]  # (B,1,1)
                J_rest = rest[:1] + scale * (rest[:n_joints] - rest[:1])  # (B, 16, 3)
                tip_offsets = scale * tip_offsets  # (B, 5, 3)
            else:
                if not self._use_betas:
                    self._warn_ignored_betas(betas, all_ignored=True)
                J_rest = rest[:n_joints]
            joints_R, joints = forward_kinematics(R_local, J_rest, MANO_PARENTS)
            R_world = joints_R
            R_tip = R_world[:, list(TIP_PARENTS)]  # (B, 5, 3, 3)
            tips = joints[:, list(TIP_PARENTS)] + (R_tip @ tip_offsets[..., None])[..., 0]

        offset = transl[:, None, :]
        joints = joints + offset
        keypoints = torch.cat([joints, tips + offset], dim=1)
        if vertices is not None:
            vertices = vertices + offset
        return ManoOutput(
            joints=joints, keypoints=keypoints, vertices=vertices, joint_rotations=R_world
        )

    def _warn_ignored_betas(self, betas: torch.Tensor, all_ignored: bool = False) -> None:
        if self._warned_betas:
            return
        ignored = betas if all_ignored else betas[:, 1:]
        if bool((ignored != 0).any()):
            self._warned_betas = True
            what = (
                "all betas (the skeleton was built from bone lengths)"
                if all_ignored
                else "betas[1:] (the skeleton path models only beta_0, as a size scale)"
            )
            logger.warning("ManoLayer(%s, skeleton): ignoring %s", self.side, what)

    def forward_numpy(
        self,
        betas: Any = None,
        global_orient: Any = None,
        hand_pose: Any = None,
        transl: Any = None,
    ) -> ManoOutput:
        """``forward`` on numpy arrays: inputs as float64 array-likes (same shapes), outputs as
        float64 numpy arrays, no autograd graph."""
        args = {}
        for name, value in (
            ("betas", betas),
            ("global_orient", global_orient),
            ("hand_pose", hand_pose),
            ("transl", transl),
        ):
            if value is None:
                args[name] = None
                continue
            try:
                args[name] = torch.as_tensor(np.asarray(value, dtype=np.float64))
            except (TypeError, ValueError) as exc:
                raise ValidationError(
                    f"{name} must be a numeric array, got {type(value).__name__}", field=name
                ) from exc
        if all(v is None for v in args.values()):
            args["hand_pose"] = torch.zeros((1, 45), dtype=torch.float64)
        with torch.no_grad():
            out = self.forward(**args)

        def to_np(t: torch.Tensor | None) -> np.ndarray | None:
            return None if t is None else t.detach().cpu().numpy()

        return ManoOutput(
            joints=to_np(out.joints),
            keypoints=to_np(out.keypoints),
            vertices=to_np(out.vertices),
            joint_rotations=to_np(out.joint_rotations),
        )
