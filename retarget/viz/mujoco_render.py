"""Stills through MuJoCo's offscreen renderer (for machines without Chromium).

The picture matches the meshcat one: same colours, camera and layout. The parent process builds
a MuJoCo model of the scene (the hand's drawn geoms in the robot colour, the simulated and the
reference object as mocap bodies, a table, a white sky), poses per frame, and the extra
drawings MuJoCo has no bodies for (the human skeleton, contact points, force arrows) as lists of
spheres and connectors; a child process (``python -m retarget.viz.mujoco_child JOB``) renders
them with ``MUJOCO_GL`` set to ``egl`` (Debian ``libegl1 libegl-mesa0 libgl1-mesa-dri``) or
``osmesa`` (``libosmesa6``). The GL backend is chosen when ``mujoco`` is imported, so each try
runs in a fresh process; a crash in a GL driver cannot take the caller down either.
"""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

import mujoco
import numpy as np

from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.rotations import aa_to_quat_wxyz
from retarget.viz import style
from retarget.viz.meshcat_geoms import drawn_geoms
from retarget.viz.mujoco_child import KIND_ARROW, KIND_CAPSULE

BACKENDS: dict[str, str] = {
    "egl": "apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri",
    "osmesa": "apt-get install libosmesa6",
}
"""MuJoCo GL backends tried in order, with the Debian packages each needs."""

log = logging.getLogger(__name__)


def build_model(hand, object_id: str, data, framing, options):
    """The scene as an ``MjModel``: drawn hand geoms, the two objects (mocap), table, sky."""
    spec = hand.build_spec()
    hand_nbody = hand.compile().nbody  # the hand's bodies come first; ours are added after
    for t in list(spec.textures):
        if t.type == mujoco.mjtTexture.mjTEXTURE_SKYBOX:
            spec.delete(t)
    white = list(style.BACKGROUND_RGB)
    spec.add_texture(
        name="viz_sky",
        type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
        rgb1=white,
        rgb2=white,
        width=16,
        height=16,
    )
    vis = spec.visual
    vis.global_.fovy = float(framing.whole.fovy)
    vis.global_.offwidth = max(int(options.width), vis.global_.offwidth)
    vis.global_.offheight = max(int(options.height), vis.global_.offheight)
    vis.headlight.ambient = [0.45, 0.45, 0.45]
    vis.headlight.diffuse = [0.55, 0.55, 0.55]
    vis.headlight.specular = [0.1, 0.1, 0.1]
    vis.map.znear = 0.005
    spec.worldbody.add_light(
        pos=[0, 0, 3], dir=[0, 0, -1], diffuse=[0.4, 0.4, 0.4], castshadow=False
    )
    if options.show_table:  # the demonstration's table, its finite box
        table = data.table
        spec.worldbody.add_geom(
            name="viz_table",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=list(table.half_size),
            pos=list(table.box_center),
            quat=list(table.quat_wxyz),
            rgba=list(style.TABLE_RGBA),
            contype=0,
            conaffinity=0,
        )
    geometry = object_geometry(object_id)
    ref_rgba = (
        style.OBJECT_RGBA if options.layout == "side_by_side" else style.REFERENCE_OBJECT_RGBA
    )
    for name, rgba in (("viz_object", style.OBJECT_RGBA), ("viz_object_ref", ref_rgba)):
        body = spec.worldbody.add_body(name=name, mocap=True)
        if geometry.visual is not None:  # a mesh object: its surface, not its convex parts
            spec.add_mesh(
                name=f"{name}_mesh",
                uservert=np.asarray(geometry.visual[0]).ravel().tolist(),
                userface=np.asarray(geometry.visual[1]).ravel().tolist(),
            )
            body.add_geom(
                type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"{name}_mesh", rgba=list(rgba),
                contype=0, conaffinity=0,
            )  # fmt: skip
            continue
        for prim in geometry.primitives:
            size = list(prim.size) + [0.0] * (3 - len(prim.size))
            body.add_geom(
                type={
                    "box": mujoco.mjtGeom.mjGEOM_BOX,
                    "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
                    "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
                    "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
                }[prim.type],
                size=size,
                pos=list(prim.pos),
                quat=list(aa_to_quat_wxyz(np.asarray(prim.rot_aa))),
                rgba=list(rgba),
                contype=0,
                conaffinity=0,
            )
    model = spec.compile()
    hand_geoms = [g for g in range(model.ngeom) if 0 < model.geom_bodyid[g] < hand_nbody]
    drawn = set(drawn_geoms(model, hand_geoms))
    for g in hand_geoms:
        model.geom_rgba[g] = style.ROBOT_RGBA
        model.geom_matid[g] = -1
        model.geom_group[g] = 1 if g in drawn else 5  # groups 0–2 are drawn, 5 is not
    model.site_group[:] = 5
    return model


def _decorations(data, framing, options, frames: np.ndarray) -> dict[str, np.ndarray]:
    """Spheres and connectors (capsules, arrows) MuJoCo draws on top of the model, per frame."""
    spheres: list[list[tuple]] = []
    links: list[list[tuple]] = []
    off = framing.human_offset
    sets = []
    if options.show_contacts:
        if data.robot_contacts is not None:
            sets.append((data.robot_contacts, np.zeros(3), 1.0, 1.0))
        if options.show_human and data.human_contacts is not None:
            sets.append((data.human_contacts, off, 0.6, 0.7))
    for t in frames:
        sph, lnk = [], []
        if options.show_human and data.human_keypoints is not None:
            kp = data.human_keypoints[t] + off
            for p in kp:
                sph.append((p, style.HUMAN_JOINT_RADIUS, style.HUMAN_RGBA))
            for a, b in style.human_bones():
                lnk.append((kp[a], kp[b], style.HUMAN_BONE_RADIUS, KIND_CAPSULE, style.HUMAN_RGBA))
        for contacts, shift, alpha, thin in sets:
            pos, force, group = contacts.at(t)
            for p, f, g in zip(pos + shift, force, group, strict=True):
                rgba = (*style.group_color(int(g))[:3], alpha)
                sph.append((p, style.CONTACT_POINT_RADIUS, rgba))
                n = float(np.linalg.norm(f))
                if n > 1e-3:
                    length = max(float(style.arrow_length(f)), style.ARROW_HEAD_LENGTH)
                    tail = p - length * f / n  # the arrow ends at the contact point
                    lnk.append((tail, p, style.ARROW_RADIUS * thin, KIND_ARROW, rgba))
        spheres.append(sph)
        links.append(lnk)
    K = len(frames)
    S = max((len(s) for s in spheres), default=0)
    L = max((len(s) for s in links), default=0)
    out = {
        "sphere_pos": np.zeros((K, S, 3)),
        "sphere_size": np.zeros((K, S)),
        "sphere_rgba": np.zeros((K, S, 4), np.float32),
        "sphere_valid": np.zeros((K, S), bool),
        "link_from": np.zeros((K, L, 3)),
        "link_to": np.zeros((K, L, 3)),
        "link_width": np.zeros((K, L)),
        "link_kind": np.zeros((K, L), np.int64),
        "link_rgba": np.zeros((K, L, 4), np.float32),
        "link_valid": np.zeros((K, L), bool),
    }
    for k in range(K):
        for i, (p, r, rgba) in enumerate(spheres[k]):
            out["sphere_pos"][k, i], out["sphere_size"][k, i] = p, r
            out["sphere_rgba"][k, i], out["sphere_valid"][k, i] = rgba, True
        for i, (a, b, w, kind, rgba) in enumerate(links[k]):
            out["link_from"][k, i], out["link_to"][k, i] = a, b
            out["link_width"][k, i], out["link_kind"][k, i] = w, kind
            out["link_rgba"][k, i], out["link_valid"][k, i] = rgba, True
    return out


def write_job(path: Path, hand, data, framing, options, frames, outputs: list[Path]) -> None:
    """Everything the child needs to render ``frames`` into ``outputs`` (one ``.npz``)."""
    model = build_model(hand, data.object_id, data, framing, options)
    mjb = np.frombuffer(_model_bytes(model, mujoco), dtype=np.uint8)
    frames = np.asarray(frames, dtype=np.int64)
    nq = data.robot_qpos.shape[1]
    qpos = np.zeros((len(frames), model.nq))
    qpos[:, :nq] = data.robot_qpos[frames]
    off = framing.human_offset
    mocap_pos = np.stack([data.object_pos[frames], data.ref_object_pos[frames] + off], axis=1)
    mocap_quat = np.stack(
        [
            aa_to_quat_wxyz(data.object_rot_aa[frames]),
            aa_to_quat_wxyz(data.ref_object_rot_aa[frames]),
        ],
        axis=1,
    )
    show_ref = options.layout == "side_by_side" or (
        options.show_reference_object and data.robot_source == "sim"
    )
    if not show_ref:
        mocap_pos[:, 1] = [0.0, 0.0, -100.0]  # out of sight, below the table
    cams = np.array(
        [[*c.lookat, c.distance, c.azimuth, c.elevation] for c in (framing.at(t) for t in frames)]
    )
    np.savez(
        path,
        model_mjb=mjb,
        qpos=qpos,
        mocap_pos=mocap_pos,
        mocap_quat=np.asarray(mocap_quat),
        cams=cams,
        size=np.array([options.width, options.height]),
        outputs=np.array([str(p) for p in outputs]),
        **_decorations(data, framing, options, frames),
    )


def _model_bytes(model, mujoco) -> bytes:
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "scene.mjb")
        mujoco.mj_saveModel(model, path, None)
        return Path(path).read_bytes()
