"""Self-collision and hand–object rows on real hands: pair selection, Jacobians against finite
differences, fingers commanded into each other, and the batched kinematics the solver uses."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from robot_poses import coupled, human_from_robot_poses

from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.trajectory import Trajectory
from retarget.config import (
    PostureConfig,
    RetargetConfig,
    SelfCollisionConfig,
    SmoothnessConfig,
    SolverConfig,
)
from retarget.hands import available_hands, get_hand
from retarget.hands.base import wrist_qpos_from_mano
from retarget.kinematics import MujocoKinematics, PinocchioKinematics
from retarget.limits import CollisionLimit
from retarget.limits.sweep import ContactSweep
from retarget.retargeter import Retargeter
from retarget.state import RobotState

HANDS = ["shadow", "allegro"]


@pytest.fixture(scope="module", params=HANDS)
def rt(request) -> Retargeter:
    return Retargeter(get_hand(request.param), object_geometry("cube2"))


def _random_pose(rt: Retargeter, rng, spread=(0.0, 1.0)) -> np.ndarray:
    q = rt.q_default.copy()
    lo, hi = rt.lower, rt.upper
    fin = np.isfinite(lo[6:]) & np.isfinite(hi[6:])
    u = rng.uniform(*spread, fin.sum())
    q[6:][fin] = lo[6:][fin] + u * (hi[6:] - lo[6:])[fin]
    return coupled(rt.scene.model, q)


def _limit_poses(rt: Retargeter, traj, n: int, rng, spread):
    """``(limit, plain, q)`` per collision limit of ``rt`` (the sweep's) and per ``n`` frames of
    ``traj``: the same pairs without the sweep (``plain``), the object posed at the frame,
    random finger poses (``spread`` of the ranges) at the human wrist's pose."""
    tg = rt.human_targets(traj)
    m, d = rt.scene.model, rt.scene.data
    for lim in (rt.collision, rt.self_collision):
        plain = CollisionLimit(m, d, lim.pairs, rt.nq, distmax=lim.distmax,
                               self_collision=lim.self_collision)  # fmt: skip
        for t in np.linspace(0, traj.num_frames - 1, n).astype(int):
            rt.scene.set_object_pose(traj.object.pos[t], traj.object.rot_aa[t])
            q = _random_pose(rt, rng, spread)
            q[:6] = wrist_qpos_from_mano(tg["wrist_R"][t], tg["wrist_p"][t])
            yield lim, plain, q


def _finger_pair_penetration(rt: Retargeter, q: np.ndarray) -> float:
    """Deepest penetration [m] among the self pairs whose geoms are on two fingers (no palm)."""
    hand_parts = rt.hand.hand_parts(rt.scene.model)
    part = {rt.scene.model.body(b).id: p for p, bodies in hand_parts.items() for b in bodies}
    m = rt.scene.model
    deepest = 0.0
    for ga, gb, d, _, _ in rt.self_distance_query.distances(q):
        pa, pb = part[m.geom_bodyid[ga]], part[m.geom_bodyid[gb]]
        if "palm" not in (pa, pb):
            deepest = max(deepest, -d)
    return deepest


# ---------------------------------------------------------------------------- pair selection
@pytest.mark.parametrize("name", available_hands())
def test_self_collision_pairs_join_different_parts_only(name):
    hand = get_hand(name)
    m = hand.compile()
    pairs = hand.self_collision_pairs()
    assert pairs, f"{name}: no self-collision pairs"
    part = {m.body(b).id: p for p, bodies in hand.hand_parts(m).items() for b in bodies}
    d = mujoco.MjData(m)
    d.qpos[:] = hand.default_qpos(m)
    mujoco.mj_kinematics(m, d)
    fromto = np.zeros(6)
    for a, b in pairs:
        ga, gb = m.geom(a).id, m.geom(b).id
        ba, bb = m.geom_bodyid[ga], m.geom_bodyid[gb]
        assert part[ba] != part[bb], (a, b)  # never two links of one finger
        assert m.body_parentid[ba] != bb and m.body_parentid[bb] != ba, (a, b)
        # Nothing that touches at the open posture (palm vs finger bases): the open hand is
        # feasible, and its resting contacts are not constraints.
        assert mujoco.mj_geomDistance(m, d, ga, gb, 0.05, fromto) > 0, (a, b)
    # Every pair of fingers is covered somewhere (the gripper's two fingers included).
    fingers = [f for f in hand.robot_fingers if f in hand.hand_parts(m)]
    covered = {frozenset((part[m.geom(a).bodyid[0]], part[m.geom(b).bodyid[0]])) for a, b in pairs}
    for i, f in enumerate(fingers):
        for g in fingers[i + 1 :]:
            assert frozenset((f, g)) in covered, (name, f, g)


def test_config_rejects_bad_collision_settings():
    from retarget.errors import RetargetError

    with pytest.raises(RetargetError, match=r"SelfCollisionConfig\.margin"):
        RetargetConfig(self_collision=SelfCollisionConfig(margin=-1e-3))
    with pytest.raises(RetargetError, match=r"SelfCollisionConfig\.distmax"):
        RetargetConfig(self_collision=SelfCollisionConfig(distmax=0.0))
    with pytest.raises(RetargetError, match=r"SolverConfig\.step_tolerance"):
        RetargetConfig(solver=SolverConfig(step_tolerance=float("nan")))


# ---------------------------------------------------------------- Jacobians vs finite differences
SMOOTH = {int(mujoco.mjtGeom.mjGEOM_SPHERE), int(mujoco.mjtGeom.mjGEOM_CAPSULE),
          int(mujoco.mjtGeom.mjGEOM_PLANE)}  # fmt: skip


def _body_point(data, body: int, p_world: np.ndarray) -> np.ndarray:
    """``p_world`` in ``body``'s frame (after ``mj_kinematics``)."""
    return data.xmat[body].reshape(3, 3).T @ (p_world - data.xpos[body])


def _check_rows(limit, kin, q, rng, errors: list, step=1e-6):
    """Rows ``G Δq ≤ h`` at ``q`` against finite differences, two ways.

    1. Exactly, against the model the row linearises: the pair's witness points held fixed to
       their bodies (the object's to the world), ``Δd = n·(Δp_b − Δp_a) = −G δ``. This checks
       the body, point, normal, sign and (self-collision) the ``J_a − J_b`` of every row.
    2. Against the true signed distance change: recorded in ``errors`` (relative error, smooth
       pair or not), since at edges and corners of boxes the distance is not differentiable.
    """
    m, d = limit.model, limit.data
    kin.forward(q)
    G, h = limit.inequalities(RobotState(q=q, kin=kin))
    r = limit.row_points(q)  # the pairs within distmax, then extra contacts of per-pair pairs
    n_closest = limit.query(q).index.size
    assert G.shape == (r.index.size, q.size) and h.shape == (r.index.size,)
    np.testing.assert_allclose(
        h, r.distance + limit.pair_margins[r.index], atol=1e-12
    )  # (no recovery cap hit)
    v = r.p_b - r.p_a
    n = v / np.linalg.norm(v, axis=1, keepdims=True) * np.where(r.distance >= 0, 1, -1)[:, None]
    ga = [limit.pairs[i][0] for i in r.index]
    gb = [limit.pairs[i][1] for i in r.index]
    ba, bb = m.geom_bodyid[ga], m.geom_bodyid[gb]
    la = [_body_point(d, b, p) for b, p in zip(ba, r.p_a, strict=True)]
    lb = [_body_point(d, b, p) for b, p in zip(bb, r.p_b, strict=True)]
    for _ in range(3):
        delta = rng.normal(size=q.size)
        delta *= step / np.abs(delta).max()
        r2 = limit.query(q + delta)  # moves data to q + δ
        predicted = -G @ delta
        for row in range(len(ga)):
            pa = d.xmat[ba[row]].reshape(3, 3) @ la[row] + d.xpos[ba[row]]
            pb = d.xmat[bb[row]].reshape(3, 3) @ lb[row] + d.xpos[bb[row]]
            fixed = n[row] @ ((pb - pa) - (r.p_b[row] - r.p_a[row]))
            assert abs(fixed - predicted[row]) <= 1e-4 * abs(predicted[row]) + 1e-12, (
                limit.pairs[r.index[row]], fixed, predicted[row])  # fmt: skip
        after = dict(zip(r2.index.tolist(), r2.distance, strict=True))
        for row, i in enumerate(r.index.tolist()[:n_closest]):  # rows of pair distances
            if i in after and abs(predicted[row]) > 1e-9:
                smooth = {m.geom_type[ga[row]], m.geom_type[gb[row]]} <= SMOOTH
                rel = abs(after[i] - r.distance[row] - predicted[row]) / abs(predicted[row])
                errors.append((smooth, rel))
    return len(ga)


def _assert_first_order(errors):
    """The rows are the distance's derivative: for smooth pairs always, for pairs with a box
    almost always (not where the nearest feature switches)."""
    smooth = np.array([e for s, e in errors if s])
    rough = np.array([e for s, e in errors if not s])
    assert smooth.size + rough.size >= 20
    if smooth.size:
        assert smooth.max() < 0.02, smooth.max()
    if rough.size:
        assert np.median(rough) < 1e-3 and np.mean(rough < 0.02) > 0.9, np.sort(rough)[-5:]


def test_self_collision_rows_match_finite_differences(rt):
    rng = np.random.default_rng(0)
    checked = penetrating = 0
    errors = []
    for _ in range(40):
        q = _random_pose(rt, rng)
        r = rt.self_collision.query(q)
        if not r.index.size or (r.distance + rt.cfg.self_collision.margin < -1e-3).any():
            continue  # (a capped recovery row is not the plain linearisation)
        penetrating += int((r.distance < 0).any())
        checked += _check_rows(rt.self_collision, rt.kin, q, rng, errors)
    assert checked >= 20 and penetrating >= 1
    _assert_first_order(errors)


def test_object_collision_rows_match_finite_differences(rt, demo_cube):
    traj = demo_cube
    tg = rt.human_targets(traj)
    rng = np.random.default_rng(1)
    checked = 0
    errors = []
    for t in np.linspace(0, traj.num_frames - 1, 8).astype(int):
        rt.scene.set_object_pose(traj.object.pos[t], traj.object.rot_aa[t])
        q = _random_pose(rt, rng, (0.2, 0.6))
        q[:6] = wrist_qpos_from_mano(tg["wrist_R"][t], tg["wrist_p"][t])
        checked += _check_rows(rt.collision, rt.kin, q, rng, errors)
    assert checked >= 10
    _assert_first_order(errors)


@pytest.fixture(scope="module")
def demo_cube() -> Trajectory:
    from dexcanvas_core.example import example_trajectories

    traj = next(t for t in example_trajectories(seed=0) if t.scene == "cube2")
    return traj.slice(100, 220)


# ----------------------------------------------------------- fingers commanded into each other
def _human_from_robot_poses(rt: Retargeter, Q: np.ndarray) -> Trajectory:
    """A 'human' whose scaled keypoints are the robot's own sites along ``Q`` (T, nq)."""
    return human_from_robot_poses(rt, Q, uuid="fingers-crossed")


@pytest.mark.parametrize("name", HANDS)
def test_fingers_commanded_into_each_other_stay_apart(name):
    """Keypoints that drive two fingers through each other: with the limit the fingers stop at
    the margin, without it they follow the keypoints into each other."""
    hand = get_hand(name)
    cfg = RetargetConfig(posture=PostureConfig(weight=0.0), smoothness=SmoothnessConfig(weight=0.0))
    on = Retargeter(hand, None, cfg)
    off = Retargeter(
        hand,
        None,
        RetargetConfig(
            posture=PostureConfig(weight=0.0),
            smoothness=SmoothnessConfig(weight=0.0),
            self_collision=SelfCollisionConfig(enabled=False),
        ),
    )
    rng = np.random.default_rng(3)
    # A reachable pose (joint ranges, couplings) with two fingers deep inside each other.
    for _ in range(2000):
        q_bad = _random_pose(on, rng)
        if _finger_pair_penetration(on, q_bad) > 0.006:
            break
    else:
        pytest.fail(f"{name}: no finger-through-finger pose found")
    q0 = on.q_default.copy()
    s = np.linspace(0.0, 1.0, 60)[:, None]
    Q = np.concatenate([(1 - s) * q0 + s * q_bad, np.tile(q_bad, (20, 1))])
    human = _human_from_robot_poses(on, Q)
    out_on = on.retarget(human)
    out_off = off.retarget(human)
    margin = cfg.self_collision.margin
    assert out_on.self_penetration_max_m <= margin + 5e-4, out_on.self_penetration_max_m
    assert out_off.self_penetration_max_m > margin + 3e-3, out_off.self_penetration_max_m
    # Without the limit the robot follows the keypoints (they come from its own poses).
    assert out_off.keypoint_err[-1] < 2e-3
    # The measured self distance is the limit's own query, frame by frame.
    assert np.isfinite(out_on.self_min_distance).any()


# ------------------------------------------------------------------------ batched kinematics
def test_batched_site_and_point_jacobians_match_mujoco(rt):
    m = rt.scene.model
    pin_kin, mj_kin = PinocchioKinematics(m), MujocoKinematics(m, nq=rt.nq)
    rng = np.random.default_rng(5)
    sites = tuple(rt.kp_sites)
    for _ in range(3):
        q = _random_pose(rt, rng)
        q[:6] = rng.uniform(-0.5, 0.5, 6)
        pin_kin.forward(q)
        mj_kin.forward(q)
        np.testing.assert_allclose(pin_kin.site_positions(sites), mj_kin.site_positions(sites),
                                   atol=1e-10)  # fmt: skip
        np.testing.assert_allclose(pin_kin.site_jacobians(sites), mj_kin.site_jacobians(sites),
                                   atol=1e-10)  # fmt: skip
        # Pinocchio's own frame placements agree with the MuJoCo site poses it reports.
        for s in sites:
            np.testing.assert_allclose(
                pin_kin.data.oMf[pin_kin.site_frames[s]].translation, pin_kin.site_position(s),
                atol=1e-10,
            )  # fmt: skip
        bodies = tuple(m.body(b).name for b in rng.integers(2, m.nbody, 6))
        pts = rng.normal(scale=0.1, size=(6, 3))
        np.testing.assert_allclose(pin_kin.point_jacobians(bodies, pts),
                                   mj_kin.point_jacobians(bodies, pts), atol=1e-10)  # fmt: skip


def test_compiled_rows_match_the_generic_rows(rt, demo_cube):
    """The rows built straight from Pinocchio's world Jacobian (the compiled path) equal the
    ones built from MuJoCo's point Jacobians (the path any other kinematics takes)."""
    m = rt.scene.model
    mj_kin = MujocoKinematics(m, nq=rt.nq)
    rng = np.random.default_rng(7)
    tg = rt.human_targets(demo_cube)
    rows = {"object": 0, "self": 0}
    for t in np.linspace(0, demo_cube.num_frames - 1, 6).astype(int):
        rt.scene.set_object_pose(demo_cube.object.pos[t], demo_cube.object.rot_aa[t])
        q = _random_pose(rt, rng, (0.2, 0.6))
        q[:6] = wrist_qpos_from_mano(tg["wrist_R"][t], tg["wrist_p"][t])
        rt.kin.forward(q)
        mj_kin.forward(q)
        for name, lim in (("object", rt.collision), ("self", rt.self_collision)):
            G, h = lim.inequalities(RobotState(q=q, kin=rt.kin))
            near = lim._near.copy()
            G2, h2 = lim.inequalities(RobotState(q=q, kin=mj_kin))
            np.testing.assert_allclose(G, G2, atol=1e-10)
            np.testing.assert_array_equal(h, h2)
            np.testing.assert_array_equal(near, lim._near)
            assert G.shape == (lim.row_points(q).index.size, rt.nq)  # (no NaN normals here)
            rows[name] += G.shape[0]
    assert rows["object"] >= 5 and rows["self"] >= 5, rows


# ------------------------------------------------------------------ one mj_collision sweep
@pytest.mark.parametrize("name", ["shadow", "allegro", "svh", "panda"])
def test_contact_sweep_matches_per_pair_distances(name, demo_cube):
    """The shared mj_collision sweep (the retargeter's default) finds the same pairs, distances,
    nearest points and normals as one mj_geomDistance per pair, for the hand–object and the
    self-collision pairs (box–box and mesh pairs go per pair inside the sweep limit too: the
    box–box ones with the sphere test as their broad phase, as mj_collision misses box–box
    pairs a few millimetres inside its margin, Panda on the example cube2: 25.7–29.8 mm apart
    with a 30 mm margin; the mesh ones with the sweep's reported pairs as candidates). Mesh
    pairs at least ``MESH_FAR`` beyond their allowed distance take the sweep's closest contact
    instead: its distance within 0.32 mm, its normal within 12°, and the pair truly not near.
    Not Ability: its penetrating capsule–mesh pairs' witness points differ by up to 64 µm."""
    rt = Retargeter(get_hand(name), object_geometry("cube2"))
    rng = np.random.default_rng(7)
    compared = direct = mesh = far = 0
    for swept, plain, q in _limit_poses(rt, demo_cube, 12, rng, (0.1, 0.7)):
        a, b = swept.query(q), plain.query(q)
        oa, ob = np.argsort(a.index), np.argsort(b.index)
        np.testing.assert_array_equal(a.index[oa], b.index[ob])
        index, dist = a.index[oa], a.distance[oa]
        allowed = np.maximum(-swept.pair_margins[index], 0.0)
        from_sweep = np.isin(index, swept._mesh_seen) & (dist >= allowed + swept.MESH_FAR)
        x = ~from_sweep
        np.testing.assert_allclose(dist[x], b.distance[ob][x], atol=1e-12)
        np.testing.assert_allclose(a.p_a[oa][x], b.p_a[ob][x], atol=1e-12)
        np.testing.assert_allclose(a.p_b[oa][x], b.p_b[ob][x], atol=1e-12)
        ok = np.isfinite(b.normal[ob, 0]) & x
        np.testing.assert_allclose(a.normal[oa][ok], b.normal[ob][ok], atol=1e-9)
        y = from_sweep
        np.testing.assert_allclose(dist[y], b.distance[ob][y], atol=3.2e-4)
        assert (b.distance[ob][y] >= allowed[y] + swept.NEAR).all()
        cos = (a.normal[oa][y] * b.normal[ob][y]).sum(axis=1)
        assert (cos >= np.cos(np.radians(12))).all(), np.degrees(np.arccos(cos.min()))
        compared += a.index.size
        direct += int(np.isin(a.index, swept._direct_seen).sum())
        mesh += int(np.isin(a.index, swept._mesh_seen).sum())
        far += int(y.sum())
    assert compared > 50
    assert direct > 0  # the per-pair path inside the sweep limit was compared too
    if name in ("svh", "panda"):
        assert mesh > 0  # and its mesh pairs, candidates from the sweep
    if name == "svh":
        assert far > 0 and mesh > far  # mesh pairs both ways


@pytest.mark.parametrize("name", ["allegro", "panda"])
def test_broad_phase_keeps_every_pair_within_reach(name, demo_cube):
    """The per-pair broad phase (bounding spheres, and the separating axis test for box–box
    pairs) drops only pairs farther than ``distmax``: against ``mj_geomDistance`` on every
    per-pair pair, random finger poses at the demonstration's wrist poses (Allegro's box
    links against each other, Panda's boxes against the cube), and it does drop some."""
    rt = Retargeter(get_hand(name), object_geometry("cube2"))
    m, d = rt.scene.model, rt.scene.data
    rng = np.random.default_rng(11)
    kept = by_boxes = 0
    for lim, plain, q in _limit_poses(rt, demo_cube, 15, rng, (0.0, 1.0)):
        d.qpos[: rt.nq] = q
        mujoco.mj_kinematics(m, d)
        cand = set(plain.candidates().tolist())
        for i, (a, b) in enumerate(plain.pairs):
            if mujoco.mj_geomDistance(m, d, a, b, lim.distmax, None) < lim.distmax:
                assert i in cand, (m.geom(a).name, m.geom(b).name)
                kept += 1
        # Box–box pairs within the spheres' reach that the separating axis test dropped:
        centre2 = ((d.geom_xpos[plain._sph_a] - d.geom_xpos[plain._sph_b]) ** 2).sum(axis=1)
        spheres = plain._sph[centre2 < plain._sph_reach2]
        by_boxes += sum(i not in cand for i in spheres.tolist())
    assert kept > 0 and by_boxes > 0


@pytest.mark.parametrize(("hand_reach", "other_reach"), [(0.01, 0.03), (0.03, 0.01)])
def test_contact_sweep_margins_give_the_asked_reaches(hand_reach, other_reach):
    """mj_collision reports hand–hand pairs up to ``hand_reach`` and hand–object pairs up to
    at least ``other_reach``, whatever the installed MuJoCo does with two geoms' margins (4.0.1
    adds them), and ``query_distance`` says how far."""
    xml = """
    <mujoco>
      <worldbody>
        <body name="a"><joint name="ax" type="slide" axis="1 0 0"/>
          <geom name="a" type="sphere" size="0.01"/></body>
        <body name="b" pos="0 0.2 0"><joint name="bx" type="slide" axis="1 0 0"/>
          <geom name="b" type="sphere" size="0.01"/></body>
        <body name="object" mocap="true" pos="0 0.4 0">
          <geom name="object" type="sphere" size="0.01"/></body>
      </worldbody>
    </mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    a, b, obj = (m.geom(n).id for n in ("a", "b", "object"))
    sweep = ContactSweep(m, d, hand_nq=2)
    sweep.set_margins([a, b], hand_reach, [obj], other_reach)
    assert sweep.query_distance(a, b) == pytest.approx(hand_reach, abs=1e-15)
    reach = sweep.query_distance(a, obj)
    assert reach >= other_reach - 1e-15

    def reported(g1, g2, gap):  # the two spheres ``gap`` apart along y
        m.body_pos[m.geom_bodyid[g2]] = m.body_pos[m.geom_bodyid[g1]] + [0.0, 0.02 + gap, 0.0]
        if g2 == obj:
            d.mocap_pos[0] = m.body_pos[m.geom_bodyid[g1]] + [0.0, 0.02 + gap, 0.0]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        return any({int(c.geom1), int(c.geom2)} == {g1, g2} for c in d.contact[: d.ncon])

    assert reported(a, b, hand_reach - 5e-4) and not reported(a, b, hand_reach + 5e-4)
    assert reported(a, obj, reach - 5e-4) and not reported(a, obj, reach + 5e-4)


def test_capsule_beside_a_cylinder_rim_gets_its_true_distance():
    """A capsule 1.6 mm beside a cylinder's rim (Shadow's middle distal over the built-in
    cylinder1, retargeted): mj_collision (MuJoCo 4.0.1) reports the pair 18 mm apart, so the
    sweep limit must take capsule–cylinder pairs per pair, at mj_geomDistance's distance."""
    xml = """
    <mujoco>
      <worldbody>
        <body name="hand" pos="0.01456463 -0.03674637 0.06018636">
          <joint name="x" type="slide" axis="1 0 0"/>
          <joint name="y" type="slide" axis="0 1 0"/>
          <joint name="z" type="slide" axis="0 0 1"/>
          <geom name="tip" type="capsule" size="0.00705"
                fromto="0.00617 0.01028 0.00041 -0.00617 -0.01028 -0.00041"/>
        </body>
        <body name="object" mocap="true">
          <geom name="cylinder" type="cylinder" size="0.025 0.06"/>
        </body>
      </worldbody>
    </mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    tip, cyl = m.geom("tip").id, m.geom("cylinder").id
    sweep = ContactSweep(m, d, hand_nq=3)
    sweep.set_margins([tip], 0.01, [cyl], 0.03)
    lim = CollisionLimit(m, d, [(tip, cyl)], hand_nq=3, distmax=0.03, sweep=sweep)
    for dz in (0.0, -0.001, 0.002):  # beside the rim, and a little below and above it
        q = np.array([0.0, 0.0, dz])
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        fromto = np.zeros(6)
        expected = mujoco.mj_geomDistance(m, d, tip, cyl, 0.03, fromto)
        assert 0.0 < expected < 0.004
        r = lim.query(q)
        np.testing.assert_array_equal(r.index, [0])
        assert r.distance[0] == pytest.approx(expected, abs=1e-12)
        np.testing.assert_allclose(r.p_a[0], fromto[:3], atol=1e-12)


def test_contact_sweep_follows_the_object(demo_cube):
    """Same q, object moved: the sweep must not reuse the previous pose's contacts."""
    rt = Retargeter(get_hand("allegro"), object_geometry("cube2"))
    tg = rt.human_targets(demo_cube)
    r = rt.retarget(demo_cube)
    on = np.flatnonzero(tg["contact_active"].any(axis=1))
    t = int(on[np.argmin(r.min_distance[on])])
    q = r.q[t]  # fingers on the cube
    obj = set(rt.scene.object_geoms)

    def to_object(limit):  # (the table may be as near as the cube: it is left out)
        return sorted((a, b, d) for a, b, d, *_ in limit.distances(q) if b in obj)

    rt.scene.set_object_pose(demo_cube.object.pos[t], demo_cube.object.rot_aa[t])
    near = to_object(rt.collision)
    assert near and min(d for *_, d in near) < 0.005
    rt.scene.set_object_pose(demo_cube.object.pos[t] + [0.0, 0.0, 0.5], demo_cube.object.rot_aa[t])
    far = to_object(rt.collision)
    plain = CollisionLimit(rt.scene.model, rt.scene.data, rt.collision.pairs, rt.nq,
                           distmax=rt.collision.distmax)  # fmt: skip
    assert far == to_object(plain) == []  # the cube moved out of reach


@pytest.mark.parametrize(
    ("hand", "pair"),
    [
        ("allegro", "cylinder4/tripod_variation"),
        ("leap", "cylinder2/extension_type"),
        ("leap", "mayonnaisebottle/large_diameter"),
    ],
)
def test_fingers_do_not_roll_into_a_cylinder(hand, pair):
    """Fingers lying along a cylinder (built-in demonstrations). Allegro's box thumb tip: with
    a row at the pair's closest point only, the box's other end turned into the cylinder
    (4.15 mm deep). LEAP's index finger: full-speed steps flipped between two rows (7.0 mm
    before the further contacts' rows, 2.3 mm with them but without the trust-region
    re-steps). LEAP around the mayonnaise bottle: a re-step's trust region too small for the
    rows' push-out made the QP infeasible (the frame keeps its last solution instead). Now:
    within the 1 mm margin + 0.5 mm on every frame."""
    from dexcanvas_core.loaders.selection import load_demonstration

    traj = load_demonstration(pair)
    rt = Retargeter(get_hand(hand), object_geometry(traj.object.name))
    r = rt.retarget(traj)
    assert -r.min_distance.min() <= rt.cfg.collision.penetration_margin + 5e-4
    # Some frame's rows hold a pair twice (both ends of a finger link on the surface).
    multi = 0
    for t in np.flatnonzero(r.min_distance < 0.002)[::10]:
        rt.scene.set_object_pose(traj.object.pos[t], traj.object.rot_aa[t])
        idx = rt.collision.row_points(r.q[t]).index
        multi += int(np.unique(idx).size < idx.size)
    assert multi > 0


def test_rows_when_every_pair_is_per_pair():
    """The Panda gripper's self-collision pairs are all box–box (none on the sweep's fast
    path): its closed fingers still give rows from their mj_collision contacts (this raised an
    IndexError in the force-preservation benchmark)."""
    rt = Retargeter(get_hand("panda"), None)
    lim = rt.self_collision
    assert lim._swept.size == 0 and lim._direct_seen.size > 0
    q = rt.q_default.copy()
    q[6:] = 0.0  # closed: the finger pads touch
    rt.kin.forward(q)
    G, h = lim.inequalities(RobotState(q=q, kin=rt.kin))
    assert (
        G.shape[0] > lim.query(q).index.size > 0 and np.isfinite(G).all() and np.isfinite(h).all()
    )


def test_end_of_step_check_sees_the_near_pairs_as_the_sweep_does(demo_cube):
    """``near_violation`` (the end-of-step check: one mj_geomDistance per pair that was within
    5 mm of its allowed distance at the linearisation, and that the rows predict within 3 mm of
    it at the step's end) gives the sweep's distance plus the
    pair's margin for those pairs at a moved configuration, for the hand–object and the self
    pairs; the sweep's cached contacts stay valid (it runs on its own MjData)."""
    rt = Retargeter(get_hand("allegro"), object_geometry("cube2"))
    r = rt.retarget(demo_cube)
    margins = rt._frame_margins(rt.human_targets(demo_cube)["contact_by_part"])  # (T, pairs)
    rng = np.random.default_rng(3)
    checked = widened = 0
    for t in np.flatnonzero(r.min_distance < 0.003)[::15]:
        rt.scene.set_object_pose(demo_cube.object.pos[t], demo_cube.object.rot_aa[t])
        q = r.q[t]
        rt.kin.forward(q)
        rt.collision.pair_margins = margins[t]  # the frame's clearances, as in retarget()
        for lim in (rt.collision, rt.self_collision):
            lim.inequalities(RobotState(q=q, kin=rt.kin))
            near = lim._near
            at_q = lim.query(q)
            k = np.isin(at_q.index, near)
            # Clearance pairs are near from farther out: within NEAR of their clearance.
            widened += int(np.sum(k & (at_q.distance >= lim.NEAR)))
            clear = np.minimum(lim.pair_margins[at_q.index[k]], 0.0)
            assert (at_q.distance[k] + clear < lim.NEAR).all()
            q2 = q + rng.normal(0.0, 0.02, q.size) * (np.arange(q.size) >= 6)
            got = lim.near_violation(q2)
            before = lim.sweep.dist.copy()
            ref = lim.query(q2)
            keep = np.isin(ref.index, near)
            v = ref.distance[keep] + lim.pair_margins[ref.index[keep]]
            want = v.min() if keep.any() else np.inf
            if np.isfinite(want) and want < lim.NEAR:
                assert got == pytest.approx(want, abs=1e-9)
                checked += 1
            else:
                assert got >= min(want, lim.NEAR) - 1e-9
            lim.query(q)  # back at q: the cached sweep answers as before
            np.testing.assert_array_equal(lim.sweep.dist, before)
    rt.collision.pair_margins = rt._base_margins.copy()
    assert checked >= 5 and widened >= 1, (checked, widened)


@pytest.mark.parametrize("hand_name", ["allegro", "shadow"])
def test_end_of_step_check_skips_only_pairs_predicted_clear(demo_cube, hand_name):
    """The end-of-step check measures the near pairs the linear rows predict within
    ``NEAR_AFTER`` of their allowed distance (and those without a row). Over a retargeted
    demonstration (Allegro's box links, Shadow's capsules) every check decides as measuring
    all near pairs would (0.5 mm inside a margin), the pairs it skips ended well clear, and it
    does skip some (else it would be the old check)."""
    from retarget.limits import _kernels

    rt = Retargeter(get_hand(hand_name), object_geometry("cube2"))
    seen = []  # (checked, full, pairs skipped)
    for lim in (rt.collision, rt.self_collision):

        def wrapped(q, lim=lim, check=lim.near_violation):
            got = check(q)
            skipped = 0
            if lim._near.size:
                q_lin, G, rows, slack = lim._near_pred
                ask = _kernels.check_after_step(G, rows, slack, lim._near, q, q_lin, lim.NEAR_AFTER)
                skipped = lim._near.size - ask.size
            lim.NEAR_AFTER = np.inf  # every near pair
            full = check(q)
            del lim.NEAR_AFTER
            seen.append((got, full, skipped))
            return got

        lim.near_violation = wrapped
    rt.retarget(demo_cube)
    got, full, skipped = np.array(seen).T
    assert got.size > 100 and skipped.sum() > 50, (got.size, skipped.sum())
    np.testing.assert_array_equal(got < -5e-4, full < -5e-4)
    assert (got >= full).all()  # the minimum over fewer pairs
    other = got > full  # the nearest pair was one skipped
    assert (full[other] > 2e-3).all(), full[other].min()
