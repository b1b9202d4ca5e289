"""Retargeting geometry on real shapes: a thin box the human's fingers sink into, fingers that
close round a ball larger than the palm, contact terms and the grip on a mesh's own surface, and
the signed-distance terms' Jacobians against finite differences.

The shapes are meshes given for catalogue ids by a manifest (the ids keep the feasibility
rules' kinds: a box, a sphere): a phone-like box 15 × 2.5 × 7.5 cm standing on its long edge
(the 2.5 cm thickness horizontal, between the thumb and the fingers of a tripod) and an
apple-sized ball of Ø 85 mm. The demonstrations are generated on them.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from dexcanvas_core.rotations import aa_to_matrix, aa_to_quat_wxyz
from retarget.config import ClosingConfig, ContactsConfig, RetargetConfig
from retarget.hands import get_hand
from retarget.retargeter import Retargeter
from retarget.state import RobotState

PHONE = (0.15, 0.025, 0.075)  # x, y (the thin axis), z [m]
APPLE_R = 0.0425


@pytest.fixture(scope="module")
def shapes(tmp_path_factory):
    """``{"phone": (geometry, tripod demonstration), "apple": (geometry, four-finger power
    sphere demonstration)}``, generated with the manifest in use (and forgotten after)."""
    from dexcanvas_core.demos import generate_demo
    from dexcanvas_core.objects.geometry import object_geometry
    from dexcanvas_core.taxonomy import clear_objects, use_objects

    base = tmp_path_factory.mktemp("geometry")
    mp = pytest.MonkeyPatch()
    mp.setenv("DEXCANVAS_CACHE_DIR", str(base / "cache"))
    trimesh.creation.box(extents=PHONE).export(base / "phone.obj")
    trimesh.creation.icosphere(subdivisions=3, radius=APPLE_R).export(base / "apple.obj")
    (base / "objects.toml").write_text(
        '[cuboid2]\nmesh = "phone.obj"\nmass_kg = 0.17\n\n'
        '[sphere1]\nmesh = "apple.obj"\nmass_kg = 0.18\n'
    )
    try:
        use_objects(base / "objects.toml")
        out = {}
        for key, pair in (("phone", "cuboid2/tripod"), ("apple", "sphere1/sphere_4_finger")):
            demo = generate_demo(pair, "operator1", 0)
            assert demo.passed, demo.report
            traj = demo.trajectory
            out[key] = (object_geometry(traj.object.name), traj)
        yield out
    finally:
        clear_objects()
        mp.undo()


def _human_tip_depth(geometry, traj) -> np.ndarray:
    """(T, 5) signed distance [m] of the human fingertip keypoints to the object."""
    from dexcanvas_core.keypoints import MANO21

    tips = [MANO21.index(f"{f}_tip") for f in ("thumb", "index", "middle", "ring", "pinky")]
    kp = traj.hand.joint_pos.astype(np.float64)[:, tips]
    R = aa_to_matrix(traj.object.rot_aa.astype(np.float64))
    p = traj.object.pos.astype(np.float64)
    return geometry.signed_distance(np.einsum("tji,tfj->tfi", R, kp - p[:, None]))


def _window(traj, depth: np.ndarray, before: int = 90, after: int = 150):
    """The frames from ``before`` frames ahead of the first human contact to ``after`` past it
    (the approach and the grasp; the solver starts from the open posture)."""
    onset = int(np.argmax((depth < 0.012).any(axis=1)))
    return traj.slice(max(onset - before, 0), min(onset + after, traj.num_frames))


def _shifted(traj, shift: float):
    """``traj`` with the object track moved ``shift`` [m] along the object's thin (y) axis:
    the human's fingers on one face sink into the box (a capture whose object pose is off)."""
    R = aa_to_matrix(traj.object.rot_aa.astype(np.float64))
    pos = traj.object.pos.astype(np.float64) + shift * R[:, :, 1]
    obj = dataclasses.replace(traj.objects[0], pos=pos)
    return dataclasses.replace(traj, objects=[obj, *traj.objects[1:]])


@pytest.mark.parametrize("hand", ["allegro", "inspire"])
@pytest.mark.parametrize("shift", [0.015, -0.015])
def test_thin_box_with_human_fingers_inside_stays_within_two_mm(shapes, hand, shift):
    """The human's fingertip keypoints 5–12 mm inside a 2.5 cm thick box (their pads, a
    finger radius further, 1–2 cm in: past the box's mid-plane, where the nearest face is the
    other one): the kinematic solution penetrates by at most 2 mm on every frame."""
    geometry, traj = shapes["phone"]
    traj = _shifted(traj, shift)
    depth = _human_tip_depth(geometry, traj)
    traj = _window(traj, depth)
    assert depth.min() < -0.005  # the human's keypoints are inside
    rt = Retargeter(get_hand(hand), geometry)
    out = rt.retarget(traj)
    assert out.contact_active.any()
    assert -out.min_distance.min() <= 0.002, -out.min_distance.min()


def _part_distances(rt: Retargeter, traj, q: np.ndarray) -> dict:
    """Per (finger, part) the human touches the object with: the robot link's distances [m]
    to the object over those frames."""
    tg = rt.human_targets(traj)
    by_part = tg["contact_by_part"]
    quat = aa_to_quat_wxyz(traj.object.rot_aa)
    obj = set(rt.scene.object_geoms)
    out: dict = {}
    for t in np.flatnonzero(by_part.any(axis=(1, 2))):
        rt.scene.set_object_pose(traj.object.pos[t], quat_wxyz=quat[t])
        near = {}
        for a, b, d, _, _ in rt.distance_query.distances(q[t]):
            if b in obj:
                near[a] = min(near.get(a, np.inf), d)
        for f, k in zip(*np.nonzero(by_part[t]), strict=True):
            parts = rt.contacts.part_geoms[f]
            if k < len(parts):
                d = min(near.get(g, rt.cfg.collision.distmax) for g in parts[k])
                out.setdefault((rt.tip_human[f], int(k)), []).append(d)
    return out


@pytest.mark.parametrize("hand", ["inspire", "ability"])
def test_fingers_close_round_a_ball_larger_than_the_palm(shapes, hand):
    """A four-finger power sphere on an 85 mm ball: every robot link whose human phalanx
    touches the ball ends at its surface (median within 5 mm, 90 % of the frames within
    7 mm; the distal links within 2.5 mm). Contact terms measuring only the offset
    along the human's normal and no closing terms leave fingers straight over the ball, 1–2 cm
    off it."""
    geometry, traj = shapes["apple"]
    traj = _window(traj, _human_tip_depth(geometry, traj), after=200)
    rt = Retargeter(get_hand(hand), geometry)
    dist = _part_distances(rt, traj, rt.retarget(traj).q)
    assert len(dist) >= 4  # distal and middle phalanges of several fingers
    for key, d in dist.items():
        assert np.median(d) <= (0.0025 if key[1] == 0 else 0.005), (key, np.median(d))
        assert np.percentile(d, 90) <= 0.007, (key, np.percentile(d, 90))
    old = RetargetConfig(contacts=ContactsConfig(hover_m=None), closing=ClosingConfig(weight=0.0))
    rt_old = Retargeter(get_hand(hand), geometry, old)
    before = _part_distances(rt_old, traj, rt_old.retarget(traj).q)
    assert max(np.median(d) for d in before.values()) > 0.01


@pytest.fixture(scope="module")
def grasp(shapes):
    """Inspire retargeted onto the ball's power sphere: ``(retargeter, trajectory, frame,
    configuration)`` at a frame where three fingers hold the ball, every finger's contact
    (its distal link) and closing term (its proximal link) set, the fingers opened a little
    (their links a few millimetres off the ball)."""
    geometry, traj = shapes["apple"]
    traj = _window(traj, _human_tip_depth(geometry, traj), after=120)
    rt = Retargeter(get_hand("inspire"), geometry)
    out = rt.retarget(traj)
    tg = rt.human_targets(traj)
    t = int(np.flatnonzero(tg["contact_active"].sum(axis=1) >= 3)[-1])
    rt.scene.set_object_pose(traj.object.pos[t], traj.object.rot_aa[t])
    F = len(rt.tip_sites)
    closing = np.zeros((F, 3), bool)
    closing[:, 1] = True
    rt.contacts.set_contacts(
        np.ones(F, bool),
        tg["contact_points"][t],
        np.zeros(F, int),
        normals=tg["contact_normals"][t],
        closing=closing,
    )
    q = out.q[t].copy()
    q[6:] -= 0.05
    return rt, traj, t, np.minimum(np.maximum(q, rt.lower), rt.upper)


def test_signed_distance_rows_match_finite_differences(grasp):
    """The contact terms' normal rows (each link's signed distance to the object) and the
    closing rows: their Jacobian ``gᵀ J(p)`` is the distance's derivative (central
    differences, every joint), and the one-pass ``(H, c)`` is the base class's."""
    from retarget.objectives.base import Objective

    rt, _, _, q = grasp
    c = rt.contacts
    c.hover = 0.0  # every normal row the link's distance (off the ball it exceeds the offset)
    F = len(rt.tip_sites)
    rt.kin.forward(q)
    s = RobotState(q=q, kin=rt.kin)
    e, J = c.error(s), c.jacobian(s)
    n_closing = e.size - 3 * F
    assert n_closing >= 2  # the middle links' closing rows
    np.testing.assert_allclose(c._gap_rows(q, np.arange(F))[0], c._cache_d, atol=1e-12)
    rows = np.r_[np.arange(0, 3 * F, 3), np.arange(3 * F, e.size)]  # the distance rows
    d0 = e[rows]
    assert (np.abs(d0) < 0.05).all() and (np.abs(d0) > 1e-4).any()
    eps = 1e-6
    for i in range(rt.nq):
        dq = np.zeros(rt.nq)
        dq[i] = eps
        hi = c.error(RobotState(q=q + dq, kin=rt.kin))[rows]
        lo = c.error(RobotState(q=q - dq, kin=rt.kin))[rows]
        np.testing.assert_allclose((hi - lo) / (2 * eps), J[rows, i], atol=2e-5, rtol=1e-3)
    rt.kin.forward(q)
    H, g = c.qp_terms(s)
    H0, g0 = Objective.qp_terms(c, s)
    np.testing.assert_allclose(H, H0, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(g, g0, rtol=1e-10, atol=1e-10)
    P, v = np.zeros_like(H), np.zeros_like(g)
    c.accumulate(s, P, v)  # what build_qp calls
    np.testing.assert_allclose(P, H0, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(v, g0, rtol=1e-10, atol=1e-10)


def test_contacts_and_grip_use_the_mesh_surface(grasp):
    """On a mesh object the contact targets lie on the mesh's own surface (its exact signed
    distance is zero there), each link's signed distance the contact term pulls on is that
    surface's distance at the link's nearest point, and the grip presses along the surface's
    normal there (where it is within 45° of the human contact's: the same face)."""
    rt, traj, t, q = grasp
    geometry = rt.geometry
    tg = rt.human_targets(traj)
    R = aa_to_matrix(traj.object.rot_aa.astype(np.float64))
    p = traj.object.pos.astype(np.float64)
    act = tg["contact_active"]
    pts = np.einsum("tji,tfj->tfi", R, tg["contact_points"] - p[:, None])[act]
    assert pts.shape[0] > 100
    np.testing.assert_allclose(geometry.signed_distance(pts), 0.0, atol=1e-6)

    idx = np.arange(len(rt.tip_sites))
    _, P, gap = rt.contacts.nearest_of(q, idx)
    loc = (P - p[t]) @ R[t]
    sdf, n = geometry.sdf_and_normal(loc)
    np.testing.assert_allclose(sdf, gap, atol=2e-4)
    surface = n @ R[t].T  # the mesh's normal at the links' points, from its signed distance
    direction = rt.contacts.nearest_directions(q, idx)
    assert (np.einsum("ki,ki->k", direction, surface) > np.cos(np.radians(3.0))).all()
    human = tg["contact_normals"][t]
    normals = rt._surface_normals(q, idx, human)
    agree = np.einsum("ki,ki->k", direction, human) > np.cos(np.radians(45.0))
    assert agree.sum() >= 2
    np.testing.assert_allclose(normals[agree], direction[agree], atol=1e-12)
    np.testing.assert_array_equal(normals[~agree], human[~agree])  # another face: the human's
    assert (np.einsum("ki,ki->k", normals[agree], human[agree]) < np.cos(np.radians(5.0))).any()
    q_in = q.copy()
    q_in[6:] += 0.3  # the fingers closed into the ball, deeper than the margin
    q_in = np.minimum(q_in, rt.upper)
    deep = rt.contacts.nearest_of(q_in, idx)[2] < -(rt.cfg.collision.penetration_margin + 5e-4)
    assert deep.any()
    inside = rt._surface_normals(q_in, idx, human)
    np.testing.assert_array_equal(inside[deep], human[deep])  # deeper: the human's normal
