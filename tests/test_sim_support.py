"""Objects that do not rest by themselves at their first pose are held until the hand moves them."""

import numpy as np
import pytest

from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.sim.support import hold_until_frame, rests_stably

EDGE = 0.05  # cube2


@pytest.fixture(scope="module")
def cube():
    return object_geometry("cube2")


def test_a_cube_on_a_face_rests_one_on_an_edge_or_above_the_table_does_not(cube):
    flat = np.array([0.4, 0.0, EDGE / 2])
    assert rests_stably(cube, np.zeros(3), flat, 0.0)
    assert rests_stably(cube, np.array([0.0, 0.0, 0.7]), flat, 0.0)  # any yaw
    on_edge = np.array([0.4, 0.0, EDGE / np.sqrt(2)])  # 45° about x: balanced on one edge
    assert not rests_stably(cube, np.array([np.pi / 4, 0.0, 0.0]), on_edge, 0.0)
    tilted = np.array([0.4, 0.0, 0.03])  # 20°: on an edge, the centre beside it
    assert not rests_stably(cube, np.array([0.35, 0.0, 0.0]), tilted, 0.0)
    above = flat + np.array([0.0, 0.0, 0.01])  # on something else
    assert not rests_stably(cube, np.zeros(3), above, 0.0)


@pytest.mark.parametrize("oid", ["sphere1", "sphere3"])
def test_a_ball_rests_on_its_point(oid):
    g = object_geometry(oid)
    r = float(g.aabb_half[2])
    assert rests_stably(g, np.array([0.3, 0.2, 0.1]), np.array([0.4, 0.0, r]), 0.0)
    assert not rests_stably(g, np.zeros(3), np.array([0.4, 0.0, r + 0.01]), 0.0)


def test_hold_until_the_demonstration_moves_it(cube):
    from types import SimpleNamespace

    T = 50
    pos = np.tile([0.4, 0.0, EDGE / np.sqrt(2)], (T, 1))
    pos[30:, 2] += np.linspace(0.001, 0.05, T - 30)  # lifted from frame 30 on
    rot = np.tile([np.pi / 4, 0.0, 0.0], (T, 1))
    traj = SimpleNamespace(object=SimpleNamespace(pos=pos, rot_aa=rot), num_frames=T)
    first = int(np.flatnonzero(np.linalg.norm(pos - pos[0], axis=1) > 0.002)[0])
    assert hold_until_frame(cube, traj, 0.0) == first
    traj.object.rot_aa = np.zeros((T, 3))
    traj.object.pos = pos - np.array([0.0, 0.0, EDGE / np.sqrt(2) - EDGE / 2])
    assert hold_until_frame(cube, traj, 0.0) == 0


def test_resimulation_holds_an_unstable_start(cube):
    """A cube captured balanced on an edge stays there until the demonstration moves it (the
    hand far away), and says how long it was held."""
    from dexcanvas_core.trajectory import HandTrack, ObjectTrack, Trajectory
    from retarget.hands import get_hand
    from retarget.validate import Resimulator

    hand = get_hand("allegro")
    T = 60
    pos = np.tile([0.4, 0.0, EDGE / np.sqrt(2)], (T, 1))
    rot = np.tile([np.pi / 4, 0.0, 0.0], (T, 1))
    pos[40:, 0] += np.linspace(0.0005, 0.01, T - 40)  # pushed along x from frame 40
    human = Trajectory(
        uuid="edge",
        timestamp=np.arange(T) / 120.0,
        fps=120.0,
        hands=[HandTrack("right", np.zeros((T, 3)), np.zeros((T, 3)), np.zeros((T, 48)))],
        objects=[ObjectTrack("cube2", pos, rot)],
    )
    resim = Resimulator(hand, cube)
    q = np.tile(resim.model.qpos0[: resim.hand_nq], (T, 1))
    q[:, 2] = 0.5  # the hand half a metre up, out of the way
    res = resim.run(q, human)
    held = res.object_held_until_frame
    assert 40 < held < 45
    assert res.object_pos_err[:held].max() < 0.002  # held at its captured pose
    assert res.metrics()["object_held_until_frame"] == held
