"""Export to MuJoCo: the re-simulation's scene as one self-contained MJCF with a keyframe per
frame, and the trajectory as ``trajectory.npz``.

The directory written::

    scene.xml         hand (floating wrist, actuators) + object (free body) + table, as
                      retarget.validate.build_sim_spec builds it for the re-simulation; one
                      <key> per frame: qpos = the re-simulated hand (q_sim) + the object's free
                      joint (position, quaternion w x y z), ctrl = the servo commands (q_command)
    assets/           the mesh files scene.xml names (paths relative to scene.xml)
    trajectory.npz    time (T,) [s], qpos (T, nq) as the keys, ctrl (T, nu), q_kinematic
                      (T, hand_nq) the retargeted hand (its fingertip sites are tip_pos),
                      tip_sites, tip_pos (T, F, 3) [m], joint_names, fps

The keys and the bodies' inertias are written exactly; the rest of the scene as
``MjSpec.to_xml`` writes it (6 significant digits: lengths within a micrometre of the
re-simulation's scene).

Play it::

    import time
    import mujoco, mujoco.viewer
    m = mujoco.MjModel.from_xml_path("out/scene.xml"); d = mujoco.MjData(m)
    with mujoco.viewer.launch_passive(m, d) as v:
        for k in range(m.nkey):
            mujoco.mj_resetDataKeyframe(m, d, k); mujoco.mj_forward(m, d); v.sync()
            time.sleep(1 / 120)
"""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np

from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.rotations import aa_to_quat_wxyz
from retarget.export.source import ExportError, ExportSource
from retarget.hands import get_hand
from retarget.scene import OBJECT_BODY
from retarget.validate import FORCE_CONTACT_TIMECONST, WRIST_DRIVERS, build_sim_spec

SCENE_XML = "scene.xml"
TRAJECTORY_NPZ = "trajectory.npz"
ASSETS_DIR = "assets"


def scene_qpos(model: mujoco.MjModel, src: ExportSource) -> np.ndarray:
    """(T, nq) ``qpos`` of the export scene ``model``: the re-simulated hand, then the object's
    free joint (position [m], quaternion w x y z)."""
    jnt = model.body_jntadr[model.body(OBJECT_BODY).id]
    obj_q = int(model.jnt_qposadr[jnt])
    hand_nq = src.q_sim.shape[1]
    if obj_q != hand_nq or model.nq != hand_nq + 7:
        raise ExportError(
            f"the {src.hand} scene has nq={model.nq} with the object at {obj_q}; the run has "
            f"{hand_nq} hand joints (made with another version of the hand model?)"
        )
    quat = aa_to_quat_wxyz(src.object_rot_aa)
    return np.concatenate([src.q_sim, src.object_pos, quat], axis=1)


def scene_ctrl(model: mujoco.MjModel, src: ExportSource) -> np.ndarray:
    """(T, nu) ``ctrl``: each actuator's joint's commanded position (``q_command``).

    With the computed-torque wrist driver the six wrist actuators are motors, whose commands
    are torques computed online; their ``ctrl`` is left 0."""
    ctrl = np.zeros((src.num_frames, model.nu))
    for a in range(model.nu):
        if model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE:  # a position servo
            ctrl[:, a] = src.q_command[:, model.jnt_qposadr[model.actuator_trnid[a, 0]]]
    lo, hi = model.actuator_ctrlrange.T
    limited = model.actuator_ctrllimited.astype(bool)
    ctrl[:, limited] = np.clip(ctrl[:, limited], lo[limited], hi[limited])
    return ctrl


def _mesh_file(mesh_file: str, source_spec: mujoco.MjSpec) -> Path:
    """Where the hand model's loader found ``mesh_file`` (absolute, or relative to the source
    model's ``meshdir``, itself relative to the model file's directory)."""
    p = Path(mesh_file)
    if p.is_absolute():
        return p
    base = Path(source_spec.modelfiledir or ".")
    meshdir = Path(source_spec.compiler.meshdir or "")
    return (base / meshdir / p) if not meshdir.is_absolute() else meshdir / p


def _freeze_inertia(spec: mujoco.MjSpec, model: mujoco.MjModel) -> None:
    """Give every body of ``spec`` its compiled mass and inertia explicitly.

    The hand's source model is compiled with its own compiler settings (``inertiafromgeom``,
    ``balanceinertia``, ``boundmass``, …), which one exported ``<compiler>`` cannot repeat
    for it alone; the compiled values make the scene file independent of them."""
    for b in spec.bodies:
        if b.name == "world":
            continue
        i = model.body(b.name).id
        b.explicitinertial = True
        b.mass = float(model.body_mass[i])
        b.ipos = model.body_ipos[i].copy()
        b.iquat = model.body_iquat[i].copy()
        b.inertia = model.body_inertia[i].copy()
        b.fullinertia = [np.nan] * 6  # unset: the diagonal ``inertia`` in ``iquat``'s frame


def _add_keys(root: ET.Element, time: np.ndarray, qpos: np.ndarray, ctrl: np.ndarray) -> None:
    """One ``<key name="frame_t">`` per frame in ``<keyframe>``, numbers written exactly
    (``repr``: ``MjSpec.to_xml`` rounds to 6 significant digits, micrometres at the
    fingertips)."""
    keyframe = root.find("keyframe")
    if keyframe is None:
        keyframe = ET.SubElement(root, "keyframe")

    for t in range(len(time)):
        ET.SubElement(
            keyframe,
            "key",
            name=f"frame_{t}",
            time=repr(float(time[t])),
            qpos=_text(qpos[t]),
            ctrl=_text(ctrl[t]),
        )


def _relink_meshes(xml: str, mesh_rel: dict[str, str], model: mujoco.MjModel) -> ET.Element:
    """``xml`` (parsed) with each ``<mesh file=…>`` pointing at its copy (``mesh_rel``: mesh
    name -> path relative to the scene file), no ``meshdir``, and each body's ``<inertial>``
    exactly as compiled in ``model``. (``MjSpec.to_xml`` compiles the spec, so the files can
    only be renamed in its text.)"""
    root = ET.fromstring(xml)
    for c in root.iter("compiler"):
        c.attrib.pop("meshdir", None)
        c.attrib.pop("assetdir", None)
    for mesh in root.iter("mesh"):
        if "file" in mesh.attrib:
            name = mesh.get("name")
            if name not in mesh_rel:
                raise ExportError(f"the scene names mesh file {mesh.get('file')!r} unknown here")
            mesh.set("file", mesh_rel[name])
    for body in root.iter("body"):
        inertial = body.find("inertial")
        if inertial is None:
            continue
        i = model.body(body.get("name")).id
        inertial.attrib.pop("fullinertia", None)
        inertial.set("mass", repr(float(model.body_mass[i])))
        inertial.set("pos", _text(model.body_ipos[i]))
        inertial.set("quat", _text(model.body_iquat[i]))
        inertial.set("diaginertia", _text(model.body_inertia[i]))
    return root


def _text(v: np.ndarray) -> str:
    """Numbers as MJCF text, exactly (``repr``)."""
    return " ".join(repr(float(x)) for x in v)


def write_mujoco(src: ExportSource, out_dir: Path) -> list[str]:
    """Write the scene, its assets and the trajectory into the new directory ``out_dir``
    (module docstring); return the files written, relative to it."""
    hand = get_hand(src.hand)
    spec = build_sim_spec(
        hand,
        object_geometry(src.object_id),
        table=src.table,
        contact_timeconst=FORCE_CONTACT_TIMECONST if src.metrics.get("forces") else None,
        wrist_driver=src.metrics.get("wrist_driver", WRIST_DRIVERS[0]),
    )
    spec.modelname = f"{src.hand}_{src.pair.replace('/', '_')}"
    model = spec.compile()
    _freeze_inertia(spec, model)
    qpos, ctrl = scene_qpos(model, src), scene_ctrl(model, src)
    written = [SCENE_XML, TRAJECTORY_NPZ]
    source_spec = hand.loader()
    copied: dict[str, str] = {}
    mesh_rel: dict[str, str] = {}  # mesh name -> its file in the export
    for mesh in spec.meshes:
        if not mesh.file:
            continue  # inline vertices (the object's primitives)
        path = _mesh_file(mesh.file, source_spec)
        if not path.is_file():
            raise ExportError(f"mesh {mesh.name!r} of hand {src.hand}: no file {path}")
        rel = copied.get(str(path))
        if rel is None:
            rel = f"{ASSETS_DIR}/{len(copied):03d}_{path.name}"
            (out_dir / ASSETS_DIR).mkdir(exist_ok=True)
            shutil.copyfile(path, out_dir / rel)
            copied[str(path)] = rel
            written.append(rel)
        mesh_rel[mesh.name] = rel
    for tex in spec.textures:
        if tex.file:
            raise ExportError(f"hand {src.hand}: texture files are not exported ({tex.file})")
    root = _relink_meshes(spec.to_xml(), mesh_rel, model)
    _add_keys(root, src.timestamp, qpos, ctrl)
    (out_dir / SCENE_XML).write_text(ET.tostring(root, encoding="unicode"))
    with open(out_dir / TRAJECTORY_NPZ, "wb") as f:
        np.savez_compressed(
            f,
            time=src.timestamp,
            qpos=qpos,
            ctrl=ctrl,
            q_kinematic=src.q,
            tip_sites=np.array(src.tip_sites),
            tip_pos=src.tip_pos,
            joint_names=np.array(src.joint_names),
            fps=np.float64(src.fps),
        )
    return written
