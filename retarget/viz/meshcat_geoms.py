"""Drawing geometry into a meshcat scene: materials, poses, primitives, meshes, MuJoCo geoms."""

from __future__ import annotations

import warnings

import numpy as np

from dexcanvas_core.rotations import aa_to_matrix
from retarget.viz import style

_MJ_BOX, _MJ_SPHERE, _MJ_CAPSULE, _MJ_ELLIPSOID, _MJ_CYLINDER, _MJ_MESH = 6, 2, 3, 4, 5, 7
_Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""Rotation taking meshcat's cylinder axis (+y) onto MuJoCo's (+z)."""


def import_meshcat():
    """``import meshcat`` without its DeprecationWarning (0.3.2 imports pyzmq's old ioloop)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import meshcat
    return meshcat


def material(rgba):
    """A meshcat Phong material of colour ``rgba`` (translucent ones do not write depth)."""
    import_meshcat()
    import meshcat.geometry as mg

    kwargs = {"color": style.rgb_hex(rgba), "opacity": float(rgba[3])}
    if rgba[3] < 1.0:
        kwargs["depthWrite"] = False  # translucent layers do not hide what is behind them
    return mg.MeshPhongMaterial(**kwargs)


def pose(R: np.ndarray | None = None, p=None, scale=None) -> np.ndarray:
    """(4, 4) transform: rotation ``R``, then per-axis ``scale``, translation ``p`` [m]."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if scale is not None:
        T[:3, :3] = T[:3, :3] @ np.diag(scale)
    if p is not None:
        T[:3, 3] = p
    return T


def quat_to_matrix(q_wxyz: np.ndarray) -> np.ndarray:
    """(3, 3) rotation of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q_wxyz
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def aa_matrix(aa: np.ndarray) -> np.ndarray:
    """(…, 3, 3) rotation matrices of axis-angle vectors ``aa`` (…, 3) [rad]."""
    return np.asarray(aa_to_matrix(np.asarray(aa, dtype=np.float64)))


def set_primitive(vis, kind: str, size, rgba, T_local: np.ndarray) -> bool:
    """Draw one MuJoCo-style primitive (``box`` half-sizes, ``sphere``, ``capsule``/``cylinder``
    radius and half-length along local z, ``ellipsoid`` radii) at ``vis``; False if unknown."""
    import_meshcat()
    import meshcat.geometry as mg

    mat = material(rgba)
    size = [float(s) for s in size]
    if kind == "box":
        vis.set_object(mg.Box([2 * size[0], 2 * size[1], 2 * size[2]]), mat)
    elif kind == "sphere":
        vis.set_object(mg.Sphere(size[0]), mat)
    elif kind == "ellipsoid":
        vis["e"].set_object(mg.Sphere(1.0), mat)
        vis["e"].set_transform(pose(scale=size[:3]))
    elif kind in ("cylinder", "capsule"):
        vis["c"].set_object(mg.Cylinder(2 * size[1], size[0]), mat)
        vis["c"].set_transform(pose(_Y_TO_Z))
        if kind == "capsule":
            for i, z in enumerate((-size[1], size[1])):
                vis[f"s{i}"].set_object(mg.Sphere(size[0]), mat)
                vis[f"s{i}"].set_transform(pose(p=[0.0, 0.0, z]))
    else:
        return False
    vis.set_transform(T_local)
    return True


def set_mesh(vis, vertices: np.ndarray, faces: np.ndarray, rgba) -> None:
    """Draw a triangle mesh (``vertices (V, 3)`` [m], ``faces (F, 3)``) at ``vis``."""
    import_meshcat()
    import meshcat.geometry as mg

    vis.set_object(
        mg.TriangularMeshGeometry(np.asarray(vertices, np.float32), np.asarray(faces, np.uint32)),
        material(rgba),
    )


_GEOM_KIND = {
    _MJ_BOX: "box",
    _MJ_SPHERE: "sphere",
    _MJ_CAPSULE: "capsule",
    _MJ_ELLIPSOID: "ellipsoid",
    _MJ_CYLINDER: "cylinder",
}


def drawn_geoms(model, hand_geoms: list[int] | None = None) -> list[int]:
    """Hand geoms to draw: the visual ones (no collisions) when the model has any, else all.
    ``hand_geoms``: the hand's geoms (default: every geom not on the world body)."""
    hand = hand_geoms
    if hand is None:
        hand = [g for g in range(model.ngeom) if model.geom_bodyid[g] > 0]
    visual = [g for g in hand if not (model.geom_contype[g] or model.geom_conaffinity[g])]
    return visual or hand


def geom_rgba(model, g: int) -> tuple[float, float, float, float]:
    mat = model.geom_matid[g]
    rgba = model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[g]
    return tuple(float(c) for c in rgba)


def set_model_geom(vis, model, g: int, rgba=None) -> bool:
    """Draw geom ``g`` of a compiled ``MjModel`` at ``vis`` (pose relative to its body), in
    ``rgba`` or the model's colour."""
    import_meshcat()
    import meshcat.geometry as mg

    T_local = pose(quat_to_matrix(model.geom_quat[g]), model.geom_pos[g])
    rgba = geom_rgba(model, g) if rgba is None else rgba
    t = int(model.geom_type[g])
    if t == _MJ_MESH:
        m = int(model.geom_dataid[g])
        v0, nv = model.mesh_vertadr[m], model.mesh_vertnum[m]
        f0, nf = model.mesh_faceadr[m], model.mesh_facenum[m]
        verts = np.asarray(model.mesh_vert[v0 : v0 + nv], dtype=np.float32)
        faces = np.asarray(model.mesh_face[f0 : f0 + nf], dtype=np.uint32)
        vis.set_object(mg.TriangularMeshGeometry(verts, faces), material(rgba))
        vis.set_transform(T_local)
        return True
    kind = _GEOM_KIND.get(t)
    return kind is not None and set_primitive(vis, kind, model.geom_size[g], rgba, T_local)
