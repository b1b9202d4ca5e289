"""Tests of the demonstration generator (``dexcanvas_core.demos``)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from dexcanvas_core.demos import (
    OPERATORS,
    BuildConfig,
    build_demos,
    builtin_pairs,
    check_trajectory,
    feasibility,
    feasibility_table,
    feasible_pairs,
    generate_demo,
    run_build,
    solve_grasp,
)
from dexcanvas_core.demos.checks import lift_grip_ratio
from dexcanvas_core.demos.grasp import cached_grasp
from dexcanvas_core.demos.grasp_problem import GRIP_RATIO_MAX, HOLD_RATIO_MAX
from dexcanvas_core.errors import UnknownNameError
from dexcanvas_core.keypoints import MANO21
from dexcanvas_core.mano.hand_model import DOF_HIGH, DOF_LOW, N_DOF, hand_model
from dexcanvas_core.objects.geometry import ObjectGeometry, object_geometry
from dexcanvas_core.objects.primitives import Primitive
from dexcanvas_core.rotations import aa_to_matrix
from dexcanvas_core.taxonomy import MANIPULATION_TYPES, OBJECTS

# -- feasibility --------------------------------------------------------------------------------


def test_feasibility_table_covers_catalogue_and_every_type():
    table = feasibility_table()
    assert len(table) == len(OBJECTS) * len(MANIPULATION_TYPES) == 29 * 21
    covered = {t for (_, t), f in table.items() if f.feasible}
    assert covered == set(MANIPULATION_TYPES)
    for f in table.values():
        assert f.reason
    pairs = feasible_pairs()
    assert len(pairs) == sum(f.feasible for f in table.values())


@pytest.mark.parametrize(
    ("pair", "ok", "word"),
    [
        ("sphere3/palmar_pinch", True, "pinch"),
        ("cylinder1/large_diameter", True, "wrap"),
        ("sphere1/rolling", True, "roll"),
        ("cylinder6/sliding", True, "slid"),
        ("scissor/distal_type", True, "loops"),
        ("cube2/rolling", False, "does not roll"),
        ("sphere1/sliding", False, "rolls"),
        ("cuboid1/palmar_pinch", False, "flat"),
        ("cube2/distal_type", False, "loops"),
        # the paper's sizes: a 2 cm ball is pinched, not wrapped against the palm; a 3 cm one
        # is too small for the ring finger; the 15 cm plate is held edge to edge
        ("sphere3/sphere_3_finger", False, "outside"),
        ("sphere2/sphere_4_finger", False, "outside"),
        ("sphere1/sphere_4_finger", True, "sphere"),
        ("sphere1/precision_sphere", True, "sphere"),
        ("cuboid1/extension_type", True, "edges 150 mm apart"),
        ("cuboid1/tripod", False, "flat"),
        ("cylinder4/lateral_pinch", False, "10 mm high"),
        ("cylinder5/sliding", False, "no room for three pads"),
        ("cuboid2/adducted_thumb", False, "too low"),
    ],
)
def test_feasibility_follows_the_taxonomy(pair, ok, word):
    f = feasibility(pair)
    assert f.feasible is ok
    assert word in f.reason


# -- geometry -----------------------------------------------------------------------------------


def _geom(*prims: Primitive) -> ObjectGeometry:
    return ObjectGeometry("test", prims, 0.1, 0.0, "test")


def test_sdf_of_primitives_is_exact():
    box = _geom(Primitive("box", (0.02, 0.03, 0.04)))
    pts = np.array([[0, 0, 0], [0.05, 0, 0], [0.02, 0, 0], [0.05, 0.07, 0.0], [0.0, 0.0, 0.035]])
    np.testing.assert_allclose(
        box.signed_distance(pts), [-0.02, 0.03, 0.0, np.hypot(0.03, 0.04), -0.005], atol=1e-12
    )
    cyl = _geom(Primitive("cylinder", (0.03, 0.05)))
    pts = np.array([[0.03, 0, 0], [0, 0, 0.07], [0.06, 0, 0.09], [0.0, 0.01, 0.0], [0, 0, 0.045]])
    np.testing.assert_allclose(
        cyl.signed_distance(pts), [0.0, 0.02, np.hypot(0.03, 0.04), -0.02, -0.005], atol=1e-12
    )
    sph = _geom(Primitive("sphere", (0.04,), pos=(0.1, 0, 0)))
    np.testing.assert_allclose(
        sph.signed_distance(np.array([[0.1, 0, 0], [0.1, 0.05, 0], [0.1, 0, 0.04]])),
        [-0.04, 0.01, 0.0],
        atol=1e-12,
    )
    cap = _geom(Primitive("capsule", (0.01, 0.05), rot_aa=(0.0, np.pi / 2, 0.0)))  # axis on x
    np.testing.assert_allclose(
        cap.signed_distance(np.array([[0.0, 0.02, 0], [0.08, 0, 0], [0.05, 0, 0.01]])),
        [0.01, 0.02, 0.0],
        atol=1e-12,
    )


@pytest.mark.parametrize(
    "object_id", ["cube2", "cylinder5", "sphere2", "banana", "powerdrill", "scissor", "bowl"]
)
def test_sdf_gradient_matches_finite_differences(object_id):
    g = object_geometry(object_id)
    rng = np.random.default_rng(3)
    pts = rng.uniform(-1.3, 1.3, (400, 3)) * g.aabb_half
    _, n = g.sdf_and_normal(pts)
    h = 1e-6
    fd = np.stack(
        [(g.signed_distance(pts + h * e) - g.signed_distance(pts - h * e)) / (2 * h)
         for e in np.eye(3)],
        axis=1,
    )  # fmt: skip
    # the union's distance has kinks (medial axes, primitive switches): almost all points agree
    agree = np.linalg.norm(fd - n, axis=1) < 1e-4
    assert agree.mean() > 0.97
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-9)


@pytest.mark.parametrize("object_id", ["cube1", "cuboid2", "cylinder3", "cylinder4", "sphere3"])
def test_closest_point_lies_on_the_surface(object_id):
    g = object_geometry(object_id)
    pts = np.random.default_rng(1).normal(size=(200, 3)) * 0.06
    cp = g.closest_point(pts)
    np.testing.assert_allclose(g.signed_distance(cp), 0.0, atol=1e-9)


@pytest.mark.parametrize("object_id", list(OBJECTS))
def test_objects_rest_on_the_table_centred(object_id):
    g = object_geometry(object_id)
    assert g.mass_kg == OBJECTS[object_id].mass_kg
    assert g.lowest_z(np.eye(3), np.array([0.0, 0.0, g.rest_z])) == pytest.approx(0.0, abs=1e-12)
    lo = np.min([p.aabb()[0] for p in g.primitives], axis=0)
    hi = np.max([p.aabb()[1] for p in g.primitives], axis=0)
    np.testing.assert_allclose(lo + hi, 0.0, atol=1e-12)  # object frame = bounding-box centre
    d = g.to_dict()
    assert d["primitives"] and json.dumps(d)


def test_primitive_objects_use_catalogue_sizes():
    # the paper's sizes, posed as the catalogue places them (z up at rest)
    assert object_geometry("cube2").aabb_half == pytest.approx([0.025] * 3)
    assert object_geometry("cylinder1").aabb_half == pytest.approx([0.035, 0.035, 0.075])
    assert object_geometry("cylinder4").aabb_half == pytest.approx([0.075, 0.005, 0.005])
    assert object_geometry("cuboid1").aabb_half == pytest.approx([0.075, 0.075, 0.01])
    assert object_geometry("cuboid2H").aabb_half == pytest.approx([0.075, 0.025, 0.0125])
    assert object_geometry("cylinder5").aabb_half == pytest.approx([0.01, 0.01, 0.0135])
    assert object_geometry("sphere3").rest_z == pytest.approx(0.01)


# -- operators and hand -------------------------------------------------------------------------


def test_five_operators_span_adult_hand_sizes(monkeypatch):
    from dexcanvas_core.mano import HandSkeleton, ManoLayer

    monkeypatch.delenv("MANO_MODEL_DIR", raising=False)
    assert list(OPERATORS) == [f"operator{i}" for i in range(1, 6)]
    scales = [o.scale for o in OPERATORS.values()]
    assert scales == sorted(scales) and 0.85 <= scales[0] and scales[-1] <= 1.15
    base = HandSkeleton.default("right").bone_lengths()
    layer = ManoLayer("right")
    for op in OPERATORS.values():
        np.testing.assert_allclose(op.skeleton().bone_lengths(), base * op.scale, rtol=1e-12)
        # the operator's betas reproduce its hand on the skeleton path
        kp = layer.forward_numpy(betas=op.betas[None]).keypoints[0]
        np.testing.assert_allclose(kp, op.skeleton().rest_keypoints, atol=1e-9)


def test_hand_kinematics_match_mano_layer():
    from dexcanvas_core.mano import ManoLayer

    hm = hand_model(1.05)
    rng = np.random.default_rng(0)
    q = rng.uniform(DOF_LOW, DOF_HIGH, (3, N_DOF))
    aa = rng.normal(size=(3, 3))
    p = rng.normal(size=(3, 3)) * 0.1
    kp, _ = hm.forward(q, aa_to_matrix(aa), p)
    ref = ManoLayer("right", skeleton=hm.skeleton).forward_numpy(
        global_orient=aa, hand_pose=hm.pose45(q), transl=p - hm.j0
    )
    np.testing.assert_allclose(kp, ref.keypoints, atol=1e-12)


# -- grasp optimisation -------------------------------------------------------------------------


@pytest.mark.parametrize(
    "pair",
    ["sphere3/palmar_pinch", "cylinder1/large_diameter", "cube2/lateral_pinch", "cube2/sliding"],
)
def test_grasp_optimisation_puts_pads_on_the_surface(pair):
    obj, kind = pair.split("/")
    g = solve_grasp(obj, kind, hand_model(1.0))
    required = np.array([c.required for c in g.contacts])
    # (whether the contacts can lift the object is ``test_accepted_grasps_can_lift_…``'s)
    assert "contact off" not in g.reason and "penetration" not in g.reason, g.reason
    assert np.all(np.abs(g.distance_m[required]) <= 1.5e-3)
    assert g.max_penetration_m <= 2e-3
    assert g.min_table_clearance_m >= -2e-3
    assert g.seconds < 10.0


def _ring(n: int, tilt: float = 0.0) -> np.ndarray:
    th = 2 * np.pi * np.arange(n) / n
    return np.stack(
        [np.cos(th) * np.cos(tilt), np.sin(th) * np.cos(tilt), np.full(n, np.sin(tilt))], 1
    )


def test_lift_grip_ratio_matches_friction_statics():
    mu = 0.5
    inner = mu  # the pyramid has an edge straight up the tangent plane: exact for lifting
    # balanced horizontal contacts lift with friction alone: total squeeze = weight / μ
    for n in (2, 3, 5):
        assert lift_grip_ratio(_ring(n), mu=mu) == pytest.approx(1 / inner, rel=1e-6)
    # a contact under the object carries the weight with no friction
    assert lift_grip_ratio(np.array([[0.0, 0.0, -1.0]]), mu=mu) == pytest.approx(1.0, rel=1e-6)
    # pads above the equator (normals tilted up by α) push the object down:
    # each normal force N gives μN cos α − N sin α of lift
    a = np.radians(10.0)
    expected = 1 / (inner * np.cos(a) - np.sin(a))
    assert lift_grip_ratio(_ring(3, a), mu=mu) == pytest.approx(expected, rel=1e-3)
    # one contact, contacts on one side, or tilted beyond the cone cannot lift at all
    assert lift_grip_ratio(np.array([[1.0, 0.0, 0.0]]), mu=mu) == np.inf
    assert lift_grip_ratio(_ring(3, np.radians(30.0)), mu=mu) == np.inf
    assert lift_grip_ratio(np.array([[1.0, 0, 0], [np.cos(2.0), np.sin(2.0), 0]]), mu=mu) == np.inf
    # normals that do not oppose spend squeeze: a pinch 150° apart needs more than 180° apart
    b = np.radians(150.0)
    skew = lift_grip_ratio(np.array([[1.0, 0, 0], [np.cos(b), np.sin(b), 0]]), mu=mu)
    assert 1 / inner < skew < np.inf
    assert lift_grip_ratio(np.zeros((0, 3)), mu=mu) == np.inf


def test_lift_grip_ratio_with_torques_charges_an_off_centre_pinch():
    # a pinch across a bar, dx from the centre of mass: the hand's lift force acts dx from the
    # weight, and only the pads' twist (≤ torsion × normal force each) keeps the bar level,
    # so the squeeze must reach dx / torsion on top of the 1/μ that lifts it
    mu, tors = 0.5, 0.0025
    n = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    for dx in (0.0, 0.01, 0.03):
        p = np.array([[dx, 0.02, 0.0], [dx, -0.02, 0.0]])
        got = lift_grip_ratio(n, p, mu=mu, torsion_m=tors)
        assert got == pytest.approx(1 / mu + dx / tors, rel=1e-6)
        assert lift_grip_ratio(n, mu=mu) == pytest.approx(1 / mu)  # forces alone: no charge
    # pads not in line (a squeeze that twists the bar about the vertical) cannot be balanced
    # by point contacts without torsion
    p = np.array([[0.01, 0.02, 0.0], [-0.01, -0.02, 0.0]])
    assert lift_grip_ratio(n, p, mu=mu, torsion_m=0.0) == np.inf
    assert lift_grip_ratio(n, p, mu=mu, torsion_m=tors) > 1 / mu
    # a tripod around the centre of mass balances without any twist
    ring = _ring(3)
    assert lift_grip_ratio(ring, 0.02 * ring, mu=mu, torsion_m=0.0) == pytest.approx(1 / mu)


def test_accepted_grasps_can_lift_their_object():
    # the acceptance test the generator applies: the optimised contacts hold the object against
    # gravity with a bounded squeeze (a long bar taken by one end, or a ball pinched above its
    # equator, is refused); the 15 cm bar, the 2 × 2.7 cm mini cylinder and the 2 cm ball
    pairs = ("cuboid2/lateral_tripod", "cylinder5/lateral_tripod", "sphere3/palmar_pinch")
    for pair in pairs:
        g = generate_demo(pair, "operator3", seed=0).grasp
        assert g.ok, (pair, g.reason)
        assert g.grip_ratio <= GRIP_RATIO_MAX and g.hold_ratio <= HOLD_RATIO_MAX
        assert g.grip_ratio == pytest.approx(lift_grip_ratio(g.normals[g.achieved]))
    geom = object_geometry("cuboid2")
    g = generate_demo("cuboid2/lateral_tripod", "operator3", seed=0).grasp
    contacts = geom.closest_point(g.points[g.achieved])
    assert np.abs(contacts[:, 0]).max() < 0.04, contacts  # near the middle, not at an end


# -- demonstrations -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def demo():
    return generate_demo("cube2/tripod", "operator2", seed=1)


def test_generated_demo_validates_and_passes(demo):
    traj = demo.trajectory
    traj.validate()
    assert demo.report.passed, demo.report.summary()
    assert traj.fps == 120.0
    assert traj.is_generated and traj.operator == "operator2" and traj.scene == "cube2"
    assert traj.gesture == "tripod" and traj.hand.name == "right"
    assert traj.hand.joint_pos.shape == (traj.num_frames, 21, 3)
    assert traj.object_move and all(m.object_name == "cube2" for m in traj.object_move)
    np.testing.assert_allclose(traj.hand.betas, OPERATORS["operator2"].betas, atol=1e-6)
    r = demo.report
    assert r.max_joint_limit_violation_rad <= 1e-3
    lo, hi = r.contact_error_range_mm
    assert -1.5 <= lo <= hi <= 1.5
    assert r.max_penetration_mm <= 2.0 and r.unsupported_motion_frames == 0
    assert 0.2 < r.peak_wrist_speed_m_s <= 1.5 and r.peak_joint_speed_rad_s <= 10.0
    assert json.dumps(r.to_dict())
    parts = {c.part for c in demo.schedule}
    assert {"thumb_ip", "index_dip", "middle_dip"} <= parts
    # the object moves only inside object_move segments
    step = np.linalg.norm(np.diff(traj.object.pos, axis=0), axis=1)
    inside = np.zeros(traj.num_frames, bool)
    for m in traj.object_move:
        inside[m.start_frame : m.end_frame + 1] = True
    assert np.all(step[~inside[1:]] < 1e-6)


def test_demo_is_deterministic_and_seeds_differ(demo):
    cached_grasp.cache_clear()
    again = generate_demo("cube2/tripod", "operator2", seed=1)
    np.testing.assert_array_equal(again.trajectory.hand.joint_pos, demo.trajectory.hand.joint_pos)
    np.testing.assert_array_equal(again.trajectory.object.pos, demo.trajectory.object.pos)
    assert again.trajectory.uuid == demo.trajectory.uuid
    other = generate_demo("cube2/tripod", "operator2", seed=2)
    assert other.trajectory.uuid != demo.trajectory.uuid
    assert not np.allclose(other.trajectory.object.pos[0], demo.trajectory.object.pos[0])


@pytest.mark.parametrize("pair", ["sphere2/rolling", "cube2/finger_transfer"])
def test_in_hand_demos_pass(pair):
    d = generate_demo(pair, "operator4", seed=0)
    d.trajectory.validate()
    assert d.report.passed, d.report.summary()


def test_infeasible_pair_is_refused():
    from dexcanvas_core.demos import DemoError

    with pytest.raises(DemoError, match="does not roll"):
        generate_demo("cube2/rolling")


# -- the checks catch injected faults -----------------------------------------------------------


def _mutated(demo):
    return copy.deepcopy(demo.trajectory)


def test_check_catches_a_finger_pushed_into_the_object(demo):
    traj = _mutated(demo)
    c = next(c for c in demo.schedule if c.capsule == "index_dip")
    g = object_geometry("cube2")
    frames = np.arange(c.start, c.end + 1)
    R = aa_to_matrix(traj.object.rot_aa[frames].astype(np.float64))
    tip = traj.hand.joint_pos[frames, MANO21.index("index_tip")].astype(np.float64)
    local = np.einsum("fji,fj->fi", R, tip - traj.object.pos[frames])
    n_world = np.einsum("fij,fj->fi", R, g.normal(local))
    for k in (MANO21.index("index3"), MANO21.index("index_tip")):
        traj.hand.joint_pos[frames, k] -= (0.005 * n_world).astype(np.float32)
    report = check_trajectory(traj, demo.schedule)
    assert not report.checks["penetration"].passed
    assert report.max_penetration_mm > 3.0
    assert not report.checks["contact"].passed


def test_check_catches_an_object_teleported_while_not_held(demo):
    traj = _mutated(demo)
    traj.object.pos[10:20] += np.float32([0.0, 0.0, 0.1])
    report = check_trajectory(traj, demo.schedule)
    assert not report.checks["support"].passed
    assert report.unsupported_motion_frames >= 10
    assert report.checks["penetration"].passed


def test_check_catches_a_joint_beyond_its_limit(demo):
    traj = _mutated(demo)
    # index PIP (MANO joint 2, hand_pose columns 6:9) flexed 150°, beyond its 110° limit
    traj.hand.hand_pose[100:110, 6:9] = np.float32([0.0, 0.0, np.deg2rad(150.0)])
    report = check_trajectory(traj, demo.schedule)
    assert not report.checks["joint_limits"].passed
    assert report.max_joint_limit_violation_rad > np.deg2rad(30.0)


# -- building datasets --------------------------------------------------------------------------


def test_build_demos_writes_a_dataset_that_reads_back(tmp_path):
    from dexcanvas_core.io import open_dataset

    out = tmp_path / "demos.lance"
    pairs = ["cube2/tripod", "sphere1/sphere_4_finger", "cube2/rolling"]
    report = build_demos(out, pairs=pairs)
    assert report.written == 2 and report.all_passed
    assert "cube2/rolling" in report.skipped
    ds = open_dataset(out)
    got = {f"{t.scene}/{t.gesture}" for t in ds}
    assert got == {"cube2/tripod", "sphere1/sphere_4_finger"}
    for t in ds:
        assert t.is_generated and t.fps == 120.0
    path = report.write_json()
    data = json.loads(path.read_text())
    assert data["written"] == 2 and len(data["demos"]) == 2
    assert info_rows(out) == 2


def info_rows(path) -> int:
    from dexcanvas_core.io import open_dataset

    return open_dataset(path).info().rows


def test_run_build_rejects_unknown_pairs_with_close_matches(tmp_path):
    cfg = BuildConfig(out=tmp_path / "x.lance", pairs=("cube2/tripd",))
    with pytest.raises(UnknownNameError, match="tripod"):
        run_build(cfg, progress=False)
    with pytest.raises(UnknownNameError, match="cube2"):
        run_build(BuildConfig(out=tmp_path / "y.lance", pairs=("cubee2/tripod",)), progress=False)
    assert not (tmp_path / "x.lance").exists()


def test_builtin_set_covers_every_type_and_light_object():
    pairs = builtin_pairs()
    assert {p.manipulation_type.name for p in pairs} == set(MANIPULATION_TYPES)
    light = {o for o, s in OBJECTS.items() if not s.heavy}
    assert {p.object.id for p in pairs} == light
    assert [str(p) for p in pairs] == [str(p) for p in builtin_pairs()]
    assert all(feasibility(p).feasible for p in pairs)
