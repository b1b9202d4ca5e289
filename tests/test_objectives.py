"""Every objective and limit: Jacobians against finite differences; QP solves a round trip."""

import mujoco
import numpy as np
import pytest
from test_kinematics import TOY

from retarget.errors import RetargetError
from retarget.kinematics import PinocchioKinematics
from retarget.limits import (
    CollisionLimit,
    CouplingLimit,
    FrameSpeedLimit,
    JointLimit,
    VelocityLimit,
)
from retarget.objectives import (
    ContactObjective,
    KeypointObjective,
    PostureObjective,
    SmoothnessObjective,
    VectorObjective,
    WristPoseObjective,
)
from retarget.qp import QPSolveError, build_qp, solve_qp
from retarget.state import RobotState

SITES = ["ff_tip_site", "th_tip_site"]


@pytest.fixture(scope="module")
def kin():
    m = mujoco.MjModel.from_xml_string(TOY)
    return PinocchioKinematics(m)


def _state(kin, q):
    kin.forward(q)
    return RobotState(q=np.asarray(q, dtype=np.float64), kin=kin)


def _fd_check(obj, kin, q, eps=1e-7, atol=1e-5):
    s = _state(kin, q)
    e0, J = obj.error(s), obj.jacobian(s)
    assert J.shape == (e0.shape[0], q.shape[0])
    for i in range(q.shape[0]):
        dq = np.zeros_like(q)
        dq[i] = eps
        e1 = obj.error(_state(kin, q + dq))
        np.testing.assert_allclose(
            (e1 - e0) / eps, J[:, i], atol=atol, err_msg=f"{obj.name} dof {i}"
        )


def _objectives(kin, rng):
    kp = KeypointObjective(SITES)
    kp.set_targets(rng.normal(size=(2, 3)))
    vec = VectorObjective([("ff_tip_site", "th_tip_site")])
    vec.set_targets(rng.normal(size=(1, 3)))
    wr = WristPoseObjective("ff_tip_site")
    # Target close to the current pose: the rotation Jacobian is exact at zero error.
    c = ContactObjective(SITES, pad_axis=np.array([0.0, 1.0, 0.0]))
    c.set_contacts(np.array([True, True]), rng.normal(size=(2, 3)), rng.normal(size=(2, 3)))
    post = PostureObjective(rng.normal(size=kin.nq))
    sm = SmoothnessObjective()
    sm.set_previous(rng.normal(size=kin.nq))
    return [kp, vec, wr, c, post, sm]


def test_objective_jacobians_match_finite_differences(kin):
    rng = np.random.default_rng(0)
    objs = _objectives(kin, rng)
    for _ in range(3):
        q = rng.uniform(-0.8, 0.8, size=kin.nq)
        kin.forward(q)
        wr = objs[2]
        wr.set_target(kin.site_position("ff_tip_site") + 0.01, kin.site_rotation("ff_tip_site"))
        for obj in objs:
            _fd_check(obj, kin, q)


def test_qp_terms_are_gauss_newton_of_the_cost(kin):
    rng = np.random.default_rng(1)
    obj = _objectives(kin, rng)[0]
    obj.weight = np.array([2.0, 0.5])
    q = rng.uniform(-0.5, 0.5, size=kin.nq)
    s = _state(kin, q)
    H, c = obj.qp_terms(s)
    # ∇(½ Σ w e²) = Jᵀ W e = c
    eps = 1e-7
    grad = np.array(
        [
            (obj.cost(_state(kin, q + eps * np.eye(kin.nq)[i])) - obj.cost(_state(kin, q)))
            / (2 * eps)
            for i in range(kin.nq)
        ]
    )
    np.testing.assert_allclose(grad, c, atol=1e-5)
    assert np.all(np.linalg.eigvalsh(H) > -1e-12)


def test_accumulate_adds_the_qp_terms(kin):
    """``build_qp``'s in-place accumulation (compiled; straight from the all-sites arrays for
    keypoints and vectors) adds exactly what ``qp_terms`` returns, whatever the weights (per
    site, zero rows)."""
    from retarget.objectives.base import Objective

    rng = np.random.default_rng(4)
    objs = _objectives(kin, rng)
    for step in range(3):
        if step == 1:
            objs[0].weight = np.array([0.0, 2.5])  # one keypoint switched off
            objs[1].weight = 3.0
        if step == 2:
            objs[4].weight = rng.uniform(0.0, 1.0, size=kin.nq)
        s = _state(kin, rng.uniform(-0.8, 0.8, size=kin.nq))
        for obj in objs:
            P0, c0 = rng.normal(size=(kin.nq, kin.nq)), rng.normal(size=kin.nq)
            P, c = P0.copy(), c0.copy()
            obj.accumulate(s, P, c)
            H, g = obj.qp_terms(s)
            np.testing.assert_allclose(P - P0, H, atol=1e-12, err_msg=f"{obj.name} {step}")
            np.testing.assert_allclose(c - c0, g, atol=1e-12, err_msg=f"{obj.name} {step}")
            H2, g2 = Objective.qp_terms(obj, s)  # the generic JᵀWJ, JᵀWe
            np.testing.assert_allclose(H, H2, atol=1e-12, err_msg=f"{obj.name} {step}")
            np.testing.assert_allclose(g, g2, atol=1e-12, err_msg=f"{obj.name} {step}")
            assert np.abs(H).max() > 0, obj.name


def test_wrist_rotation_error_is_the_rotation_vector_up_to_pi():
    """The wrist objective's compiled rotation error is the rotation vector of ``R R*ᵀ``,
    angle in [0, π], against SciPy's, at random rotations and at angles near 0 and π (every
    branch of the quaternion extraction: the trace, and each diagonal element largest)."""
    from scipy.spatial.transform import Rotation

    from retarget.objectives._kernels import pose_error

    rng = np.random.default_rng(7)
    axes = rng.normal(size=(60, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([rng.uniform(0, np.pi, 30), np.pi - 10.0 ** -rng.uniform(3, 9, 15),
                             10.0 ** -rng.uniform(3, 13, 15)])  # fmt: skip
    axes[30:33] = np.eye(3)  # near π about each axis: each diagonal branch
    R_target = Rotation.random(random_state=3).as_matrix()
    p, p_target = rng.normal(size=3), rng.normal(size=3)
    for rv in axes * angles[:, None]:
        R = Rotation.from_rotvec(rv).as_matrix() @ R_target
        e = np.empty(6)
        pose_error(p, R.reshape(9), p_target, R_target, e)
        np.testing.assert_allclose(e[:3], p - p_target, atol=1e-15)
        want = Rotation.from_matrix(R @ R_target.T).as_rotvec()
        if np.linalg.norm(want) > np.pi - 1e-6:  # ±axis·π are the same rotation
            assert abs(np.linalg.norm(e[3:]) - np.pi) < 1e-6
            np.testing.assert_allclose(np.abs(e[3:]), np.abs(want), atol=1e-6)
        else:
            np.testing.assert_allclose(e[3:], want, atol=1e-9, rtol=1e-9)


def test_memoised_qp_terms_follow_weight_and_mask_changes(kin):
    """Posture and smoothness memoise their diagonal Hessian; it must track new weights and
    masks, and match the generic ``JᵀWJ, JᵀWe`` of their error and Jacobian."""
    from retarget.objectives.base import Objective

    rng = np.random.default_rng(3)
    post = PostureObjective(rng.normal(size=kin.nq), weight=1e-3)
    sm = SmoothnessObjective(weight=0.05)
    sm.set_previous(rng.normal(size=kin.nq))
    mask_b = rng.random(kin.nq) < 0.5
    mask_b[0] = True
    for step in range(4):
        if step == 1:
            post.weight = rng.uniform(0.1, 2.0, size=kin.nq)
            sm.weight = 3.0
        if step == 2:
            post.mask = mask_b
            post.weight = 0.7
        if step == 3:
            post.mask = ~mask_b
        q = rng.uniform(-0.5, 0.5, size=kin.nq)
        s = _state(kin, q)
        for obj in (post, sm):
            H, c = obj.qp_terms(s)
            H_ref, c_ref = Objective.qp_terms(obj, s)
            np.testing.assert_allclose(H, H_ref, atol=1e-15, err_msg=f"{obj.name} step {step}")
            np.testing.assert_allclose(c, c_ref, atol=1e-15, err_msg=f"{obj.name} step {step}")
            # Shared memo: a caller accumulating into the returned arrays must fail loudly.
            with pytest.raises(ValueError):
                H += 1.0


def test_keypoint_round_trip_recovers_sites(kin):
    """Random robot pose → its sites → solve from another pose → same sites within 1 mm."""
    rng = np.random.default_rng(2)
    lower, upper = kin.model.lowerPositionLimit.copy(), kin.model.upperPositionLimit.copy()
    lower[lower < -10], upper[upper > 10] = -1.0, 1.0
    limited = np.ones(kin.nq, bool)
    for _ in range(5):
        q_true = rng.uniform(lower, upper) * 0.8
        kin.forward(q_true)
        targets = np.stack([kin.site_position(s) for s in SITES])
        R = kin.site_rotation("ff_tip_site")
        kp = KeypointObjective(SITES, weight=1.0)
        kp.set_targets(targets)
        wr = WristPoseObjective("ff_tip_site", weight=(0.0, 0.1))
        wr.set_target(targets[0], R)
        q = np.clip(q_true + rng.normal(scale=0.2, size=kin.nq), lower, upper)
        limits = [JointLimit(lower, upper, limited)]
        for _ in range(50):
            s = _state(kin, q)
            q = q + solve_qp(build_qp(s, [kp, wr], limits, damping=1e-4))
        s = _state(kin, q)
        assert np.abs(kp.error(s)).max() < 1e-3
        assert np.all(q >= lower - 1e-9) and np.all(q <= upper + 1e-9)


def test_joint_and_velocity_limits_bound_the_step(kin):
    q = np.zeros(kin.nq)
    s = _state(kin, q)
    kp = KeypointObjective(SITES)
    kp.set_targets(np.full((2, 3), 5.0))  # unreachable: pulls hard
    vmax = 0.5
    dq = solve_qp(build_qp(s, [kp], [VelocityLimit(vmax)]))
    assert np.abs(dq).max() <= vmax * s.dt + 1e-9


def test_frame_speed_limit_bounds_the_motion_since_the_last_frame(kin):
    """Iterates pulled hard towards an unreachable target stay within ``v_max·dt`` of the
    previous frame's solution on the bounded joints, however many steps they take; the
    others move freely; a start outside the band only steps back towards it."""
    kp = KeypointObjective(SITES)
    kp.set_targets(np.full((2, 3), 5.0))
    q_prev = np.zeros(kin.nq)
    v = np.full(kin.nq, np.inf)
    v[0] = 0.5
    lim = FrameSpeedLimit(q_prev, v)
    q = q_prev.copy()
    free = 0.0
    for _ in range(5):
        s = _state(kin, q)
        q = q + solve_qp(build_qp(s, [kp], [lim]))
        assert abs(q[0] - q_prev[0]) <= v[0] * s.dt + 1e-9
        free = max(free, np.abs(q[1:] - q_prev[1:]).max())
    assert abs(q[0] - q_prev[0]) == pytest.approx(v[0] * s.dt)  # the bound is what stops it
    assert free > 10 * v[0] * s.dt  # the unbounded joints are not held back
    q_out = q_prev.copy()
    q_out[0] = 3 * v[0] * s.dt
    lb, ub = lim.bounds(_state(kin, q_out))
    assert lb[0] == pytest.approx(-4 * v[0] * s.dt) and ub[0] == 0.0  # back, not further out
    assert np.isinf(lb[1:]).all() and np.isinf(ub[1:]).all()
    with pytest.raises(RetargetError, match="one per joint"):
        FrameSpeedLimit(q_prev, v[:2])


COUPLED = """
<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body>
      <joint name="a" axis="0 0 1"/>
      <geom size="0.01"/>
      <body pos="0.1 0 0">
        <joint name="b" axis="0 0 1"/>
        <geom size="0.01"/>
        <site name="tip" pos="0.1 0 0"/>
      </body>
    </body>
  </worldbody>
  <equality><joint joint1="b" joint2="a" polycoef="0 0.7 0.1 0 0"/></equality>
</mujoco>
"""


def test_coupling_rows_hold_after_solving():
    m = mujoco.MjModel.from_xml_string(COUPLED)
    kin = PinocchioKinematics(m)
    coupling = CouplingLimit.from_mjmodel(m)
    kp = KeypointObjective(["tip"])
    kp.set_targets(np.array([[0.05, 0.15, 0.0]]))
    q = np.array([0.3, -0.2])  # violates b = 0.7 a + 0.1 a²
    for _ in range(20):
        q = q + solve_qp(build_qp(_state(kin, q), [kp], [coupling], damping=1e-4))
    assert q[1] == pytest.approx(0.7 * q[0] + 0.1 * q[0] ** 2, abs=1e-6)


@pytest.mark.parametrize("hand_name", ["svh", "inspire", "ability"])
def test_coupling_rows_linearise_the_residual(hand_name):
    """Each equality row is ``A Δq = b`` with ``b = −r(q)`` and ``A = ∂r/∂q`` for the
    coupling residual ``r = a₁ᵀq − p(a₂ᵀq)`` (MuJoCo's polycoef), checked against
    ``np.polyval`` and central differences at random joint positions."""
    from retarget.hands import get_hand

    m = get_hand(hand_name).build_spec().compile()
    coupling = CouplingLimit.from_mjmodel(m)
    assert coupling.rows, hand_name
    A1 = np.array([a1 for a1, _, _ in coupling.rows])
    A2 = np.array([a2 for _, a2, _ in coupling.rows])
    C = np.array([c for _, _, c in coupling.rows])

    def residual(q):
        return A1 @ q - np.array([np.polyval(c[::-1], x) for c, x in zip(C, A2 @ q, strict=True)])

    rng = np.random.default_rng(3)
    kin = PinocchioKinematics(m)
    for _ in range(3):
        q = rng.uniform(-0.5, 1.0, m.nv)
        A, b = coupling.equalities(_state(kin, q))
        np.testing.assert_allclose(b, -residual(q), atol=1e-12)
        eps = 1e-6
        J = np.stack(
            [(residual(q + eps * e) - residual(q - eps * e)) / (2 * eps) for e in np.eye(m.nv)],
            axis=1,
        )
        np.testing.assert_allclose(A, J, atol=1e-8)


@pytest.mark.parametrize("hand_name", ["shadow", "svh", "inspire", "ability", "panda"])
def test_follower_map_moves_coupled_joints_with_their_servos(hand_name):
    """``CouplingLimit.follower_map``: a displacement ``C Δq`` of the servoed joints keeps every
    coupling (equality rows, Shadow's narrow J0–J1 tendons) to first order (residual change
    O(ε²) by central differences), is the identity on the servoed joints and has zero columns
    for the followers."""
    from retarget.hands import get_hand

    m = get_hand(hand_name).build_spec().compile()
    coupling = CouplingLimit.from_mjmodel(m)
    servoed = np.zeros(m.nv, bool)
    for a in range(m.nu):
        servoed[m.jnt_dofadr[m.actuator_trnid[a, 0]]] = True
    followers = ~servoed
    assert followers.any(), hand_name
    narrow = np.array(
        [a for a, lo, hi in coupling.ranges if np.count_nonzero(a) > 1 and hi - lo <= 2e-3]
    ).reshape(-1, m.nv)
    A1 = np.array([a1 for a1, _, _ in coupling.rows]).reshape(-1, m.nv)
    A2 = np.array([a2 for _, a2, _ in coupling.rows]).reshape(-1, m.nv)
    P = np.array([c for _, _, c in coupling.rows]).reshape(-1, 5)

    def residual(q):
        eq = A1 @ q - np.array([np.polyval(c[::-1], x) for c, x in zip(P, A2 @ q, strict=True)])
        return np.concatenate([eq, narrow @ q])

    rng = np.random.default_rng(5)
    q = rng.uniform(-0.3, 0.6, m.nv)
    C = coupling.follower_map(q, followers)
    np.testing.assert_array_equal(C[:, followers], 0.0)
    np.testing.assert_allclose(C[np.ix_(servoed, servoed)], np.eye(servoed.sum()))
    moved = np.abs(C[np.ix_(followers, servoed)]).sum(axis=1) > 0
    assert moved.sum() >= 1  # some follower is driven
    for _ in range(3):
        dq = C @ rng.normal(size=m.nv)
        eps = 1e-4
        d = (residual(q + eps * dq) - residual(q - eps * dq)) / (2 * eps)
        np.testing.assert_allclose(d, 0.0, atol=1e-6)
    # A nonlinear linkage: the map's slope is p'(q) at the configuration.
    mc = mujoco.MjModel.from_xml_string(COUPLED)
    cc = CouplingLimit.from_mjmodel(mc)
    assert not cc.linear and coupling.linear
    for a in (0.0, 0.5):
        Cc = cc.follower_map(np.array([a, 0.0]), np.array([False, True]))
        assert Cc[1, 0] == pytest.approx(0.7 + 0.2 * a) and Cc[0, 0] == 1.0


TENDON_COUPLED = """
<mujoco>
  <worldbody>
    <body name="a">
      <joint name="j1" type="hinge" axis="0 0 1" range="-2 2"/>
      <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.01"/>
      <body name="b" pos="0.1 0 0">
        <joint name="j0" type="hinge" axis="0 0 1" range="-2 2"/>
        <geom type="capsule" fromto="0 0 0 0.05 0 0" size="0.01"/>
        <site name="tip" pos="0.05 0 0"/>
      </body>
    </body>
  </worldbody>
  <tendon>
    <fixed name="couple" limited="true" range="-0.001 0.001">
      <joint joint="j0" coef="0.00705"/>
      <joint joint="j1" coef="-0.00805"/>
    </fixed>
  </tendon>
</mujoco>
"""


def test_limited_tendon_rows_hold_after_solving():
    """A Shadow-style distal coupling (a fixed tendon held within ±1 mm): the target asks for a
    straight distal joint, the rows keep j0 ≈ 1.14 j1 as the simulator will."""
    m = mujoco.MjModel.from_xml_string(TENDON_COUPLED)
    kin = PinocchioKinematics(m)
    coupling = CouplingLimit.from_mjmodel(m)
    assert coupling and not coupling.rows and len(coupling.ranges) == 1
    kp = KeypointObjective(["tip"])
    # Reachable with j1 = 0.8, j0 = 0 (which violates the tendon by 6.4 mm).
    a, b = 0.8, 0.0
    tip = np.array(
        [0.1 * np.cos(a) + 0.05 * np.cos(a + b), 0.1 * np.sin(a) + 0.05 * np.sin(a + b), 0]
    )
    kp.set_targets(tip[None])
    q = np.zeros(2)  # (j1, j0)
    for _ in range(30):
        q = q + solve_qp(build_qp(_state(kin, q), [kp], [coupling], damping=1e-4))
    L = 0.00705 * q[1] - 0.00805 * q[0]
    assert -0.001 - 1e-9 <= L <= 0.001 + 1e-9
    assert q[0] > 0.3  # it still reached towards the target
    free = q.copy()
    for _ in range(30):
        free = free + solve_qp(build_qp(_state(kin, free), [kp], [], damping=1e-4))
    assert abs(0.00705 * free[1] - 0.00805 * free[0]) > 0.002  # without the rows it breaks it


def test_one_joint_tendon_range_is_a_box_bound():
    """A limited tendon on one joint (Shadow's actuator tendons) is that joint's interval: box
    bounds instead of rows, which the step respects and which pull a violation back."""
    xml = TENDON_COUPLED.replace(
        "</tendon>",
        '  <fixed name="one" limited="true" range="-0.002 0.004"><joint joint="j1" coef="-0.01"/>'
        "</fixed>\n  </tendon>",
    )
    m = mujoco.MjModel.from_xml_string(xml)
    kin = PinocchioKinematics(m)
    coupling = CouplingLimit.from_mjmodel(m)
    assert len(coupling.ranges) == 2
    s = _state(kin, np.array([0.1, 0.0]))
    G, _ = coupling.inequalities(s)
    assert G.shape == (2, 2)  # the two-joint coupling only
    lo, hi = coupling.bounds(s)  # -0.002 ≤ -0.01·j1 ≤ 0.004  ⇔  -0.4 ≤ j1 ≤ 0.2
    np.testing.assert_allclose([lo[0], hi[0]], [-0.4 - 0.1, 0.2 - 0.1])
    assert lo[1] == -np.inf and hi[1] == np.inf
    kp = KeypointObjective(["tip"])
    kp.set_targets(np.array([[0.0, 0.15, 0.0]]))  # straight up: j1 = π/2, beyond the range
    for q in (np.zeros(2), np.array([0.5, 0.57])):  # inside, and outside it
        for _ in range(30):
            q = q + solve_qp(build_qp(_state(kin, q), [kp], [coupling], damping=1e-4))
        assert -0.4 - 1e-9 <= q[0] <= 0.2 + 1e-9
        assert q[0] == pytest.approx(0.2, abs=1e-6)  # pressed against the bound


OBJECT_SCENE = """
<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="finger">
      <joint name="x" type="slide" axis="1 0 0"/>
      <geom name="pad" type="sphere" size="0.01"/>
      <site name="tip" pos="0 0 0"/>
    </body>
    <body name="object" mocap="true" pos="0.1 0 0">
      <geom name="box" type="box" size="0.02 0.02 0.02"/>
    </body>
  </worldbody>
</mujoco>
"""


def test_collision_limit_stops_at_the_surface():
    m = mujoco.MjModel.from_xml_string(OBJECT_SCENE)
    d = mujoco.MjData(m)
    kin = PinocchioKinematics(m)
    pad = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "pad")
    box = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "box")
    lim = CollisionLimit(m, d, [(pad, box)], hand_nq=1, margin=0.0, distmax=0.2)
    kp = KeypointObjective(["tip"])
    kp.set_targets(np.array([[0.1, 0.0, 0.0]]))  # the box centre: would penetrate
    q = np.zeros(1)
    for _ in range(30):
        q = q + solve_qp(build_qp(_state(kin, q), [kp], [lim], damping=1e-6))
    # Sphere of radius 1 cm stops at the box face x = 0.08: centre at 0.07.
    assert q[0] == pytest.approx(0.07, abs=5e-4)
    # The linearised row matches the true distance change.
    s = _state(kin, np.array([0.03]))
    G, h = lim.inequalities(s)
    assert h[0] == pytest.approx(0.08 - 0.03 - 0.01, abs=1e-6)
    np.testing.assert_allclose(G[0], [1.0], atol=1e-9)


def test_infeasible_problem_raises_with_problem_attached(kin):
    s = _state(kin, np.zeros(kin.nq))
    kp = KeypointObjective(SITES)
    kp.set_targets(np.zeros((2, 3)))
    G = np.eye(kin.nq)[:1]
    bad = type(
        "Bad",
        (JointLimit,),
        {"inequalities": lambda self, st: (np.vstack([G, -G]), np.array([-1.0, -1.0]))},
    )
    with pytest.raises(QPSolveError, match="no solution") as e:
        solve_qp(build_qp(s, [kp], [bad(np.zeros(1), np.zeros(1))]))
    assert e.value.problem.G.shape == (2, kin.nq)
