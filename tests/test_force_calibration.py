"""Force calibration: servo commands corrected in simulation until the fingers press like the
human's (``retarget.force_calibration``)."""

from __future__ import annotations

import itertools
import json

import mujoco
import numpy as np
import pytest
from finger_scenes import finger_pressing_a_fixed_box

from retarget.config import ForceMatchingConfig, RetargetConfig
from retarget.errors import RetargetError
from retarget.force_calibration import (
    ForceCalibrationConfig,
    calibrate_forces,
    correction,
    force_error,
    match_error,
    profile_correlation,
)
from retarget.force_matching import squeeze_offsets


def _pressed_force(m: mujoco.MjModel, ctrl: np.ndarray) -> np.ndarray:
    """The finger's steady force on the box (world frame, on the box) under ``ctrl``."""
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    d.ctrl[:] = ctrl
    for _ in range(2000):
        mujoco.mj_step(m, d)
    f = np.zeros(3)
    for i in range(d.ncon):
        f6 = np.zeros(6)
        mujoco.mj_contactForce(m, d, i, f6)
        frame = d.contact[i].frame.reshape(3, 3)
        # the contact frame's normal points from geom1 to geom2; force on geom2 is +f
        on_geom2 = frame.T @ f6[:3]
        f += on_geom2 if m.geom_bodyid[d.contact[i].geom2] == 0 else -on_geom2
    return f


def test_correction_brings_a_soft_contact_to_the_commanded_force():
    """``K⁻¹Jᵀf`` alone presses 60–90 % of the force at MuJoCo's default contact softness
    (tests/test_force_matching.py); the calibration's correction, re-measured and applied again,
    brings the pressed force within 2 % of the target in a few iterations, and each step
    shrinks the error (the measured force is the iteration's only input)."""
    m = finger_pressing_a_fixed_box(solref=0.02, wrist=True)
    nq = 8
    q = np.zeros((1, nq))
    target = np.array([[[0.0, 0.0, -3.0]]])  # pressing down on the box
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    jacp = np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jacp, None, m.site("tip_site").id)
    kp = m.actuator_gainprm[:, 0].copy()
    kp[:6] = np.inf
    ctrl = q[0] + squeeze_offsets([jacp], target[0], kp)
    errs = []
    for _ in range(5):
        f = _pressed_force(m, ctrl)
        errs.append(abs(np.linalg.norm(f) - 3.0) / 3.0)
        ctrl = ctrl + correction(
            m, nq, q, ["tip_site"], target, f[None, None], gain=1.0, smooth_frames=1,
            tolerance_n=0.0,
        )[0]  # fmt: skip
    assert 0.1 < errs[0] < 0.4  # the soft contact's loss
    assert all(b < a for a, b in itertools.pairwise(errs))
    assert errs[-1] < 0.02
    # the wrist's commands never move: the fingers' servos press
    assert np.all(ctrl[:6] == 0.0)


def test_correction_backs_off_a_finger_pressing_too_hard_and_leaves_late_frames():
    """A finger pressing more than its target is backed off along its own force; frames from
    ``frames`` on (after a re-simulation lost the object) and errors within the tolerance get
    no change; a finger pressing nothing is pushed along the target's direction."""
    m = finger_pressing_a_fixed_box(solref=0.005, wrist=True)
    nq = 8
    q = np.zeros((3, nq))
    target = np.tile([[[0.0, 0.0, -1.0]]], (3, 1, 1))
    realized = np.array([[[0.0, 0.0, -2.0]], [[0.0, 0.0, 0.0]], [[0.0, 0.0, -5.0]]])
    dq = correction(m, nq, q, ["tip_site"], target, realized, 1.0, 1, 0.0, frames=2)
    # pressing too hard (frame 0) and not at all (frame 1): opposite changes of the finger
    assert np.all(dq[:, :6] == 0.0)
    assert np.sign(dq[0, 6:]) @ np.sign(dq[1, 6:]) < 0 and np.abs(dq[0, 6:]).max() > 0
    assert np.all(dq[2] == 0.0)  # past `frames`
    small = correction(m, nq, q, ["tip_site"], target, target * 1.01, 1.0, 1, 0.02)
    assert np.all(small == 0.0)  # within the tolerance
    with pytest.raises(RetargetError, match="do not match"):
        correction(m, nq, q, ["tip_site", "tip_site"], target, realized, 1.0, 1, 0.0)


def test_force_error_is_the_pooled_relative_error_of_the_loaded_fingers():
    H = np.zeros((10, 3))
    H[:, 0] = 2.0  # loaded
    H[:2, 1] = 5.0  # touched on 2 frames only: not scored
    R = H.copy()
    R[:, 0] = 1.5
    R[:, 2] = 9.0  # a finger the human never loads: not scored here
    assert force_error(H, R) == pytest.approx(0.25)
    assert force_error(np.zeros((4, 2)), np.ones((4, 2))) is None
    with pytest.raises(RetargetError, match="gain"):
        ForceCalibrationConfig(gain=1.5).validate()
    with pytest.raises(RetargetError, match="iterations"):
        ForceCalibrationConfig(iterations=-1).validate()


def test_match_error_adds_the_profile_mismatch_to_the_magnitude_error():
    """The calibration's choice: pooled magnitude error plus 1 − the mean whole-clip
    correlation over the loaded fingers. Twice the human's force in step with it scores 1 + 0;
    the right mean force a quarter-period late scores its magnitude error + 1 − its correlation;
    a finger the human never loads counts in neither."""
    t = np.linspace(0, 2 * np.pi, 200)
    H = np.zeros((200, 2))
    H[:, 0] = 1.0 + np.sin(t)
    R = 2 * H.copy()
    R[:, 1] = 3.0  # unloaded by the human: not scored
    assert profile_correlation(H, R) == pytest.approx(1.0)
    assert match_error(force_error(H, R), profile_correlation(H, R)) == pytest.approx(1.0)
    late = np.zeros_like(H)
    late[:, 0] = 1.0 + np.cos(t)
    c = float(np.corrcoef(H[:, 0], late[:, 0])[0, 1])
    assert abs(c) < 0.05 and profile_correlation(H, late) == pytest.approx(c)
    assert match_error(force_error(H, late), c) == pytest.approx(force_error(H, late) + 1 - c)
    # (T, F, 3) forces score as their magnitudes
    H3 = np.zeros((200, 2, 3))
    H3[..., 2] = H
    assert profile_correlation(H3, 2 * H3) == pytest.approx(1.0)
    assert profile_correlation(np.zeros((5, 2)), np.ones((5, 2))) is None
    assert match_error(None, None) == np.inf


@pytest.fixture(scope="module")
def shadow_force_matched():
    """Shadow force-matched on the built-in cube2/tripod, the human's forces from the force
    pipeline's open-loop tracker, and its stiff-contact re-simulation."""
    from dexcanvas_core.demos import generate_demo
    from dexcanvas_core.objects.geometry import object_geometry
    from dexcanvas_core.sim.pipeline import SimConfig, simulate
    from retarget.hands import get_hand
    from retarget.retargeter import Retargeter
    from retarget.validate import FORCE_CONTACT_TIMECONST, Resimulator, ValidateConfig

    demo = generate_demo("cube2/tripod", "operator1", seed=0).trajectory
    human = simulate(demo, SimConfig(tracker="open_loop")).trajectory
    hand, geo = get_hand("shadow"), object_geometry("cube2")
    rt = Retargeter(hand, geo, RetargetConfig(force_matching=ForceMatchingConfig(enabled=True)))
    robot = rt.retarget(human)
    resim = Resimulator(hand, geo, ValidateConfig(contact_timeconst=FORCE_CONTACT_TIMECONST))
    return rt, resim, robot, human


def test_calibration_presses_closer_to_the_human_and_keeps_the_object(shadow_force_matched):
    """On a real hand: the chosen iterate keeps the object (as the input did) and its fingers'
    forces are nearer the human's (the force error drops, the correlation does not fall); the
    choice is the successful iterate with the least force error; the commands it returns are
    the ones its re-simulation ran (re-simulated again: the same forces)."""
    from retarget.metrics import force_metrics

    rt, resim, robot, human = shadow_force_matched
    sim0 = resim.run(robot.q_command, human)
    assert sim0.success
    cal = calibrate_forces(rt, resim, robot, human, sim0, ForceCalibrationConfig(iterations=3))
    its = cal.iterates
    assert len(its) == 4 and its[0].force_error is not None
    assert cal.success and its[cal.chosen].success
    ok = [k for k, it in enumerate(its) if it.success]
    scores = [its[k].force_error + 1 - its[k].profile_correlation for k in ok]
    assert cal.chosen == ok[int(np.argmin(scores))]
    assert cal.chosen > 0 and its[cal.chosen].force_error < 0.9 * its[0].force_error
    before = force_metrics(robot, sim0, human, rt)["force_profile_correlation_mean"]
    after = force_metrics(robot, cal.sim, human, rt)["force_profile_correlation_mean"]
    # each iterate's correlation is the one metrics.json reports for it
    assert its[0].profile_correlation == pytest.approx(before)
    assert its[cal.chosen].profile_correlation == pytest.approx(after)
    assert after >= before - 0.01
    again = resim.run(cal.commands, human)
    np.testing.assert_allclose(again.finger_force_world, cal.sim.finger_force_world)
    assert cal.commands.shape == robot.q_command.shape
    wrist = slice(0, 6)
    np.testing.assert_array_equal(cal.commands[:, wrist], robot.q_command[:, wrist])
    assert 0 < cal.finger_cmd_deviation_rad < 0.1
    m = cal.metrics()
    assert m["force_error_after"] == its[cal.chosen].force_error and m["compute_s"] > 0
    json.dumps(m)  # metrics.json-ready
    # zero iterations: the input, unchanged
    same = calibrate_forces(rt, resim, robot, human, sim0, ForceCalibrationConfig(iterations=0))
    assert same.chosen == 0 and np.array_equal(same.commands, robot.q_command)


def test_calibration_needs_a_force_matched_trajectory(shadow_force_matched):
    from dataclasses import replace

    rt, resim, robot, human = shadow_force_matched
    with pytest.raises(RetargetError, match="--forces"):
        calibrate_forces(rt, resim, replace(robot, human_force=None), human)


def test_refined_targets_are_calibrated_in_the_refinement_scene(shadow_force_matched):
    """A refinement's servo targets calibrated in its own scene (``calibrate_refined``):
    iterate 0 is the refinement's rollout; the chosen iterate keeps the object and is no
    further from the human's forces; the wrist's targets do not move; and the targets it
    returns, replayed open loop in that scene, reproduce its rollout."""
    from dataclasses import replace

    from retarget.force_calibration import force_error
    from retarget.refine import RefineConfig, calibrate_refined, refine
    from retarget.validate import FORCE_CONTACT_TIMECONST

    rt, _, robot, human = shadow_force_matched
    human = human.slice(0, 360)  # the grasp and the lift
    robot = rt.retarget(human)
    hand, geo = rt.hand, rt.geometry
    cfg = RefineConfig(contact_timeconst=FORCE_CONTACT_TIMECONST, retries=0)
    rf = refine(hand, geo, human, robot, rt.tip_sites, cfg)
    assert rf.success
    cal = calibrate_refined(hand, geo, human, robot, rt.tip_sites, rf, cfg,
                            ForceCalibrationConfig(iterations=2))  # fmt: skip
    c = cal.calibration
    assert len(c["iterates"]) == 3 and c["iterates"][0]["success"]
    col = [list(hand.robot_fingers).index(hand.fingers[f]) for f in rt.tip_human]
    assert c["force_error_before"] == pytest.approx(
        force_error(robot.human_force, rf.finger_force_world[:, col])
    )
    assert cal.success and c["chosen_iterate"] > 0  # (0.30 → 0.21 measured)
    assert c["force_error_after"] < 0.9 * c["force_error_before"]
    assert cal.compute_s > rf.compute_s
    m = hand.compile()
    act_q = np.array([m.jnt_qposadr[m.actuator_trnid[a, 0]] for a in range(m.nu)])
    np.testing.assert_array_equal(cal.ctrl[:, act_q < 6], rf.ctrl[:, act_q < 6])
    # replayed open loop (the refinement's tracker without residual) on these targets
    q_cmd = robot.q_command.copy()
    q_cmd[:, act_q] = cal.ctrl
    again = refine(hand, geo, human, replace(robot, q_command=q_cmd), rt.tip_sites,
                   replace(cfg, tracker="open_loop"))  # fmt: skip
    np.testing.assert_allclose(again.object_pos_err, cal.object_pos_err, atol=1e-9)
    np.testing.assert_allclose(again.finger_force_world, cal.finger_force_world, atol=1e-9)
    json.dumps(cal.metrics())
