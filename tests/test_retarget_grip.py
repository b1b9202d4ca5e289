"""The default grip: contact forces from the object's weight and motion (``grip="wrench"``)
instead of a fixed squeeze depth, and which fingers press at all."""

from __future__ import annotations

import numpy as np
import pytest

from dexcanvas_core.loaders.selection import load_demonstration
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.rotations import aa_to_matrix
from retarget.config import GripConfig, RetargetConfig
from retarget.grip import opposed_contacts
from retarget.hands import get_hand
from retarget.retargeter import Retargeter


def test_opposed_contacts():
    n = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0], [-0.5, -0.866, 0]])
    active = np.array([True, True, True, False, True])
    # 0 ↔ 1 and 1·4 = 0.5 (no), 0·4 = −0.5 (yes); 2 (top face) opposes nobody; 3 is inactive
    np.testing.assert_array_equal(opposed_contacts(active, n), [True, True, False, False, True])
    assert not opposed_contacts(np.array([True, False]), n[:2]).any()  # one finger alone


@pytest.fixture(scope="module")
def lifted_run():
    """Allegro on the built-in cube1/quadpod (the 8 cm cube picked up and lifted): its index
    finger touches the cube alone for ~25 frames before the others, and the kinematic solution
    leaves a finger ~1 mm inside the cube on a few contact frames. (On the built-in
    cube2/tripod the fingers arrive within 3 frames of each other and none sinks in.)"""
    traj = load_demonstration("cube1/quadpod")
    geom = object_geometry(traj.object.name)
    rt = Retargeter(get_hand("allegro"), geom)
    assert rt.cfg.grip.mode == "wrench"
    return traj, geom, rt, rt.retarget(traj)


def test_grip_forces_carry_the_weight_off_the_table(lifted_run):
    """Physics invariant: where the object is off the table and barely accelerating, the
    planned robot contact forces sum to its weight (up the way); on the table, before the
    grip's lead time, the hand is asked for no force (only opposed fingers squeeze)."""
    traj, geom, rt, r = lifted_run
    p = traj.object.pos.astype(np.float64)
    low = geom.lowest_z(aa_to_matrix(traj.object.rot_aa.astype(np.float64)), p)
    acc = np.zeros_like(p)
    acc[1:-1] = (p[2:] - 2 * p[1:-1] + p[:-2]) * traj.fps**2
    still = (low > 0.02) & (np.linalg.norm(acc, axis=1) < 0.3)
    assert still.sum() > 50
    total = r.robot_force[still].sum(axis=1)
    mg = geom.mass_kg * 9.81
    ok = r.wrench_shortfall[still] < 0.05 * mg
    assert ok.mean() > 0.9
    np.testing.assert_allclose(total[ok, 2], mg, rtol=0.15)
    assert np.abs(total[ok, :2]).max() < 0.15 * mg
    # the wrench asked for: the weight off the table, nothing on it before the lead time
    W = rt._grip_targets(traj)["wrench"]
    np.testing.assert_allclose(W[still, 2], mg, rtol=0.05)
    rest = low < 1e-3
    rest[np.flatnonzero(~rest)[0] - round(rt.cfg.grip.lead_s * traj.fps) - 1 :] = False
    assert rest.sum() > 50 and not W[rest].any()


def test_a_lone_finger_is_not_pressed_into_the_object(lifted_run):
    """On the table, a frame whose only contact has no finger pushing back keeps the command
    on the kinematic solution (pressing it would only shove the object)."""
    traj, geom, rt, r = lifted_run
    tg = rt.human_targets(traj)
    lone = tg["contact_active"].sum(axis=1) == 1
    p = traj.object.pos.astype(np.float64)
    low = geom.lowest_z(aa_to_matrix(traj.object.rot_aa.astype(np.float64)), p)
    frames = np.flatnonzero(lone & (low < 1e-3))
    frames = frames[frames < np.flatnonzero(low > 1e-3)[0] - 30]
    assert frames.size > 10  # the index finger touches first
    np.testing.assert_array_equal(r.q_command[frames], r.q[frames])


def test_depth_grip_still_available_and_validated():
    rt = Retargeter(
        get_hand("allegro"), object_geometry("cube2"), RetargetConfig(grip=GripConfig(mode="depth"))
    )
    assert rt.cfg.grip.mode == "depth"
    from retarget.errors import RetargetError

    with pytest.raises(RetargetError, match=r"GripConfig\.mode"):
        RetargetConfig(grip=GripConfig(mode="hard"))
    with pytest.raises(RetargetError, match=r"GripConfig\.force_n"):
        RetargetConfig(grip=GripConfig(force_n=-1.0))


def test_the_command_presses_from_the_surface_not_from_the_penetration(lifted_run):
    """A pressed finger that the kinematic solution leaves inside the object (within its
    penetration margin) is commanded back onto the surface before its force offset: asked for
    a negligible force, its contact point moves out along the normal by the depth (else the
    servo would press the depth's stiffness force on top of the plan's)."""
    import mujoco

    from dexcanvas_core.rotations import aa_to_quat_wxyz

    traj, _, rt, r = lifted_run
    tg = rt.human_targets(traj)

    quat = aa_to_quat_wxyz(traj.object.rot_aa)
    found = None
    for t in np.flatnonzero(tg["contact_active"].any(axis=1)):
        rt.scene.set_object_pose(traj.object.pos[t], quat_wxyz=quat[t])
        rt.contacts.set_contacts(
            tg["contact_active"][t], tg["contact_points"][t], tg["contact_part"][t]
        )
        d = rt.contacts.finger_distances(r.q[t])
        deep = np.flatnonzero(tg["contact_active"][t] & (d < -5e-4))
        if deep.size:
            found = t, int(deep[0]), float(d[deep[0]])
            break
    assert found is not None, "no contact frame with a finger inside the object"
    t, i, depth = found
    fm = rt._grip_targets(traj)
    fm["mode"] = "human"
    n = tg["contact_normals"][t, i]
    fm["human_force"] = np.zeros((traj.num_frames, len(rt.tip_sites), 3))
    fm["human_force"][t, i] = -0.002 * n  # pressing, negligibly
    fm["wrench"] = np.zeros_like(fm["wrench"])
    dq = rt._force_squeeze(r.q[t], t, tg, fm)
    assert np.abs(dq).max() > 0
    p0 = rt.contacts.finger_point_array(r.q[t])[i].copy()
    # the same body point at the command
    body = rt.contacts.finger_points(r.q[t])[i][0]
    m, data = rt.scene.model, rt.scene.data
    bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body)
    data.qpos[: rt.nq] = r.q[t]
    mujoco.mj_kinematics(m, data)
    local = data.xmat[bid].reshape(3, 3).T @ (p0 - data.xpos[bid])
    data.qpos[: rt.nq] = r.q[t] + dq
    mujoco.mj_kinematics(m, data)
    p1 = data.xpos[bid] + data.xmat[bid].reshape(3, 3) @ local
    assert (p1 - p0) @ n == pytest.approx(-depth, rel=0.2)
