"""The re-simulation's wrist driver (``retarget.wrist_drive``): a force-limited computed-torque
controller that carries the robot hand along fast human-like wrist commands."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.trajectory import HandTrack, ObjectTrack, Trajectory
from retarget.errors import RetargetError
from retarget.hands import WristGains, get_hand
from retarget.validate import Resimulator, ValidateConfig, servo_summary
from retarget.wrist_drive import WristReference, frame_steps

FPS = 120.0


def _min_jerk(tau: np.ndarray) -> np.ndarray:
    tau = np.clip(tau, 0.0, 1.0)
    return 10 * tau**3 - 15 * tau**4 + 6 * tau**5


def carry(peak_speed: float, peak_acc: float, hold: float = 0.15):
    """Timestamps and wrist commands (T, 6): at rest, a straight minimum-jerk carry reaching
    ``peak_speed`` [m/s] and ``peak_acc`` [m/s²] while the hand turns 90° in 0.5 s, at rest,
    the same back."""
    duration = 5.7735 * peak_speed / (1.875 * peak_acc)  # min-jerk: v = 1.875 D/T, a = 5.77 D/T²
    dist = peak_speed * duration / 1.875
    back = hold + duration + hold
    t = np.arange(0.0, back + max(duration, 0.5) + hold, 1 / FPS)
    s = _min_jerk((t - hold) / duration) - _min_jerk((t - back) / duration)
    u = np.array([1.0, 0.6, 0.4]) / np.linalg.norm([1.0, 0.6, 0.4])
    p = np.array([-0.4, -0.3, 0.4]) + dist * s[:, None] * u
    axis = np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])
    angle = np.pi / 2 * (_min_jerk((t - hold) / 0.5) - _min_jerk((t - back) / 0.5))
    euler = Rotation.from_rotvec(angle[:, None] * axis).as_euler("XYZ")
    return t, np.c_[p, euler]


def free_air(hand, t: np.ndarray, wrist: np.ndarray, **cfg):
    """A re-simulation of ``hand`` in free air (no table, the object 10 m away) and the joint
    commands: the wrist's ``wrist`` (T, 6), the fingers held open."""
    T = len(t)
    human = Trajectory(
        uuid="wrist-carry",
        timestamp=t,
        fps=FPS,
        hands=[HandTrack("right", np.zeros((T, 3)), np.zeros((T, 3)), np.zeros((T, 48)))],
        objects=[ObjectTrack("cube2", np.tile([10.0, 10.0, 0.5], (T, 1)), np.zeros((T, 3)))],
    )
    sim = Resimulator(hand, object_geometry("cube2"), ValidateConfig(table=False, **cfg))
    q = np.tile(hand.default_qpos(sim.model)[: sim.hand_nq], (T, 1))
    q[:, :6] = wrist
    return sim, q, human


@pytest.mark.parametrize("name", ["shadow", "allegro"])
def test_wrist_follows_a_fast_human_carry(name):
    """At a human wrist's top speed and acceleration (2.5 m/s, 15 m/s², turning 90° in 0.5 s)
    the computed-torque wrist stays within 5 mm and 2° on average (measured: below 0.5 mm and
    0.1°), without touching its limits; the position servos it replaces trail by centimetres."""
    hand = get_hand(name)
    t, wrist = carry(2.5, 15.0)
    sim, q, human = free_air(hand, t, wrist)
    m = sim.run(q, human).metrics()
    assert m["wrist_driver"] == "computed_torque"
    assert m["wrist_pos_tracking_err_mean_m"] <= 5e-3
    assert m["wrist_rot_tracking_err_mean_deg"] <= 2.0
    assert m["wrist_pos_tracking_err_max_m"] < 5e-3
    assert m["wrist_force_saturation_fraction"] == m["wrist_torque_saturation_fraction"] == 0.0
    assert m["wrist_force_max_n"] < m["wrist_force_limit_n"] == hand.wrist_gains.force_slide
    sim, q, human = free_air(hand, t, wrist, wrist_driver="servo")
    servo = sim.run(q, human).metrics()
    assert servo["wrist_driver"] == "servo"
    assert servo["wrist_pos_tracking_err_mean_m"] > 0.02


def test_held_wrist_sits_on_target_carrying_the_hands_weight():
    """Held still in free air, the wrist sits on its target, and the force the arm applies is
    the hand's weight (gravity compensation by the driver's bias term)."""
    hand = get_hand("allegro")
    t = np.arange(0.0, 1.0, 1 / FPS)
    wrist = np.tile([0.1, -0.2, 0.4, 0.3, -0.4, 1.0], (len(t), 1))
    sim, q, human = free_air(hand, t, wrist)
    res = sim.run(q, human)
    assert res.wrist_pos_err.max() < 1e-6
    assert np.degrees(res.wrist_rot_err.max()) < 1e-3
    weight = sim.model.body_subtreemass[sim.model.body("wrist").id] * 9.81
    np.testing.assert_allclose(res.wrist_force_peak, weight, rtol=1e-3)


def test_force_and_torque_limits_hold_against_an_impossible_command():
    """A 50 m/s² carry with a 20 N arm (2 N·m per hinge), then a 0.3 m and 90° jump in one
    frame: the force the arm applies (measured from the simulation's actuator forces) never
    exceeds the limits, the metrics and the summary say how often they bound, and the hand
    still arrives where commanded."""
    weak = dataclasses.replace(
        get_hand("allegro"), wrist_gains=WristGains(force_slide=20.0, torque_hinge=2.0)
    )
    t, wrist = carry(1.0, 50.0)
    n = len(t)
    t = np.r_[t, t[-1] + np.arange(1, 121) / FPS]
    wrist = np.r_[wrist, np.tile(wrist[-1] + [0.0, 0.0, 0.3, 0.0, 0.0, np.pi / 2], (120, 1))]

    applied = []

    class Measuring(Resimulator):
        def _contact_forces(self, d):  # after every physics step
            f = d.actuator_force[self.wrist_act] + d.qfrc_gravcomp[:6]
            applied.append((np.linalg.norm(f[:3]), np.abs(f[3:]).max()))
            return super()._contact_forces(d)

    _, q, human = free_air(weak, t, wrist)
    sim = Measuring(weak, object_geometry("cube2"), ValidateConfig(table=False))
    res = sim.run(q, human)
    force, torque = np.array(applied).T
    assert force.max() <= 20.0 * (1 + 1e-9) and torque.max() <= 2.0 * (1 + 1e-9)
    assert force.max() > 19.9 and torque.max() > 1.99  # the limits bound
    m = res.metrics()
    assert (m["wrist_force_limit_n"], m["wrist_torque_limit_nm"]) == (20.0, 2.0)
    assert m["wrist_force_max_n"] == pytest.approx(force.max(), rel=1e-12)
    assert 0.0 < m["wrist_force_saturation_fraction"] < 0.5
    assert 0.0 < m["wrist_torque_saturation_fraction"] < 0.5
    assert "at its force / torque limit in" in servo_summary(m)  # said on the terminal
    assert res.wrist_pos_err[n - 1] > 0.01  # the carry was too fast for 20 N
    assert res.wrist_pos_err[-1] < 1e-3 and np.degrees(res.wrist_rot_err[-1]) < 0.1


def test_reference_rests_at_the_ends_and_passes_slow_motion():
    """The reference starts and ends nearly at rest on the commands, passes a 2 Hz motion
    within 1 % of its amplitude, and its velocity and acceleration are the differences of its
    samples; without smoothing it goes through every command."""
    h = 0.002
    t = np.arange(0.0, 2.0, 1 / FPS)
    q = np.zeros((len(t), 6))
    q[:, 0] = 0.05 * np.sin(2 * np.pi * 2.0 * t) * _min_jerk(t / 0.5) * _min_jerk((2 - t) / 0.5)
    q[:, 5] = 0.3
    steps = frame_steps(t, h)
    assert steps[0] == 0 and np.all(np.diff(steps) == 4)  # 8.33 ms frames: 4 steps of 2 ms
    ref = WristReference.from_frames(q, steps, h)
    assert ref.q.shape == (steps[-1] + 1, 6)
    np.testing.assert_allclose(ref.q[0], q[0], atol=1e-4)  # within 0.1 mm of the first command
    np.testing.assert_allclose(ref.v[0], 0.0, atol=1e-2)  # and nearly at rest
    np.testing.assert_allclose(ref.q[-1], q[-1], atol=1e-4)
    np.testing.assert_allclose(ref.q[steps], q, atol=0.01 * 0.05)
    np.testing.assert_allclose(ref.v[1:], np.diff(ref.q, axis=0) / h, atol=1e-9)
    np.testing.assert_allclose(ref.a[1:-1], np.diff(ref.q, 2, axis=0) / h**2, atol=1e-6)
    exact = WristReference.from_frames(q, steps, h, smoothing_hz=None)
    np.testing.assert_allclose(exact.q[steps], q, atol=1e-9)


def test_bad_driver_settings_are_refused():
    with pytest.raises(RetargetError, match="unknown wrist driver 'pid'"):
        ValidateConfig(wrist_driver="pid")
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(RetargetError, match="wrist_smoothing_hz"):
            ValidateConfig(wrist_smoothing_hz=bad)
