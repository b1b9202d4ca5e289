"""The run as a meshcat scene: robot hand, object, translucent human hand, contacts and forces.

>>> from retarget.viz.meshcat_connection import connect, meshcat_server
>>> from retarget.viz.meshcat_scene import MeshcatScene
>>> with meshcat_server() as server:              # listens on 127.0.0.1 only
...     vis = connect(server)
...     scene = MeshcatScene(vis, data, hand)     # data: retarget.viz.data.SceneData
...     scene.animate()                           # plays at the data's frame rate
...     print(server.web_url); input("press enter to stop")

Scene tree (under ``/meshcat/dexcanvas``, translated so the camera's target is the origin):
``robot/<body>/<geom>`` (the hand's visual meshes, or its collision primitives when it has no
visual geoms), ``object`` (the object as simulated), ``human/{joints,bones,object_ref,
contacts}`` (the demonstration: MANO21 skeleton, the reference object, its contacts) and
``robot_contacts``. A contact is a slot ``g<group>_<k>`` with a point, a force arrow (length
∝ force, ``style.FORCE_SCALE_M_PER_N``) and the colour of its finger; slots not in contact at a
frame are hidden. ``layout='side_by_side'`` moves the human group aside instead of overlaying it.

The server and the connection: :mod:`retarget.viz.meshcat_connection`; drawing primitives,
meshes and MuJoCo geoms: :mod:`retarget.viz.meshcat_geoms`.
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import Iterator
from pathlib import Path

import mujoco
import numpy as np

from dexcanvas_core.objects.geometry import object_geometry
from retarget.hands import get_hand
from retarget.viz import style
from retarget.viz.contacts import ContactFrames
from retarget.viz.data import SceneData, load_human_for_run, load_run, scene_data
from retarget.viz.errors import VizError
from retarget.viz.meshcat_connection import connect, meshcat_server
from retarget.viz.meshcat_geoms import (
    aa_matrix,
    drawn_geoms,
    import_meshcat,
    material,
    pose,
    quat_to_matrix,
    set_mesh,
    set_model_geom,
    set_primitive,
)
from retarget.viz.view import Framing, SceneOptions, frame_scene, robot_body_positions

log = logging.getLogger(__name__)

ROOT = "dexcanvas"
MAX_SLOTS_PER_GROUP = 24
"""Most contact points drawn per finger and frame (more are dropped, with a log message)."""
SNAPSHOT_CSS = "<style>.dg { display: none !important; } body { margin: 0; }</style>"
"""Hides meshcat's control panel in snapshot pages."""


# ---------------------------------------------------------------------------- the scene


class MeshcatScene:
    """Draw a :class:`~retarget.viz.data.SceneData` into a ``meshcat.Visualizer``.

    Geometry is sent once at construction; :meth:`show_frame` poses it at one data frame,
    :meth:`animate` sends the whole trajectory as a meshcat animation, :meth:`frame_html` and
    :meth:`animation_html` return self-contained pages (``Visualizer.static_html``).
    """

    def __init__(self, vis, data: SceneData, hand, options: SceneOptions | None = None):
        self.vis = vis
        self.data = data
        self.options = (options or SceneOptions()).validate()
        self.model = hand.compile()
        self._mjdata = mujoco.MjData(self.model)
        nq = data.robot_qpos.shape[1]
        if nq != self.model.nq:
            raise VizError(
                f"robot trajectory has {nq} joints, hand {hand.name!r} has {self.model.nq}"
            )
        self.framing: Framing = frame_scene(
            data, self.options, robot_body_positions(self.model, data.robot_qpos)
        )
        self.root = vis[ROOT]
        # Everything of the demonstration (hand, its object, its contacts) is under "human".
        self.root["human"].set_transform(pose(p=self.framing.human_offset))
        self._setup_view()
        self._build_robot()
        self._build_object()
        if self.options.show_human and data.human_keypoints is not None:
            self._build_human()
        self._animated = False
        self._slots: dict[str, list[tuple[int, int]]] = {}
        if self.options.show_contacts:
            for name, contacts in self._contact_sets():
                self._build_slots(name, contacts)
        self.show_frame(0)

    # -- construction ---------------------------------------------------------------------
    def _setup_view(self) -> None:
        vis, cam = self.vis, self.framing.whole
        vis["/Grid"].set_property("visible", False)
        vis["/Axes"].set_property("visible", False)
        vis["/Background"].set_property("top_color", list(style.BACKGROUND_RGB))
        vis["/Background"].set_property("bottom_color", list(style.BACKGROUND_RGB))
        self._set_camera(cam)
        if self.options.show_table:  # the demonstration's table, its finite box
            table = self.data.table
            set_primitive(
                self.root["table"],
                "box",
                table.half_size,
                style.TABLE_RGBA,
                pose(quat_to_matrix(np.asarray(table.quat_wxyz)), table.box_center),
            )

    def _set_camera(self, cam: style.CameraView) -> None:
        # Content is shifted so the camera's target is the origin: meshcat's orbit controls
        # turn about the origin of the camera's parent frame.
        self.root.set_transform(pose(p=-np.asarray(cam.lookat)))
        off = cam.eye - np.asarray(cam.lookat)
        camera = self.vis["/Cameras/default/rotated/<object>"]
        # The camera's parent frame is rotated +90° about x (meshcat's y-up camera).
        camera.set_property("position", [float(off[0]), float(off[2]), float(-off[1])])
        camera.set_property("fov", float(cam.fovy))

    def _build_robot(self) -> None:
        m = self.model
        self._robot_bodies: list[int] = []
        for g in drawn_geoms(m):
            b = int(m.geom_bodyid[g])
            drawn = set_model_geom(self._body_vis(b)[f"g{g}"], m, g, rgba=style.ROBOT_RGBA)
            if drawn and b not in self._robot_bodies:
                self._robot_bodies.append(b)

    def _body_vis(self, b: int):
        return self.root["robot"][self.model.body(b).name or f"body{b}"]

    def _build_object(self) -> None:
        geom = object_geometry(self.data.object_id)
        targets = [(self.root["object"], style.OBJECT_RGBA)]
        self._show_ref = self.options.layout == "side_by_side" or (
            self.options.show_reference_object and self.data.robot_source == "sim"
        )
        if self._show_ref:
            rgba = style.REFERENCE_OBJECT_RGBA
            if self.options.layout == "side_by_side":
                rgba = style.OBJECT_RGBA
            targets.append((self.root["human"]["object_ref"], rgba))
        for vis, rgba in targets:
            if geom.visual is not None:  # a mesh object: its surface, not its convex parts
                set_mesh(vis["mesh"], *geom.visual, rgba)
                continue
            for i, prim in enumerate(geom.primitives):
                T = pose(aa_matrix(prim.rot_aa), prim.pos)
                set_primitive(vis[f"p{i}"], prim.type, prim.size, rgba, T)

    def _build_human(self) -> None:
        import_meshcat()
        import meshcat.geometry as mg

        human = self.root["human"]
        mat = material(style.HUMAN_RGBA)
        for j in range(21):
            human["joints"][f"j{j}"].set_object(mg.Sphere(style.HUMAN_JOINT_RADIUS), mat)
        for k, _ in enumerate(style.human_bones()):
            body = human["bones"][f"b{k}"]["body"]
            body.set_object(mg.Cylinder(1.0, style.HUMAN_BONE_RADIUS), mat)
            body.set_transform(pose(p=[0.0, 0.5, 0.0]))  # unit cylinder from 0 to 1 along y

    def _contact_sets(self) -> list[tuple[str, ContactFrames]]:
        out = []
        if self.data.robot_contacts is not None:
            out.append(("robot_contacts", self.data.robot_contacts))
        if self.options.show_human and self.data.human_contacts is not None:
            out.append(("human/contacts", self.data.human_contacts))
        return out

    def _slot_root(self, name: str):
        node = self.root
        for part in name.split("/"):
            node = node[part]
        return node

    def _build_slots(self, name: str, contacts: ContactFrames) -> None:
        import_meshcat()
        import meshcat.geometry as mg

        counts = np.minimum(contacts.max_per_group(), MAX_SLOTS_PER_GROUP)
        human = name.startswith("human")
        slots = []
        root = self._slot_root(name)
        for g, n in enumerate(counts):
            rgba = style.group_color(g)
            if human:
                rgba = (*rgba[:3], 0.6)
            mat = material(rgba)
            r = style.ARROW_RADIUS * (0.7 if human else 1.0)
            for k in range(int(n)):
                s = root[f"g{g}_{k}"]
                s["point"].set_object(mg.Sphere(style.CONTACT_POINT_RADIUS), mat)
                s["shaft"]["body"].set_object(mg.Cylinder(1.0, r), mat)
                s["shaft"]["body"].set_transform(pose(p=[0.0, 0.5, 0.0]))
                cone = mg.Cylinder(
                    style.ARROW_HEAD_LENGTH, radiusTop=0.0, radiusBottom=style.ARROW_HEAD_RADIUS
                )
                s["head"]["body"].set_object(cone, mat)
                s["head"]["body"].set_transform(pose(p=[0.0, style.ARROW_HEAD_LENGTH / 2, 0.0]))
                slots.append((g, k))
        self._slots[name] = slots

    # -- posing ---------------------------------------------------------------------------
    def _robot_poses(self, t: int) -> list[tuple[int, np.ndarray]]:
        d = self._mjdata
        d.qpos[:] = self.data.robot_qpos[t]
        mujoco.mj_kinematics(self.model, d)
        return [(b, pose(quat_to_matrix(d.xquat[b]), d.xpos[b])) for b in self._robot_bodies]

    def _frame_poses(self, t: int):
        """Every posed node at frame ``t``: ``(node, R, p, scale or None, visible or None)``."""
        data = self.data
        out = []
        for b, T in self._robot_poses(t):
            out.append((self._body_vis(b), T[:3, :3], T[:3, 3], None, None))
        out.append(
            (
                self.root["object"],
                aa_matrix(data.object_rot_aa[t]),
                data.object_pos[t],
                None,
                None,
            )
        )
        if self._show_ref:
            out.append(
                (
                    self.root["human"]["object_ref"],
                    aa_matrix(data.ref_object_rot_aa[t]),
                    data.ref_object_pos[t],
                    None,
                    None,
                )
            )
        if self.options.show_human and data.human_keypoints is not None:
            kp = data.human_keypoints[t]
            human = self.root["human"]
            for j in range(21):
                out.append((human["joints"][f"j{j}"], np.eye(3), kp[j], None, None))
            for k, (a, b) in enumerate(style.human_bones()):
                v = kp[b] - kp[a]
                length = max(float(np.linalg.norm(v)), 1e-6)
                out.append(
                    (human["bones"][f"b{k}"], style.rotation_y_to(v), kp[a], [1, length, 1], None)
                )
        for name, contacts in self._contact_sets():
            out.extend(self._contact_poses(name, contacts, t))
        return out

    def _contact_poses(self, name: str, contacts: ContactFrames, t: int):
        root = self._slot_root(name)
        pos, force, group = contacts.at(t)
        used: dict[int, int] = {}
        placed: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        for p, f, g in zip(pos, force, group, strict=True):
            k = used.get(int(g), 0)
            used[int(g)] = k + 1
            placed[(int(g), k)] = (p, f)
        dropped = sum(max(0, n - MAX_SLOTS_PER_GROUP) for n in used.values())
        if dropped:
            log.info(
                "frame %d: %d contact point(s) beyond %d per finger not drawn",
                t,
                dropped,
                MAX_SLOTS_PER_GROUP,
            )
        out = []
        for g, k in self._slots.get(name, []):
            s = root[f"g{g}_{k}"]
            if (g, k) not in placed:
                out.append((s, np.eye(3), np.zeros(3), None, False))
                continue
            p, f = placed[(g, k)]
            length = max(float(style.arrow_length(f)), style.ARROW_HEAD_LENGTH)
            shaft = max(length - style.ARROW_HEAD_LENGTH, 1e-6)
            show_arrow = float(np.linalg.norm(f)) > 1e-3
            # The arrow ends at the contact point, pointing along the force on the object.
            out.append((s, style.rotation_y_to(f), p, None, True))
            out.append((s["shaft"], np.eye(3), [0.0, -length, 0.0], [1, shaft, 1], show_arrow))
            out.append(
                (s["head"], np.eye(3), [0.0, -style.ARROW_HEAD_LENGTH, 0.0], None, show_arrow)
            )
        return out

    def show_frame(self, t: int, *, follow: bool = True) -> None:
        """Pose everything at data frame ``t``; ``follow``: aim the camera at this frame's
        content (same direction and distance for every frame), else at the whole trajectory."""
        (t,) = self.data.check_frames([t])
        self._set_camera(self.framing.at(int(t)) if follow else self.framing.whole)
        for node, R, p, scale, visible in self._frame_poses(int(t)):
            node.set_transform(pose(R, p, scale))
            if visible is not None:
                node.set_property("visible", bool(visible))

    def animate(self, max_fps: float = 30.0, play: bool = True, loop: bool = True) -> dict:
        """Send the trajectory as a meshcat animation that plays in real time.

        Keyframes are every ``stride``-th data frame (``stride`` keeps them at or below
        ``max_fps``) and the clip runs at ``fps / stride``, so its duration is the
        demonstration's. Returns ``{"stride", "fps", "frames"}``.
        """
        import_meshcat()
        from meshcat.animation import Animation

        if max_fps <= 0:
            raise VizError(f"max_fps must be positive, got {max_fps}")
        stride = max(1, math.ceil(self.data.fps / max_fps - 1e-9))
        fps = self.data.fps / stride
        anim = Animation(default_framerate=fps)
        frames = range(0, self.data.num_frames, stride)
        for i, t in enumerate(frames):
            with anim.at_frame(self.vis, i) as frame:
                for node, R, p, scale, visible in self._frame_poses(t):
                    target = frame
                    for part in node.path.entries[1:]:  # drop the visualizer's root
                        target = target[part]
                    target.set_transform(pose(R, p))
                    if scale is not None:
                        target.set_property("scale", "vector3", [float(s) for s in scale])
                    if visible is not None:
                        target.set_property("visible", "boolean", bool(visible))
        self.show_frame(0, follow=False)
        self.vis.set_animation(anim, play=play, repetitions=math.inf if loop else 1)
        self._animated = True
        return {"stride": stride, "fps": fps, "frames": len(frames)}

    def frame_html(self, t: int) -> str:
        """A self-contained page of frame ``t`` without meshcat's control panel."""
        if self._animated:  # a still page must not play the animation
            import_meshcat()
            from meshcat.animation import Animation

            self.vis.set_animation(Animation(), play=False)
            self._animated = False
        self.show_frame(t)
        return _with_css(self.vis.static_html(), SNAPSHOT_CSS)

    def animation_html(self, max_fps: float = 30.0) -> str:
        """A self-contained page that plays the whole trajectory (meshcat controls kept)."""
        self.animate(max_fps=max_fps)
        return self.vis.static_html()


def _with_css(html: str, css: str) -> str:
    head = html.find("</head>")
    return html[:head] + css + html[head:] if head >= 0 else css + html


@contextlib.contextmanager
def view_run(
    run_dir: str | Path, options: SceneOptions | None = None, max_fps: float = 30.0
) -> Iterator[str]:
    """Serve a run's animated scene on 127.0.0.1 while the block runs; yields the URL.

    >>> with view_run("runs/shadow_cube2_tripod_0") as url:  # doctest: +SKIP
    ...     input(f"open {url} (Enter stops the server)")
    """
    run = load_run(run_dir)
    hand = get_hand(run.metrics["hand"])
    data = scene_data(run, load_human_for_run(run), hand=hand)
    with meshcat_server() as server:
        vis = connect(server)
        try:
            MeshcatScene(vis, data, hand, options).animate(max_fps=max_fps)
            yield server.web_url
        finally:
            vis.window.close()
