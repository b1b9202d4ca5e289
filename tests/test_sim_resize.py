"""Size-aware reference (``dexcanvas_core.sim.resize``): the hand follows a resized object."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dexcanvas_core.demos import generate_demo
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS, MANO21
from dexcanvas_core.mocap import fit_markers, render_markers
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.sim.grip import distal_geoms
from dexcanvas_core.sim.hand import HINGE_HIGH, HINGE_LOW
from dexcanvas_core.sim.pipeline import SimConfig, prepare, simulate
from dexcanvas_core.sim.reference import build_reference
from dexcanvas_core.sim.resize import ResizeConfig, adapt_reference_to_size

SCALE = 0.8
EXACT = SimConfig(reference_lowpass_hz=None, object_scale=SCALE)
"""Targets as adapted (no low-pass), object 20 % smaller."""


@pytest.fixture(scope="module")
def pinch():
    """``cuboid3H/lateral_pinch`` (the 5 × 5 × 2.5 cm, 82 g heavy cuboid) by operator3, seed
    27, through the force benchmark's mocap stage (1 mm marker noise, 10 % dropout). At size
    ×0.8, replayed open loop, the unadapted reference drops the cuboid (frame 318 of 742)."""
    traj = generate_demo("cuboid3H/lateral_pinch", "operator3", seed=27).trajectory
    stream = render_markers(traj, noise_mm=1.0, dropout=0.1, seed=27)
    fit = fit_markers(
        stream,
        object_id=traj.object.name,
        uuid=traj.uuid,
        operator=traj.operator,
        gesture=traj.gesture,
    )
    return fit.trajectory


@pytest.fixture(scope="module")
def prepared(pinch):
    """``(original reference, adapted reference, scene)`` at size ×0.8, no low-pass."""
    _g, ref0, _s = prepare(pinch, dataclasses.replace(EXACT, adapt_reference_to_size=False))
    _g, ref, scene = prepare(pinch, EXACT)
    return ref0, ref, scene


def _pad_gaps(scene, ctrl, obj_pos, obj_quat, geometry) -> np.ndarray:
    """``(T, 5)`` gap [m] between each distal capsule's surface and the object surface, with
    the scene's own kinematics (independent of the IK's)."""
    m = scene.model
    d = mujoco.MjData(m)
    geoms = distal_geoms(scene)
    s = np.linspace(-1.0, 1.0, 11)
    out = np.zeros((len(ctrl), len(geoms)))
    R_o = Rotation.from_quat(obj_quat, scalar_first=True).as_matrix()
    for t in range(len(ctrl)):
        d.qpos[scene.hand.qpos_adr] = ctrl[t]
        mujoco.mj_kinematics(m, d)
        for k, g in enumerate(geoms):
            axis = d.geom_xmat[g].reshape(3, 3)[:, 2]
            pts = d.geom_xpos[g] + np.outer(s * m.geom_size[g, 1], axis)
            sd = geometry.signed_distance((pts - obj_pos[t]) @ R_o[t])
            out[t, k] = sd.min() - m.geom_size[g, 0]
    return out


def test_scale_one_is_the_identity(pinch):
    base = object_geometry(pinch.object.name)
    ref = build_reference(pinch, base)
    out, report = adapt_reference_to_size(ref, base, base, pinch.object.pos, 1.0)
    assert report.frames_adapted.any()  # the IK did run on the grasp frames
    np.testing.assert_allclose(out.ctrl(), ref.ctrl(), atol=1e-9)
    np.testing.assert_allclose(out.keypoints, ref.keypoints, atol=1e-9)
    np.testing.assert_allclose(out.tip_distance, ref.tip_distance, atol=1e-9)


def test_contacting_pads_keep_their_gap_on_the_resized_surface(pinch, prepared):
    ref0, ref, scene = prepared
    base = object_geometry(pinch.object.name)
    src = pinch.object.pos.astype(np.float64)
    gap0 = _pad_gaps(scene, ref0.ctrl(), src, ref0.object_quat, base)
    # without the adaptation, the same pads against the smaller object: centimetre-scale
    # gaps (the fingers close on air), which is what dropped the object
    gap_raw = _pad_gaps(scene, ref0.ctrl(), ref0.object_pos, ref0.object_quat, scene.geometry)
    gap1 = _pad_gaps(scene, ref.ctrl(), ref.object_pos, ref.object_quat, scene.geometry)
    touching = gap0 < 0.003
    assert touching.sum() > 200  # finger-frames of the pinch
    assert np.median(np.abs(gap_raw - gap0)[touching]) > 0.004
    err = np.abs(gap1 - gap0)[touching]
    assert np.median(err) < 0.001
    assert np.quantile(err, 0.95) < 0.002


def test_limits_respected_and_far_frames_untouched(prepared):
    ref0, ref, scene = prepared
    assert (ref.hinges >= HINGE_LOW - 1e-12).all() and (ref.hinges <= HINGE_HIGH + 1e-12).all()
    ctrl = ref.ctrl()
    assert (ctrl >= scene.hand.ctrl_low).all() and (ctrl <= scene.hand.ctrl_high).all()
    # the approach: the hand starts far from the object, and those frames are the captured
    # ones; the adaptation fades in: where the reference itself moves by less than 0.2 (m or
    # rad) per frame (the unfiltered mocap fit jumps more on ~4 % of frames), the correction
    # changes by less than 0.02 per frame at 120 Hz (measured: 0.012)
    changed = np.abs(ctrl - ref0.ctrl()).max(axis=1) > 0
    assert not changed[0] and changed.any()
    first = int(np.argmax(changed))
    assert (~changed[:first]).all()
    jump = np.abs(np.diff(ctrl - ref0.ctrl(), axis=0)).max(axis=1)
    smooth = np.abs(np.diff(ref0.ctrl(), axis=0)).max(axis=1) < 0.2
    assert smooth.mean() > 0.9
    assert jump[smooth].max() < 0.02


def test_keypoints_and_tip_relations_follow_the_adapted_hand(pinch, prepared):
    ref0, ref, scene = prepared
    R_o = Rotation.from_quat(ref.object_quat, scalar_first=True).as_matrix()
    tips = ref.keypoints[:, [MANO21.index(f"{f}_tip") for f in FINGERS]]
    tips_obj = np.einsum("tji,tkj->tki", R_o, tips - ref.object_pos[:, None])
    np.testing.assert_allclose(ref.tips_object, tips_obj, atol=1e-12)
    np.testing.assert_allclose(
        ref.tip_distance, scene.geometry.signed_distance(tips_obj), atol=1e-12
    )
    # the human fingertips near the original object (tip keypoint within 2 cm of its surface)
    # keep their distance to the resized one: measured median change 0.94 mm, against 5.0 mm
    # for the unadapted reference
    d_src = build_reference(pinch, object_geometry(pinch.object.name)).tip_distance
    near = np.abs(d_src) < 0.02
    assert near.sum() > 300
    assert np.median(np.abs(ref.tip_distance - d_src)[near]) < 0.0015
    assert np.median(np.abs(ref0.tip_distance - d_src)[near]) > 0.004


def test_resized_pinch_now_holds_the_object(pinch):
    """End to end: the pair that dropped the ×0.8 object holds it with the adapted
    reference (open-loop tracker: the reference and the grip alone, no planning)."""
    cfg = SimConfig(tracker="open_loop", object_scale=SCALE)
    before = simulate(pinch, dataclasses.replace(cfg, adapt_reference_to_size=False))
    after = simulate(pinch, cfg)
    assert not before.success and before.metrics["failed_at_frame"] is not None
    assert after.success, after.metrics["object_pos_err_max_m"]
    assert after.metrics["object_pos_err_max_m"] < 0.03


def test_bad_settings_are_refused(prepared):
    _ref0, ref, _scene = prepared
    with pytest.raises(ValidationError):
        ResizeConfig(near_m=0.05, far_m=0.01).validate()
    with pytest.raises(ValidationError):
        base = object_geometry("cuboid3H")
        adapt_reference_to_size(ref, base, base, np.zeros((3, 3)), 0.8)
