"""Robot joint configurations for tests: the model's joint couplings applied by hand."""

from __future__ import annotations

import mujoco
import numpy as np


def coupled(m: mujoco.MjModel, q: np.ndarray) -> np.ndarray:
    """``q`` with every joint-coupling equality of ``m`` (``mjEQ_JOINT``, polynomial in the
    driving joint) made exact: the driven joints take the value their driver gives them."""
    q = q.copy()
    for e in range(m.neq):
        if m.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT and m.eq_obj2id[e] >= 0:
            c = m.eq_data[e]
            x = q[m.jnt_qposadr[m.eq_obj2id[e]]]
            q[m.jnt_qposadr[m.eq_obj1id[e]]] = c[0] + c[1] * x + c[2] * x**2 + c[3] * x**3
    return q


def human_from_robot_poses(rt, Q: np.ndarray, uuid: str = "robot-poses"):
    """A 'human' (no object) whose retargeting targets are the robot's own poses along ``Q``
    (T, nq): its scaled keypoints are the robot's keypoint sites and its wrist is the robot
    wrist site's pose taken back through the hand's calibrated wrist offset, so the wrist
    target the retargeter derives is the robot's wrist again."""
    from dexcanvas_core.keypoints import MANO21
    from dexcanvas_core.rotations import matrix_to_aa
    from dexcanvas_core.trajectory import HandTrack, Trajectory
    from retarget.hands.base import WRIST_SITE

    Q = np.atleast_2d(np.asarray(Q, float))
    T = Q.shape[0]
    off = rt.hand.wrist_offset if rt.cfg.wrist.use_offset else None
    kp = np.zeros((T, 21, 3))
    pos, rot = np.zeros((T, 3)), np.zeros((T, 3))
    for t, q in enumerate(Q):
        rt.kin.forward(q)
        R, p = rt.kin.site_rotation(WRIST_SITE), rt.kin.site_position(WRIST_SITE)
        if off is not None:
            R, p = off.human_wrist(R, p)
        kp[t] = p
        for name, site in zip(rt.kp_names, rt.kp_sites, strict=True):
            kp[t, MANO21.index(name)] = p + (rt.kin.site_position(site) - p) / rt.scale
        pos[t], rot[t] = p, matrix_to_aa(R)
    hand = HandTrack(
        name="right", global_pos=pos, global_rot_aa=rot, hand_pose=np.zeros((T, 48)), joint_pos=kp
    )
    return Trajectory(
        uuid=uuid, timestamp=np.arange(T) / 120.0, fps=120.0, hands=[hand], objects=[]
    )
