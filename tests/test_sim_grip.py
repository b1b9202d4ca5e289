"""Grip force–load coupling of the force pipeline (``dexcanvas_core.sim.physics.carried_load``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dexcanvas_core.demos import OPERATORS, generate_demo
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.sim.grip import contact_keeping_force, squeeze_offsets
from dexcanvas_core.sim.physics import GRAVITY, carried_load
from dexcanvas_core.sim.pipeline import SimConfig, prepare, simulate
from dexcanvas_core.sim.tracker import TrackingConfig, TrackingEnv

FPS = 100.0
LIFT, SET_DOWN = 100, 200
"""Frames of the synthetic track: rests, lifts at 0.2 m/s from ``LIFT``, is back at ``SET_DOWN``."""


def _lift_track(geometry) -> tuple[np.ndarray, np.ndarray]:
    T = 300
    z = np.full(T, geometry.rest_z)
    up = np.arange(LIFT, 150)
    z[up] += 0.2 * (up - LIFT) / FPS
    z[150:SET_DOWN] = z[149] - 0.2 * (np.arange(150, SET_DOWN) - 149) / FPS * (z[149] - z[0]) / (
        0.2 * 50 / FPS
    )
    z[SET_DOWN:] = geometry.rest_z
    pos = np.stack([np.zeros(T), np.zeros(T), z], axis=1)
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (T, 1))
    return pos, quat


def test_carried_load_is_zero_on_the_table_and_full_before_lift_off():
    geo = object_geometry("cube2H")
    pos, quat = _lift_track(geo)
    lead = 0.2
    n = round(lead * FPS)
    lam = carried_load(geo, pos, quat, FPS, clear_m=(0.001, 0.004), lead_s=lead)
    assert lam.shape == (300,) and lam.min() >= 0.0 and lam.max() <= 1.0
    # resting long before lift-off and after set-down: the table carries the object
    assert np.all(lam[: LIFT - n - 1] == 0.0)
    assert np.all(lam[SET_DOWN + n // 2 :] == 0.0)
    # the whole weight by half the lead before the reference leaves the table, and in the air
    # until the object is back within the clearance ramp (4 mm) of the table (frame 197)
    np.testing.assert_allclose(lam[LIFT - n // 2 + 1 : SET_DOWN - 3], 1.0, atol=1e-9)
    # built up gradually (a ramp, not a step), never decreasing towards lift-off
    ramp = lam[LIFT - n - 1 : LIFT - n // 2 + 1]
    assert np.all(np.diff(ramp) >= 0.0) and np.any((ramp > 0.2) & (ramp < 0.8))
    # no anticipation: the share follows the clearance alone
    lam0 = carried_load(geo, pos, quat, FPS, lead_s=0.0)
    assert lam0[LIFT] == 0.0 and lam0[LIFT + 5] == 1.0


def test_carried_load_refuses_bad_ramps():
    geo = object_geometry("cube2")
    pos, quat = _lift_track(geo)
    with pytest.raises(ValidationError):
        carried_load(geo, pos, quat, FPS, clear_m=(0.004, 0.001))
    with pytest.raises(ValidationError):
        carried_load(geo, pos, quat, FPS, lead_s=-0.1)


HEAVY_LIFT = slice(140, 380)
"""Approach, grasp and lift-off of the heavy demonstration (fingers near the cylinder from
frame 167, the whole weight carried from frame 321)."""


@pytest.fixture(scope="module")
def heavy():
    """``cylinder1/large_diameter`` (operator1, seed 0) simulated with ``cylinder1H``, the
    catalogue's heaviest object (0.554 kg): a weight-sized grip force from the first finger's
    approach pushes a resting heavy object before the grasp holds it."""
    traj = generate_demo("cylinder1/large_diameter", sorted(OPERATORS)[0], 0).trajectory
    _g, ref, scene = prepare(traj, SimConfig(object_id="cylinder1H"))
    return traj, ref, scene


def test_squeeze_force_follows_the_carried_load(heavy):
    _traj, ref, scene = heavy
    env = TrackingEnv(scene, ref, TrackingConfig(grip=False))
    t = int(np.flatnonzero((env.tip_weight > 0.99).sum(axis=1) >= 2)[0])  # two pads on it
    W = env.tip_weight[t : t + 1]
    sl = slice(t, t + 1)
    mg = scene.mass_kg * GRAVITY
    n_near = max(1.0, float((W > 0.5).sum()))
    F_load = 3.0 * mg / (1.0 * n_near)
    out = {}
    for load, additive in ((0.0, False), (1.0, False), (1.0, True), (0.5, True)):
        _off, f = squeeze_offsets(
            scene, env.ctrl_ref[sl], ref.object_pos[sl], ref.object_quat[sl], W,
            force_min_n=4.0, safety=3.0, friction=1.0, balance=False, load=np.array([load]),
            additive=additive,
        )  # fmt: skip
        out[load, additive] = f[0]
    np.testing.assert_allclose(out[0.0, False], W[0] * 4.0)
    np.testing.assert_allclose(out[1.0, False], W[0] * max(4.0, F_load))
    np.testing.assert_allclose(out[1.0, True], W[0] * (4.0 + F_load))
    np.testing.assert_allclose(out[0.5, True], W[0] * (4.0 + 0.5 * F_load))
    with pytest.raises(ValidationError):
        squeeze_offsets(
            scene, env.ctrl_ref[sl], ref.object_pos[sl], ref.object_quat[sl], W,
            force_min_n=4.0, safety=3.0, friction=1.0, load=np.array([1.5]),
        )  # fmt: skip


def test_resting_heavy_object_gets_no_weight_sized_squeeze(heavy):
    """The commanded pad forces stay at the contact-keeping force while the reference object
    rests on the table, and carry ``safety`` × its weight by friction once it is lifted."""
    _traj, ref, scene = heavy
    cfg = TrackingConfig()
    env = TrackingEnv(scene, ref, cfg)
    old = TrackingEnv(
        scene, ref, dataclasses.replace(cfg, grip_load_lead_s=None, grip_additive=False)
    )
    resting = env.load == 0.0
    carried = env.load == 1.0
    assert resting.any() and carried.any()
    touching = resting & (env.tip_weight > 0).any(axis=1)
    assert touching.sum() > 20  # the fingers reach the object well before it is lifted
    # at most the balanced contact-keeping force per pad while it rests …
    assert env.grip_force[touching].max() <= cfg.grip_force_min_n * 1.5
    # … where the earlier model pressed the first finger with a weight-sized force
    assert old.grip_force[touching].max() > 2.5 * cfg.grip_force_min_n
    # in the air the pads' friction carries the weight with margin
    mg = scene.mass_kg * GRAVITY
    held = carried & ((env.tip_weight > 0.5).sum(axis=1) >= 2)
    assert held.sum() > 50
    total = env.grip_force[held].sum(axis=1)
    assert np.median(total) >= cfg.grip_safety * mg


def test_heavy_object_is_lifted_without_being_dropped(heavy):
    """Approach, grasp and lift-off of the heavy cylinder (``HEAVY_LIFT``) tracked by the MPC:
    the object follows the reference, and the hand carries its weight once lifted."""
    traj, _ref, _scene = heavy
    res = simulate(traj.slice(HEAVY_LIFT.start, HEAVY_LIFT.stop), SimConfig(object_id="cylinder1H"))
    assert res.success, res.metrics["failed_at_frame"]
    assert res.metrics["object_pos_err_max_m"] < 0.02
    # the hand carries the object's weight at the end of the clip
    assert res.wrench[-10:, 2].mean() > 0.8 * res.metrics["mass_kg"] * GRAVITY


def test_contact_keeping_force_is_gentler_on_light_objects():
    # k · m·g inside the range, clipped at both ends
    assert contact_keeping_force(0.085, 4.0, 2.0, 2.7) == pytest.approx(2.7 * 0.085 * GRAVITY)
    assert contact_keeping_force(0.012, 4.0, 2.0, 2.7) == 2.0
    assert contact_keeping_force(0.200, 4.0, 2.0, 2.7) == 4.0
    assert contact_keeping_force(0.509, 4.0, 2.0, 2.7) == 4.0
    # no floor: the fixed force of the earlier model
    assert contact_keeping_force(0.012, 4.0, None, 2.7) == 4.0
    for floor, k in ((0.0, 2.7), (5.0, 2.7), (2.0, -1.0)):
        with pytest.raises(ValidationError):
            contact_keeping_force(0.1, 4.0, floor, k)


def _held_grip_n(traj, object_id: str, cfg: TrackingConfig) -> tuple[float, float]:
    """Median commanded pad-force sum [N] over the frames the hand carries the object with two
    or more pads on it, and the object's mass [kg]."""
    _g, ref, scene = prepare(traj, SimConfig(object_id=object_id))
    env = TrackingEnv(scene, ref, cfg)
    held = (env.load == 1.0) & ((env.tip_weight > 0.5).sum(axis=1) >= 2)
    assert held.sum() > 100
    return float(np.median(env.grip_force[held].sum(axis=1))), scene.mass_kg


def test_grip_force_follows_the_load_as_human_grip_does():
    """The same cube2/tripod grasp of the light cube (37 g) and its heavy duplicate (123 g):
    the grip scales with the weight (grip ≈ safety × load / μ plus a small baseline), at least
    0.6 × the mass ratio. A 2 N contact-keeping floor (50 % of the light cube's grip) does not."""
    traj = generate_demo("cube2/tripod", sorted(OPERATORS)[0], 0).trajectory
    for cfg, holds in ((TrackingConfig(), True), (TrackingConfig(grip_force_floor_n=2.0), False)):
        f_light, m_light = _held_grip_n(traj, "cube2", cfg)
        f_heavy, m_heavy = _held_grip_n(traj, "cube2H", cfg)
        ratio = (f_heavy / f_light) / (m_heavy / m_light)
        assert (ratio >= 0.6) == holds, (cfg.grip_force_floor_n, ratio)
    assert f_light > 3 * m_light * GRAVITY  # even the light cube is held with margin


@pytest.mark.slow
def test_light_object_is_lifted_with_a_gentle_grip():
    """``cylinder5/lateral_tripod``: the 6 g mini cylinder (the paper's D2 × 2.7 cm), carried
    from frame 281. The weight-scaled contact force lifts it with pads pressing a fraction of a
    newton, where the fixed 4 N of the earlier model is 68 × its weight per pad."""
    traj = generate_demo("cylinder5/lateral_tripod", sorted(OPERATORS)[0], 0).trajectory
    res = simulate(traj.slice(0, 360), SimConfig())
    assert res.success, res.metrics["failed_at_frame"]
    assert res.metrics["mass_kg"] == pytest.approx(0.006)
    assert res.metrics["object_pos_err_max_m"] < 0.02
    pads = res.metrics["hold_finger_force_mean_n"]
    assert pads is not None and 0.0 < max(pads.values()) < 1.0
    # the hand carries the object's weight at the end of the clip
    assert res.wrench[-10:, 2].mean() > 0.8 * res.metrics["mass_kg"] * GRAVITY
