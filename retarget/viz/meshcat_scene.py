"""The run as a meshcat scene: robot hand, object, translucent human hand, contacts and forces.

>>> from retarget.viz.meshcat_scene import MeshcatScene, meshcat_server, connect
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

The server is meshcat's own bridge, started by :func:`meshcat_server` as a child process bound
to 127.0.0.1 (``_meshcat_server``), checked after start (:func:`listening_addresses`) and
ended with its process group when the ``with`` block ends, also on errors.
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import math
import os
import select
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from retarget.viz import style
from retarget.viz._process import managed_process
from retarget.viz.data import ContactFrames, SceneData
from retarget.viz.errors import VizError
from retarget.viz.view import Framing, SceneOptions, frame_scene, robot_body_positions

log = logging.getLogger(__name__)

ROOT = "dexcanvas"
MAX_SLOTS_PER_GROUP = 24
"""Most contact points drawn per finger and frame (more are dropped, with a log message)."""
SNAPSHOT_CSS = "<style>.dg { display: none !important; } body { margin: 0; }</style>"
"""Hides meshcat's control panel in snapshot pages."""

_MJ_BOX, _MJ_SPHERE, _MJ_CAPSULE, _MJ_ELLIPSOID, _MJ_CYLINDER, _MJ_MESH = 6, 2, 3, 4, 5, 7
_Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""Rotation taking meshcat's cylinder axis (+y) onto MuJoCo's (+z)."""


# ---------------------------------------------------------------------------- server


def _import_meshcat():
    """``import meshcat`` without its DeprecationWarning (0.3.2 imports pyzmq's old ioloop)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import meshcat
    return meshcat


@dataclass(frozen=True)
class MeshcatServer:
    """A running meshcat server (see :func:`meshcat_server`)."""

    zmq_url: str
    web_url: str
    pid: int


def listening_addresses(pid: int) -> list[tuple[str, int]]:
    """``(ip, port)`` of every TCP socket process ``pid`` listens on (Linux ``/proc``)."""
    inodes = set()
    fd_dir = Path(f"/proc/{pid}/fd")
    for fd in fd_dir.iterdir():
        with contextlib.suppress(OSError):
            target = os.readlink(fd)
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    out = []
    for table, v6 in (("tcp", False), ("tcp6", True)):
        path = Path(f"/proc/{pid}/net/{table}")
        if not path.exists():
            continue
        for line in path.read_text().splitlines()[1:]:
            cols = line.split()
            if len(cols) < 10 or cols[3] != "0A" or cols[9] not in inodes:  # 0A: LISTEN
                continue
            addr_hex, port_hex = cols[1].split(":")
            raw = bytes.fromhex(addr_hex)
            # /proc prints each 32-bit word of the address in host (little-endian) order.
            words = b"".join(raw[i : i + 4][::-1] for i in range(0, len(raw), 4))
            ip = ipaddress.IPv6Address(words) if v6 else ipaddress.IPv4Address(words)
            out.append((str(ip), int(port_hex, 16)))
    return out


def _read_lines(proc: subprocess.Popen, n: int, deadline: float) -> list[str]:
    """The first ``n`` lines the process prints (unbuffered reads, so select() stays exact)."""
    fd = proc.stdout.fileno()
    buf = b""
    while buf.count(b"\n") < n:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise VizError("the meshcat server did not start within its time limit")
        ready, _, _ = select.select([fd], [], [], remaining)
        if ready:
            chunk = os.read(fd, 4096)
            if not chunk:
                raise VizError(f"the meshcat server exited at start (code {proc.wait()})")
            buf += chunk
    return [line.strip() for line in buf.decode().splitlines()[:n]]


@contextlib.contextmanager
def meshcat_server(timeout_s: float = 30.0) -> Iterator[MeshcatServer]:
    """Start a meshcat server on 127.0.0.1; stop it (and its children) when the block ends.

    Raises :class:`VizError` if it does not come up, or listens anywhere but on loopback.
    """
    with (
        tempfile.TemporaryFile() as errlog,
        managed_process(
            [sys.executable, "-u", "-m", "retarget.viz._meshcat_server"],
            stdout=subprocess.PIPE,
            stderr=errlog,
        ) as proc,
    ):
        deadline = time.monotonic() + timeout_s
        try:
            urls = dict(line.split("=", 1) for line in _read_lines(proc, 2, deadline))
        except (VizError, ValueError) as e:
            errlog.seek(0)
            tail = errlog.read().decode(errors="replace").strip().splitlines()[-5:]
            raise VizError(f"{e}: {' | '.join(tail)}") from None
        addresses = listening_addresses(proc.pid) if Path("/proc/self/fd").is_dir() else []
        public = [a for a in addresses if not ipaddress.ip_address(a[0]).is_loopback]
        if public:
            raise VizError(f"the meshcat server listens beyond this machine: {public}")
        yield MeshcatServer(zmq_url=urls["zmq_url"], web_url=urls["web_url"], pid=proc.pid)


def connect(server: MeshcatServer, timeout_s: float = 60.0):
    """A ``meshcat.Visualizer`` talking to ``server`` (requests time out after ``timeout_s``)."""
    import zmq

    meshcat = _import_meshcat()
    from meshcat.visualizer import ViewerWindow

    class Window(ViewerWindow):
        # meshcat's own window prints the URL and waits forever on a dead server.
        def __init__(self, zmq_url: str, web_url: str):
            self.server_proc = None
            self.zmq_url = zmq_url
            self.web_url = web_url
            self.connect_zmq()

        def connect_zmq(self):
            self.zmq_socket = self.context.socket(zmq.REQ)
            self.zmq_socket.setsockopt(zmq.LINGER, 0)
            self.zmq_socket.setsockopt(zmq.RCVTIMEO, int(1000 * timeout_s))
            self.zmq_socket.setsockopt(zmq.SNDTIMEO, int(1000 * timeout_s))
            self.zmq_socket.connect(self.zmq_url)

        def close(self):
            self.zmq_socket.close(linger=0)

    return meshcat.Visualizer(window=Window(server.zmq_url, server.web_url))


# ---------------------------------------------------------------------------- geometry


def _material(rgba):
    _import_meshcat()
    import meshcat.geometry as mg

    kwargs = {"color": style.rgb_hex(rgba), "opacity": float(rgba[3])}
    if rgba[3] < 1.0:
        kwargs["depthWrite"] = False  # translucent layers do not hide what is behind them
    return mg.MeshPhongMaterial(**kwargs)


def _pose(R: np.ndarray | None = None, p=None, scale=None) -> np.ndarray:
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if scale is not None:
        T[:3, :3] = T[:3, :3] @ np.diag(scale)
    if p is not None:
        T[:3, 3] = p
    return T


def _quat_to_matrix(q_wxyz: np.ndarray) -> np.ndarray:
    w, x, y, z = q_wxyz
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _aa_to_matrix(aa: np.ndarray) -> np.ndarray:
    from dexcanvas_core.rotations import aa_to_matrix

    return np.asarray(aa_to_matrix(np.asarray(aa, dtype=np.float64)))


def set_primitive(vis, kind: str, size, rgba, T_local: np.ndarray) -> bool:
    """Draw one MuJoCo-style primitive (``box`` half-sizes, ``sphere``, ``capsule``/``cylinder``
    radius and half-length along local z, ``ellipsoid`` radii) at ``vis``; False if unknown."""
    _import_meshcat()
    import meshcat.geometry as mg

    mat = _material(rgba)
    size = [float(s) for s in size]
    if kind == "box":
        vis.set_object(mg.Box([2 * size[0], 2 * size[1], 2 * size[2]]), mat)
    elif kind == "sphere":
        vis.set_object(mg.Sphere(size[0]), mat)
    elif kind == "ellipsoid":
        vis["e"].set_object(mg.Sphere(1.0), mat)
        vis["e"].set_transform(_pose(scale=size[:3]))
    elif kind in ("cylinder", "capsule"):
        vis["c"].set_object(mg.Cylinder(2 * size[1], size[0]), mat)
        vis["c"].set_transform(_pose(_Y_TO_Z))
        if kind == "capsule":
            for i, z in enumerate((-size[1], size[1])):
                vis[f"s{i}"].set_object(mg.Sphere(size[0]), mat)
                vis[f"s{i}"].set_transform(_pose(p=[0.0, 0.0, z]))
    else:
        return False
    vis.set_transform(T_local)
    return True


def set_mesh(vis, vertices: np.ndarray, faces: np.ndarray, rgba) -> None:
    """Draw a triangle mesh (``vertices (V, 3)`` [m], ``faces (F, 3)``) at ``vis``."""
    _import_meshcat()
    import meshcat.geometry as mg

    vis.set_object(
        mg.TriangularMeshGeometry(np.asarray(vertices, np.float32), np.asarray(faces, np.uint32)),
        _material(rgba),
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
    _import_meshcat()
    import meshcat.geometry as mg

    T_local = _pose(_quat_to_matrix(model.geom_quat[g]), model.geom_pos[g])
    rgba = geom_rgba(model, g) if rgba is None else rgba
    t = int(model.geom_type[g])
    if t == _MJ_MESH:
        m = int(model.geom_dataid[g])
        v0, nv = model.mesh_vertadr[m], model.mesh_vertnum[m]
        f0, nf = model.mesh_faceadr[m], model.mesh_facenum[m]
        verts = np.asarray(model.mesh_vert[v0 : v0 + nv], dtype=np.float32)
        faces = np.asarray(model.mesh_face[f0 : f0 + nf], dtype=np.uint32)
        vis.set_object(mg.TriangularMeshGeometry(verts, faces), _material(rgba))
        vis.set_transform(T_local)
        return True
    kind = _GEOM_KIND.get(t)
    return kind is not None and set_primitive(vis, kind, model.geom_size[g], rgba, T_local)


# ---------------------------------------------------------------------------- the scene


class MeshcatScene:
    """Draw a :class:`~retarget.viz.data.SceneData` into a ``meshcat.Visualizer``.

    Geometry is sent once at construction; :meth:`show_frame` poses it at one data frame,
    :meth:`animate` sends the whole trajectory as a meshcat animation, :meth:`frame_html` and
    :meth:`animation_html` return self-contained pages (``Visualizer.static_html``).
    """

    def __init__(self, vis, data: SceneData, hand, options: SceneOptions | None = None):
        import mujoco

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
        self.root["human"].set_transform(_pose(p=self.framing.human_offset))
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
                _pose(_quat_to_matrix(np.asarray(table.quat_wxyz)), table.box_center),
            )

    def _set_camera(self, cam: style.CameraView) -> None:
        # Content is shifted so the camera's target is the origin: meshcat's orbit controls
        # turn about the origin of the camera's parent frame.
        self.root.set_transform(_pose(p=-np.asarray(cam.lookat)))
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
        from dexcanvas_core.objects.geometry import object_geometry

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
                T = _pose(_aa_to_matrix(prim.rot_aa), prim.pos)
                set_primitive(vis[f"p{i}"], prim.type, prim.size, rgba, T)

    def _build_human(self) -> None:
        _import_meshcat()
        import meshcat.geometry as mg

        human = self.root["human"]
        mat = _material(style.HUMAN_RGBA)
        for j in range(21):
            human["joints"][f"j{j}"].set_object(mg.Sphere(style.HUMAN_JOINT_RADIUS), mat)
        for k, _ in enumerate(style.human_bones()):
            body = human["bones"][f"b{k}"]["body"]
            body.set_object(mg.Cylinder(1.0, style.HUMAN_BONE_RADIUS), mat)
            body.set_transform(_pose(p=[0.0, 0.5, 0.0]))  # unit cylinder from 0 to 1 along y

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
        _import_meshcat()
        import meshcat.geometry as mg

        counts = np.minimum(contacts.max_per_group(), MAX_SLOTS_PER_GROUP)
        human = name.startswith("human")
        slots = []
        root = self._slot_root(name)
        for g, n in enumerate(counts):
            rgba = style.group_color(g)
            if human:
                rgba = (*rgba[:3], 0.6)
            mat = _material(rgba)
            r = style.ARROW_RADIUS * (0.7 if human else 1.0)
            for k in range(int(n)):
                s = root[f"g{g}_{k}"]
                s["point"].set_object(mg.Sphere(style.CONTACT_POINT_RADIUS), mat)
                s["shaft"]["body"].set_object(mg.Cylinder(1.0, r), mat)
                s["shaft"]["body"].set_transform(_pose(p=[0.0, 0.5, 0.0]))
                cone = mg.Cylinder(
                    style.ARROW_HEAD_LENGTH, radiusTop=0.0, radiusBottom=style.ARROW_HEAD_RADIUS
                )
                s["head"]["body"].set_object(cone, mat)
                s["head"]["body"].set_transform(_pose(p=[0.0, style.ARROW_HEAD_LENGTH / 2, 0.0]))
                slots.append((g, k))
        self._slots[name] = slots

    # -- posing ---------------------------------------------------------------------------
    def _robot_poses(self, t: int) -> list[tuple[int, np.ndarray]]:
        import mujoco

        d = self._mjdata
        d.qpos[:] = self.data.robot_qpos[t]
        mujoco.mj_kinematics(self.model, d)
        return [(b, _pose(_quat_to_matrix(d.xquat[b]), d.xpos[b])) for b in self._robot_bodies]

    def _frame_poses(self, t: int):
        """Every posed node at frame ``t``: ``(node, R, p, scale or None, visible or None)``."""
        data = self.data
        out = []
        for b, T in self._robot_poses(t):
            out.append((self._body_vis(b), T[:3, :3], T[:3, 3], None, None))
        out.append(
            (
                self.root["object"],
                _aa_to_matrix(data.object_rot_aa[t]),
                data.object_pos[t],
                None,
                None,
            )
        )
        if self._show_ref:
            out.append(
                (
                    self.root["human"]["object_ref"],
                    _aa_to_matrix(data.ref_object_rot_aa[t]),
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
            node.set_transform(_pose(R, p, scale))
            if visible is not None:
                node.set_property("visible", bool(visible))

    def animate(self, max_fps: float = 30.0, play: bool = True, loop: bool = True) -> dict:
        """Send the trajectory as a meshcat animation that plays in real time.

        Keyframes are every ``stride``-th data frame (``stride`` keeps them at or below
        ``max_fps``) and the clip runs at ``fps / stride``, so its duration is the
        demonstration's. Returns ``{"stride", "fps", "frames"}``.
        """
        _import_meshcat()
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
                    target.set_transform(_pose(R, p))
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
            _import_meshcat()
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
    from retarget.hands import get_hand
    from retarget.viz.data import load_human_for_run, load_run, scene_data

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
