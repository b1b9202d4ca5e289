"""The table: a box of finite extent, carried per trajectory, in every scene."""

from __future__ import annotations

import dataclasses
import math
import re

import mujoco
import numpy as np
import pytest
from public_layout import public_row, write_public_dataset

from dexcanvas_core.errors import DatasetError, ValidationError
from dexcanvas_core.io import open_dataset, write_dataset
from dexcanvas_core.sim.scene import TABLE_GEOM, add_table
from dexcanvas_core.table import DEFAULT_TABLE, Table, table_of

SKEWED = Table(
    top_z_m=0.735, size_x_m=0.9, size_y_m=0.6, thickness_m=0.03,
    center_x_m=0.31, center_y_m=-0.07, yaw_rad=0.4,
)  # fmt: skip


def test_table_geometry():
    t = SKEWED
    corners = t.corners_world()
    np.testing.assert_allclose(corners[:, 2], t.top_z_m)
    # the corners are on the edges: inside with a hair of margin, outside with a negative one
    assert t.over(corners, 1e-9).all() and not t.over(corners, -1e-6).any()
    sides = np.linalg.norm(np.diff(np.vstack([corners, corners[:1]]), axis=0), axis=1)
    np.testing.assert_allclose(sides, [t.size_x_m, t.size_y_m] * 2)
    centre = np.array([t.center_x_m, t.center_y_m, t.top_z_m + 0.1])
    assert t.height_above(centre) == pytest.approx(0.1)
    assert t.edge_distance(centre) == pytest.approx(-0.5 * t.size_y_m)
    # 5 cm beyond the middle of the long side (the table's +y side, yawed)
    side_y = np.array([-math.sin(t.yaw_rad), math.cos(t.yaw_rad), 0.0])
    out = centre + (0.5 * t.size_y_m + 0.05) * side_y
    assert t.height_above(out) == np.inf
    assert t.edge_distance(out) == pytest.approx(0.05)


@pytest.mark.parametrize(
    "bad", [{"size_x_m": 0.0}, {"thickness_m": -0.01}, {"top_z_m": math.nan}, {"yaw_rad": "0"}]
)
def test_table_rejects_bad_values(bad):
    with pytest.raises(ValidationError, match="table"):
        Table(**bad)


def test_table_from_dict_names_unknown_keys():
    with pytest.raises(ValidationError, match=r"unknown table field.*'height'"):
        Table.from_dict({"height": 0.7})
    assert Table.from_dict(SKEWED.to_dict()) == SKEWED


def test_table_round_trips_through_lance(tmp_path):
    rng = np.random.default_rng(3)
    write_public_dataset(tmp_path / "pub.lance", [public_row(rng, uuid=f"u{i}") for i in range(2)])
    a, b = open_dataset(tmp_path / "pub.lance").iter_trajectories()
    assert a.table is None and table_of(a) is DEFAULT_TABLE  # absent → the default
    a = dataclasses.replace(a, table=SKEWED)
    out = write_dataset([a, b], tmp_path / "with_table.lance")
    ra, rb = open_dataset(out).iter_trajectories()
    assert ra.table == SKEWED  # float64 children: bit-exact
    assert rb.table is None
    # written back with the read schema: the same again
    again = write_dataset([ra, rb], tmp_path / "again.lance", schema=open_dataset(out).schema)
    assert [t.table for t in open_dataset(again).iter_trajectories()] == [SKEWED, None]
    # a table that the schema cannot hold is an error, not a silent loss
    with pytest.raises(DatasetError, match="table"):
        write_dataset([b, a], tmp_path / "lost.lance")


def _drop_scene(table: Table, xy: tuple[float, float]) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """A 4 cm cube dropped from 10 cm above the table top at world ``xy``."""
    spec = mujoco.MjSpec()
    spec.option.timestep = 0.002
    add_table(spec, table)
    body = spec.worldbody.add_body(name="cube", pos=[xy[0], xy[1], table.top_z_m + 0.1])
    body.add_freejoint()
    g = body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.02, 0.02, 0.02])
    g.mass = 0.05
    m = spec.compile()
    return m, mujoco.MjData(m)


@pytest.mark.parametrize("table", [DEFAULT_TABLE, SKEWED], ids=["default", "skewed"])
def test_object_rests_on_the_table_and_falls_beside_it(table):
    inside = np.array([table.center_x_m, table.center_y_m])
    # 3 cm beyond a corner, along the diagonal
    corner = table.corners_world()[0, :2]
    beyond = corner + 0.03 * (corner - inside) / np.linalg.norm(corner - inside)
    for xy, rests in ((inside, True), (beyond, False)):
        m, d = _drop_scene(table, tuple(xy))
        assert m.geom(TABLE_GEOM).type == mujoco.mjtGeom.mjGEOM_BOX
        for _ in range(int(1.0 / m.opt.timestep)):
            mujoco.mj_step(m, d)
        z = d.qpos[2]
        if rests:  # on the top: centre half a cube above it, at rest
            assert z == pytest.approx(table.top_z_m + 0.02, abs=2e-3)
            assert np.abs(d.qvel).max() < 1e-2
        else:  # nothing beyond the edge: 1 s of free fall from 10 cm ends far below the top
            assert z < table.top_z_m - 3.0


# -- retargeting: the table clearance applies over the table only ---------------------------------


def _lowered_demo(dz: float):
    """A short cube2/tripod demonstration (grasp and lift) moved down by ``dz`` [m]: its
    fingertips go below z = 0."""
    from dexcanvas_core.example import example_trajectories

    traj = next(t for t in example_trajectories(seed=0) if t.scene == "cube2").slice(100, 160)
    h, o = traj.hand, traj.object
    shift = np.float32([0.0, 0.0, -dz])
    hand = dataclasses.replace(h, global_pos=h.global_pos + shift, joint_pos=h.joint_pos + shift)
    obj = dataclasses.replace(o, pos=o.pos + shift)
    return dataclasses.replace(traj, hands=[hand], objects=[obj])


def _tip_z(rt, q: np.ndarray) -> np.ndarray:
    """(T, F) world z [m] of the robot's fingertip sites along ``q``."""
    m, d = rt.scene.model, mujoco.MjData(rt.scene.model)
    sites = [m.site(s).id for s in rt.tip_sites]
    out = np.empty((q.shape[0], len(sites)))
    for t, qt in enumerate(q):
        d.qpos[: rt.nq] = qt
        mujoco.mj_kinematics(m, d)
        out[t] = d.site_xpos[sites, 2]
    return out


def _table_distance(rt, q: np.ndarray) -> float:
    """Smallest distance [m] of any hand collision geom from the table along ``q``."""
    m, d = rt.scene.model, mujoco.MjData(rt.scene.model)
    table = rt.scene.table_geoms[0]
    low = np.inf
    for qt in q:
        d.qpos[: rt.nq] = qt
        mujoco.mj_kinematics(m, d)
        for g in rt.scene.hand_geoms:
            low = min(low, mujoco.mj_geomDistance(m, d, g, table, 0.05, None))
    return low


def test_retargeting_keeps_clear_of_the_table_only_over_it():
    from dexcanvas_core.objects.geometry import object_geometry
    from retarget.errors import RetargetError
    from retarget.hands import get_hand
    from retarget.retargeter import Retargeter

    traj = _lowered_demo(0.04)
    tips = traj.hand.joint_pos[:, [4, 8, 12, 16, 20]]  # MANO21 fingertips
    assert tips[..., 2].min() < -0.02  # the human's fingertips 2 cm and more below z = 0
    hand, geom = get_hand("shadow"), object_geometry("cube2")
    # The table's +x edge 5 cm short of every hand keypoint: all of the hand beyond its edge.
    edge_x = float(traj.hand.joint_pos[..., 0].min()) - 0.05
    beside = Table(center_x_m=edge_x - 0.6)
    rt = Retargeter(hand, geom, table=beside)
    q_beside = rt.retarget(dataclasses.replace(traj, table=beside)).q
    reached = _tip_z(rt, q_beside).min()
    assert reached < -0.015  # the targets below the top are reached: nothing holds the hand up
    # The same demonstration over the default table: the hand keeps its clearance above it.
    rt = Retargeter(hand, geom)
    assert rt.table == DEFAULT_TABLE and DEFAULT_TABLE.over(tips).all()
    q_over = rt.retarget(traj).q
    assert _tip_z(rt, q_over).min() > DEFAULT_TABLE.top_z_m
    assert _table_distance(rt, q_over) > rt.cfg.collision.table_clearance - 1e-3
    # a Retargeter refuses a trajectory on another table than its own
    with pytest.raises(RetargetError, match=re.escape("table=dexcanvas_core.table.table_of")):
        rt.retarget(dataclasses.replace(traj, table=beside))


def test_plausibility_check_holds_the_hand_above_the_table_only_over_it():
    from dexcanvas_core.demos.checks import check_trajectory

    traj = _lowered_demo(0.04)  # fingertips 2 cm and more below the top
    over = check_trajectory(traj).checks["hand_table"]
    assert not over.passed and over.value > 15.0  # [mm] below the default table's top
    edge_x = float(traj.hand.joint_pos[..., 0].min()) - 0.05
    beside = dataclasses.replace(traj, table=Table(center_x_m=edge_x - 0.6))
    assert check_trajectory(beside).checks["hand_table"].value == 0.0
