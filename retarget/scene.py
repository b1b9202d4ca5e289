"""MuJoCo scenes for retargeting and re-simulation: a robot hand plus a catalogue object.

The object is built from its primitive composition
(``dexcanvas_core.objects.geometry.object_geometry``): one geom per primitive, the catalogue
mass spread over the primitives by volume. In the retargeting scene the object is a mocap body
(kinematic, posed from the human data); in the re-simulation scene it is a free body on a
table (a box of finite extent, :class:`dexcanvas_core.table.Table`).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from dexcanvas_core.rotations import aa_to_quat_wxyz
from dexcanvas_core.sim import mujoco_log  # noqa: F401 (MuJoCo's warnings to logging, not a file)
from dexcanvas_core.sim.scene import OBJECT_BODY, TABLE_GEOM, add_object, add_table
from dexcanvas_core.table import DEFAULT_TABLE, Table, table_of
from retarget.errors import RetargetError

# The object and the table are built exactly as in the force pipeline's scenes.
__all__ = [
    "OBJECT_BODY",
    "TABLE_GEOM",
    "Scene",
    "add_object",
    "add_table",
    "build_retarget_scene",
    "check_table",
]


def check_table(table: Table | None, traj, what: str) -> None:
    """Raise when trajectory ``traj`` names another table than ``table``, the one the scene
    of ``what`` (e.g. ``"Retargeter"``) was built with (``None``: a scene without a table
    takes any trajectory)."""
    if table is None:
        return
    want = table_of(traj)
    if want != table:
        raise RetargetError(
            f"trajectory {traj.uuid} was performed on {want}, but this {what} was built for "
            f"{table}; build it with table=dexcanvas_core.table.table_of(trajectory)"
        )


@dataclass
class Scene:
    """A compiled hand + object scene and the ids the solver and simulator need."""

    model: mujoco.MjModel
    data: mujoco.MjData
    hand_nq: int
    hand_geoms: list[int]
    object_geoms: list[int]
    object_body: int
    table_geoms: list[int]
    table: Table | None = None
    """The table the scene was built with (``None``: none)."""

    def set_object_pose(
        self, p_world: np.ndarray, rot_aa: np.ndarray | None = None, quat_wxyz=None
    ) -> None:
        """Pose the (mocap) object: position [m] and axis-angle [rad], or (``quat_wxyz``) a
        unit quaternion, scalar first (a whole trajectory's converted at once is ~50× cheaper
        than one conversion per frame)."""
        mid = self.model.body_mocapid[self.object_body]
        if mid < 0:
            raise RetargetError("set_object_pose needs the mocap object of a retargeting scene")
        if (rot_aa is None) == (quat_wxyz is None):
            raise RetargetError("set_object_pose: give exactly one of rot_aa and quat_wxyz")
        self.data.mocap_pos[mid] = p_world
        if quat_wxyz is None:
            quat_wxyz = aa_to_quat_wxyz(np.asarray(rot_aa, dtype=np.float64))
        self.data.mocap_quat[mid] = quat_wxyz


def build_retarget_scene(
    hand, geometry=None, table: Table | None = DEFAULT_TABLE, self_collision: bool = False
) -> Scene:
    """Hand (floating wrist) + the object as a mocap body (+ ``table``; ``None``: no table),
    for the kinematic QP. Without an object there is no table either.

    ``self_collision``: build the hand's self-collision variant (``HandModel.build_spec``), so
    that the model's contact filters (``contype``/``conaffinity``, excluded body pairs) describe
    the hand–hand pairs the solver keeps apart; the scene is kinematic either way.
    """
    spec = hand.build_spec(self_collision=self_collision)
    if geometry is not None:
        add_object(spec, geometry, mocap=True)
        if table is not None:
            add_table(spec, table)
    model = spec.compile()
    scene = _scene(model, geometry is not None)
    scene.table = table if scene.table_geoms else None
    return scene


def _scene(model: mujoco.MjModel, with_object: bool) -> Scene:
    names = [
        mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or "" for g in range(model.ngeom)
    ]
    hand_geoms = [g for g, n in enumerate(names) if n.endswith("_collision") or "_collision_" in n]
    obj_body = (
        mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OBJECT_BODY) if with_object else -1
    )
    object_geoms = [
        g for g in range(model.ngeom) if with_object and model.geom_bodyid[g] == obj_body
    ]
    hand_nq = sum(1 for j in range(model.njnt) if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE)
    table = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, TABLE_GEOM)
    return Scene(
        model=model,
        data=mujoco.MjData(model),
        hand_nq=hand_nq,
        hand_geoms=hand_geoms,
        object_geoms=object_geoms,
        object_body=obj_body,
        table_geoms=[table] if table >= 0 else [],
    )
