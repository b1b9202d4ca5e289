"""Seeing the results: meshcat server and scene, stills from both renderers, process hygiene,
contacts for the pictures, and the errors of ``retarget snapshot``.

One short shadow/cube2/tripod run (120 frames of a generated demonstration, with synthetic
contact records so the human side has forces) is made once per module; stills are checked by their
pixels, not only for existing.
"""

from __future__ import annotations

import ctypes.util
import dataclasses
import json
import os
import socket
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from system_packages import require, requires

from dexcanvas_core.demos import generate_demo
from dexcanvas_core.io import write_dataset
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.trajectory import CONTACT_PARTS, FORCE_GROUPS, Contacts, part_group
from retarget.cli import main
from retarget.hands import get_hand
from retarget.viz import chromium, style
from retarget.viz._process import tagged_processes
from retarget.viz.contacts import ContactFrames, infer_contacts, robot_body_parts
from retarget.viz.data import load_human_for_run, load_run, scene_data
from retarget.viz.meshcat_connection import connect, listening_addresses, meshcat_server
from retarget.viz.meshcat_scene import MeshcatScene
from retarget.viz.resim import record_resimulation
from retarget.viz.view import SceneOptions

HAS_CHROMIUM = chromium.find_chromium() is not None
needs_chromium = requires(
    HAS_CHROMIUM, "headless Chromium not installed (apt-get install chromium)"
)
FINGER_FORCE_N = {"thumb": 3.0, "index": 2.0, "middle": 1.0, "ring": 0.5, "pinky": 0.5, "palm": 1.0}
"""Force [N] of each synthetic contact record, by finger."""


def with_contact_records(traj, geometry):
    """The demonstration with one contact record per touching hand part and frame (the parts
    inferred from its keypoints; force ``FINGER_FORCE_N`` towards the object's centre)."""
    inferred = infer_contacts(traj, geometry)
    frame, parts, pos, force = [], [], [], []
    for t in range(traj.num_frames):
        seen = set()
        for p, part in zip(inferred.pos_world[t], inferred.part[t], strict=True):
            if part < 0 or part in seen:
                continue
            seen.add(part)
            name = CONTACT_PARTS[part]
            inward = traj.object.pos[t] - p
            f = FINGER_FORCE_N[FORCE_GROUPS[part_group(name)]] * inward / np.linalg.norm(inward)
            frame.append(t)
            parts.append(name)
            pos.append(p)
            force.append(f)
    K = len(frame)
    zeros = np.zeros((K, 3))
    contacts = Contacts(
        num_frames=traj.num_frames,
        frame=np.array(frame),
        hand_name=["right"] * K,
        joint_name=parts,
        object_name=[traj.scene] * K,
        totals={
            "total_force_world": np.array(force),
            "total_force_wrist": zeros,
            "total_force_joint": zeros,
            "total_force_object": zeros,
        },
        pair_offsets=np.arange(K + 1),
        pairs={
            "force_normal": np.array(force),
            "pos_world": np.array(pos),
            "pos_wrist": zeros,
            "pos_joint": zeros,
            "pos_object": zeros,
        },
    )
    return dataclasses.replace(traj, contacts=contacts)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """120 frames of a generated cube2/tripod demonstration (reaching until frame 47, holding
    after, lifting from frame 104), with contact records."""
    traj = generate_demo("cube2/tripod", "operator2", seed=1).trajectory.slice(200, 320)
    traj = with_contact_records(traj, object_geometry("cube2"))
    path = tmp_path_factory.mktemp("viz") / "d.lance"
    write_dataset([traj], path)
    return path


@pytest.fixture(scope="module")
def snap(dataset, tmp_path_factory):
    """``retarget snapshot`` retargeting the pair itself (the issue's acceptance command on
    the small dataset): run files, two stills, scene.html, manifest."""
    out = tmp_path_factory.mktemp("snap")
    renderer = "chromium" if HAS_CHROMIUM else "mujoco"
    argv = [
        "snapshot",
        "--hand",
        "shadow",
        "--pair",
        "cube2/tripod",
        "--dataset",
        str(dataset),
        "--frames",
        "0,60",
        "--renderer",
        renderer,
        "--out",
        str(out),
        "--quiet",
    ]
    assert main(argv) == 0
    return out


@pytest.fixture(scope="module")
def scene_inputs(snap):
    run = load_run(snap)
    human = load_human_for_run(run)
    hand = get_hand("shadow")
    sim = record_resimulation(hand, object_geometry("cube2"), run.arrays["q_command"], human)
    return run, human, hand, sim


# ---------------------------------------------------------------------------- pixels


def pixel_masks(png: Path) -> dict[str, np.ndarray]:
    """Background (white), robot (slate), object (orange) and human (skin) pixels."""
    img = np.asarray(Image.open(png).convert("RGB"), dtype=np.int32)
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return {
        "background": np.all(np.abs(img - 255) <= 12, axis=2),
        "robot": (b - r > 12) & (b > g) & (np.max(img, axis=2) < 200),
        "object": (r > 120) & (r - b > 90) & (g > 0.3 * r) & (g < 0.75 * r),
        "human": (r > 200) & (r - b > 40) & (g > 0.7 * r) & (g < 0.95 * r),
    }


def assert_scene_visible(png: Path) -> dict[str, float]:
    """The picture shows the scene: white background around it, the robot hand, both objects
    and the human hand, each covering a meaningful area, the human to the left of the robot."""
    masks = pixel_masks(png)
    c = {k: float(m.mean()) for k, m in masks.items()}
    assert 0.2 < c["background"] < 0.97, c  # not blank, not filled by the table
    assert c["robot"] > 0.01, c  # the robot hand covers more than 1 % of the picture
    assert c["object"] > 0.005, c  # two 5 cm cubes
    assert c["human"] > 0.002, c  # the translucent human hand
    x_robot = np.nonzero(masks["robot"])[1].mean()
    x_human = np.nonzero(masks["human"])[1].mean()
    assert x_human < x_robot, (x_human, x_robot)  # side by side: human left, robot right
    return c


# ---------------------------------------------------------------------------- meshcat server


def test_listening_addresses_reads_proc():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert ("127.0.0.1", port) in listening_addresses(os.getpid())


def test_meshcat_server_listens_on_loopback_only():
    with meshcat_server() as server:
        addrs = listening_addresses(server.pid)
        ports = {p for _, p in addrs}
        web_port = int(server.web_url.rsplit(":", 1)[1].split("/")[0])
        zmq_port = int(server.zmq_url.rsplit(":", 1)[1])
        assert {web_port, zmq_port} <= ports  # both of meshcat's sockets are seen …
        assert all(ip == "127.0.0.1" for ip, _ in addrs), addrs  # … and only on loopback
        page = urllib.request.urlopen(server.web_url, timeout=10).read().decode()
        assert "<title>MeshCat</title>" in page or "main.min.js" in page
        pid = server.pid
    assert not Path(f"/proc/{pid}").exists() and tagged_processes() == []


def test_meshcat_server_stops_on_error():
    with pytest.raises(RuntimeError, match="injected"):
        with meshcat_server() as server:
            pid = server.pid
            raise RuntimeError("injected")
    assert not Path(f"/proc/{pid}").exists() and tagged_processes() == []


# ---------------------------------------------------------------------------- scene data


def test_inferred_contacts_of_a_tripod(scene_inputs):
    _, human, _, _ = scene_inputs
    human = dataclasses.replace(human, contacts=None)
    c = infer_contacts(human, object_geometry("cube2"))
    freq = dict(zip(CONTACT_PARTS, c.part_frequency(), strict=True))
    # A tripod holds the cube with thumb, index and middle pads; ring, pinky and palm stay off.
    for part in ("thumb_ip", "index_dip", "middle_dip"):
        assert freq[part] > 0.3, freq
    for part in ("ring_dip", "pinky_dip", "palm"):
        assert freq[part] == 0.0, freq
    assert not c.force_world.any()  # no forces without records


def test_recorded_resimulation_is_the_run(scene_inputs):
    run, _human, _hand, sim = scene_inputs
    # Same simulation, same inputs: the very object trajectory retarget run stored.
    np.testing.assert_array_equal(sim.result.object_pos_sim, run.arrays["object_pos_sim"])
    assert sim.qpos.shape == run.arrays["q"].shape and np.isfinite(sim.qpos).all()
    # The simulated hand follows its command: wrist within 3 cm of the retargeted wrist
    # (measured 1.1 cm; 4.9 cm when uniformly scaled keypoints left the thumb 2 cm short of
    # its contact target at onset and the retargeted wrist dived 6.8 cm to close the gap).
    assert np.abs(sim.qpos[:, :3] - run.arrays["q"][:, :3]).max() < 0.03
    groups = {FORCE_GROUPS[g] for g in sim.contacts.group[sim.contacts.valid]}
    # The thumb against a finger the human's tripod used (which one carries the cube is the
    # grip plan's choice: here ~2.8 N on the thumb, ~2.4 N on the middle finger and ≤ 0.5 N on
    # the index).
    assert "thumb" in groups and groups & {"index", "middle"}, groups
    # Forces are those of the hand on the object: they push into it, along the inward normal
    # of the cube face each point is on (friction tilts a force, never past the face). A point
    # within 1 mm of two faces is on their edge (83 of the 194 here, the 5 cm cube's pads
    # reach its edges) and pushes in through either face: the index finger on the +x face's
    # top edge presses 0.4 N into it while lifting the cube by friction, upward against the
    # top face's inward normal.
    from dexcanvas_core.rotations import aa_to_matrix

    t, k = np.nonzero(sim.contacts.valid)
    R = aa_to_matrix(sim.result.object_rot_sim[t])  # (n, 3, 3) cube → world
    local = np.einsum("nji,nj->ni", R, sim.contacts.pos_world[t, k] - sim.result.object_pos_sim[t])
    on = np.abs(local) > np.abs(local).max(axis=1, keepdims=True) - 1e-3  # (n, 3) faces
    f = sim.contacts.force_world[t, k]
    # (n, 3) the force along each axis' face's inward normal, −R[:, :, a] · sign(local_a)
    push = -np.einsum("nia,ni->na", R, f) * np.sign(local)
    into = (on & (push > 0)).any(axis=1)
    pressing = np.linalg.norm(f, axis=1) > 1e-6  # (points within the margin carry no force)
    assert pressing.sum() > 100
    assert into[pressing].mean() > 0.95, into[pressing].mean()


def test_robot_bodies_map_onto_human_parts():
    hand = get_hand("allegro")
    model = hand.compile()
    group, part = robot_body_parts(hand, model)
    by_name = {
        model.body(b).name: CONTACT_PARTS[part[b]] for b in range(model.nbody) if part[b] >= 0
    }
    # The fingertip body is welded to the distal link: both are the distal phalanx.
    assert by_name["link_3.0"] == by_name["link_3.0_tip"] == "index_dip"
    assert by_name["link_2.0"] == "index_pip" and by_name["link_15.0_tip"] == "thumb_ip"
    assert by_name["palm_link"] == "palm"
    assert set(group[1:]) <= set(range(len(FORCE_GROUPS)))  # every hand body belongs somewhere


def test_contact_frames_from_records(scene_inputs):
    _, human, _, _ = scene_inputs
    c = ContactFrames.from_contacts(human.contacts)
    t = int(np.argmax(c.valid.sum(axis=1)))
    _pos, force, group = c.at(t)
    for f, g in zip(force, group, strict=True):  # the synthetic records' magnitudes
        assert np.linalg.norm(f) == pytest.approx(FINGER_FORCE_N[FORCE_GROUPS[g]], rel=1e-5)
    assert style.arrow_length(np.array([3.0, 0.0, 0.0])) == pytest.approx(0.06)
    assert style.arrow_length(np.array([100.0, 0.0, 0.0])) == style.ARROW_MAX_LENGTH
    R = style.rotation_y_to(np.array([0.3, -0.2, 0.9]))
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(
        R[:, 1], np.array([0.3, -0.2, 0.9]) / np.linalg.norm([0.3, -0.2, 0.9])
    )


def test_meshcat_scene_animation_and_pages(scene_inputs):
    run, human, hand, sim = scene_inputs
    data = scene_data(run, human, hand=hand, sim=sim)
    with meshcat_server() as server:
        vis = connect(server)
        scene = MeshcatScene(vis, data, hand, SceneOptions(layout="overlay"))
        assert scene.framing.human_offset.tolist() == [0.0, 0.0, 0.0]
        still = scene.frame_html(60)
        info = scene.animate()
        animated = vis.static_html()
        vis.window.close()
    # Real time: keyframes every `stride` frames, played at fps / stride (120 Hz → 30 Hz).
    assert info["stride"] * info["fps"] == pytest.approx(data.fps)
    assert info["frames"] == -(-data.num_frames // info["stride"]) and info["fps"] <= 30.0
    assert ".dg { display: none" in still and "<script src" not in animated
    assert len(animated) > len(still)  # the animation's keyframes are in the page
    with pytest.raises(Exception, match="out of range"):
        scene.show_frame(data.num_frames)


def test_view_run_serves_the_animation_locally(snap):
    from retarget.viz import view_run

    with view_run(snap) as url:
        assert url.startswith("http://127.0.0.1:")
        assert "main.min.js" in urllib.request.urlopen(url, timeout=10).read().decode()
    assert tagged_processes() == []


def test_side_by_side_moves_the_human_left_of_the_camera(scene_inputs):
    run, human, hand, sim = scene_inputs
    from retarget.viz.view import frame_scene, robot_body_positions

    data = scene_data(run, human, hand=hand, sim=sim)
    opts = SceneOptions(side_offset_m=0.25)
    framing = frame_scene(data, opts, robot_body_positions(hand.compile(), data.robot_qpos))
    off = framing.human_offset
    assert np.linalg.norm(off) == pytest.approx(0.25) and off[2] == 0.0
    right = np.cross(framing.whole.forward, [0.0, 0.0, 1.0])
    assert off @ right < 0  # to the camera's left
    assert off @ framing.whole.forward == pytest.approx(0.0, abs=1e-12)  # not in depth


# ---------------------------------------------------------------------------- stills


def test_snapshot_retargets_and_draws_visible_scene(snap):
    manifest = json.loads((snap / "snapshots.json").read_text())
    assert manifest["frames"] == [0, 60] and manifest["hand"] == "shadow"
    assert (snap / "robot_trajectory.npz").is_file() and (snap / "metrics.json").is_file()
    stats = [assert_scene_visible(snap / f) for f in manifest["files"]]
    a, b = (np.asarray(Image.open(snap / f), dtype=np.float64) for f in manifest["files"])
    assert np.abs(a - b).mean() > 1.0  # frame 0 (reaching) and frame 60 (holding) differ
    assert stats[1]["robot"] > 0.01
    page = (snap / "scene.html").read_text()
    assert "<script src" not in page and "new MeshCat.Viewer" in page  # self-contained


@needs_chromium
def test_chromium_renderer(snap):
    assert json.loads((snap / "snapshots.json").read_text())["renderer"] == "chromium"


@needs_chromium
def test_scene_html_plays_the_animation(snap, tmp_path):
    """The page moves by itself: shots a quarter of its 1 s loop apart (virtual time) are not
    all the same frame. Two fixed times can both land in the 0.5 s the hand holds still (the
    animation starts a little after the page loads): 0.2 s and 0.7 s once gave the same
    frame on a loaded machine, 0.2 s and 2.5 s frames 0.28 apart."""
    shots = []
    for budget_ms in (100, 350, 600, 850):
        png = chromium.screenshot(
            snap / "scene.html", tmp_path / f"{budget_ms}.png", budget_ms=budget_ms
        )
        shots.append(np.asarray(Image.open(png).convert("RGB"), dtype=np.float64))
        assert pixel_masks(png)["robot"].mean() > 0.005
    diffs = [np.abs(a - b).mean() for i, a in enumerate(shots) for b in shots[i + 1 :]]
    assert max(diffs) > 0.5


@pytest.mark.parametrize("backend", ["egl", "osmesa"])
def test_mujoco_renderer(backend, snap, tmp_path, monkeypatch):
    lib = {"egl": "EGL", "osmesa": "OSMesa"}[backend]
    if ctypes.util.find_library(lib) is None:
        hint = {"egl": "libegl1 libegl-mesa0 libgl1-mesa-dri", "osmesa": "libosmesa6"}[backend]
        require(False, f"lib{lib} missing (apt-get install {hint})")
    monkeypatch.setenv("MUJOCO_GL", backend)
    out = tmp_path / "mj"
    argv = [
        "snapshot",
        "--run",
        str(snap),
        "--frames",
        "60",
        "--renderer",
        "mujoco",
        "--no-html",
        "--out",
        str(out),
        "--quiet",
    ]
    assert main(argv) == 0
    manifest = json.loads((out / "snapshots.json").read_text())
    assert manifest["renderer"] == "mujoco" and manifest["scene_html"] is None
    assert_scene_visible(out / "frame_0060.png")


def test_run_with_snapshot_flag(dataset, tmp_path):
    out = tmp_path / "run"
    argv = [
        "run",
        "--hand",
        "allegro",
        "--pair",
        "cube2/tripod",
        "--dataset",
        str(dataset),
        "--out",
        str(out),
        "--quiet",
        "--snapshot",
        "--renderer",
        "mujoco",
    ]
    assert main(argv) == 0
    manifest = json.loads((out / "snapshots.json").read_text())
    assert manifest["frames"] == [0, 60, 119] and manifest["hand"] == "allegro"
    assert (out / "metrics.json").is_file() and (out / "scene.html").is_file()
    assert_scene_visible(out / manifest["files"][1])


# ---------------------------------------------------------------------------- hygiene, errors


@needs_chromium
def test_no_browser_or_server_survives_an_error(snap, tmp_path, monkeypatch):
    """Chromium is killed mid-render (a timeout far too short): the command fails cleanly and
    neither the browser, its helpers nor the meshcat server are left running."""
    original = chromium.screenshot

    def hurried(page, png, **kwargs):
        return original(page, png, **{**kwargs, "timeout_s": 0.3})

    monkeypatch.setattr(chromium, "screenshot", hurried)
    argv = [
        "snapshot",
        "--run",
        str(snap),
        "--frames",
        "0",
        "--renderer",
        "chromium",
        "--out",
        str(tmp_path / "x"),
        "--quiet",
    ]
    assert main(argv) == 2
    assert tagged_processes() == []


def test_no_process_left_after_commands(snap):
    assert tagged_processes() == []


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--hand", "shdow", "--pair", "cube2/tripod"], "did you mean 'shadow'"),
        (["--hand", "shadow", "--pair", "cube2/tripd"], "did you mean 'tripod'"),
        (
            ["--hand", "shadow", "--pair", "cube2/tripod", "--frames", "0,500"],
            "frame 500 out of range: the demonstration has 120 frames (0–119)",
        ),
        (["--hand", "shadow", "--pair", "cube2/tripod", "--frames", "0,x"], "'x' is not a frame"),
        (["--hand", "shadow", "--pair", "cube2/tripod", "--every", "0"], "at least 1"),
        (["--pair", "cube2/tripod"], "give --hand and --pair"),
        (["--hand", "shadow", "--pair", "cube2/tripod", "--run", "."], "not both"),
        (["--hand", "shadow", "--pair", "cube2/tripod", "--width", "4"], "outside 16"),
    ],
)
def test_snapshot_errors(argv, message, dataset, tmp_path, capsys):
    assert main(["snapshot", *argv, "--dataset", str(dataset), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "retarget snapshot: error:" in err and message in err
    assert not list(tmp_path.iterdir())  # nothing retargeted or drawn before the check


def test_snapshot_run_dir_errors(snap, tmp_path, capsys):
    missing = tmp_path / "nope"
    assert main(["snapshot", "--run", str(missing), "--out", str(tmp_path / "o")]) == 2
    assert "does not exist" in capsys.readouterr().err
    partial = tmp_path / "partial"
    partial.mkdir()
    (partial / "metrics.json").write_text((snap / "metrics.json").read_text())
    assert main(["snapshot", "--run", str(partial), "--out", str(tmp_path / "o")]) == 2
    assert "has no robot_trajectory.npz" in capsys.readouterr().err
    assert main(["snapshot", "--run", str(snap), "--frames", "120", "--out", str(tmp_path)]) == 2
    assert "frame 120 out of range" in capsys.readouterr().err


def test_no_renderer_names_the_packages(snap, tmp_path, monkeypatch, capsys):
    from retarget.viz import snapshot

    monkeypatch.setattr(chromium, "find_chromium", lambda: None)
    monkeypatch.setattr(snapshot, "mujoco_available", lambda: dict(snapshot.mujoco_render.BACKENDS))
    out = tmp_path / "o"
    assert main(["snapshot", "--run", str(snap), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "apt-get install chromium" in err and "apt-get install libosmesa6" in err
    assert "libegl1" in err
    assert main(["snapshot", "--run", str(snap), "--renderer", "chromium", "--out", str(out)]) == 2
    assert "apt-get install chromium" in capsys.readouterr().err
