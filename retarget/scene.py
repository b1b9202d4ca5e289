"""MuJoCo scenes for retargeting and re-simulation: a robot hand plus a catalogue object.

The object is built from its primitive composition (``dexcanvas_core.demos.object_geometry``):
one geom per primitive, the catalogue mass spread over the primitives by volume. In the
retargeting scene the object is a mocap body (kinematic, posed from the human data); in the
re-simulation scene it is a free body on a table.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from dexcanvas_core.rotations import aa_to_quat_wxyz
from retarget.errors import RetargetError

OBJECT_BODY = "object"
TABLE_GEOM = "table"

_MJ_GEOM = {
    "box": mujoco.mjtGeom.mjGEOM_BOX,
    "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
    "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
    "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
}


def _volume(kind: str, size: tuple[float, ...]) -> float:
    if kind == "box":
        return 8.0 * size[0] * size[1] * size[2]
    if kind == "sphere":
        return 4.0 / 3.0 * np.pi * size[0] ** 3
    if kind == "cylinder":
        return np.pi * size[0] ** 2 * 2.0 * size[1]
    if kind == "capsule":
        return np.pi * size[0] ** 2 * 2.0 * size[1] + 4.0 / 3.0 * np.pi * size[0] ** 3
    raise RetargetError(f"unknown primitive type {kind!r}")


def add_object(
    spec: mujoco.MjSpec,
    geometry,
    *,
    mocap: bool,
    friction: tuple[float, float, float] = (1.0, 0.005, 0.0001),
    rgba: tuple[float, float, float, float] = (0.85, 0.45, 0.2, 1.0),
) -> mujoco.MjsBody:
    """Add the object body (``OBJECT_BODY``) with one geom per primitive.

    ``mocap=True``: a kinematic mocap body (retargeting). ``False``: a free body whose geoms
    carry the catalogue mass split by volume (re-simulation).
    """
    body = spec.worldbody.add_body(name=OBJECT_BODY, mocap=mocap)
    if not mocap:
        body.add_freejoint(name="object_free")
    vols = np.array([_volume(p.type, p.size) for p in geometry.primitives])
    masses = geometry.mass_kg * vols / vols.sum()
    for i, (prim, mass) in enumerate(zip(geometry.primitives, masses, strict=True)):
        size = list(prim.size) + [0.0] * (3 - len(prim.size))
        g = body.add_geom(
            name=f"object_{i}_{prim.name}" if prim.name else f"object_{i}",
            type=_MJ_GEOM[prim.type],
            size=size,
            pos=list(prim.pos),
            quat=list(aa_to_quat_wxyz(np.asarray(prim.rot_aa))),
            rgba=list(rgba),
            friction=list(friction),
        )
        g.mass = float(mass)
        g.contype = 1
        g.conaffinity = 1
        g.condim = 4
    return body


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

    def set_object_pose(self, p_world: np.ndarray, rot_aa: np.ndarray) -> None:
        """Pose the (mocap) object: position [m] and axis-angle [rad]."""
        mid = self.model.body_mocapid[self.object_body]
        if mid < 0:
            raise RetargetError("set_object_pose needs the mocap object of a retargeting scene")
        self.data.mocap_pos[mid] = p_world
        self.data.mocap_quat[mid] = aa_to_quat_wxyz(np.asarray(rot_aa, dtype=np.float64))


def add_table(spec: mujoco.MjSpec) -> None:
    """The table: a plane at z = 0 (world frame), the surface the demonstrations start on."""
    g = spec.worldbody.add_geom(
        name=TABLE_GEOM,
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[1.0, 1.0, 0.01],
        rgba=[0.6, 0.6, 0.6, 1.0],
    )
    g.contype = 1
    g.conaffinity = 1
    g.condim = 3


def build_retarget_scene(hand, geometry=None, table: bool = True) -> Scene:
    """Hand (floating wrist) + the object as a mocap body (+ the table), for the kinematic QP."""
    spec = hand.build_spec()
    if geometry is not None:
        add_object(spec, geometry, mocap=True)
        if table:
            add_table(spec)
    model = spec.compile()
    return _scene(model, geometry is not None)


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
