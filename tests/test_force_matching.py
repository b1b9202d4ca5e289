"""Force matching: the contact-force distribution QP and the K⁻¹Jᵀf squeeze."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest
from finger_scenes import finger_pressing_a_fixed_box

from benchmarks.force_preservation.jobs import _hand_job
from dexcanvas_core.taxonomy import OBJECTS
from retarget.config import (
    ClosingConfig,
    ContactsConfig,
    ForceMatchingConfig,
    GripConfig,
    PostureConfig,
    RetargetConfig,
    SolverConfig,
    WristConfig,
)
from retarget.errors import RetargetError
from retarget.force_matching import distribute, grasp_matrix, squeeze_offsets

G = 9.81


def _box_grasp():
    """Three contacts on a 6 cm box centred at the origin: thumb on −x, two fingers on +x."""
    points = np.array([[-0.03, 0.0, 0.0], [0.03, 0.015, 0.0], [0.03, -0.015, 0.0]])
    normals = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    return points, normals


def _in_cones(f, normals, mu):
    u = -normals
    fn = np.einsum("ij,ij->i", f, u)
    ft = np.linalg.norm(f - fn[:, None] * u, axis=1)
    return np.all(fn >= -1e-9) and np.all(ft <= mu * fn + 1e-6)


def test_qp_reproduces_a_required_wrench_inside_the_friction_cones():
    points, normals = _box_grasp()
    m = 0.3
    W = np.array([0.0, 0.0, m * G, 0.0, 0.0, 0.0])  # hold the box against gravity
    d = distribute(points, normals, np.zeros((3, 3)), W, np.zeros(3), mu=0.8)
    np.testing.assert_allclose(d.wrench, W, atol=0.02 * m * G)
    assert d.force_shortfall_n < 0.02 * m * G and d.torque_shortfall_nm < 1e-3
    assert _in_cones(d.forces, normals, 0.8)
    # the weight is shared by friction; the squeeze balances (no net x force)
    assert d.forces[:, 2].sum() == pytest.approx(m * G, rel=0.02)
    np.testing.assert_allclose(grasp_matrix(points, np.zeros(3)) @ d.forces.reshape(-1), d.wrench)


def test_qp_keeps_human_forces_that_already_produce_the_wrench():
    points, normals = _box_grasp()
    f_h = np.array([[3.0, 0.0, 1.0], [-1.5, 0.0, 0.5], [-1.5, 0.0, 0.5]])
    W = grasp_matrix(points, np.zeros(3)) @ f_h.reshape(-1)
    d = distribute(points, normals, f_h, W, np.zeros(3), mu=1.0)
    np.testing.assert_allclose(d.forces, f_h, atol=1e-3)
    assert d.tracking_error.max() < 1e-3


def test_missing_finger_is_redistributed_and_torque_limits_show_as_shortfall():
    points, normals = _box_grasp()
    f_h = np.array([[3.0, 0.0, 1.0], [-1.5, 0.0, 0.5], [-1.5, 0.0, 0.5]])
    W = grasp_matrix(points, np.zeros(3)) @ f_h.reshape(-1)
    # a hand without the third finger: two contacts must still lift the box
    d = distribute(points[:2], normals[:2], f_h[:2], W, np.zeros(3), mu=1.0)
    assert abs(d.wrench[2] - W[2]) < 0.05 and abs(d.wrench[0]) < 0.05
    # joint torque limits too low for the load: the QP stays feasible and reports a shortfall
    J = [np.eye(3) * 0.05, np.eye(3) * 0.05]  # 5 cm lever per joint, 3 joints per finger
    tiny = distribute(points[:2], normals[:2], f_h[:2], W, np.zeros(3), mu=1.0,
                      jacobians=[np.hstack([Ji, np.zeros((3, 3))]) if i == 0
                                 else np.hstack([np.zeros((3, 3)), Ji])
                                 for i, Ji in enumerate(J)],
                      tau_max=np.full(6, 0.02))  # fmt: skip
    assert tiny.force_shortfall_n > 0.5
    tau = 0.05 * np.abs(tiny.forces).reshape(-1)
    assert np.all(tau <= 0.02 + 1e-6)


def test_bad_inputs_are_refused():
    points, normals = _box_grasp()
    with pytest.raises(RetargetError, match="NaN"):
        distribute(points, normals, np.full((3, 3), np.nan), np.zeros(6), np.zeros(3))
    with pytest.raises(RetargetError, match="rows"):
        distribute(points, normals[:2], np.zeros((3, 3)), np.zeros(6), np.zeros(3))


def test_squeeze_offsets_press_with_the_intended_force():
    """Δq = K⁻¹Jᵀf on a single finger against a fixed box: the contact force is the command
    within 10 % with stiff contacts (5 ms). The re-simulations press through the force
    pipeline's softer ones (20 ms), where the finger sinks in and loses ~25 % (below), and the
    force calibration makes that up (tests/test_force_calibration.py)."""
    m = finger_pressing_a_fixed_box(solref=0.005)
    d = mujoco.MjData(m)
    kp = m.actuator_gainprm[:, 0]
    for F in (1.0, 3.0, 6.0):
        mujoco.mj_resetData(m, d)
        mujoco.mj_forward(m, d)
        # the distal link rests on the box; a vertical force's moment arms only depend on x
        p = d.geom_xpos[m.geom("tip").id].copy()
        jacp = np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, jacp, None, p, m.body("l2").id)
        dq = squeeze_offsets([jacp], np.array([[0.0, 0.0, -F]]), kp)
        d.ctrl[:] = dq
        for _ in range(2000):
            mujoco.mj_step(m, d)
        fn = 0.0
        for i in range(d.ncon):
            f6 = np.zeros(6)
            mujoco.mj_contactForce(m, d, i, f6)
            fn += f6[0]
        assert d.ncon >= 1 and fn == pytest.approx(F, rel=0.10)
    # joints without a servo get no offset
    out = squeeze_offsets([np.ones((3, 3))], np.ones((1, 3)), np.array([1.0, np.inf, 0.0]))
    assert out[1] == 0.0 and out[2] == 0.0 and out[0] == pytest.approx(3.0)


def _coupledfinger_pressing_a_fixed_box():
    """A two-joint finger with one servo, on the proximal joint; the distal joint is tied to it
    by a linkage, ``j2 = 1.5 j1`` (Ability's and Inspire's fingers, SVH's mimic joints). Only
    the sphere at its tip rests on a fixed box."""
    spec = mujoco.MjSpec()
    spec.compiler.degree = False
    spec.option.timestep = 0.002
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    links = []
    parent, pos = spec.worldbody, [0, 0, 0.1]
    for name in ("j1", "j2"):
        b = parent.add_body(name=f"l{name[1]}", pos=pos, gravcomp=1)
        b.add_joint(name=name, type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 1, 0], damping=0.05,
                    armature=1e-4)  # fmt: skip
        b.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, 0.04, 0, 0],
                   size=[0.005, 0, 0], density=1000)  # fmt: skip
        links.append(b)
        parent, pos = b, [0.05, 0, 0]
    links[1].add_geom(name="tip", type=mujoco.mjtGeom.mjGEOM_SPHERE, pos=[0.04, 0, 0],
                      size=[0.008, 0, 0], density=1000)  # fmt: skip
    spec.worldbody.add_geom(name="box", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.05, 0.05, 0.02],
                            pos=[0.09, 0, 0.1 - 0.008 - 0.02])  # fmt: skip
    eq = spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1="j2", name2="j1")
    eq.data[:5] = [0.0, 1.5, 0.0, 0.0, 0.0]
    eq.solref = [0.005, 1.0]  # as the hands' linkages (retarget.hands.build)
    a = spec.add_actuator(name="j1", target="j1", trntype=mujoco.mjtTrn.mjTRN_JOINT)
    a.set_to_position(kp=5.0, dampratio=1.0)
    for g in spec.geoms:
        g.solref = [0.005, 1.0]
    return spec.compile()


def test_a_coupled_joint_carries_its_share_of_the_squeeze():
    """A servo that drives a linkage: Δq = K⁻¹(J C)ᵀf, with ``C`` the coupling's follower map
    (``CouplingLimit.follower_map``), presses with the intended force within 10 %; the servo's
    own Jacobian column alone (the linkage's joint left out) presses with less than 75 % of it."""
    from retarget.limits.coupling import CouplingLimit

    m = _coupledfinger_pressing_a_fixed_box()
    d = mujoco.MjData(m)
    kp = np.array([5.0, np.inf])
    C = CouplingLimit.from_mjmodel(m).follower_map(np.zeros(2), np.array([False, True]))
    np.testing.assert_allclose(C, [[1.0, 0.0], [1.5, 0.0]], atol=1e-12)

    def pressed(jac: np.ndarray, F: float) -> float:
        mujoco.mj_resetData(m, d)
        d.ctrl[:] = squeeze_offsets([jac], np.array([[0.0, 0.0, -F]]), kp)[:1]
        for _ in range(2000):
            mujoco.mj_step(m, d)
        assert d.ncon >= 1
        return sum(_normal(m, d, i) for i in range(d.ncon))

    mujoco.mj_forward(m, d)
    jacp = np.zeros((3, m.nv))
    bottom = d.geom_xpos[m.geom("tip").id] - [0.0, 0.0, 0.008]  # the contact point
    mujoco.mj_jac(m, d, jacp, None, bottom, m.body("l2").id)
    for F in (1.0, 3.0):
        assert pressed(jacp @ C, F) == pytest.approx(F, rel=0.10)
        assert pressed(jacp, F) < 0.75 * F


def test_soft_default_contacts_press_less_than_commanded():
    """At MuJoCo's default solref (0.02 s), the force pipeline's and the force-matching
    re-simulations' (``FORCE_CONTACT_TIMECONST``), the finger sinks into the box and the servo
    loses part of its deflection: what the force calibration corrects."""
    from dexcanvas_core.sim.scene import PhysicsSettings
    from retarget.validate import FORCE_CONTACT_TIMECONST

    assert FORCE_CONTACT_TIMECONST == PhysicsSettings().solref[0] == 0.02
    m = finger_pressing_a_fixed_box(solref=0.02)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    jacp = np.zeros((3, m.nv))
    mujoco.mj_jac(m, d, jacp, None, d.geom_xpos[m.geom("tip").id].copy(), m.body("l2").id)
    d.ctrl[:] = squeeze_offsets([jacp], np.array([[0.0, 0.0, -3.0]]), m.actuator_gainprm[:, 0])
    for _ in range(2000):
        mujoco.mj_step(m, d)
    fn = sum(_normal(m, d, i) for i in range(d.ncon))
    assert 0.6 * 3.0 < fn < 0.9 * 3.0


def _normal(m, d, i) -> float:
    f6 = np.zeros(6)
    mujoco.mj_contactForce(m, d, i, f6)
    return float(f6[0])


@pytest.fixture(scope="module")
def human_with_forces():
    """The cube2/tripod demonstration annotated by the force pipeline (open-loop tracker)."""
    from dexcanvas_core.demos import generate_demo
    from dexcanvas_core.sim.pipeline import SimConfig, simulate

    demo = generate_demo("cube2/tripod", "operator1", seed=0).trajectory
    res = simulate(demo, SimConfig(tracker="open_loop"))
    assert res.success
    return res.trajectory


def test_retargeter_matches_the_human_object_force(human_with_forces):
    from dexcanvas_core.objects.geometry import object_geometry
    from dexcanvas_core.rotations import aa_to_matrix
    from retarget.hands import get_hand
    from retarget.retargeter import Retargeter

    traj = human_with_forces.slice(300, 420)  # grasp held, object lifted
    r = Retargeter(
        get_hand("allegro"),
        object_geometry("cube2"),
        RetargetConfig(force_matching=ForceMatchingConfig(enabled=True)),
    )
    out = r.retarget(traj)
    assert out.robot_force.shape == (traj.num_frames, len(r.tip_sites), 3)
    touching = np.linalg.norm(out.human_force, axis=2).sum(1) > 0.1
    assert touching.sum() > 50
    # the commanded robot forces carry the human hand's object force (weight included)
    human = traj.contacts.finger_totals()[:, :5].sum(1)
    robot = out.robot_force.sum(1)
    err = np.linalg.norm(robot - human, axis=1)[touching]
    assert np.median(err) < 0.1 * np.median(np.linalg.norm(human, axis=1)[touching]) + 0.05
    assert np.median(out.wrench_shortfall[touching]) < 0.1
    # and become servo offsets on the contact frames only
    dq = np.abs(out.q_command - out.q)[:, 6:].max(axis=1)
    assert dq[touching].min() > 1e-4
    # A refinement whose fingers pressed exactly as planned, that lost the object at frame 90:
    # its force metrics cover the 90 frames it tracked, the profile correlation is 1 for
    # every finger, and the object force error is the plan's own over those frames.
    from types import SimpleNamespace

    from retarget.metrics import refined_force_metrics

    hand = r.hand
    fingers = list(hand.robot_fingers)
    planned = np.zeros((90, len(fingers) + 1, 3))
    for i, f in enumerate(r.tip_human):
        planned[:, fingers.index(hand.fingers[f])] = out.human_force[:90, i]
    refined = SimpleNamespace(finger_force_world=planned, fingers=fingers)
    m = refined_force_metrics(out, refined, traj, r)
    assert "wrench_feasible_fraction" not in m
    pressing = {f: v for f, v in m["force_per_finger"].items() if v["profile_correlation"]}
    assert len(pressing) >= 2  # (a finger the plan never loads has no correlation)
    for f, v in pressing.items():
        assert v["profile_correlation"] == pytest.approx(1.0), f
        assert v["relative_magnitude_error"] == pytest.approx(0.0, abs=1e-6), f
    lifted = (
        r.geometry.lowest_z(
            aa_to_matrix(traj.object.rot_aa[:90].astype(np.float64)),
            traj.object.pos[:90].astype(np.float64),
        )
        > 0.01
    )
    plan_err = np.linalg.norm(out.human_force[:90].sum(1) - human[:90], axis=1)
    sel = touching[:90] & lifted
    assert m["object_force_error_mean_n"] == pytest.approx(plan_err[sel].mean(), rel=1e-5)
    # Load shares: each finger's mean human force over the mapped fingers' sum.
    shares = {f: v["load_share"] for f, v in m["force_per_finger"].items()}
    assert sum(shares.values()) == pytest.approx(1.0)
    H90 = np.linalg.norm(out.human_force[:90], axis=2).mean(axis=0)
    for i, f in enumerate(r.tip_human):
        assert shares[f] == pytest.approx(H90[i] / H90.sum()), f
    assert m["force_profile_correlation_mean_load_bearing"] == pytest.approx(1.0)
    # A robot finger that never presses where the human's did reproduces none of its
    # profile: correlation 0 (counted in the mean), not left out. The most loaded one also
    # counts among the load-bearing fingers; the light touches do not.
    f0 = max(pressing, key=shares.get)
    silent = planned.copy()
    silent[:, fingers.index(hand.fingers[f0])] = 0.0
    m0 = refined_force_metrics(
        out, SimpleNamespace(finger_force_world=silent, fingers=fingers), traj, r
    )
    v0 = m0["force_per_finger"][f0]
    assert v0["profile_correlation"] == 0.0 and v0["correlation"] == 0.0
    assert v0["relative_magnitude_error"] == pytest.approx(1.0)
    n = len(pressing)
    assert m0["force_profile_correlation_mean"] == pytest.approx((n - 1) / n)
    from retarget.force_scores import LOAD_BEARING_SHARE

    nb = sum(1 for f in pressing if shares[f] >= LOAD_BEARING_SHARE)
    assert 1 <= nb
    assert m0["force_profile_correlation_mean_load_bearing"] == pytest.approx((nb - 1) / nb)
    assert v0["robot_force_mean_n"] == 0.0
    assert v0["human_force_mean_n"] == pytest.approx(H90[r.tip_human.index(f0)])
    # A robot finger pressing where the human's never did has no human profile to match:
    # no correlation, but the contact precision says it.
    idle = [f for f, v in m["force_per_finger"].items() if v["relative_magnitude_error"] is None]
    assert idle, m["force_per_finger"]
    extra = planned.copy()
    extra[:, fingers.index(hand.fingers[idle[0]]), 2] = np.linspace(0.0, 2.0, 90)
    m1 = refined_force_metrics(
        out, SimpleNamespace(finger_force_world=extra, fingers=fingers), traj, r
    )
    assert m1["force_per_finger"][idle[0]]["profile_correlation"] is None
    assert m1["force_profile_correlation_mean"] == pytest.approx(1.0)
    assert m1["contact_precision"] < m["contact_precision"]
    too_short = SimpleNamespace(finger_force_world=planned[:2], fingers=fingers)
    assert refined_force_metrics(out, too_short, traj, r) is None


def test_force_scale_squeezes_harder_with_the_same_object_force(human_with_forces):
    """``force_scale``: the plan asks for that multiple of the human's finger forces; the extra
    is squeeze between the fingers, so the object's net force stays the required one, and the
    metrics' human side stays the human's own forces."""
    from dexcanvas_core.objects.geometry import object_geometry
    from retarget.errors import RetargetError
    from retarget.hands import get_hand
    from retarget.retargeter import Retargeter

    traj = human_with_forces.slice(300, 420)  # grasp held, object lifted
    outs = {}
    for k in (1.0, 1.5):
        r = Retargeter(
            get_hand("allegro"),
            object_geometry("cube2"),
            RetargetConfig(force_matching=ForceMatchingConfig(enabled=True, scale=k)),
        )
        outs[k] = r.retarget(traj)
    np.testing.assert_array_equal(outs[1.0].human_force, outs[1.5].human_force)
    touching = np.linalg.norm(outs[1.0].human_force, axis=2).sum(1) > 0.1
    pressed = {k: np.linalg.norm(o.robot_force, axis=2).sum(1)[touching] for k, o in outs.items()}
    human = np.linalg.norm(outs[1.0].human_force, axis=2).sum(1)[touching]
    assert np.median(pressed[1.0] / human) == pytest.approx(1.0, abs=0.15)
    assert np.median(pressed[1.5] / human) == pytest.approx(1.5, abs=0.2)
    net = {k: o.robot_force.sum(1)[touching] for k, o in outs.items()}
    diff = np.linalg.norm(net[1.5] - net[1.0], axis=1)
    assert np.median(diff) < 0.1 * np.median(np.linalg.norm(net[1.0], axis=1)) + 0.05
    # and the commands press deeper
    depth = {k: np.abs(o.q_command - o.q)[touching, 6:].sum(1) for k, o in outs.items()}
    assert np.median(depth[1.5]) > 1.2 * np.median(depth[1.0])
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(RetargetError, match=r"ForceMatchingConfig\.scale"):
            RetargetConfig(force_matching=ForceMatchingConfig(enabled=True, scale=bad))


def test_force_scale_without_forces_says_what_to_do(tmp_path, capsys):
    from retarget.cli import main

    out = tmp_path / "never"
    rc = main(["run", "--hand", "allegro", "--pair", "cube2/tripod", "--force-scale", "1.5",
               "--quiet", "--out", str(out)])  # fmt: skip
    assert rc == 2 and not out.exists()
    assert "add --forces" in capsys.readouterr().err


def test_contact_flags_come_from_the_captured_geometry_unless_asked(human_with_forces):
    """By default a force-annotated demonstration gets the same contact targets as the bare
    capture (the records only supply forces); ``contacts_from="records"`` takes the flags from
    the force pipeline's records, where the simulated hand touched."""
    import dataclasses

    from dexcanvas_core.objects.geometry import object_geometry
    from retarget.hands import get_hand
    from retarget.retargeter import Retargeter

    traj = human_with_forces.slice(250, 420)
    bare = dataclasses.replace(traj, contacts=None)
    hand, geom = get_hand("allegro"), object_geometry("cube2")
    rt = Retargeter(hand, geom, RetargetConfig())
    a, b = rt.human_targets(traj), rt.human_targets(bare)
    assert a["contact_active"].sum() > 100
    for k in ("contact_active", "contact_part", "contact_points"):
        np.testing.assert_array_equal(a[k], b[k])
    rec = Retargeter(hand, geom, RetargetConfig(contacts=ContactsConfig(source="records")))
    c = rec.human_targets(traj)
    parts = rec._parts_from_records(traj)  # (T, F, 3)
    assert c["contact_active"].sum() > 100
    assert not (c["contact_active"] & ~parts.any(-1)).any()  # only where a record says so
    assert c["contact_active"][parts[..., 0]].all()  # every recorded fingertip contact
    assert (c["contact_active"] != a["contact_active"]).any()  # the two sources differ here
    allowed = r"ContactsConfig\.source: unknown value 'sim'; allowed: geometry, records"
    with pytest.raises(RetargetError, match=allowed):
        RetargetConfig(contacts=ContactsConfig(source="sim"))


def test_force_matching_without_forces_says_what_to_do():
    from dexcanvas_core.demos import generate_demo
    from dexcanvas_core.objects.geometry import object_geometry
    from retarget.hands import get_hand
    from retarget.retargeter import Retargeter

    demo = generate_demo("cube2/tripod", "operator1", seed=0).trajectory.slice(0, 20)
    r = Retargeter(
        get_hand("allegro"),
        object_geometry("cube2"),
        RetargetConfig(force_matching=ForceMatchingConfig(enabled=True)),
    )
    with pytest.raises(RetargetError, match="dexcanvas simulate"):
        r.retarget(demo)


def test_cli_run_forces_reports_force_preservation(human_with_forces, tmp_path):

    from dexcanvas_core.io import write_dataset
    from retarget.cli import main

    src = tmp_path / "h.lance"
    write_dataset([human_with_forces], src)
    out = tmp_path / "run"
    rc = main(["run", "--hand", "allegro", "--pair", "cube2/tripod", "--dataset", str(src),
               "--forces", "--quiet", "--out", str(out)])  # fmt: skip
    m = json.loads((out / "metrics.json").read_text())
    assert rc == (0 if m["success"] or m.get("success_refined") else 3)  # 3: failed validation
    m = json.loads((out / "metrics.json").read_text())
    assert m["forces"] and m["human_force_pipeline"] is None  # forces came with the dataset
    for key in ("force_correlation_mean", "force_profile_correlation_mean",
                "force_profile_correlation_mean_load_bearing",
                "object_force_error_mean_n", "contact_precision",
                "contact_recall", "wrench_feasible_fraction"):  # fmt: skip
        assert m[key] is not None and np.isfinite(m[key])
    assert set(m["force_per_finger"]) == {"thumb", "index", "middle", "ring"}
    assert 0.0 <= m["contact_recall"] <= 1.0
    # Force calibration (10 re-simulations by default): the written commands are the chosen
    # iterate's, the planned ones kept beside them; the result reported is the chosen one's.
    cal = m["calibration"]
    assert len(cal["iterates"]) == 11 and 0 <= cal["chosen_iterate"] <= 10
    chosen = cal["iterates"][cal["chosen_iterate"]]
    assert chosen["success"] == m["success"]
    assert chosen["object_pos_err_max_m"] == pytest.approx(m["object_pos_err_max_m"])
    if cal["iterates"][0]["success"]:  # calibration never loses a kept object
        assert m["success"]
        assert cal["match_error_after"] <= cal["match_error_before"]
        assert chosen["profile_correlation"] == pytest.approx(m["force_profile_correlation_mean"])
    with np.load(out / "robot_trajectory.npz") as z:
        dq = z["q_command"] - z["q_command_planned"]
    assert np.all(dq[:, :6] == 0.0)  # the wrist is not calibrated
    assert (np.abs(dq).max() > 0) == (cal["chosen_iterate"] > 0)
    # The report's force plot adds the plan: the force QP's force per mapped finger.
    from dexcanvas_core.trajectory import FORCE_GROUPS
    from retarget.hands import get_hand
    from retarget.viz import plots
    from retarget.viz.data import load_run
    from retarget.viz.report import force_notes

    run = load_run(out)
    f = plots.finger_forces(run.arrays, get_hand("allegro"), None)
    P = np.linalg.norm(run.arrays["robot_force"], axis=-1)
    for i, name in enumerate(("thumb", "index", "middle", "ring")):
        np.testing.assert_allclose(f["plan"][:, FORCE_GROUPS.index(name)], P[:, i])
    assert np.isnan(f["plan"][:, FORCE_GROUPS.index("pinky")]).all()
    assert np.isnan(f["plan"][:, FORCE_GROUPS.index("palm")]).all()
    # without the demonstration's records, the human side is the forces the run matched
    Hm = np.linalg.norm(run.arrays["human_force"], axis=-1)
    for i, name in enumerate(("thumb", "index", "middle", "ring")):
        np.testing.assert_allclose(f["human"][:, FORCE_GROUPS.index(name)], Hm[:, i])
    assert np.isnan(f["human"][:, FORCE_GROUPS.index("palm")]).all()
    notes = force_notes(m)
    assert notes and set(notes) <= set(m["force_per_finger"])
    for name, text in notes.items():
        v = m["force_per_finger"][name]
        assert f"{v['profile_correlation']:.2f}" in text
        reach = v["contact_reach_m"]  # every scored finger has a reach (or None)
        assert (f"plan {1000 * reach:.0f} mm" if reach is not None else "no contact") in text
    # the run's reached-finger summary counts the fingers within REACH_M
    from retarget.force_scores import REACH_M
    from retarget.viz.report import metrics_rows

    scored = [v for v in m["force_per_finger"].values() if v["profile_correlation"] is not None]
    within = [v for v in scored if (v["contact_reach_m"] or np.inf) <= REACH_M]
    assert (m["fingers_reached"], m["fingers_scored"]) == (len(within), len(scored))
    assert any(k.startswith("force matching: fingers whose plan") for k, _ in metrics_rows(m))
    # the band-limited correlation: every scored finger has one, and the run their mean
    smooth = [v["profile_correlation_smoothed"] for v in scored]
    assert all(-1.0 <= c <= 1.0 for c in smooth)
    assert m["force_profile_correlation_mean_smoothed"] == pytest.approx(np.mean(smooth))
    row = dict(metrics_rows(m))
    key = next(k for k in row if k.startswith("force matching: correlation with the human"))
    assert "over 50 ms" in key
    assert row[key].endswith(f"{m['force_profile_correlation_mean_smoothed']:.2f}")
    assert main(["report", str(out), "--no-snapshots", "--renderer", "mujoco"]) == 0
    assert "the force matching&#x27;s plan" in (out / "report.html").read_text()


def test_refinement_rescues_a_failing_replay_and_reports_its_cost():
    """Allegro on the built-in cuboid3/palmar_pinch (the 5 × 5 × 2.5 cm, 22 g cuboid),
    retargeted with the fixed-depth grip, each frame started from the last solution and
    isotropic contact targets (``grip="depth"``, ``warm_start_extrapolate=False``,
    ``contact_tangent_weight=1``, the earlier wrist and posture weights 0.3 and 1e-3, contact
    offsets along the human's normals only and no closing terms: the defaults hold this one
    open loop): replayed open loop (default soft contacts) the cuboid
    slips out (at frame 304); the sampling MPC on the robot hand keeps it (DexCanvas rule, no
    frame over 5 cm), moving the commanded wrist by under a millimetre (0.7 mm)."""
    from dexcanvas_core.loaders.selection import load_demonstration
    from dexcanvas_core.objects.geometry import object_geometry
    from dexcanvas_core.rotations import aa_to_matrix
    from retarget.hands import get_hand
    from retarget.refine import RefineConfig, refine
    from retarget.retargeter import Retargeter

    demo = load_demonstration("cuboid3/palmar_pinch")  # the built-in one
    hand, geo = get_hand("allegro"), object_geometry("cuboid3")
    rt = Retargeter(
        hand,
        geo,
        RetargetConfig(
            grip=GripConfig(mode="depth"),
            solver=SolverConfig(warm_start_extrapolate=False),
            contacts=ContactsConfig(tangent_weight=1.0, hover_m=None),
            wrist=WristConfig(position_weight=0.3, rotation_weight=0.3),
            posture=PostureConfig(weight=1e-3),
            closing=ClosingConfig(weight=0.0),
        ),
    )
    robot = rt.retarget(demo)
    # the default re-simulation's contacts (the stiff ones of force matching alone keep it)
    soft = {"contact_timeconst": None}
    replay = refine(hand, geo, demo, robot, rt.tip_sites, RefineConfig(tracker="open_loop", **soft))
    assert replay.finger_ctrl_deviation_rad == 0.0 and replay.wrist_pos_deviation_m == 0.0
    refined = refine(hand, geo, demo, robot, rt.tip_sites, RefineConfig(**soft))
    assert not replay.success and replay.failed_at_frame is not None  # the cuboid slips out
    assert refined.success and refined.object_pos_err.max() < 0.05
    assert 0 < refined.wrist_pos_deviation_m < 0.03
    assert refined.ctrl.shape == (demo.num_frames, hand.compile().nu)
    m = refined.metrics()
    assert m["frames_tracked"] == demo.num_frames and m["compute_s"] > 0
    # The refined simulation's finger forces carry the lifted cuboid's weight (the mean over
    # the frames the human holds it 4 cm or more above the table, where the refined one, within
    # 5 cm of it, cannot touch the table; its mean acceleration there is small): 0.207 N
    # measured against m·g = 0.216 N, and no net horizontal force.
    assert refined.fingers == ["th", "ff", "mf", "rf"]
    assert refined.finger_force_world.shape == (demo.num_frames, 5, 3)
    R_o = aa_to_matrix(demo.object.rot_aa.astype(np.float64))
    lifted = geo.lowest_z(R_o, demo.object.pos.astype(np.float64)) > 0.04
    assert lifted.sum() > 100
    net = refined.finger_force_world[lifted].sum(axis=1).mean(axis=0)
    weight = geo.mass_kg * 9.81
    assert abs(net[2] - weight) < 0.1 * weight and np.linalg.norm(net[:2]) < 0.05 * weight
    assert m["finger_force_mean_n"]["th"] > 1.0  # the thumb opposes the fingers
    with pytest.raises(RetargetError, match="unknown refinement tracker"):
        refine(hand, geo, demo, robot, rt.tip_sites, RefineConfig(tracker="ppo"))


def test_refinement_backtracking_resumes_exactly_from_its_checkpoints():
    """A checkpoint restored and replayed with the same residuals reproduces the physics (the
    backtracking resumes from the state it saved, not an approximation of it); a refinement
    that keeps losing the object uses every retry and reports them; bad settings are refused."""
    from dataclasses import replace

    from dexcanvas_core.loaders.selection import load_demonstration
    from dexcanvas_core.objects.geometry import object_geometry
    from dexcanvas_core.sim.mpc import SamplingMPC
    from retarget.hands import get_hand
    from retarget.refine import RefineConfig, _checkpoint, _restore, refine
    from retarget.refine_scene import tracking_env
    from retarget.retargeter import Retargeter

    demo = load_demonstration("cube2/tripod").slice(250, 310)
    hand, geo = get_hand("allegro"), object_geometry("cube2")
    rt = Retargeter(hand, geo)
    robot = rt.retarget(demo)
    cfg = RefineConfig()
    env, _, _ = tracking_env(hand, geo, demo, robot, rt.tip_sites, cfg)
    mpc = SamplingMPC(cfg.mpc)
    env.reset()
    mpc.reset(env)
    rng = np.random.default_rng(0)
    actions = rng.normal(0.0, 0.05, (40, env.action_dim))
    for a in actions[:10]:
        env.step(a)
    cp = _checkpoint(env, mpc)
    for a in actions[10:]:
        env.step(a)
    first = np.array(env.log.object_pos), np.array(env.log.hand_qpos)
    _restore(env, mpc, cp)
    assert env.t == 10 and len(env.log.pos_err) == 11 and env.failed_at is None
    for a in actions[10:]:
        env.step(a)
    np.testing.assert_array_equal(np.array(env.log.object_pos), first[0])
    np.testing.assert_array_equal(np.array(env.log.hand_qpos), first[1])

    # an object error bound nothing meets: every attempt fails, each resumes further back
    strict = replace(cfg, tracking=replace(cfg.tracking, fail_pos_m=1e-9), retries=2)
    res = refine(hand, geo, demo, robot, rt.tip_sites, strict)
    assert not res.success and res.attempts == 3 and res.metrics()["attempts"] == 3
    assert res.object_pos_err.shape[0] == res.ctrl.shape[0] == res.failed_at_frame + 1
    once = refine(hand, geo, demo, robot, rt.tip_sites, replace(strict, retries=0))
    assert once.attempts == 1 and once.compute_s < res.compute_s
    for bad in ({"retries": -1}, {"backtrack_s": 0.0}, {"retry_samples": 0.5}):
        with pytest.raises(RetargetError, match="backtracking"):
            refine(hand, geo, demo, robot, rt.tip_sites, replace(cfg, **bad))


def test_refinement_runs_on_a_gripper_whose_fingers_are_shared():
    """The panda gripper drives index and middle with one finger: one tip site, listed twice."""
    from dexcanvas_core.loaders.selection import load_demonstration
    from dexcanvas_core.objects.geometry import object_geometry
    from retarget.hands import get_hand
    from retarget.refine import RefineConfig, refine
    from retarget.retargeter import Retargeter

    demo = load_demonstration("cube2/tripod").slice(250, 300)
    hand, geo = get_hand("panda"), object_geometry("cube2")
    rt = Retargeter(hand, geo)
    assert len(set(rt.tip_sites)) < len(rt.tip_sites)
    res = refine(
        hand, geo, demo, rt.retarget(demo), rt.tip_sites, RefineConfig(tracker="open_loop")
    )
    assert res.object_pos_err.shape[0] >= 1


def test_viz_replays_a_force_matching_run_exactly(human_with_forces, tmp_path):
    """Stills and reports replay the run's re-simulation: with --forces, its stiff contacts."""

    from dexcanvas_core.io import write_dataset
    from dexcanvas_core.objects.geometry import object_geometry
    from retarget.cli import main
    from retarget.hands import get_hand
    from retarget.viz.resim import record_resimulation

    traj = human_with_forces.slice(250, 400)
    src = tmp_path / "h.lance"
    write_dataset([traj], src)
    out = tmp_path / "run"
    assert main(["run", "--hand", "allegro", "--pair", "cube2/tripod", "--dataset", str(src),
                 "--forces", "--quiet", "--out", str(out)]) == 0  # fmt: skip
    metrics = json.loads((out / "metrics.json").read_text())
    with np.load(out / "robot_trajectory.npz") as z:
        q_command, obj = z["q_command"], z["object_pos_sim"]
    rec = record_resimulation(
        get_hand("allegro"), object_geometry("cube2"), q_command, traj, metrics=metrics
    )
    np.testing.assert_allclose(rec.result.object_pos_sim, obj, atol=1e-9)


def test_cli_forces_lifts_the_heavy_cube_with_allegro(tmp_path):
    """The issue's acceptance command: the heavy cube (cube2H, 3.3× cube2) on the built-in
    tripod demonstration, human forces from the force pipeline, matched on Allegro; the force
    squeeze first closes the gap the kinematic solution leaves (without that the fingers press
    0.2 N in the air and the cube drops)."""

    from retarget.cli import main

    out = tmp_path / "run"
    rc = main(["run", "--hand", "allegro", "--pair", "cube2H/tripod", "--forces", "--quiet",
               "--out", str(out)])  # fmt: skip
    assert rc == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["success"] and m["object_pos_err_max_m"] < 0.05
    weight = 9.81 * OBJECTS["cube2H"].mass_kg  # the paper's 123 g
    pressed = m["finger_force_mean_n"]["th"]
    assert pressed > 0.5 * weight, m["finger_force_mean_n"]  # the thumb opposes the fingers
    assert m["object_force_error_mean_n"] < 0.15 * weight


def test_refinement_finger_action_closes_the_finger_on_the_object():
    """``RefineConfig.finger_close_m``: on the frames where its human finger touches, each
    finger's action column also moves the fingertip that far towards the object's centre
    (first order: MuJoCo's kinematics at the commanded step), on top of the force offset; on
    the other frames, and for the wrist, the columns are unchanged."""
    import mujoco

    from dexcanvas_core.loaders.selection import load_demonstration
    from dexcanvas_core.objects.geometry import object_geometry
    from retarget.hands import get_hand
    from retarget.refine import RefineConfig
    from retarget.refine_scene import tracking_env
    from retarget.retargeter import Retargeter

    demo = load_demonstration("cube2/tripod").slice(250, 330)
    hand, geo = get_hand("allegro"), object_geometry("cube2")
    rt = Retargeter(hand, geo)
    robot = rt.retarget(demo)
    env0, act_q, _ = tracking_env(
        hand, geo, demo, robot, rt.tip_sites, RefineConfig(finger_close_m=0.0)
    )
    env1, _, _ = tracking_env(
        hand, geo, demo, robot, rt.tip_sites, RefineConfig(finger_close_m=0.005)
    )
    dM = env1.M - env0.M  # (T, nu, 6 + F)
    assert not dM[:, :, :6].any()
    m = env1.scene.model
    d = mujoco.MjData(m)

    def tip(q, site):
        d.qpos[: q.size] = q
        mujoco.mj_kinematics(m, d)
        return d.site_xpos[site].copy()

    checked = 0
    for i, name in enumerate(rt.tip_sites):
        on = robot.contact_active[:, i]
        assert not dM[~on, :, 6 + i].any()
        if not on.any():
            continue
        site = m.site(name).id
        for t in np.flatnonzero(on)[:: max(1, on.sum() // 4)]:
            q = robot.q[t]
            step = np.zeros_like(q)
            step[act_q] = dM[t, :, 6 + i]
            p0 = tip(q, site)
            moved = tip(q + step, site) - p0
            towards = demo.object.pos[t] - p0
            towards /= np.linalg.norm(towards)
            assert 0.6 * 0.005 < np.linalg.norm(moved) < 1.05 * 0.005
            assert moved @ towards > 0.9 * np.linalg.norm(moved)
            checked += 1
    assert checked >= 8


def test_refinement_finger_action_scales_the_force_offset_by_the_offset_gain():
    """``RefineConfig.offset_gain``: each finger's action column (without the closing step) is
    that finger's servo offsets ``q_command − q`` times the gain, on its own actuators only;
    the wrist's columns do not change with it."""
    from dexcanvas_core.loaders.selection import load_demonstration
    from dexcanvas_core.objects.geometry import object_geometry
    from retarget.hands import get_hand
    from retarget.refine import RefineConfig
    from retarget.refine_scene import tracking_env
    from retarget.retargeter import Retargeter

    demo = load_demonstration("cube2/tripod").slice(250, 300)
    hand, geo = get_hand("allegro"), object_geometry("cube2")
    rt = Retargeter(hand, geo)
    robot = rt.retarget(demo)
    envs = {
        g: tracking_env(
            hand, geo, demo, robot, rt.tip_sites, RefineConfig(finger_close_m=0.0, offset_gain=g)
        )
        for g in (1.0, 2.5)
    }
    (env1, act_q, _), (env2, _, _) = envs[1.0], envs[2.5]
    np.testing.assert_array_equal(env1.M[:, :, :6], env2.M[:, :, :6])
    offsets = (robot.q_command - robot.q)[:, act_q]
    fingers = env1.M[:, :, 6:]
    assert np.abs(offsets[:, act_q >= 6]).max() > 1e-3  # the squeeze presses somewhere
    # each finger actuator belongs to one finger's column, which carries its offset
    np.testing.assert_allclose(fingers.sum(axis=2)[:, act_q >= 6], offsets[:, act_q >= 6])
    assert ((fingers != 0).sum(axis=2) <= 1).all()
    np.testing.assert_allclose(env2.M[:, :, 6:], 2.5 * fingers)


def test_refinement_closing_step_moves_coupled_joints_with_their_servo():
    """On a hand whose distal joints follow their servo through a linkage (Ability), the
    closing step is the damped least-squares step on the fingertip's Jacobian through the
    servo *and* the joints it drives: checked against that Jacobian by central differences of
    MuJoCo's kinematics with the couplings applied (``robot_poses.coupled``). The servo's own
    column alone gives a step ~1.5× too long on these fingers."""
    import mujoco
    from robot_poses import coupled

    from dexcanvas_core.loaders.selection import load_demonstration
    from dexcanvas_core.objects.geometry import object_geometry
    from retarget.hands import get_hand
    from retarget.refine import RefineConfig
    from retarget.refine_scene import tracking_env
    from retarget.retargeter import Retargeter

    demo = load_demonstration("cube2/tripod").slice(250, 300)
    hand, geo = get_hand("ability"), object_geometry("cube2")
    rt = Retargeter(hand, geo)
    robot = rt.retarget(demo)
    close = 0.005
    env0, act_q, _ = tracking_env(
        hand, geo, demo, robot, rt.tip_sites, RefineConfig(finger_close_m=0.0)
    )
    env1, _, _ = tracking_env(
        hand, geo, demo, robot, rt.tip_sites, RefineConfig(finger_close_m=close)
    )
    dM = env1.M - env0.M
    m = env1.scene.model
    d = mujoco.MjData(m)
    nq = robot.q.shape[1]

    def tip(q, site):
        d.qpos[:nq] = coupled(m, q)[:nq]
        mujoco.mj_kinematics(m, d)
        return d.site_xpos[site].copy()

    checked = 0
    for i, name in enumerate(rt.tip_sites):
        on = np.flatnonzero(robot.contact_active[:, i])
        if not on.size:
            continue
        site = m.site(name).id
        t = int(on[on.size // 2])
        q = coupled(m, np.r_[robot.q[t], np.zeros(m.nq - nq)])[:nq]
        cols = np.flatnonzero(dM[t, :, 6 + i])  # this finger's servos
        assert cols.size and (act_q[cols] >= 6).all()
        J = np.zeros((3, cols.size))
        for k, a in enumerate(cols):
            e = np.zeros(nq)
            e[act_q[a]] = 1e-6
            J[:, k] = (tip(q + e, site) - tip(q - e, site)) / 2e-6
        u = demo.object.pos[t] - tip(q, site)
        u *= close / np.linalg.norm(u)
        want = J.T @ np.linalg.solve(J @ J.T + 1e-4 * np.eye(3), u)
        np.testing.assert_allclose(dM[t, cols, 6 + i], want, rtol=0.05, atol=1e-5)
        checked += 1
    assert checked >= 2


def test_finger_force_profiles_score_a_reproduction_numerically():
    """Per finger: a reproduction at twice the force correlates perfectly and is off by 100 %;
    one that never presses scores 0; a finger the reference never loads is not scored."""
    from retarget.force_scores import correlation_means, finger_force_profiles

    h = np.array([0.0, 0.0, 1.0, 2.0, 3.0, 2.0, 1.0, 0.0, 0.0, 0.0])
    H = np.stack([h, h, 0.01 * h, 0.5 * h], axis=1)  # the third is a graze: ≤ 0.03 N
    R = np.stack([2.0 * h, np.zeros_like(h), 0.01 * h, h[::-1]], axis=1)
    per = finger_force_profiles(H, R, ("thumb", "index", "middle", "ring"))
    assert per["thumb"]["correlation"] == pytest.approx(1.0)
    assert per["thumb"]["profile_correlation"] == pytest.approx(1.0)
    assert per["thumb"]["relative_magnitude_error"] == pytest.approx(1.0)
    assert per["index"]["correlation"] == 0.0 and per["index"]["relative_magnitude_error"] == 1.0
    assert per["middle"]["correlation"] is None and per["middle"]["profile_correlation"] is None
    # the mirrored profile: over every frame, np.corrcoef's value
    assert per["ring"]["profile_correlation"] == pytest.approx(np.corrcoef(h, h[::-1])[0, 1])
    shares = [per[f]["load_share"] for f in per]
    assert sum(shares) == pytest.approx(1.0) and shares[0] == pytest.approx(1 / 2.51)
    m = correlation_means(per)
    assert m["force_profile_correlation_mean"] == pytest.approx(
        np.mean([1.0, 0.0, per["ring"]["profile_correlation"]])
    )
    # load-bearing (≥ 10 % of the force): thumb, index and ring; the graze is not scored
    assert m["force_correlation_mean_load_bearing"] == pytest.approx(
        np.mean([1.0, 0.0, per["ring"]["correlation"]])
    )
    with pytest.raises(RetargetError, match="must both be"):
        finger_force_profiles(H, R[:, :3], ("thumb", "index", "middle", "ring"))


def test_finger_reach_is_the_median_plan_distance_over_the_loaded_frames():
    """``contact_reach_m``: the plan's finger-to-contact distance, median over the frames the
    human finger loads (NaN frames skipped, none: ``None``); the ``_reached`` mean scores only
    fingers within ``REACH_M``; a reach of the wrong shape is refused."""
    from retarget.force_scores import REACH_M, correlation_means, finger_force_profiles

    h = np.array([0.0, 0.0, 1.0, 2.0, 3.0, 2.0, 1.0, 0.0, 0.0, 0.0])
    H = np.stack([h, h, h], axis=1)
    R = np.stack([h, 0.5 * h[::-1], np.zeros_like(h)], axis=1)
    reach = np.full((10, 3), np.nan)
    reach[:, 0] = 0.001  # thumb: on its contact throughout
    reach[2:7, 1] = [0.004, 0.02, 0.03, 0.05, np.nan]  # index: median of four loaded frames
    reach[0, 1] = 0.0  # (a frame the human does not load: not counted)
    fingers = ("thumb", "index", "ring")  # ring: no contact target where the human loads
    per = finger_force_profiles(H, R, fingers, reach)
    assert per["thumb"]["contact_reach_m"] == pytest.approx(0.001)
    assert per["index"]["contact_reach_m"] == pytest.approx(0.025)
    assert per["ring"]["contact_reach_m"] is None
    m = correlation_means(per)
    assert (m["fingers_reached"], m["fingers_scored"]) == (1, 3)
    assert m["force_profile_correlation_mean_reached"] == pytest.approx(1.0)
    assert m["force_profile_correlation_mean"] == pytest.approx(
        np.mean([1.0, np.corrcoef(h, h[::-1])[0, 1], 0.0])
    )
    assert 0.001 <= REACH_M < 0.025
    assert "fingers_reached" not in correlation_means(finger_force_profiles(H, R, fingers))
    with pytest.raises(RetargetError, match="reach"):
        finger_force_profiles(H, R, fingers, reach[:, :2])


def test_band_limited_correlation_sees_the_profile_through_contact_chatter():
    """``profile_correlation_smoothed``: a reproduction of the human's slow profile plus a
    contact bouncing at half the frame rate correlates poorly frame by frame, and near
    perfectly once both are averaged over the demonstration's bandwidth (``band_frames``
    even, so the alternation cancels); a reproduction of the wrong shape stays wrong; the
    window is the force pipeline's 50 ms capture smoothing, and a bad one is refused."""
    from dexcanvas_core.sim.signal import moving_average
    from retarget.force_scores import correlation_means, finger_force_profiles, profile_band_frames

    T = 240
    h = 2.0 * np.clip(np.sin(np.linspace(0.0, 2 * np.pi, T)), 0.0, None)  # one press, 0–2 N
    chatter = np.where(np.arange(T) % 2, 1.5, -1.5) * (h > 0.3)
    H = np.stack([h, h], axis=1)
    R = np.stack([np.clip(h + chatter, 0.0, None), h[::-1]], axis=1)
    n = profile_band_frames(120.0)
    assert n == 6 and profile_band_frames(30.0) == 2  # 50 ms
    per = finger_force_profiles(H, R, ("thumb", "index"), band_frames=n)
    raw, smooth = per["thumb"]["profile_correlation"], per["thumb"]["profile_correlation_smoothed"]
    assert raw < 0.8 and smooth > 0.98
    want = np.corrcoef(moving_average(h[:, None], n)[:, 0], moving_average(R[:, :1], n)[:, 0])
    assert smooth == pytest.approx(want[0, 1])
    assert per["index"]["profile_correlation_smoothed"] < 0.0  # the mirrored press
    m = correlation_means(per)
    assert m["force_profile_correlation_mean_smoothed"] == pytest.approx(
        np.mean([smooth, per["index"]["profile_correlation_smoothed"]])
    )
    assert "force_profile_correlation_mean_smoothed" not in correlation_means(
        finger_force_profiles(H, R, ("thumb", "index"))
    )
    assert finger_force_profiles(H, R, ("thumb", "index"), band_frames=np.int64(n)) == per
    with pytest.raises(RetargetError, match="band_frames"):
        finger_force_profiles(H, R, ("thumb", "index"), band_frames=0)
    with pytest.raises(RetargetError, match="band_frames"):
        finger_force_profiles(H, R, ("thumb", "index"), band_frames=2.5)
    with pytest.raises(RetargetError, match="fps"):
        profile_band_frames(0.0)


def test_human_replay_is_scored_like_a_robot_against_the_first_simulation(human_with_forces):
    """The same simulation reproduces itself exactly; one lagging by 5 frames (compared over
    the common frames) does not; missing forces and unknown fingers are refused."""
    from retarget.metrics import human_replay_metrics

    h = human_with_forces
    same = human_replay_metrics(h, h)
    scored = {f: v for f, v in same["force_per_finger"].items() if v["correlation"] is not None}
    assert len(scored) >= 2  # a tripod: thumb, index, middle
    for v in scored.values():
        assert v["correlation"] == pytest.approx(1.0)
        assert v["relative_magnitude_error"] == pytest.approx(0.0)
    assert same["force_profile_correlation_mean"] == pytest.approx(1.0)
    lag = human_replay_metrics(h, h.slice(5, h.num_frames))
    assert lag["frames"] == h.num_frames - 5
    assert lag["force_profile_correlation_mean"] < 0.999
    assert human_replay_metrics(h, h, fingers=("thumb",))["force_per_finger"].keys() == {"thumb"}
    with pytest.raises(RetargetError, match="unknown finger"):
        human_replay_metrics(h, h, fingers=("palm",))
    bare = h.slice(0, h.num_frames)
    bare.contacts = None
    with pytest.raises(RetargetError, match="second trajectory has no contact forces"):
        human_replay_metrics(h, bare)
    with pytest.raises(RetargetError, match="common frames"):
        human_replay_metrics(h, h.slice(0, 2))


def test_cli_human_replay_scores_the_human_forces_against_themselves(
    human_with_forces, tmp_path, capsys
):
    """``retarget run --forces --human-replay``: the force pipeline runs again at another MPC
    seed, and metrics.json holds that replay scored against the matched forces on the hand's
    fingers, beside the robot's; without --forces the option is refused before any work."""

    from dexcanvas_core.io import write_dataset
    from retarget.cli import main
    from retarget.human_forces import HUMAN_REPLAY_SEED

    src = tmp_path / "h.lance"
    write_dataset([human_with_forces.slice(250, 370)], src)
    out = tmp_path / "run"
    rc = main(["run", "--hand", "allegro", "--pair", "cube2/tripod", "--dataset", str(src),
               "--forces", "--human-replay", "--out", str(out)])  # fmt: skip
    assert rc == 0
    m = json.loads((out / "metrics.json").read_text())
    hr = m["human_replay"]
    assert hr["mpc_seed"] == HUMAN_REPLAY_SEED and hr["success"]
    assert set(hr["force_per_finger"]) == set(m["force_per_finger"])  # the hand's fingers
    assert hr["frames"] == 120
    for key in ("force_profile_correlation_mean", "force_correlation_mean"):
        assert -1.0 <= hr[key] <= 1.0 and -1.0 <= m[key] <= 1.0
    # another sample of the same stochastic tracker: close to the first, not equal to it
    assert 0.3 < hr["force_profile_correlation_mean"] < 0.9999
    assert "human replay (MPC seed 1)" in capsys.readouterr().out
    # the report shows both, per finger and for the run
    from retarget.viz.report import force_notes, metrics_rows

    notes = force_notes(m)
    for f, text in notes.items():
        r = hr["force_per_finger"][f]["profile_correlation"]
        assert f"(human replay {r:.2f})" in text
    rows = dict(metrics_rows(m))
    label = "human replay (MPC seed 1): the human against itself"
    assert rows[label] == (
        f"{hr['force_profile_correlation_mean']:.2f} / {hr['force_correlation_mean']:.2f} / "
        f"{hr['force_profile_correlation_mean_smoothed']:.2f}"
    )
    assert main(["report", str(out), "--no-snapshots", "--renderer", "mujoco"]) == 0
    assert label in (out / "report.html").read_text()
    failed = {**m, "human_replay": {"mpc_seed": 1, "success": False, "failed_at_frame": 88}}
    assert dict(metrics_rows(failed))[label] == "lost the object at frame 88"
    never = tmp_path / "never"
    rc = main(["run", "--hand", "allegro", "--pair", "cube2/tripod", "--human-replay",
               "--quiet", "--out", str(never)])  # fmt: skip
    assert rc == 2 and not never.exists()
    assert "add --forces" in capsys.readouterr().err


def test_force_benchmark_scores_every_variant_against_the_human_without_d(human_with_forces):
    """``python -m benchmarks.force_preservation --variants c``: (c)'s force columns come from the
    human's forces mapped onto the hand (``Retargeter.human_finger_forces``), the same numbers
    as when (d) runs beside it; (d)'s own mapping is that one too."""
    from dexcanvas_core.objects.geometry import object_geometry
    from retarget.hands import get_hand
    from retarget.retargeter import Retargeter

    h = human_with_forces.slice(250, 400)
    base = {"hand": "shadow", "index": 0, "pair": "cube2/tripod", "object_id": "cube2"}
    base.update(object_variant="light", frames=h.num_frames, human_forces=True)
    alone = {r["variant"]: r for r in _hand_job((base, h, h, "free", ("c",), {}, {}, 2))}
    both = {r["variant"]: r for r in _hand_job((base, h, h, "free", ("c", "d"), {}, {}, 2))}
    for k in ("force_profile_correlation_mean", "force_correlation_mean", "contact_recall"):
        assert alone["c"][k] is not None
        assert alone["c"][k] == pytest.approx(both["c"][k])
    assert alone["c"]["force_per_finger"] == both["c"]["force_per_finger"]
    assert alone["c"]["wrench_feasible_fraction"] is None  # the force QP's: (d) only
    assert both["d"]["wrench_feasible_fraction"] is not None
    # (d) is force-calibrated (2 iterations here): the row is the chosen iterate's, the plan's
    # own result beside it; a kept lift stays kept
    assert both["d"]["calibration_iterate"] in (0, 1, 2)
    assert both["d"]["success"] or not both["d"]["planned_success"]
    rt = Retargeter(get_hand("shadow"), object_geometry("cube2"))
    F = rt.human_finger_forces(h)
    assert F.shape == (h.num_frames, len(rt.tip_sites), 3)
    assert np.linalg.norm(F, axis=2).max() > 0.5  # a tripod presses
    bare = h.slice(0, h.num_frames)
    bare.contacts = None
    with pytest.raises(RetargetError, match="force pipeline first"):
        rt.human_finger_forces(bare)


def test_force_matching_backs_unloaded_touching_fingers_off_the_surface(human_with_forces):
    """A finger the captured hand touches the object with while the human's simulated finger
    presses nothing is commanded ``idle_contact_clearance`` off the surface (its servo presses
    nowhere the human did not); frames without such a finger are commanded as without it."""
    from dexcanvas_core.objects.geometry import object_geometry
    from retarget.hands import get_hand
    from retarget.retargeter import Retargeter

    traj = human_with_forces.slice(200, 450)
    hand, geom = get_hand("shadow"), object_geometry("cube2")
    rt = Retargeter(
        hand,
        geom,
        RetargetConfig(
            force_matching=ForceMatchingConfig(enabled=True, idle_contact_clearance=0.001)
        ),
    )
    off = Retargeter(
        hand,
        geom,
        RetargetConfig(
            force_matching=ForceMatchingConfig(enabled=True, idle_contact_clearance=None)
        ),
    )
    out, ref = rt.retarget(traj), off.retarget(traj)
    tg = rt.human_targets(traj)
    idle = tg["contact_active"] & (np.linalg.norm(out.human_force, axis=2) <= 1e-3)
    assert idle.sum() >= 20  # the middle finger grazes the cube on 19 frames here, the index on 7
    np.testing.assert_allclose(out.q, ref.q)  # the kinematic solution is the same
    d_cmd, d_q, finger = [], [], []
    for t, f in zip(*np.nonzero(idle), strict=True):
        rt.scene.set_object_pose(traj.object.pos[t], traj.object.rot_aa[t])
        rt.contacts.set_contacts(
            tg["contact_active"][t], tg["contact_points"][t], tg["contact_part"][t]
        )
        d_cmd.append(rt.contacts.finger_distances(out.q_command[t])[f])
        d_q.append(rt.contacts.finger_distances(out.q[t])[f])
        finger.append(f)
    d_cmd, d_q, thumb = np.array(d_cmd), np.array(d_q), np.array(finger) == 0
    assert np.median(d_q) < 0.0008  # the solution leaves them on the surface
    # the command backs the fingers out to ~1 mm (first order) …
    assert (~thumb).sum() >= 20 and np.percentile(d_cmd[~thumb], 5) > 0.0009
    # … the thumb as far as its joints allow: the plan holds THJ2 at its upper limit on the
    # frames it is idle here, so it gets part of the way out, and never goes in
    thumb_j = out.joint_names.index("THJ2")
    held = np.abs(out.q[np.nonzero(idle)[0][thumb], thumb_j] - rt.upper[thumb_j]) < 1e-4
    assert held.all() and np.median(d_cmd[thumb]) > 3e-4
    assert np.all(d_cmd[thumb] >= np.minimum(d_q[thumb], 0.001) - 1e-4)
    plain = ~idle.any(axis=1)
    np.testing.assert_allclose(out.q_command[plain], ref.q_command[plain], atol=1e-12)
    assert not np.allclose(out.q_command[~plain], ref.q_command[~plain])
    with pytest.raises(RetargetError, match=r"ForceMatchingConfig\.idle_contact_clearance"):
        RetargetConfig(force_matching=ForceMatchingConfig(idle_contact_clearance=-0.001))
