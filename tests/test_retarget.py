"""Retargeting on real hand models: round trip, backends, penetration, CLI and its errors."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from robot_poses import coupled, human_from_robot_poses

from dexcanvas_core.example import example_trajectories
from dexcanvas_core.io import write_dataset
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.rotations import aa_to_matrix
from dexcanvas_core.trajectory import Trajectory
from retarget.cli import main
from retarget.config import (
    CollisionConfig,
    ContactsConfig,
    ForceMatchingConfig,
    JointLimitsConfig,
    KeypointsConfig,
    PostureConfig,
    RetargetConfig,
    SmoothnessConfig,
    SolverConfig,
    VelocityConfig,
    WristConfig,
)
from retarget.errors import HandModelError, RetargetError
from retarget.hands import get_hand
from retarget.kinematics import MujocoKinematics, PinocchioKinematics
from retarget.retargeter import Retargeter
from retarget.state import RobotState


def run_exit_code(out) -> int:
    """The exit code ``retarget run`` owes a finished run in ``out``: 0 when the re-simulation
    (or its refinement) kept the object, 3 when it failed validation."""
    m = json.loads((Path(out) / "metrics.json").read_text())
    return 0 if m["success"] or m.get("success_refined") else 3


@pytest.fixture(scope="module")
def demo() -> Trajectory:
    """A short scripted cube2/tripod demonstration (grasp and lift frames)."""
    traj = next(t for t in example_trajectories(seed=0) if t.scene == "cube2")
    return traj.slice(100, 220)


def _robot_keypoint_human(rt: Retargeter, q: np.ndarray) -> Trajectory:
    """A two-frame 'human' whose retargeting targets are the robot's own pose ``q``."""
    return human_from_robot_poses(rt, np.tile(q, (2, 1)), uuid="robot-pose")


@pytest.mark.parametrize("hand_name", ["allegro", "shadow"])
def test_round_trip_recovers_robot_keypoints(hand_name):
    """Random robot pose → its keypoints → retarget → the same keypoints within 1 mm."""
    hand = get_hand(hand_name)
    rt = Retargeter(
        hand,
        None,
        RetargetConfig(
            solver=SolverConfig(first_frame_iterations=60, iterations=10),
            posture=PostureConfig(weight=0.0),
            smoothness=SmoothnessConfig(weight=0.0),
            velocity=VelocityConfig(max_joint_speed=1e3),
        ),
    )
    rng = np.random.default_rng(0)
    lo, hi = rt.lower.copy(), rt.upper.copy()
    tested = 0
    for _ in range(4):
        q = hand.default_qpos(rt.scene.model)[: rt.nq].copy()
        q[:3] = rng.uniform(-0.2, 0.2, 3)
        q[3:6] = rng.uniform(-0.5, 0.5, 3)
        fin = np.isfinite(lo[6:]) & np.isfinite(hi[6:])
        q[6:][fin] = lo[6:][fin] + rng.uniform(0.2, 0.8, fin.sum()) * (hi[6:] - lo[6:])[fin]
        # Respect couplings: project through the model's equality (follower from leader).
        q = coupled(rt.scene.model, q)
        if rt.self_distance_query.min_distance(q) < 0:
            continue  # fingers through each other: not a pose the robot can take
        human = _robot_keypoint_human(rt, q)
        out = rt.retarget(human)
        assert out.keypoint_err[-1] < 1e-3, out.keypoint_err
        tested += 1
    assert tested >= 2


def test_backends_agree_on_kinematic_terms(demo):
    hand = get_hand("allegro")
    rt = Retargeter(hand, object_geometry("cube2"))
    m = rt.scene.model
    pin_kin, mj_kin = PinocchioKinematics(m), MujocoKinematics(m, nq=rt.nq)
    tg = rt.human_targets(demo)
    rt.keypoints.set_targets(tg["keypoints"][10])
    rt.wrist.set_target(tg["wrist_p"][10], tg["wrist_R"][10])
    rng = np.random.default_rng(1)
    q = rt.q_default + rng.normal(scale=0.05, size=rt.nq)
    for obj in (rt.keypoints, rt.wrist, rt.vectors):
        if obj is rt.vectors:
            obj.set_targets(tg["vectors"][10])
        pin_kin.forward(q)
        mj_kin.forward(q)
        Hp, cp = obj.qp_terms(RobotState(q=q, kin=pin_kin))
        Hm, cm = obj.qp_terms(RobotState(q=q, kin=mj_kin))
        np.testing.assert_allclose(Hp, Hm, atol=1e-8)
        np.testing.assert_allclose(cp, cm, atol=1e-8)
        # build_qp's accumulation: compiled from Pinocchio's all-sites arrays, generic on MuJoCo.
        for kin in (pin_kin, mj_kin):
            P, c = np.zeros_like(Hp), np.zeros_like(cp)
            obj.accumulate(RobotState(q=q, kin=kin), P, c)
            np.testing.assert_allclose(P, Hm, atol=1e-8)
            np.testing.assert_allclose(c, cm, atol=1e-8)


def test_mink_backend_runs_and_matches(demo):
    hand = get_hand("allegro")
    geo = object_geometry("cube2")
    a = Retargeter(hand, geo, RetargetConfig(solver=SolverConfig(backend="pinocchio"))).retarget(
        demo
    )
    b = Retargeter(hand, geo, RetargetConfig(solver=SolverConfig(backend="mink"))).retarget(demo)
    # Same objectives and hand–object rows; the self-collision limit is mink's own, so the
    # solutions agree to within a few millimetres of keypoint error.
    assert abs(a.keypoint_err.mean() - b.keypoint_err.mean()) < 5e-3
    # The hand–object rows and the wrist's speed bound hold on mink too (with mink's own
    # collision limit this demo went 3.2 mm into the cube).
    cfg = RetargetConfig()
    assert b.min_distance[1:].min() > -(cfg.collision.penetration_margin + 5e-4)
    dt = np.diff(demo.timestamp)[:, None]
    assert (np.abs(np.diff(b.q[:, :3], axis=0)) <= cfg.velocity.max_wrist_speed * dt + 1e-6).all()


@pytest.mark.parametrize("backend", ["pinocchio", "mink"])
def test_shadow_distal_coupling_holds(demo, backend):
    """Shadow's limited fixed tendons (distal J0 ≈ 1.14 J1 within ±1 mm, and the sum bounds)
    hold along the retargeted trajectory on both backends, as the simulator enforces them."""
    from retarget.limits import CouplingLimit

    rt = Retargeter(
        get_hand("shadow"),
        object_geometry("cube2"),
        RetargetConfig(solver=SolverConfig(backend=backend)),
    )
    coupling = CouplingLimit.from_mjmodel(rt.scene.model)
    assert len(coupling.ranges) >= 4
    out = rt.retarget(demo)
    G = coupling._G[:, : rt.nq]
    L = out.q[1:] @ G.T  # (the first frame starts from the open posture)
    assert (L >= coupling._lo - 2e-4).all() and (L <= coupling._hi + 2e-4).all()
    bent = out.q[:, [out.joint_names.index(f"{f}J0") for f in ("FF", "MF")]]
    assert bent.max() > 0.2  # the distal joints follow the middle ones


def test_no_penetration_beyond_margin(demo):
    cfg = RetargetConfig()
    out = Retargeter(get_hand("shadow"), object_geometry("cube2"), cfg).retarget(demo)
    assert out.min_distance.min() > -(cfg.collision.penetration_margin + 1e-3)
    assert out.contact_active.any()


@pytest.mark.parametrize("part", [0, 1, 2])
def test_surface_contact_jacobian_matches_finite_differences(demo, part):
    """Every contact link (0 distal, 1 middle, 2 proximal phalanx)."""
    rt = Retargeter(get_hand("allegro"), object_geometry("cube2"))
    tg = rt.human_targets(demo)
    t = int(np.flatnonzero(tg["contact_active"].any(axis=1))[0])
    rt.scene.set_object_pose(demo.object.pos[t], demo.object.rot_aa[t])
    F = len(rt.tip_sites)
    rt.contacts.set_contacts(np.ones(F, bool), tg["contact_points"][t], np.full(F, part))
    m = rt.scene.model
    links = {int(m.body_weldid[m.body(b).id]) for b, _ in rt.contacts.finger_points(rt.q_default)}
    tips = {int(m.body_weldid[m.site(s).bodyid[0]]) for s in rt.tip_sites}
    assert (links == tips) == (part == 0)  # the middle and proximal links are not the tips'

    q = rt.q_default.copy()
    q[:6] = [*tg["wrist_p"][t], 0, 0, 0]
    rt.kin.forward(q)
    s = RobotState(q=q, kin=rt.kin)
    J = rt.contacts.jacobian(s)
    # J is the Jacobian of each finger's nearest surface point held fixed to its link (the
    # Gauss–Newton model of the term); check it against that point moved by finite differences.
    pts = rt.contacts.finger_points(q)
    kin = rt.kin
    local = [kin.data.oMf[kin.body_frames[b]].actInv(p) for b, p in pts]

    def points(qq):
        kin.forward(qq)
        return np.concatenate(
            [kin.data.oMf[kin.body_frames[b]].act(x) for (b, _), x in zip(pts, local, strict=True)]
        )

    p0 = points(q)
    eps = 1e-7
    for i in range(rt.nq):
        dq = np.zeros(rt.nq)
        dq[i] = eps
        np.testing.assert_allclose((points(q + dq) - p0) / eps, J[:, i], atol=1e-5)


def test_surface_contact_qp_terms_equal_error_and_jacobian(demo):
    """The contact term's one-pass ``(H, c)`` is ``JᵀWJ, JᵀWe`` of its error and Jacobian,
    with the ramps in the weights and inactive fingers left out."""
    from retarget.objectives.base import Objective

    rt = Retargeter(get_hand("shadow"), object_geometry("cube2"))
    tg = rt.human_targets(demo)
    t = int(np.flatnonzero(tg["contact_active"].sum(axis=1) >= 2)[0])
    rt.scene.set_object_pose(demo.object.pos[t], demo.object.rot_aa[t])
    F = len(rt.tip_sites)
    active = tg["contact_active"][t].copy()
    active[np.flatnonzero(~active)[:1]] = False
    ramp = np.linspace(0.3, 1.0, F)
    rt.contacts.set_contacts(active, tg["contact_points"][t], tg["contact_part"][t], ramp)
    q = rt.q_default.copy()
    q[:6] = [*tg["wrist_p"][t], 0.1, -0.2, 0.3]
    rt.kin.forward(q)
    s = RobotState(q=q, kin=rt.kin)
    H, c = rt.contacts.qp_terms(s)
    H0, c0 = Objective.qp_terms(rt.contacts, s)
    assert np.abs(c0).max() > 1e-6  # the fingers are off their targets
    np.testing.assert_allclose(H, H0, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(c, c0, rtol=1e-12, atol=1e-14)
    P, g = np.zeros_like(H), np.zeros_like(c)
    rt.contacts.accumulate(s, P, g)  # what build_qp calls
    np.testing.assert_allclose(P, H0, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(g, c0, rtol=1e-12, atol=1e-14)
    rt.contacts.set_contacts(np.zeros(F, bool), tg["contact_points"][t])
    H, c = rt.contacts.qp_terms(s)
    assert not H.any() and not c.any()
    before = P.copy(), g.copy()
    rt.contacts.accumulate(s, P, g)
    np.testing.assert_array_equal(P, before[0])  # nothing added
    np.testing.assert_array_equal(g, before[1])


@pytest.mark.parametrize("gap", [False, True])
def test_surface_contact_tangent_weight_scales_only_the_tangential_pull(demo, gap):
    """With surface normals and a tangent weight α, each contact's weight is
    ``w (n nᵀ + α (I − n nᵀ))``: full along the normal, α across it (one pass and base class
    agree, and both equal that matrix built by hand). With ``contact_hover_m`` 0 the normal
    row is the link's signed distance ``d`` with the Jacobian ``gᵀ J`` instead of
    ``nᵀ(p − p*)`` and ``nᵀ J`` (where they differ; on a face they are the same); the
    tangential rows are the same."""
    from retarget.objectives.base import Objective

    alpha = 0.2
    cfg = RetargetConfig(
        contacts=ContactsConfig(tangent_weight=alpha, hover_m=0.0 if gap else None)
    )
    rt = Retargeter(get_hand("shadow"), object_geometry("cube2"), cfg)
    tg = rt.human_targets(demo)
    t = int(np.flatnonzero(tg["contact_active"].sum(axis=1) >= 2)[0])
    rt.scene.set_object_pose(demo.object.pos[t], demo.object.rot_aa[t])
    active = tg["contact_active"][t]
    n = tg["contact_normals"][t]
    q = rt.q_default.copy()
    q[:6] = [*tg["wrist_p"][t], 0.1, -0.2, 0.3]
    rt.kin.forward(q)
    s = RobotState(q=q, kin=rt.kin)
    rt.contacts.set_contacts(active, tg["contact_points"][t], tg["contact_part"][t], normals=n)
    H, c = rt.contacts.qp_terms(s)
    H0, c0 = Objective.qp_terms(rt.contacts, s)
    np.testing.assert_allclose(H, H0, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(c, c0, rtol=1e-10, atol=1e-12)
    Pa, ca = np.zeros_like(H), np.zeros_like(c)
    rt.contacts.accumulate(s, Pa, ca)  # build_qp's compiled pass, in the surface frames
    np.testing.assert_allclose(Pa, H0, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(ca, c0, rtol=1e-10, atol=1e-12)
    idx = np.flatnonzero(active)
    pts = rt.contacts.finger_points(q)
    P = rt.contacts.finger_point_array(q)[idx]
    J = rt.kin.point_jacobians(tuple(pts[i][0] for i in idx), P)
    Hm, cm = np.zeros_like(H), np.zeros_like(c)
    _, _, dist = rt.contacts.nearest_of(q, idx)
    for k, i in enumerate(idx):
        u = n[i] / np.linalg.norm(n[i])
        W = rt.cfg.contacts.weight * alpha * (np.eye(3) - np.outer(u, u))
        Hm += J[k].T @ W @ J[k]
        cm += J[k].T @ W @ (P[k] - tg["contact_points"][t][i])
        if gap:  # the row d + gᵀ J Δq, g the distance's direction at the link's point
            g = rt.contacts._cache_g[i]
            Hm += rt.cfg.contacts.weight * np.outer(g @ J[k], g @ J[k])
            cm += rt.cfg.contacts.weight * dist[k] * (g @ J[k])
        else:
            Hm += rt.cfg.contacts.weight * np.outer(u @ J[k], u @ J[k])
            cm += rt.cfg.contacts.weight * (u @ (P[k] - tg["contact_points"][t][i])) * (u @ J[k])
    np.testing.assert_allclose(H, Hm, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(c, cm, rtol=1e-9, atol=1e-9)
    assert np.abs(cm).max() > 1e-6
    with pytest.raises(RetargetError, match="normals must be"):
        rt.contacts.set_contacts(active, tg["contact_points"][t], normals=n[:2])


def test_nearest_of_computes_only_the_asked_fingers(demo, monkeypatch):
    """The grip squeeze's ``nearest_of`` gives the asked fingers' entries of ``finger_points``
    and ``finger_distances`` (same bodies, points and distances), querying only their links."""
    import mujoco

    rt = Retargeter(get_hand("shadow"), object_geometry("cube2"))
    tg = rt.human_targets(demo)
    t = int(np.flatnonzero(tg["contact_active"].sum(axis=1) >= 2)[0])
    rt.scene.set_object_pose(demo.object.pos[t], demo.object.rot_aa[t])
    F = len(rt.tip_sites)
    rt.contacts.set_contacts(np.ones(F, bool), tg["contact_points"][t], np.zeros(F, int))
    q = rt.q_default.copy()
    q[:6] = [*tg["wrist_p"][t], 0.1, -0.2, 0.3]
    idx = np.array([3, 0])
    calls = []
    geom_distance = mujoco.mj_geomDistance
    monkeypatch.setattr(
        mujoco,
        "mj_geomDistance",
        lambda m, d, a, b, *r: calls.append(a) or geom_distance(m, d, a, b, *r),
    )
    bodies, P, gap = rt.contacts.nearest_of(q, idx)
    asked = {g for i in idx for g in rt.contacts.part_geoms[i][0]}
    assert calls and set(calls) <= asked
    monkeypatch.undo()
    pts, dist = rt.contacts.finger_points(q), rt.contacts.finger_distances(q)
    assert bodies == tuple(pts[i][0] for i in idx)
    np.testing.assert_array_equal(P, np.array([pts[i][1] for i in idx]))
    np.testing.assert_array_equal(gap, dist[idx])


def test_contact_error_per_finger_and_shape_errors():
    from retarget.metrics import contact_error_per_finger

    err = np.array([[0.001, np.nan, np.nan], [0.003, 0.02, np.nan]])
    assert contact_error_per_finger(err, ["thumb", "index", "middle"]) == {
        "thumb": pytest.approx(0.002),
        "index": pytest.approx(0.02),
    }
    with pytest.raises(RetargetError, match="must be \\(frames, 2\\)"):
        contact_error_per_finger(err, ["thumb", "index"])


@pytest.fixture(scope="module")
def small_dataset(tmp_path_factory, demo):
    path = tmp_path_factory.mktemp("rt") / "d.lance"
    write_dataset([demo], path)
    return path


def test_cli_run_writes_outputs(small_dataset, tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(
        [
            "run",
            "--hand",
            "allegro",
            "--pair",
            "cube2/tripod",
            "--dataset",
            str(small_dataset),
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert rc == run_exit_code(out)
    m = json.loads((out / "metrics.json").read_text())
    for key in ("success", "object_pos_err_max_m", "object_pos_err_mean_m",
                "object_rot_err_mean_rad", "keypoint_err_mean_m", "penetration_max_m",
                "self_penetration_max_m", "ms_per_frame"):  # fmt: skip
        assert key in m
    assert 0.0 <= m["self_penetration_max_m"] < 2e-3
    # per-finger contact error: the mean over each finger's contact frames of the saved errors
    z = np.load(out / "robot_trajectory.npz")
    per = m["contact_err_per_finger_m"]
    assert per and set(per) <= {"thumb", "index", "middle", "ring", "pinky"}
    allegro = get_hand("allegro")
    names = [f for f in ("thumb", "index", "middle", "ring", "pinky") if allegro.fingers.get(f)]
    for k, f in enumerate(names):
        e = z["contact_err"][:, k]
        assert (f in per) == bool(np.isfinite(e).any())
        if f in per:
            assert per[f] == pytest.approx(np.nanmean(e), rel=1e-9)
    assert set(m["contacts_off_target"]) == {f for f, e in per.items() if e > 0.01}
    assert z["self_min_distance"].shape == (120,)
    assert z["q"].shape == (120, len(z["joint_names"]))
    assert z["finger_force_world"].shape == (120, 5, 3)
    # the weight-aware grip's commanded contact forces (Allegro: 4 fingers)
    assert z["robot_force"].shape == (120, 4, 3) and z["wrench_shortfall"].shape == (120,)
    assert "human_force" not in z.files
    # servo tracking: recomputed from the simulated and commanded joints in the outputs
    assert z["q_sim"].shape == z["q_command"].shape == (120, len(z["joint_names"]))
    names = list(z["joint_names"])
    slides = [names.index(j) for j in ("wrist_tx", "wrist_ty", "wrist_tz")]
    werr = np.linalg.norm(z["q_sim"][:, slides] - z["q_command"][:, slides], axis=1)
    assert m["wrist_pos_tracking_err_mean_m"] == pytest.approx(werr.mean(), rel=1e-9)
    assert m["wrist_pos_tracking_err_max_m"] == pytest.approx(werr.max(), rel=1e-9)
    # the wrist's rotation error is the angle between the simulated and commanded orientations
    from scipy.spatial.transform import Rotation

    hinges = [names.index(j) for j in ("wrist_rx", "wrist_ry", "wrist_rz")]
    R_sim, R_cmd = (Rotation.from_euler("XYZ", z[k][:, hinges]) for k in ("q_sim", "q_command"))
    angle = np.degrees((R_sim.inv() * R_cmd).magnitude())
    assert m["wrist_rot_tracking_err_mean_deg"] == pytest.approx(angle.mean(), rel=1e-6)
    assert m["wrist_driver"] == "computed_torque"
    assert (m["wrist_force_limit_n"], m["wrist_torque_limit_nm"]) == (200.0, 20.0)
    assert 0 < m["wrist_force_max_n"] <= 200.0 and m["wrist_force_saturation_fraction"] == 0.0
    servo = m["finger_servo_err_mean_deg"]
    assert set(servo) == set(allegro.robot_fingers)
    thumb = allegro.robot_fingers.index(allegro.fingers["thumb"])
    assert servo[allegro.fingers["thumb"]] == pytest.approx(
        np.degrees(z["finger_servo_err"][:, thumb].mean()), rel=1e-9
    )
    assert all(0.0 <= v < 30.0 for v in servo.values())
    assert not list(out.glob(".*tmp"))


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--hand", "shdow", "--pair", "cube2/tripod"], "did you mean 'shadow'"),
        (["--hand", "shadow", "--pair", "cube2/tripd"], "did you mean 'tripod'"),
        (["--hand", "shadow", "--pair", "cube2"], "cube2/tripod"),
        (["--hand", "panda", "--pair", "sphere1/rolling"], "cannot perform 'rolling'"),
        (
            ["--hand", "shadow", "--pair", "cube2/tripod", "--set", "w_contact=1"],
            "unknown RetargetConfig field(s) w_contact (did you mean w_contacts",
        ),
        (
            ["--hand", "shadow", "--pair", "cube2/tripod", "--set", "force_matching=True"],
            "force_matching is the run's own option, use --forces",
        ),
        (
            ["--hand", "shadow", "--pair", "cube2/tripod", "--set", "w_contacts=-1"],
            "ContactsConfig.weight must be finite and >= 0",
        ),
        (
            ["--hand", "shadow", "--pair", "cube2/tripod", "--set", "iterations=0"],
            "iterations must be >= 1",
        ),
        *(
            (
                ["--hand", "shadow", "--pair", "cube2/tripod", "--time-scale", bad],
                f"--time-scale must be a finite number from 1 to 10 (the demonstration is "
                f"executed that many times slower), got '{bad}'",
            )
            for bad in ("0.5", "0", "-2", "nan", "inf", "11", "abc")
        ),
    ],
)
def test_cli_run_errors(argv, message, small_dataset, capsys):
    assert main(["run", *argv, "--dataset", str(small_dataset), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "retarget run: error:" in err and message in err


def test_cli_run_time_scale_slows_the_demonstration_and_says_so(small_dataset, tmp_path, capsys):
    """``retarget run --time-scale 2`` executes the demonstration twice as slowly: the same
    frames at half the rate, recorded in metrics.json and on the terminal; a replay of the run
    (``retarget.viz``) stretches it alike and reproduces the re-simulation."""
    from retarget.pipeline import RunConfig
    from retarget.time_scale import time_scaled
    from retarget.viz.data import load_human_for_run, load_run
    from retarget.viz.resim import record_resimulation

    out = tmp_path / "slow"
    argv = ["run", "--hand", "allegro", "--pair", "cube2/tripod", "--dataset",
            str(small_dataset), "--out", str(out), "--time-scale", "2"]  # fmt: skip
    assert main(argv) == run_exit_code(out)
    assert "executed 2× slower than demonstrated" in capsys.readouterr().out
    m = json.loads((out / "metrics.json").read_text())
    assert m["time_scale"] == 2.0 and m["frames"] == 120 and m["fps"] == pytest.approx(60.0)
    with np.load(out / "robot_trajectory.npz") as z:
        np.testing.assert_allclose(np.diff(z["timestamp"]), 2 / 120, rtol=1e-6)
        obj = z["object_pos_sim"]
    run = load_run(out)
    human = load_human_for_run(run)
    assert human.fps == pytest.approx(60.0)
    rec = record_resimulation(
        get_hand("allegro"), object_geometry("cube2"), run.arrays["q_command"], human, metrics=m
    )
    np.testing.assert_allclose(rec.result.object_pos_sim, obj, atol=1e-9)
    # the default executes the demonstration as captured; the stretch keeps every frame
    assert RunConfig(hand="allegro", pair="cube2/tripod").time_scale == 1.0
    slow = time_scaled(human, 1.5)
    assert slow.num_frames == human.num_frames and slow.duration == pytest.approx(
        1.5 * human.duration
    )
    np.testing.assert_array_equal(slow.hand.joint_pos, human.hand.joint_pos)


def test_cli_run_set_changes_the_retargeting_and_is_recorded(small_dataset, tmp_path, capsys):
    """``retarget run --set NAME=VALUE`` reaches the retargeter (a contact weight 200× weaker
    moves the links' contact points by millimetres), and metrics.json and the summary
    say what was changed; a malformed pair is argparse's usage error."""
    base = ["run", "--hand", "shadow", "--pair", "cube2/tripod", "--dataset", str(small_dataset)]
    assert main([*base, "--out", str(tmp_path / "a"), "--quiet"]) == run_exit_code(tmp_path / "a")
    argv = [*base, "--out", str(tmp_path / "b"), "--set", "w_contacts=1.0", "--set", "iterations=5"]
    assert main(argv) == run_exit_code(tmp_path / "b")
    assert "w_contacts=1.0, iterations=5" in capsys.readouterr().out
    a = json.loads((tmp_path / "a" / "metrics.json").read_text())
    b = json.loads((tmp_path / "b" / "metrics.json").read_text())
    assert a["retarget_overrides"] == {}
    assert b["retarget_overrides"] == {"w_contacts": 1.0, "iterations": 5}
    assert b["retarget_config"]["w_contacts"] == 1.0 and b["retarget_config"]["iterations"] == 5
    assert abs(b["contact_err_mean_m"] - a["contact_err_mean_m"]) > 1e-3
    with pytest.raises(SystemExit) as e:
        main([*base, "--set", "w_contacts"])
    assert e.value.code == 2
    assert "expected NAME=VALUE, got 'w_contacts'" in capsys.readouterr().err


def test_cli_run_refuses_negative_refine_retries(capsys):
    with pytest.raises(SystemExit) as e:  # argparse's usage error
        main(["run", "--hand", "shadow", "--pair", "cube2/tripod", "--refine-retries", "-1"])
    assert e.value.code == 2
    assert "--refine-retries: expected a whole number >= 0, got '-1'" in capsys.readouterr().err


def test_cli_run_defaults_are_the_run_config_defaults():
    """The CLI states its defaults literally (``retarget.run`` loads only to run): they must
    be ``RunConfig``'s, and ``RunConfig``'s refinement retries ``RefineConfig``'s."""
    from retarget.cli import build_parser
    from retarget.cli_args import _plain_run_config
    from retarget.pipeline import RunConfig
    from retarget.refine import RefineConfig

    args = build_parser().parse_args(["run", "--hand", "shadow", "--pair", "cube2/tripod"])
    cli = _plain_run_config(args)
    ref = RunConfig(hand="shadow", pair="cube2/tripod")
    assert cli == ref
    assert ref.refine_retries == RefineConfig().retries == 4
    from retarget.force_calibration import ForceCalibrationConfig

    assert ref.calibrate_iterations == ForceCalibrationConfig().iterations == 10


def test_cli_run_pair_missing_from_dataset(small_dataset, capsys):
    rc = main(
        [
            "run",
            "--hand",
            "shadow",
            "--pair",
            "sphere1/tripod",
            "--dataset",
            str(small_dataset),
            "--quiet",
        ]
    )
    assert rc == 2
    assert "no trajectory matches" in capsys.readouterr().err


def test_keypoint_only_entry_point(demo):
    from dexcanvas_core.keypoints import convert_keypoints
    from dexcanvas_core.rotations import rotation_angle_between_aa
    from retarget.keypoint_input import keypoints_to_trajectory, retarget_keypoints

    kp = demo.hand.joint_pos.astype(np.float64)
    t = keypoints_to_trajectory(convert_keypoints(kp, "mano21", "openpose21"), 120.0, "openpose21")
    # The palm is rigid in MANO: the wrist rotation is recovered exactly.
    assert rotation_angle_between_aa(t.hand.global_rot_aa, demo.hand.global_rot_aa).max() < 1e-4
    np.testing.assert_allclose(t.hand.joint_pos, kp, atol=1e-6)
    out = retarget_keypoints(get_hand("allegro"), kp[:20], 120.0)
    assert out.q.shape[0] == 20 and np.isfinite(out.keypoint_err).all()
    bad = kp.copy()
    bad[3, 4, 1] = np.nan
    with pytest.raises(RetargetError, match="NaN or inf \\(first at frame 3\\)"):
        keypoints_to_trajectory(bad, 120.0)
    with pytest.raises(RetargetError, match=r"shape \(T, 21, 3\)"):
        keypoints_to_trajectory(kp[:, :20], 120.0)


def test_cli_keypoints_retargets_a_keypoint_file(demo, tmp_path, capsys):
    from dexcanvas_core.keypoints import convert_keypoints

    kp = convert_keypoints(demo.hand.joint_pos[:30].astype(np.float64), "mano21", "openpose21")
    np.savez(tmp_path / "kp.npz", keypoints=kp * 1000.0)  # in millimetres
    out = tmp_path / "out"
    rc = main(
        [
            "keypoints",
            "--hand",
            "leap",
            "--input",
            str(tmp_path / "kp.npz"),
            "--order",
            "openpose21",
            "--units",
            "mm",
            "--fps",
            "120",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["frames"] == 30 and 0 < m["keypoint_err_mean_m"] < 0.05
    with np.load(out / "robot_trajectory.npz") as z:
        assert z["q"].shape[0] == 30
    # the same keypoints as CSV (63 columns, header), in metres
    np.savetxt(tmp_path / "kp.csv", kp.reshape(30, 63), delimiter=",", header="x0,y0,z0,...")
    rc = main(
        [
            "keypoints",
            "--hand",
            "leap",
            "--input",
            str(tmp_path / "kp.csv"),
            "--order",
            "openpose21",
            "--fps",
            "120",
            "--out",
            str(tmp_path / "o2"),
        ]
    )
    assert rc == 0
    bad = kp.copy()
    bad[5, 2] = np.nan
    np.save(tmp_path / "bad.npy", bad)
    rc = main(
        [
            "keypoints",
            "--hand",
            "leap",
            "--input",
            str(tmp_path / "bad.npy"),
            "--fps",
            "120",
            "--out",
            str(tmp_path / "o3"),
        ]
    )
    assert rc == 2 and "frame 5" in capsys.readouterr().err
    rc = main(
        [
            "keypoints",
            "--hand",
            "leap",
            "--input",
            str(tmp_path / "nope.npy"),
            "--fps",
            "120",
            "--out",
            str(tmp_path / "o4"),
        ]
    )
    assert rc == 2 and "does not exist" in capsys.readouterr().err


def test_link_contacts_hold_a_lateral_pinch_on_the_thumb_pad():
    """The built-in cube2/lateral_pinch: the thumb presses the cube with its pad, its tip
    keypoint (the end of the finger) stays farther than contact_threshold from the cube. With
    contacts on the distal phalanx's pad (link contacts) the thumb has a contact on over 300
    frames and the robot's thumb distal link meets the human's pad point; without them, none."""
    from dexcanvas_core.loaders.selection import load_demonstration

    traj = load_demonstration("cube2/lateral_pinch")
    geom = object_geometry(traj.object.name)
    off = Retargeter(
        get_hand("shadow"), geom, RetargetConfig(contacts=ContactsConfig(link_contacts=False))
    )
    on = Retargeter(get_hand("shadow"), geom)
    thumb = on.tip_human.index("thumb")
    assert not off.human_targets(traj)["contact_active"][:, thumb].any()
    tg = on.human_targets(traj)
    pad = tg["contact_active"][:, thumb]
    assert pad.sum() > 300 and (tg["contact_part"][pad, thumb] == 0).all()
    r = on.retarget(traj)
    assert np.nanmedian(r.contact_err[pad, thumb]) < 0.003
    assert -r.min_distance.min() <= on.cfg.collision.penetration_margin + 5e-4


def test_a_fingertip_body_belongs_to_its_distal_link():
    """Allegro's fingertips are jointless bodies on the distal links (``link_7.0_tip`` on
    ``link_7.0``): one rigid link, so one contact part (MuJoCo's weld groups), and the next
    parts are the middle and proximal links. Counted as a part of its own, the distal link
    stood for the human's middle phalanx and kept the non-contact clearance from the cube
    where the human's fingertip touched it: on the built-in cube2/tripod the middle finger
    hovered 4 mm off the cube; now its distal link touches it."""
    from dexcanvas_core.loaders.selection import load_demonstration

    traj = load_demonstration("cube2/tripod")
    rt = Retargeter(get_hand("allegro"), object_geometry(traj.object.name))
    m = rt.scene.model
    links = [[{int(m.body_weldid[m.geom_bodyid[g]]) for g in gs} for gs in parts]
             for parts in rt.contacts.part_geoms]  # fmt: skip
    for f, parts in enumerate(links):
        assert all(len(p) == 1 for p in parts), (rt.tip_human[f], parts)
        assert len({next(iter(p)) for p in parts}) == 3, (rt.tip_human[f], parts)  # 3 links
        bodies = {m.body(m.geom_bodyid[g]).name for g in rt.contacts.part_geoms[f][0]}
        assert any(b.endswith("_tip") for b in bodies) and len(bodies) == 2, bodies
    tg = rt.human_targets(traj)
    mid = rt.tip_human.index("middle")
    on = np.flatnonzero(tg["contact_active"][:, mid] & (tg["contact_part"][:, mid] == 0))
    assert on.size > 100
    r = rt.retarget(traj)
    gap = []
    for t in on[::10]:
        rt.scene.set_object_pose(traj.object.pos[t], traj.object.rot_aa[t])
        rt.contacts.set_contacts(tg["contact_active"][t], tg["contact_points"][t])
        gap.append(rt.contacts.finger_distances(r.q[t])[mid])
    assert np.median(gap) < 1e-3, np.median(gap)


def test_joint_limit_margin_keeps_finger_joints_inside_their_ranges():
    """``joint_limit_margin`` keeps every finger joint of the kinematic solution that far inside
    its range (at most a quarter of it), the wrist's coordinates untouched; the grip's servo
    commands may still use the whole range. On the built-in cube2/tripod Allegro's middle
    distal joint rests on its extension limit without the margin (its pad on the cube's top
    edge, pulled along the surface towards the human's contact point at force matching's
    ``contact_tangent_weight``) and 0.1 rad inside it with."""
    from dexcanvas_core.loaders.selection import load_demonstration

    traj = load_demonstration("cube2/tripod").slice(250, 400)
    geom = object_geometry(traj.object.name)
    hand = get_hand("allegro")
    ctw = RetargetConfig().force_matching.tangent_weight
    plain = Retargeter(
        hand,
        geom,
        RetargetConfig(
            joint_limits=JointLimitsConfig(margin=0.0), contacts=ContactsConfig(tangent_weight=ctw)
        ),
    )
    inner = Retargeter(
        hand,
        geom,
        RetargetConfig(
            joint_limits=JointLimitsConfig(margin=0.1), contacts=ContactsConfig(tangent_weight=ctw)
        ),
    )
    j7 = plain.kin.joint_names.index("joint_7.0")
    q0 = plain.retarget(traj).q
    assert np.isclose(q0[:, j7], plain.lower[j7], atol=1e-3).mean() > 0.9
    r = inner.retarget(traj)
    m = np.minimum(0.1, 0.25 * (inner.upper - inner.lower))
    fingers = slice(6, inner.nq)
    tol = inner.cfg.solver.step_tolerance
    assert (r.q[:, fingers] >= (inner.lower + m)[fingers] - tol).all()
    assert (r.q[:, fingers] <= (inner.upper - m)[fingers] + tol).all()
    assert r.q[:, j7].min() > inner.lower[j7] + 0.1 - tol
    assert (r.q_command >= inner.lower - 1e-9).all() and (r.q_command <= inner.upper + 1e-9).all()
    with pytest.raises(RetargetError, match=r"JointLimitsConfig\.margin"):
        RetargetConfig(joint_limits=JointLimitsConfig(margin=-0.1))


def test_joint_limit_margin_defaults_to_the_hands_own():
    """``RetargetConfig.joint_limits.margin=None`` (the default) takes the hand's
    ``HandModel.joint_limit_margin`` (Allegro 0.05 rad, the others 0); a number overrides it;
    the mink backend's configuration limit gets the same ranges."""
    geom = object_geometry("cube2")
    allegro, shadow = get_hand("allegro"), get_hand("shadow")
    assert allegro.joint_limit_margin == 0.05 and shadow.joint_limit_margin == 0.0
    for hand, want in ((allegro, 0.05), (shadow, 0.0)):
        rt = Retargeter(hand, geom)
        fingers = np.zeros(rt.nq, bool)
        fingers[6:] = np.isfinite(rt.lower[6:]) & np.isfinite(rt.upper[6:])
        inner = np.minimum(want, 0.25 * (rt.upper - rt.lower))
        np.testing.assert_allclose(rt._solve_lower[fingers], (rt.lower + inner)[fingers])
        np.testing.assert_allclose(rt._solve_upper[fingers], (rt.upper - inner)[fingers])
        np.testing.assert_array_equal(rt._solve_lower[:6], rt.lower[:6])
    zero = Retargeter(allegro, geom, RetargetConfig(joint_limits=JointLimitsConfig(margin=0.0)))
    np.testing.assert_array_equal(zero._solve_lower, zero.lower)
    mk = Retargeter(allegro, geom, RetargetConfig(solver=SolverConfig(backend="mink")))
    cl = mk._mink.limits[0]
    lim = mk.scene.model.jnt_limited[: mk.nq].astype(bool)
    np.testing.assert_allclose(cl.lower[: mk.nq][lim], mk._solve_lower[lim])
    np.testing.assert_allclose(cl.upper[: mk.nq][lim], mk._solve_upper[lim])
    with pytest.raises(HandModelError, match="joint_limit_margin"):
        dataclasses.replace(allegro, joint_limit_margin=-0.1)


def test_contact_parts_are_validated():
    rt = Retargeter(get_hand("allegro"), object_geometry("cube2"))
    F = len(rt.tip_sites)
    with pytest.raises(RetargetError, match="parts"):
        rt.contacts.set_contacts(np.ones(F, bool), np.zeros((F, 3)), np.full(F, 3))


def test_contact_ramp_rises_and_falls():
    from retarget.targets import contact_ramp

    active = np.zeros((12, 2), bool)
    active[2:10, 0] = True  # 8 frames
    active[5:6, 1] = True  # 1 frame
    r = contact_ramp(active, 3.0)
    np.testing.assert_allclose(r[2:10, 0], [1 / 3, 2 / 3, 1, 1, 1, 1, 2 / 3, 1 / 3])
    assert r[5, 1] == pytest.approx(1 / 3) and (r[~active] == 1).all()


def test_onsets_do_not_snap_the_wrist():
    """Shadow on the built-in cuboid3/lateral_tripod: contacts switched on and off at full
    weight in every direction (``contact_tangent_weight`` 1), with nothing else in the way,
    move the retargeted wrist at up to 2.7 m/s (the human's at most 0.55 m/s); a 0.1 s contact
    ramp keeps it below 2.5 m/s (0.8), and the default frame-to-frame bound
    (``max_wrist_speed``) at 1.5 m/s per axis."""
    from dexcanvas_core.loaders.selection import load_demonstration

    traj = load_demonstration("cuboid3/lateral_tripod")
    geom = object_geometry(traj.object.name)
    peak = {}
    for name, cfg in {
        "free": RetargetConfig(
            velocity=VelocityConfig(max_wrist_speed=np.inf),
            keypoints=KeypointsConfig(scaling="uniform"),
            contacts=ContactsConfig(tangent_weight=1.0),
        ),
        "ramp": RetargetConfig(
            velocity=VelocityConfig(max_wrist_speed=np.inf),
            keypoints=KeypointsConfig(scaling="uniform"),
            contacts=ContactsConfig(tangent_weight=1.0, ramp_s=0.1),
        ),
        "default": RetargetConfig(),
    }.items():
        rt = Retargeter(get_hand("shadow"), geom, cfg)
        q = rt.retarget(traj).q
        peak[name] = (np.linalg.norm(np.diff(q[1:, :3], axis=0), axis=1) * traj.fps).max()
    human = np.linalg.norm(np.diff(traj.hand.global_pos, axis=0), axis=1) * traj.fps
    assert human.max() < 1.0  # the bound, not the human's own speed, is what is measured
    assert peak["ramp"] < 2.5 < peak["free"]
    # The bound is per axis (box bounds): |v| ≤ √3 · 1.5 m/s at most.
    assert peak["default"] <= np.sqrt(3) * 1.5 + 1e-6
    assert peak["default"] < 0.6 * peak["free"]


def test_surface_scaling_keeps_touching_keypoints_touching():
    """``keypoint_scaling="surface"``: each target is the uniformly scaled keypoint moved along
    the surface normal until its distance to the surface is the robot-sized finger radius plus
    the human's gap (``s·ρ + (d − ρ)``) near the object, ``s·d`` from ``scale_blend_m`` out
    and within the finger radius; ``uniform`` is the plain scaling about the centre."""
    demo = next(t for t in example_trajectories(seed=0) if t.scene == "cube2")  # reach + grasp
    geom = object_geometry("cube2")
    rt = Retargeter(get_hand("shadow"), geom)
    uni = Retargeter(
        get_hand("shadow"), geom, RetargetConfig(keypoints=KeypointsConfig(scaling="uniform"))
    )
    s, blend, rho = rt.scale, rt.cfg.keypoints.scale_blend_m, rt.cfg.keypoints.finger_radius_m
    assert s > 1.2 and rt.cfg.keypoints.scaling == "surface"
    h_kp = demo.hand.joint_pos.astype(np.float64)
    c = demo.object.pos.astype(np.float64)[:, None]
    R = np.stack([aa_to_matrix(a) for a in demo.object.rot_aa.astype(np.float64)])

    def sdf(p):
        return geom.sdf_and_normal(np.einsum("tji,tkj->tki", R, p - c))

    u = uni._scaled_keypoints(demo, h_kp)
    np.testing.assert_allclose(u, c + s * (h_kp - c))
    out = rt._scaled_keypoints(demo, h_kp)
    d, _ = sdf(h_kp)
    d_out, _ = sdf(out)
    d_u, n_u = sdf(u)
    # Moved along the surface normal at the scaled keypoint only (no sideways component).
    n_world = np.einsum("tij,tkj->tki", R, n_u)
    move = u - out
    along = np.einsum("tki,tki->tk", move, n_world)[..., None] * n_world
    np.testing.assert_allclose(move - along, 0.0, atol=1e-9)
    touch = (d >= 0) & (d < rho)
    gap = (d >= rho) & (d < rho + 0.004)  # smoothstep still ≤ 2 % of the way to s
    far = d >= rho + blend
    assert touch.sum() > 20 and gap.sum() > 20 and far.sum() > 100  # the demo has all three
    # On a box's faces the move lands exactly at the asked distance (not across an edge).
    face = np.abs(d_out - d_u) < 0.5 * np.abs(d_u)
    np.testing.assert_allclose(d_out[touch & face], s * d[touch & face], atol=1e-3)
    np.testing.assert_allclose(d_out[gap & face], s * rho + d[gap & face] - rho, atol=1e-3)
    np.testing.assert_allclose(d_out[far & face], s * d[far & face], atol=1e-3)
    # Uniform scaling pushed the touching keypoints (s − 1)·r off: farther than this.
    assert (d_u[touch] - d_out[touch]).mean() > 0.005
    tg = rt.human_targets(demo)  # the wrist, keypoint and vector targets are these points
    assert rt.cfg.wrist.use_offset  # the wrist target: the scaled wrist, then the offset
    R_h = aa_to_matrix(demo.hand.global_rot_aa.astype(np.float64))
    np.testing.assert_allclose(tg["wrist_p"], rt.hand.wrist_offset.apply(R_h, out[:, 0])[1])
    np.testing.assert_allclose(tg["keypoints"], out[:, rt.kp_index])
    a, b = rt.vec_human[0]
    np.testing.assert_allclose(tg["vectors"][:, 0], out[:, a] - out[:, b])
    with pytest.raises(RetargetError, match=r"KeypointsConfig\.scaling"):
        RetargetConfig(keypoints=KeypointsConfig(scaling="centre"))
    with pytest.raises(RetargetError, match=r"VelocityConfig\.max_wrist_speed"):
        RetargetConfig(velocity=VelocityConfig(max_wrist_speed=0.0))


def test_force_matching_takes_its_own_contact_tangent_weight():
    """Kinematic retargeting lets contacts slide along the surface (``contact_tangent_weight``);
    force matching, which places the human's forces at the human's contact points, holds them
    nearer (``force_contact_tangent_weight``). Bad values are refused by name."""
    hand, geom = get_hand("shadow"), object_geometry("cube2")
    cfg = RetargetConfig(
        contacts=ContactsConfig(tangent_weight=0.02),
        force_matching=ForceMatchingConfig(tangent_weight=0.3),
    )
    assert Retargeter(hand, geom, cfg).contacts.tangent_weight == 0.02
    fm = cfg.with_overrides({"force_matching.enabled": True})
    assert Retargeter(hand, geom, fm).contacts.tangent_weight == 0.3
    for k, name in (
        ("contact_tangent_weight", "ContactsConfig.tangent_weight"),
        ("force_contact_tangent_weight", "ForceMatchingConfig.tangent_weight"),
    ):
        for v in (-0.1, np.nan):
            with pytest.raises(RetargetError, match=name):
                RetargetConfig.from_overrides({k: v})


def test_predicted_start_moves_the_wrist_as_the_human_and_the_fingers_at_their_velocity():
    """``predicted_start`` (the warm start's prediction): the wrist by the human's step, its
    Euler angles wrapped across ±π; the fingers by their last step only while no contact flag
    changed over the last two frames; all clipped to the ranges."""
    from retarget._kernels import predicted_start

    rng = np.random.default_rng(5)
    n = 12
    lower, upper = -np.full(n, 1.0), np.full(n, 1.0)
    lower[:3], upper[:3] = -np.inf, np.inf  # the wrist position is unbounded
    for case in range(40):
        Q = rng.uniform(-0.9, 0.9, size=(2, n))
        wq = rng.uniform(-0.5, 0.5, size=(2, 6))
        if case % 4 == 0:  # an Euler angle crossing ±π
            wq[0, 4], wq[1, 4] = np.pi - 0.01, -np.pi + 0.02
        active = rng.random((5, 4)) < 0.5
        if case % 2:
            active[1:4] = active[2]  # no flag changed over frames 1–3
        q0 = predicted_start(Q, wq, active, 3, lower, upper)
        step = wq[1] - wq[0]
        step[3:] = np.angle(np.exp(1j * step[3:]))  # the same angle in (−π, π]
        want = Q[1].copy()
        want[:6] += step
        if case % 2:
            want[6:] += Q[1, 6:] - Q[0, 6:]
        np.testing.assert_allclose(q0, np.clip(want, lower, upper), atol=1e-12)
        if case % 4 == 0:  # a 0.03 rad step, not −2π + 0.03
            assert q0[4] == pytest.approx(min(Q[1, 4] + 0.03, upper[4]), abs=1e-12)


def test_warm_start_keeps_the_joint_couplings():
    """Ability's middle joint drives its distal one (``q₉ = 0.72 + 1.06 q₈``). A finger
    closing back to its range's end: the prediction clips the driving joint at 0 and moves
    the driven one on, 0.26 rad off the coupling, more than the QP's velocity bound can undo
    in one iterate (its equality rows made the frame infeasible). The warm start then falls
    back to the last solution; a prediction inside the ranges is kept."""
    from robot_poses import coupled

    rt = Retargeter(get_hand("ability"), None)
    m = rt.scene.model
    Q = np.tile(rt.q_default, (2, 1))
    Q[0, 8], Q[1, 8] = 0.30, 0.05  # a middle joint closing back towards 0 (its lower limit)
    Q = np.stack([coupled(m, q) for q in Q])
    wq = np.zeros((2, 6))
    active = np.zeros((3, len(rt.tip_sites)), bool)
    q0 = rt._warm_start(Q, wq, active, 2)
    np.testing.assert_array_equal(q0, Q[1])
    Q[0, 8] = 0.1  # a small step: the prediction stays inside the range and is kept
    Q = np.stack([coupled(m, q) for q in Q])
    q0 = rt._warm_start(Q, wq, active, 2)
    assert q0[8] == pytest.approx(0.0, abs=1e-12) and not np.array_equal(q0, Q[1])


def test_predicted_warm_start_takes_fewer_steps_without_overshooting():
    """Frames start from a prediction (wrist moved as the human's, fingers at their last
    velocity): fewer QP solves per frame, the same keypoint error, and no faster wrist at a
    contact onset than when starting from the previous solution (extrapolating the robot
    wrist's own jump there doubled it)."""
    from dexcanvas_core.loaders.selection import load_demonstration

    traj = load_demonstration("cuboid3/lateral_tripod")
    geom = object_geometry(traj.object.name)
    out = {}
    for ws in (False, True):
        rt = Retargeter(
            get_hand("shadow"), geom, RetargetConfig(solver=SolverConfig(warm_start_extrapolate=ws))
        )
        solves = [0]
        step = rt._solve_step

        def counted(*a, _step=step, _n=solves, **k):
            _n[0] += 1
            return _step(*a, **k)

        rt._solve_step = counted
        r = rt.retarget(traj)
        speed = np.linalg.norm(np.diff(r.q[:, :3], axis=0), axis=1) * traj.fps
        out[ws] = (solves[0] / traj.num_frames, r.keypoint_err.mean(), speed.max())
    assert out[True][0] < 0.85 * out[False][0]
    assert out[True][1] < out[False][1] + 5e-4
    assert out[True][2] < 1.1 * out[False][2]


def test_links_the_human_keeps_clear_stay_clear(demo):
    """Where the human's phalanx does not touch the object, the robot link standing for it
    keeps ``noncontact_clearance`` from it (to the linearisation's accuracy); where it touches,
    the plain non-penetration margin applies. Without the clearance some such link comes
    closer on this demonstration."""
    geom = object_geometry("cube2")

    def closest_clear(rt, r, tg):
        """Per frame, the smallest distance [m] of a robot link whose human phalanx is clear."""
        m = rt.scene.model
        part_of = {}
        for f, parts in enumerate(rt.contacts.part_geoms):
            for k, gs in enumerate(parts):
                for g in gs:
                    part_of.setdefault(g, []).append((f, k))
        obj = set(rt.scene.object_geoms)
        out = np.full(demo.num_frames, np.inf)
        for t in range(demo.num_frames):
            rt.scene.set_object_pose(demo.object.pos[t], demo.object.rot_aa[t])
            for ga, gb, d, _pa, _pb in rt.distance_query.distances(r.q[t]):
                fk = part_of.get(ga)
                if gb in obj and fk and not any(tg["contact_by_part"][t, f, k] for f, k in fk):
                    out[t] = min(out[t], d)
        assert m.ngeom > 0
        return out

    rt = Retargeter(get_hand("shadow"), geom)
    tg = rt.human_targets(demo)
    assert tg["contact_by_part"].any() and not tg["contact_by_part"].all()
    r = rt.retarget(demo)
    d_on = closest_clear(rt, r, tg)
    clear = rt.cfg.collision.noncontact_clearance
    assert clear > 0 and d_on.min() > clear - 1e-3, d_on.min()
    np.testing.assert_array_equal(rt.collision.pair_margins, rt._base_margins)  # restored
    off = Retargeter(
        get_hand("shadow"),
        geom,
        RetargetConfig(collision=CollisionConfig(noncontact_clearance=0.0)),
    )
    d_off = closest_clear(off, off.retarget(demo), tg)
    assert d_off.min() < clear - 1e-3 < d_on.min()
    # The margins themselves: touching parts and the palm keep the penetration margin.
    by_part = np.zeros_like(tg["contact_by_part"][0])
    m0 = rt._frame_margins(by_part)
    is_part = rt._pair_parts.any(axis=1)
    table = rt._base_margins < 0
    assert (m0[is_part & ~table] == -clear).all()
    assert (m0[~is_part] == rt._base_margins[~is_part]).all()
    by_part[:] = True
    np.testing.assert_array_equal(rt._frame_margins(by_part), rt._base_margins)


def test_wrist_weight_scales_the_wrist_term(demo):
    """``HandModel.wrist_weight`` multiplies ``RetargetConfig``'s wrist weights (0 on the Panda
    gripper and SVH: no wrist term is built); with it the gripper's pads follow the human's
    fingertips instead of its wrist (keypoint error lower on the example cube2/tripod)."""
    geom = object_geometry("cube2")
    shadow, panda = get_hand("shadow"), get_hand("panda")
    assert shadow.wrist_weight == 1.0 and panda.wrist_weight == 0.0
    assert get_hand("svh").wrist_weight == 0.0
    cfg = RetargetConfig(wrist=WristConfig(position_weight=0.2, rotation_weight=0.1))
    rt = Retargeter(dataclasses.replace(shadow, wrist_weight=0.5), geom, cfg)
    np.testing.assert_allclose(rt.wrist.weights(6), [0.1] * 3 + [0.05] * 3)
    assert rt.wrist in rt._objectives()
    free = Retargeter(panda, geom)
    assert free.wrist not in free._objectives()
    pinned = Retargeter(dataclasses.replace(panda, wrist_weight=1.0), geom)
    assert pinned.wrist in pinned._objectives()
    err_free = free.retarget(demo).keypoint_err.mean()
    err_pinned = pinned.retarget(demo).keypoint_err.mean()
    assert err_free < 0.85 * err_pinned  # measured 31.7 vs 42.1 mm, (err_free, err_pinned)
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(HandModelError, match="wrist_weight"):
            dataclasses.replace(shadow, wrist_weight=bad)


def test_resimulation_measures_servo_lag(demo):
    """The re-simulation's servo tracking errors: zero for a held pose in free air, growing
    with the command's speed for the one joint that moves, zero for the fingers that do not."""
    from retarget.validate import Resimulator

    hand = get_hand("allegro")
    sim = Resimulator(hand, object_geometry("cube2"))
    q0 = hand.default_qpos(sim.model)[: sim.hand_nq].copy()
    q0[2] = 0.4  # wrist_tz: the hand 40 cm up, touching nothing
    T = demo.num_frames
    held = sim.run(np.tile(q0, (T, 1)), demo)
    m = held.servo_metrics()
    assert max(m["finger_servo_err_mean_deg"].values()) < 0.01
    assert m["wrist_pos_tracking_err_mean_m"] < 1e-6
    assert m["wrist_rot_tracking_err_mean_deg"] < 0.01
    index = sim.fingers.index(hand.fingers["index"])
    j = sim.act_q[np.flatnonzero(sim.act_finger == index)[1]]
    t = demo.timestamp - demo.timestamp[0]
    lag = {}
    for hz in (0.5, 2.0):
        q = np.tile(q0, (T, 1))
        q[:, j] += 0.3 * np.sin(2 * np.pi * hz * t)
        res = sim.run(q, demo)
        assert res.q_sim.shape == (T, sim.hand_nq)
        # the finger's error is its moving joint's: |q_sim − q| at that joint
        err_j = np.abs(res.q_sim[:, j] - q[:, j])
        np.testing.assert_allclose(res.finger_servo_err[:, index], err_j, atol=1e-12)
        others = [v for f, v in res.servo_metrics()["finger_servo_err_mean_deg"].items()
                  if f != hand.fingers["index"]]  # fmt: skip
        assert max(others) < 0.01
        lag[hz] = float(np.degrees(err_j.mean()))
    assert 1.0 < lag[0.5] < lag[2.0] / 2
