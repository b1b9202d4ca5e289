"""MuJoCo scenes of the force pipeline: the simulated MANO hand, a catalogue object, a table.

The table is a box of finite extent (:class:`dexcanvas_core.table.Table`; the trajectory's own,
else the default), not an infinite plane.

Objects are built from their primitive composition
(``dexcanvas_core.objects.geometry.object_geometry``):
primitives exactly, YCB items as the documented primitive compositions of that module, one
geom per primitive with the catalogue mass spread over them by volume. The robot side
(``retarget.scene``) builds its scenes with the same :func:`add_object` and :func:`add_table`.

Physics follows DESIGN.md: ``implicitfast``, elliptic cones, ``impratio`` 10, condim 4 on the
fingertips (3 elsewhere on the hand), a time step of a fraction of the data frame (several
physics steps per frame). :class:`PhysicsSettings` is recorded next to every force annotation.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.mano.skeleton import HandSkeleton
from dexcanvas_core.rotations import aa_to_quat_wxyz
from dexcanvas_core.sim import mujoco_log  # noqa: F401 (MuJoCo's warnings to logging, not a file)
from dexcanvas_core.sim.hand import SimHand, add_hand
from dexcanvas_core.table import DEFAULT_TABLE, Table

OBJECT_BODY = "object"
OBJECT_ANCHOR = "object_anchor"
TABLE_GEOM = "table"
OBJECT_CONTYPE = 1
OBJECT_CONAFFINITY = 1 | 2
"""Objects collide with the table (bit 1) and with hands whose contype has bit 1 or 2."""

_MJ_GEOM = {
    "box": mujoco.mjtGeom.mjGEOM_BOX,
    "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
    "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
    "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
}


def add_object(
    spec: mujoco.MjSpec,
    geometry,
    *,
    mocap: bool,
    friction: tuple[float, float, float] = (1.0, 0.005, 0.0001),
    rgba: tuple[float, float, float, float] = (0.85, 0.45, 0.2, 1.0),
    mass_kg: float | None = None,
) -> mujoco.MjsBody:
    """Add the object body (``OBJECT_BODY``) with one geom per primitive (a mesh object: one
    mesh geom per convex part).

    ``mocap=True``: a kinematic mocap body (retargeting). ``False``: a free body whose geoms
    carry the mass (``mass_kg``, default the catalogue mass) split by volume, or, when the
    geometry gives principal moments (``inertia_diag``), a body with that explicit inertia at
    the volume centroid. The geometry's own ``friction`` (sliding), when set, replaces
    ``friction[0]``.
    """
    body = spec.worldbody.add_body(name=OBJECT_BODY, mocap=mocap)
    if not mocap:
        body.add_freejoint(name="object_free")
    total = geometry.mass_kg if mass_kg is None else float(mass_kg)
    vols = np.array([p.volume for p in geometry.primitives])
    masses = total * vols / vols.sum()
    explicit = geometry.inertia_diag is not None and not mocap
    if explicit:
        body.explicitinertial = True
        body.mass = total
        body.ipos = list(geometry.com)
        body.inertia = list(geometry.inertia_diag)
    fr = list(friction)
    if geometry.friction is not None:
        fr[0] = float(geometry.friction)
    for i, (prim, mass) in enumerate(zip(geometry.primitives, masses, strict=True)):
        name = f"object_{i}_{prim.name}" if prim.name else f"object_{i}"
        if prim.type == "mesh":
            spec.add_mesh(
                name=f"{name}_mesh",
                uservert=prim.part.vertices.ravel().tolist(),
                userface=prim.part.faces.ravel().tolist(),
            )
            g = body.add_geom(
                name=name,
                type=mujoco.mjtGeom.mjGEOM_MESH,
                meshname=f"{name}_mesh",
                rgba=list(rgba),
                friction=fr,
            )
        else:
            size = list(prim.size) + [0.0] * (3 - len(prim.size))
            g = body.add_geom(
                name=name,
                type=_MJ_GEOM[prim.type],
                size=size,
                pos=list(prim.pos),
                quat=list(aa_to_quat_wxyz(np.asarray(prim.rot_aa))),
                rgba=list(rgba),
                friction=fr,
            )
        g.mass = 0.0 if explicit else float(mass)
        g.contype = OBJECT_CONTYPE
        g.conaffinity = OBJECT_CONAFFINITY
        g.condim = 4
    return body


def add_table(
    spec: mujoco.MjSpec,
    table: Table | None = None,
    friction: tuple[float, float, float] = (1.0, 0.005, 0.0001),
):
    """The table (``TABLE_GEOM``): a box of finite extent whose top is the surface the
    demonstrations start on (``table``, default :data:`~dexcanvas_core.table.DEFAULT_TABLE`).
    Beyond its edges nothing holds a hand or an object up."""
    table = DEFAULT_TABLE if table is None else table
    g = spec.worldbody.add_geom(
        name=TABLE_GEOM,
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(table.half_size),
        pos=list(table.box_center),
        quat=list(table.quat_wxyz),
        rgba=[0.6, 0.6, 0.6, 1.0],
        friction=list(friction),
    )
    g.contype = 1
    g.conaffinity = 1
    g.condim = 3
    return g


@dataclass(frozen=True)
class PhysicsSettings:
    """Solver settings of the force pipeline (recorded with every force annotation)."""

    substeps: int = 4
    """Physics steps per data frame (the time step is ``1 / (fps · substeps)``)."""
    integrator: str = "implicitfast"
    cone: str = "elliptic"
    impratio: float = 10.0
    solref: tuple[float, float] = (0.02, 1.0)
    solimp: tuple[float, float, float, float, float] = (0.9, 0.95, 0.001, 0.5, 2.0)
    object_friction: tuple[float, float, float] = (1.0, 0.005, 0.0001)
    """Sliding, torsional [m], rolling [m] friction of the object (MuJoCo takes the max of the
    two geoms' coefficients per contact)."""
    table_friction: tuple[float, float, float] = (0.6, 0.005, 0.0001)
    max_timestep_s: float = 0.0025
    noslip_iterations: int = 0

    def timestep(self, fps: float) -> float:
        dt = 1.0 / (fps * self.substeps)
        if dt > self.max_timestep_s * (1 + 1e-9):
            raise ValidationError(
                f"{self.substeps} physics steps per frame at {fps:g} fps give a {dt * 1e3:.2f} ms "
                f"time step, above the {self.max_timestep_s * 1e3:.1f} ms limit; raise substeps",
                field="substeps",
            )
        return dt

    def as_dict(self, fps: float) -> dict:
        d = dataclasses.asdict(self)
        d["timestep_s"] = self.timestep(fps)
        d["engine"] = f"mujoco {mujoco.__version__}"
        return d


_INTEGRATORS = {
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "euler": mujoco.mjtIntegrator.mjINT_EULER,
    "rk4": mujoco.mjtIntegrator.mjINT_RK4,
}
_CONES = {"elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC, "pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL}


def apply_physics(spec: mujoco.MjSpec, physics: PhysicsSettings, fps: float) -> None:
    """Write the solver settings of ``physics`` into ``spec.option``."""
    if physics.integrator not in _INTEGRATORS or physics.cone not in _CONES:
        raise ValidationError(
            f"integrator must be one of {sorted(_INTEGRATORS)} and cone one of {sorted(_CONES)}",
            field="physics",
        )
    spec.option.timestep = physics.timestep(fps)
    spec.option.integrator = _INTEGRATORS[physics.integrator]
    spec.option.cone = _CONES[physics.cone]
    spec.option.impratio = physics.impratio
    spec.option.o_solref = list(physics.solref)
    spec.option.o_solimp = list(physics.solimp)
    spec.option.noslip_iterations = physics.noslip_iterations


@dataclass
class SimScene:
    """A compiled hand + object + table scene and the ids the tracker and force code use."""

    model: mujoco.MjModel
    data: mujoco.MjData
    hand: SimHand
    geometry: object
    object_body: int
    object_qpos_adr: int
    object_dof_adr: int
    object_geoms: np.ndarray
    table_geom: int
    anchor_mocap: int
    weld_eq: int
    fps: float
    physics: PhysicsSettings
    table: Table | None = DEFAULT_TABLE
    """The scene's table (``table_geom`` is -1 when it has none)."""

    @property
    def mass_kg(self) -> float:
        return float(self.model.body_mass[self.object_body])

    @property
    def substeps(self) -> int:
        return self.physics.substeps

    def support_gap(self, object_pos: np.ndarray, object_quat: np.ndarray) -> np.ndarray:
        """``(...)`` height [m] of the posed object's lowest point above the table top, ``inf``
        where its origin is beyond the table's edges or the scene has no table (nothing holds
        it up); ``object_pos (..., 3)`` [m], ``object_quat (..., 4)`` (w, x, y, z)."""
        p = np.asarray(object_pos, dtype=np.float64)
        R = Rotation.from_quat(np.asarray(object_quat, dtype=np.float64), scalar_first=True)
        low = np.asarray(self.geometry.lowest_z(R.as_matrix(), p), dtype=np.float64)
        if self.table is None:
            return np.full(low.shape, np.inf)
        return self.table.height_above(np.concatenate([p[..., :2], low[..., None]], axis=-1))

    def object_pose(self, data: mujoco.MjData | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Object frame position [m] and quaternion (w, x, y, z) in the world."""
        d = self.data if data is None else data
        a = self.object_qpos_adr
        return d.qpos[a : a + 3].copy(), d.qpos[a + 3 : a + 7].copy()


OBJECT_HOLD = "object_hold"
"""The weld equality that holds the object to the mocap body :data:`OBJECT_ANCHOR`."""


def add_object_hold(spec: mujoco.MjSpec) -> None:
    """A mocap body :data:`OBJECT_ANCHOR` and an inactive weld :data:`OBJECT_HOLD` of the object
    to it: activated, it holds the object where the anchor is (a clip that starts mid-grasp, an
    object leaning on something not captured, ``dexcanvas_core.sim.support``)."""
    anchor = spec.worldbody.add_body(name=OBJECT_ANCHOR, mocap=True)
    anchor.add_site(name="object_anchor_site", size=[0.002, 0, 0])
    eq = spec.add_equality(
        name=OBJECT_HOLD,
        type=mujoco.mjtEq.mjEQ_WELD,
        objtype=mujoco.mjtObj.mjOBJ_BODY,
        name1=OBJECT_BODY,
        name2=OBJECT_ANCHOR,
    )
    eq.active = False
    eq.solref = [0.02, 1.0]


def build_scene(
    geometry,
    skeleton: HandSkeleton,
    *,
    fps: float,
    physics: PhysicsSettings | None = None,
    R_base: np.ndarray | None = None,
    mass_kg: float | None = None,
    friction_scale: float = 1.0,
    table: Table | None = DEFAULT_TABLE,
) -> SimScene:
    """Compile the force pipeline's scene for one demonstration.

    Args:
        geometry: the object's ``ObjectGeometry`` (possibly scaled).
        skeleton: the subject's hand skeleton (right hand).
        fps: the demonstration's frame rate (sets the time step with ``physics.substeps``).
        R_base: base frame of the wrist hinges (see :mod:`dexcanvas_core.sim.hand`).
        mass_kg: object mass (default the catalogue mass).
        friction_scale: multiplies the object's and table's sliding friction.
        table: the table (the trajectory's, ``dexcanvas_core.table.table_of``); ``None``: none.
    """
    physics = PhysicsSettings() if physics is None else physics
    if not (np.isfinite(friction_scale) and friction_scale > 0):
        raise ValidationError(f"friction_scale must be positive, got {friction_scale}")
    spec = mujoco.MjSpec()
    spec.modelname = f"mano_{geometry.object_id}"
    apply_physics(spec, physics, fps)
    spec.compiler.autolimits = True
    spec.compiler.degree = False  # every angle here is in radians
    hand = add_hand(spec, skeleton, R_base=R_base)
    fr = np.array(physics.object_friction) * (friction_scale, 1.0, 1.0)
    add_object(spec, geometry, mocap=False, friction=tuple(fr), mass_kg=mass_kg)
    add_object_hold(spec)
    # fingertip positions in the object frame (the tracker's contact-keeping reward)

    for f in FINGERS:
        spec.add_sensor(
            name=f"tip_in_object_{f}",
            type=mujoco.mjtSensor.mjSENS_FRAMEPOS,
            objtype=mujoco.mjtObj.mjOBJ_SITE,
            objname=f"mano_tip_{f}",
            reftype=mujoco.mjtObj.mjOBJ_BODY,
            refname=OBJECT_BODY,
        )
    if table is not None:
        tf = np.array(physics.table_friction) * (friction_scale, 1.0, 1.0)
        add_table(spec, table, friction=tuple(tf))
    model = spec.compile()
    data = mujoco.MjData(model)
    hand.bind(model)
    obj = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OBJECT_BODY)
    jnt = model.body_jntadr[obj]
    return SimScene(
        model=model,
        data=data,
        hand=hand,
        geometry=geometry,
        object_body=obj,
        object_qpos_adr=int(model.jnt_qposadr[jnt]),
        object_dof_adr=int(model.jnt_dofadr[jnt]),
        object_geoms=np.flatnonzero(model.geom_bodyid == obj),
        table_geom=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, TABLE_GEOM),
        anchor_mocap=int(
            model.body_mocapid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OBJECT_ANCHOR)]
        ),
        weld_eq=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, OBJECT_HOLD),
        fps=float(fps),
        physics=physics,
        table=table,
    )
