"""The Pinocchio model derived from an MjModel reproduces MuJoCo's kinematics."""

import mujoco
import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.kinematics import PinocchioKinematics

# A small hand-like tree exercising what the real hands use: a 6-DoF floating wrist made of
# slides + hinges in one body, rotated bodies, hinge anchors off the body origin, a body without
# joints, sites with their own orientation.
TOY = """
<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="wrist" pos="0.1 -0.2 0.3" quat="0.9 0.1 0.3 -0.2">
      <joint name="tx" type="slide" axis="1 0 0"/>
      <joint name="ty" type="slide" axis="0 1 0"/>
      <joint name="tz" type="slide" axis="0 0 1"/>
      <joint name="rx" type="hinge" axis="1 0 0" pos="0.01 0 0"/>
      <joint name="ry" type="hinge" axis="0 1 0" pos="0 0.02 0"/>
      <joint name="rz" type="hinge" axis="0 0 1"/>
      <geom type="box" size="0.04 0.01 0.05" mass="0.3"/>
      <body name="palm_plate" pos="0 0 0.05" euler="0.2 0 0.1">
        <geom type="sphere" size="0.01" mass="0.01"/>
        <body name="ff_proximal" pos="0.02 0 0.03" quat="1 0.2 0 0">
          <joint name="ff_abd" axis="1 0 0" range="-0.3 0.3"/>
          <joint name="ff_mcp" axis="0 1 0" pos="0 0 0.005" range="0 1.6"/>
          <geom type="capsule" fromto="0 0 0 0 0 0.04" size="0.008"/>
          <body name="ff_distal" pos="0 0 0.045">
            <joint name="ff_pip" axis="0.2 1 0.1" pos="0 0.003 0" range="0 1.7"/>
            <geom type="capsule" fromto="0 0 0 0 0 0.03" size="0.007"/>
            <site name="ff_tip_site" pos="0 0.004 0.032" euler="0.3 0.2 0.1"/>
          </body>
        </body>
        <body name="th_proximal" pos="-0.02 0.01 0.0" euler="0 0.8 0">
          <joint name="th_slide" type="slide" axis="0 0 1" range="-0.01 0.01"/>
          <joint name="th_rot" axis="1 1 0"/>
          <geom type="capsule" fromto="0 0 0 0 0 0.04" size="0.009"/>
          <site name="th_tip_site" pos="0 0 0.045"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.fixture(scope="module")
def toy():
    m = mujoco.MjModel.from_xml_string(TOY)
    return m, PinocchioKinematics(m)


def _mj_site(m, d, name):
    sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)
    return d.site_xpos[sid].copy(), d.site_xmat[sid].reshape(3, 3).copy(), sid


def test_site_poses_match_mujoco(toy):
    m, kin = toy
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.uniform(-1, 1, size=m.nq)
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        kin.forward(q)
        for site in ("ff_tip_site", "th_tip_site"):
            p, R, _ = _mj_site(m, d, site)
            np.testing.assert_allclose(kin.site_position(site), p, atol=1e-10)
            np.testing.assert_allclose(kin.site_rotation(site), R, atol=1e-10)


def test_site_jacobians_match_mujoco(toy):
    m, kin = toy
    d = mujoco.MjData(m)
    q = np.random.default_rng(1).uniform(-1, 1, size=m.nq)
    d.qpos[:] = q
    mujoco.mj_forward(m, d)
    kin.forward(q)
    for site in ("ff_tip_site", "th_tip_site"):
        _, _, sid = _mj_site(m, d, site)
        jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        mujoco.mj_jacSite(m, d, jp, jr, sid)
        J = kin.site_jacobian(site)
        np.testing.assert_allclose(J[:3], jp, atol=1e-10)
        np.testing.assert_allclose(J[3:], jr, atol=1e-10)


def test_point_jacobian_matches_finite_differences(toy):
    m, kin = toy
    q = np.random.default_rng(2).uniform(-1, 1, size=m.nq)
    kin.forward(q)
    body = "ff_distal"
    fid = kin.body_frames[body]
    offset = np.array([0.003, -0.002, 0.02])  # a point fixed in the body
    M = kin.data.oMf[fid]
    p = M.act(offset)
    J = kin.point_jacobian(body, p)
    eps = 1e-6
    for i in range(m.nv):
        dq = np.zeros(m.nv)
        dq[i] = eps
        kin.forward(q + dq)
        p2 = kin.data.oMf[fid].act(offset)
        np.testing.assert_allclose((p2 - p) / eps, J[:, i], atol=1e-5)
    kin.forward(q)


def test_limits_and_names(toy):
    _, kin = toy
    assert kin.joint_names[:6] == ["tx", "ty", "tz", "rx", "ry", "rz"]
    j = kin.joint_names.index("ff_mcp")
    assert kin.model.lowerPositionLimit[j] == 0 and kin.model.upperPositionLimit[j] == 1.6
    with pytest.raises(RetargetError, match=r"unknown site 'nope'.*ff_tip_site"):
        kin.site_position("nope")


def test_free_joint_is_refused():
    m = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint/><geom size='0.1'/></body></worldbody></mujoco>"
    )
    with pytest.raises(RetargetError, match="hinge and slide joints only"):
        PinocchioKinematics(m)


def test_mujoco_and_pinocchio_backends_agree(toy):
    from retarget.kinematics import MujocoKinematics

    m, pin_kin = toy
    mj_kin = MujocoKinematics(m)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-1, 1, size=m.nq)
        pin_kin.forward(q)
        mj_kin.forward(q)
        for site in ("ff_tip_site", "th_tip_site"):
            np.testing.assert_allclose(
                mj_kin.site_position(site), pin_kin.site_position(site), atol=1e-10
            )
            np.testing.assert_allclose(
                mj_kin.site_jacobian(site), pin_kin.site_jacobian(site), atol=1e-10
            )
        p = pin_kin.site_position("ff_tip_site") + 0.01
        np.testing.assert_allclose(
            mj_kin.point_jacobian("ff_distal", p),
            pin_kin.point_jacobian("ff_distal", p),
            atol=1e-10,
        )
