"""The child process of the MuJoCo still renderer (:mod:`retarget.viz.mujoco_render`).

``python -m retarget.viz.mujoco_child JOB`` renders every frame of a job file (written by
:func:`retarget.viz.mujoco_render.write_job`) to its PNG, with the GL backend that ``MUJOCO_GL``
names in its environment. It imports nothing of the project but this module, so each try starts
fast.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import numpy as np

SPHERE_KEYS = ("sphere_pos", "sphere_size", "sphere_rgba", "sphere_valid")
"""The job arrays of the spheres drawn on top of the model (K frames, S spheres)."""
LINK_KEYS = ("link_from", "link_to", "link_width", "link_kind", "link_rgba", "link_valid")
"""The job arrays of the connectors (capsules, arrows) drawn on top of the model."""
KIND_CAPSULE, KIND_ARROW = 0, 1
"""``link_kind`` values."""


def render_job(job_path: str) -> None:
    """Render every frame of a job file to its PNG (runs in the child process)."""
    # Imported here: with a missing GL library ``import mujoco`` fails, and the parent reads that
    # failure as one line (``__main__`` below).
    import mujoco
    from PIL import Image

    job = np.load(job_path)
    with tempfile.TemporaryDirectory() as d:
        mjb = os.path.join(d, "scene.mjb")
        Path(mjb).write_bytes(job["model_mjb"].tobytes())
        model = mujoco.MjModel.from_binary_path(mjb)
    data = mujoco.MjData(model)
    width, height = (int(v) for v in job["size"])
    renderer = mujoco.Renderer(model, height=height, width=width)
    try:
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        opt = mujoco.MjvOption()
        opt.sitegroup[:] = 0
        for k, out in enumerate(job["outputs"]):
            data.qpos[:] = job["qpos"][k]
            data.mocap_pos[:] = job["mocap_pos"][k]
            data.mocap_quat[:] = job["mocap_quat"][k]
            mujoco.mj_kinematics(model, data)
            c = job["cams"][k]
            cam.lookat[:] = c[:3]
            cam.distance, cam.azimuth, cam.elevation = float(c[3]), float(c[4]), float(c[5])
            renderer.update_scene(data, camera=cam, scene_option=opt)
            _add_decorations(renderer.scene, job, k, mujoco)
            Image.fromarray(renderer.render()).save(str(out))
    finally:
        renderer.close()


def _add_decorations(scene, job, k: int, mujoco) -> None:
    eye = np.eye(3).reshape(-1)

    def new_geom():
        if scene.ngeom >= scene.maxgeom:
            return None
        g = scene.geoms[scene.ngeom]
        scene.ngeom += 1
        return g

    for p, r, rgba, ok in zip(*(job[n][k] for n in SPHERE_KEYS), strict=True):
        g = new_geom() if ok else None
        if g is not None:
            mujoco.mjv_initGeom(
                g,
                mujoco.mjtGeom.mjGEOM_SPHERE,
                np.array([r, r, r]),
                p,
                eye,
                rgba.astype(np.float32),
            )
    for a, b, w, kind, rgba, ok in zip(*(job[n][k] for n in LINK_KEYS), strict=True):
        g = new_geom() if ok else None
        if g is None:
            continue
        t = mujoco.mjtGeom.mjGEOM_ARROW if kind == KIND_ARROW else mujoco.mjtGeom.mjGEOM_CAPSULE
        mujoco.mjv_initGeom(g, t, np.zeros(3), np.zeros(3), eye, rgba.astype(np.float32))
        mujoco.mjv_connector(g, t, float(w), a, b)


if __name__ == "__main__":
    try:
        render_job(sys.argv[1])
    except Exception as e:  # report one line to the parent, which tries the next backend
        print(f"{type(e).__name__}: {e}", file=sys.stderr)
        sys.exit(1)
