"""The force pipeline: simulated MANO hand, tracking, contact forces, synthesis, CLI."""

from __future__ import annotations

import dataclasses
import json

import mujoco
import numpy as np
import pytest

from dexcanvas_core.cli import main as dexcanvas_main
from dexcanvas_core.demos import generate_demo
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.io import open_dataset, write_dataset
from dexcanvas_core.mano.skeleton import HandSkeleton
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.safe_io import OutputExistsError
from dexcanvas_core.sim.forces import read_contacts
from dexcanvas_core.sim.grip import balanced_forces, squeeze_offsets
from dexcanvas_core.sim.hand import (
    HAND_JOINTS,
    HINGE_HIGH,
    HINGE_LOW,
    joint_angles_to_mano,
    mano_to_joint_angles,
)
from dexcanvas_core.sim.mpc import MPCConfig, SamplingMPC, track
from dexcanvas_core.sim.pipeline import SimConfig, prepare, simulate
from dexcanvas_core.sim.reference import build_reference, keypoint_residual, lowpass_reference
from dexcanvas_core.sim.scene import OBJECT_BODY, add_object, build_scene
from dexcanvas_core.sim.synthesis import (
    Perturbation,
    PerturbationRanges,
    apply_pose_perturbation,
    synthesize_one,
)
from dexcanvas_core.sim.tracker import ACTION_DIM, TrackingEnv
from dexcanvas_core.taxonomy import OBJECTS

G = 9.81
EXACT = SimConfig(reference_lowpass_hz=None)
"""Targets exactly as given (no low-pass): for the tests that compare with the demonstration."""


@pytest.fixture(scope="module")
def demo():
    return generate_demo("cube2/tripod", "operator1", seed=0).trajectory


@pytest.fixture(scope="module")
def open_loop(demo):
    # the targets exactly as demonstrated (the low-pass has its own test): the tests below
    # check conversions and force extraction against the demonstration itself
    return simulate(
        demo, SimConfig(tracker="open_loop", reference_lowpass_hz=None), keep_state=True
    )


# -- the hand ---------------------------------------------------------------------------------


def test_hinge_decomposition_round_trips_mano_poses():
    rng = np.random.default_rng(0)
    pose = rng.normal(scale=0.4, size=(50, 45))
    back = joint_angles_to_mano(mano_to_joint_angles(pose))
    # compare rotations (axis-angle is unique below pi)
    from scipy.spatial.transform import Rotation

    a = Rotation.from_rotvec(pose.reshape(-1, 3))
    b = Rotation.from_rotvec(back.reshape(-1, 3))
    assert np.max((a.inv() * b).magnitude()) < 1e-9


def test_simulated_hand_reproduces_the_demonstration_keypoints(demo):
    _geo, ref, scene = prepare(demo, EXACT)
    res = keypoint_residual(scene, ref)
    assert res.shape == (demo.num_frames,)
    assert res.max() < 1e-6  # exact kinematics, no joint limit hit in this demo
    assert ref.hinge_clip.max() == 0.0


def test_joint_ranges_are_radians_and_actuated():
    scene = build_scene(object_geometry("cube2"), HandSkeleton.default(), fps=120)
    m = scene.model
    assert m.nu == len(HAND_JOINTS) == 51
    fingers = scene.hand.qpos_adr[6:]
    jnt = [m.dof_jntid[a] for a in scene.hand.dof_adr[6:]]
    np.testing.assert_allclose(m.jnt_range[jnt, 0], HINGE_LOW)
    np.testing.assert_allclose(m.jnt_range[jnt, 1], HINGE_HIGH)
    assert len(fingers) == 45
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert m.opt.timestep == pytest.approx(1 / 480)


@pytest.mark.parametrize("object_id", sorted(OBJECTS))
def test_every_scene_compiles_and_steps_under_noisy_controls(object_id):
    geo = object_geometry(object_id)
    scene = build_scene(geo, HandSkeleton.default(), fps=120)
    m, d = scene.model, scene.data
    h = scene.hand
    rng = np.random.default_rng(1)
    a = scene.object_qpos_adr
    d.qpos[a : a + 3] = (0.0, 0.0, geo.rest_z)
    d.qpos[a + 3] = 1.0
    # hand above the object, fingers noisy inside their ranges
    d.qpos[h.qpos_adr[:3]] = (-0.1, 0.0, geo.rest_z + 0.08)
    mujoco.mj_forward(m, d)
    for _ in range(150):
        ctrl = rng.uniform(h.ctrl_low, h.ctrl_high)
        ctrl[:3] = d.qpos[h.qpos_adr[:3]] + rng.normal(scale=0.01, size=3)
        ctrl[3:6] = rng.normal(scale=0.2, size=3)
        d.ctrl[h.actuator] = ctrl
        mujoco.mj_step(m, d)
    assert np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()
    warnings = {mujoco.mjtWarning(i).name: d.warning[i].number for i in range(len(d.warning))}
    assert not any(warnings.values()), warnings


@pytest.mark.parametrize("object_id", [o for o in OBJECTS if OBJECTS[o].is_primitive])
def test_object_body_has_the_catalogue_mass_and_inertia(object_id):
    # the free object body of the force pipeline carries the paper's mass and the inertia of the
    # true solid (``ObjectSpec.inertia_diag_kg_m2``, object frame) within 1 %
    spec = OBJECTS[object_id]
    mj = mujoco.MjSpec()
    add_object(mj, object_geometry(object_id), mocap=False)
    model = mj.compile()
    b = model.body(OBJECT_BODY).id
    assert model.body_mass[b] == pytest.approx(spec.mass_kg, rel=1e-9)
    assert np.allclose(model.body_ipos[b], 0.0, atol=1e-12)
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, model.body_iquat[b])
    R = R.reshape(3, 3)
    I_obj = R @ np.diag(model.body_inertia[b]) @ R.T  # (3, 3) about the centre, object frame
    expected = np.array(spec.inertia_diag_kg_m2)
    np.testing.assert_allclose(np.diag(I_obj), expected, rtol=0.01)
    assert np.abs(I_obj - np.diag(np.diag(I_obj))).max() < 0.01 * expected.max()


# -- forces -----------------------------------------------------------------------------------


def test_static_hold_carries_the_objects_weight(open_loop):
    m = open_loop.metrics
    assert open_loop.success
    assert m["hold_frames"] > 60
    assert m["hold_weight_ratio"] == pytest.approx(1.0, abs=0.03)
    # frame by frame too: the hand's vertical force during the hold is m·g within 10 %
    Fz = open_loop.wrench[open_loop.hold, 2] / (m["mass_kg"] * G)
    assert np.median(np.abs(Fz - 1.0)) < 0.1
    # the tripod's load is carried by the thumb against the fingers
    hold = m["hold_finger_force_mean_n"]
    assert hold["thumb"] > 0.5 and hold["index"] + hold["middle"] > 0.5
    assert hold["palm"] == 0.0


def test_newton_euler_holds_with_the_extracted_forces(open_loop):
    # the residual is the contact solver's, relative to m·g: it grows with the grip's internal
    # forces (measured 5.5e-4 with a max(F_min, load) pad force, 1.1e-3 with F_min + load)
    assert np.median(open_loop.newton_euler_sim) < 2e-3
    assert open_loop.metrics["newton_euler_capture_median"] < 0.05


def test_summed_contact_forces_match_cfrc_ext(open_loop, demo):
    res = open_loop
    scene, ref = res.scene, res.reference
    env = TrackingEnv(scene, ref)
    m, d = scene.model, scene.data
    frame = int(np.flatnonzero(res.hold)[10])
    for _ in range(frame):
        env.step(np.zeros(ACTION_DIM))
    mujoco.mj_forward(m, d)
    mujoco.mj_rnePostConstraint(m, d)
    sc = read_contacts(scene, d)
    assert sc.force.shape[0] >= 2
    F = sc.force.sum(0) + sc.table_force
    com = d.xipos[scene.object_body]
    tau = np.cross(sc.pos - com, sc.force).sum(0) + sc.torque.sum(0) + sc.table_torque_com
    cfrc = d.cfrc_ext[scene.object_body]  # [torque, force] about the subtree COM
    np.testing.assert_allclose(F, cfrc[3:], atol=1e-6 * max(1.0, np.abs(F).max()))
    np.testing.assert_allclose(tau, cfrc[:3], atol=1e-6)
    # every hand contact pushes into the object (positive normal force)
    assert np.all(np.einsum("ij,ij->i", sc.force, sc.normal) > 0)


def test_balanced_forces_cancel_and_stay_near_target():
    n = np.array([[1.0, 0, 0], [-1.0, 0, 0], [-1.0, 0.0, 0.0]])
    F = balanced_forces(n, np.zeros((0, 3)), 4.0)
    # equal pad forces would push with 4 N; the balanced ones push with a quarter of that
    assert np.linalg.norm(F @ n) <= 1.0 + 1e-6
    assert F.min() >= 0 and np.abs(F - 4.0).max() <= 1.0 + 1e-6
    # lsq optimum of (F0 - F1 - F2)² + Σ(F - 4)²: F0 = 5, F1 = F2 = 3
    assert F == pytest.approx([5.0, 3.0, 3.0], abs=1e-4)
    # fingers all on one side with a palm opposite: the palm takes the net force
    F = balanced_forces(n[1:], np.array([[1.0, 0, 0]]), 4.0)
    assert F == pytest.approx([4.0, 4.0], abs=1e-6)


@pytest.fixture(scope="module")
def thumb_on_a_face():
    """cube2/tripod by operator1, seed 1, replayed open loop: its thumb pad presses the middle
    of a side face (grasp contact normal +y). Seed 0's (the ``demo`` fixture) sits on the
    cube's vertical edge (normal at 45° between two faces)."""
    demo = generate_demo("cube2/tripod", "operator1", seed=1).trajectory
    return simulate(
        demo, SimConfig(tracker="open_loop", reference_lowpass_hz=None), keep_state=True
    )


def test_squeeze_offsets_produce_the_commanded_pad_force(thumb_on_a_face):
    """Joint-target offsets K⁻¹Jᵀf against a fixed object: measured force follows the command.

    The thumb presses a face: on an edge (seed 0's thumb) the commanded force points along the
    edge's diagonal normal, and the pad rolls round the edge onto a face as it presses, so the
    force read along the contact normal falls behind the command (51, 51, 40 % at 2, 4, 8 N;
    no joint limit or actuator force limit is reached). On the face: 63, 65, 70 %."""
    FORCES = (2.0, 4.0, 8.0)
    open_loop = thumb_on_a_face
    scene, ref = open_loop.scene, open_loop.reference
    env = TrackingEnv(scene, ref, dataclasses.replace(env_cfg(), grip=False))
    fr = int(np.flatnonzero(open_loop.hold)[0])
    m, d = scene.model, scene.data
    measured = []
    for F in FORCES:
        W = np.zeros((1, 5))
        W[0, 0] = 1.0  # the thumb only, alone against the welded object
        off, cmd = squeeze_offsets(
            scene, env.ctrl_ref[fr : fr + 1], ref.object_pos[fr : fr + 1],
            ref.object_quat[fr : fr + 1], W, force_min_n=F, safety=0.0, friction=1.0, balance=False,
        )  # fmt: skip
        assert cmd[0, 0] == pytest.approx(F)
        mujoco.mj_resetData(m, d)
        d.qpos[scene.hand.qpos_adr] = env.ctrl_ref[fr]
        a = scene.object_qpos_adr
        d.qpos[a : a + 3] = ref.object_pos[fr]
        d.qpos[a + 3 : a + 7] = ref.object_quat[fr]
        d.mocap_pos[scene.anchor_mocap] = ref.object_pos[fr]
        d.mocap_quat[scene.anchor_mocap] = ref.object_quat[fr]
        d.eq_active[scene.weld_eq] = 1
        ctrl = env.ctrl_ref[fr] + off[0]
        d.ctrl[scene.hand.actuator] = ctrl
        for _ in range(500):
            mujoco.mj_step(m, d)
        sc = read_contacts(scene, d)
        thumb = [scene.hand.geom_part[int(g)].startswith("thumb") for g in sc.hand_geom]
        measured.append(float(np.einsum("ij,ij->i", sc.force, sc.normal)[thumb].sum()))
    measured = np.array(measured)
    assert np.all(np.diff(measured) > 0)
    # soft contacts let the finger sink in a little: the force reached is 50–110 % of the command
    ratio = measured / np.array(FORCES)
    assert np.all((ratio > 0.5) & (ratio < 1.1)), ratio


def env_cfg():
    from dexcanvas_core.sim.tracker import TrackingConfig

    return TrackingConfig()


# -- trackers ---------------------------------------------------------------------------------


def test_mpc_is_deterministic_and_tracks(demo):
    short = demo.slice(200, 320)  # the grasp and the start of the lift
    out = []
    for _ in range(2):
        _geo, ref, scene = prepare(short, SimConfig())
        env = TrackingEnv(scene, ref)
        mpc = SamplingMPC(MPCConfig(samples=8, seed=3))
        log = track(env, mpc)
        out.append(np.array(log.object_pos))
        assert mpc.rollout_steps > 0
    np.testing.assert_array_equal(out[0], out[1])
    assert env.failed_at is None


def test_a_learned_policy_plugs_in_through_the_tracker_interface(demo):
    class Policy:
        """Stands in for a trained residual policy: reads observations, returns actions."""

        def reset(self, env):
            self.seen = 0

        def act(self, env):
            obs = env.observation()
            assert obs["hand_qpos"].shape == (51,) and obs["ref_ctrl_next"].shape == (51,)
            self.seen += 1
            return np.full(ACTION_DIM, 0.001)

    _geo, ref, scene = prepare(demo.slice(0, 40), SimConfig())
    env = TrackingEnv(scene, ref)
    pol = Policy()
    track(env, pol)
    assert pol.seen == 39
    assert np.all(env.u > 0)  # the smoothed residual integrated the actions


def test_bad_inputs_are_refused(demo):
    with pytest.raises(ValidationError, match="unknown tracker"):
        simulate(demo, SimConfig(tracker="ppo"))
    with pytest.raises(ValidationError, match="object_scale"):
        simulate(demo, SimConfig(object_scale=0.0))
    left = dataclasses.replace(demo, hands=[dataclasses.replace(demo.hand, name="left")])
    with pytest.raises(ValidationError, match="right hand"):
        simulate(left)
    _geo, ref, scene = prepare(demo.slice(0, 3), SimConfig())
    env = TrackingEnv(scene, ref)
    with pytest.raises(ValidationError, match="non-finite"):
        env.step(np.full(ACTION_DIM, np.nan))


# -- outputs ----------------------------------------------------------------------------------


def test_annotated_trajectory_round_trips_through_lance(open_loop, tmp_path):
    tr = open_loop.trajectory
    assert tr.contacts is not None and tr.contacts.num_pairs > 100
    assert tr.object_wrench_world.shape == (tr.num_frames, 6)
    assert tr.solver_settings["integrator"] == "implicitfast"
    assert tr.hand.urdf_dof.shape == (tr.num_frames, 26)
    # per-finger totals equal the sum of the point forces
    totals = tr.contacts.finger_totals()
    np.testing.assert_allclose(totals.sum(1), tr.object_wrench_world[:, :3], atol=1e-4)
    write_dataset([tr], tmp_path / "sim.lance")
    back = next(iter(open_dataset(tmp_path / "sim.lance").iter_trajectories()))
    np.testing.assert_array_equal(back.contacts.force_world, tr.contacts.force_world)
    np.testing.assert_array_equal(back.object_wrench_world, tr.object_wrench_world)
    assert back.solver_settings == json.loads(json.dumps(tr.solver_settings))


def test_cli_simulate_writes_contacts_forces_and_wrench(tmp_path, demo, capsys):
    src = tmp_path / "src.lance"
    write_dataset([demo], src)
    out = tmp_path / "sim.lance"
    rc = dexcanvas_main(
        ["simulate", "--pair", "cube2/tripod", "--dataset", str(src), "--out", str(out),
         "--tracker", "open_loop"]
    )  # fmt: skip
    assert rc == 0
    printed = capsys.readouterr().out
    assert "SUCCESS" in printed and "object error" in printed
    t = next(iter(open_dataset(out).iter_trajectories()))
    assert t.contacts.num_records > 0 and t.object_wrench_world is not None
    assert np.abs(t.contacts.finger_totals()).max() > 0.5
    m = json.loads((tmp_path / "sim.lance.metrics.json").read_text())
    assert m["success"] and (tmp_path / "sim.lance.forces.png").stat().st_size > 10_000
    # existing output is not replaced without --overwrite
    rc = dexcanvas_main(["simulate", "--pair", "cube2/tripod", "--dataset", str(src),
                         "--out", str(out), "--tracker", "open_loop"])  # fmt: skip
    assert rc == 2 and "--overwrite" in capsys.readouterr().err
    rc = dexcanvas_main(["simulate", "--pair", "cube9/tripod", "--out", str(tmp_path / "x")])
    assert rc == 2 and "cube9" in capsys.readouterr().err


# -- synthesis --------------------------------------------------------------------------------


def test_pose_perturbation_moves_hand_and_object_rigidly(demo):
    p = Perturbation(shift_xy_m=(0.03, -0.02), yaw_rad=0.4)
    moved = apply_pose_perturbation(demo, p)
    rel = demo.hand.joint_pos - demo.object.pos[:, None]
    rel_moved = moved.hand.joint_pos - moved.object.pos[:, None]
    # distances between hand keypoints and the object are unchanged; heights too
    np.testing.assert_allclose(
        np.linalg.norm(rel, axis=-1), np.linalg.norm(rel_moved, axis=-1), atol=1e-5
    )
    np.testing.assert_allclose(moved.object.pos[:, 2], demo.object.pos[:, 2], atol=1e-6)
    # the MANO wrist stays consistent with the keypoints
    _geo, ref, scene = prepare(moved, EXACT)
    assert keypoint_residual(scene, ref).max() < 1e-5


def test_synthesized_rollout_is_a_consistent_generated_trajectory(demo):
    short = demo.slice(150, 420)
    tr, metrics = synthesize_one(
        short, 0, 7, SimConfig(tracker="open_loop"),
        PerturbationRanges(
            size=0.05, mass=0.05, friction=0.05, hand=0.01, object_offset_m=0.0,
            object_offset_yaw_rad=0.0,
        ),
    )  # fmt: skip
    assert metrics["perturbation"]["object_scale"] != 1.0
    if tr is None:
        pytest.fail(f"a mild perturbation failed: {metrics}")
    assert tr.is_generated and tr.seed_uuid == short.uuid and tr.uuid != short.uuid
    assert json.loads(tr.extras["synthesis"])["index"] == 0
    # its hand track is the simulated hand: re-simulating it reproduces its own keypoints
    _geo, ref, scene = prepare(tr, EXACT)
    assert keypoint_residual(scene, ref).max() < 1e-4
    tr.validate()


def test_synthesize_refuses_existing_output(tmp_path, demo):
    from dexcanvas_core.sim.run import SynthesizeConfig, run_synthesize

    (tmp_path / "o.lance").mkdir()
    with pytest.raises(OutputExistsError, match="overwrite"):
        run_synthesize(SynthesizeConfig(dataset=tmp_path / "x", out=tmp_path / "o.lance"))


def test_cli_synthesize_expands_and_resumes(tmp_path, demo, capsys):
    """Mild perturbations with the open-loop tracker keep rollouts; a crashed run resumes."""
    from dexcanvas_core.cli import _sim_config
    from dexcanvas_core.cli_parser import build_parser
    from dexcanvas_core.sim.run import _synth_row

    src = tmp_path / "src.lance"
    short = demo.slice(150, 420)
    write_dataset([short], src)
    out = tmp_path / "syn.lance"
    args = ["synthesize", "--dataset", str(src), "--expand", "2", "--out", str(out),
            "--tracker", "open_loop", "--seed", "7", "--size", "0.05", "--mass", "0.05",
            "--friction", "0.05", "--hand-scale", "0.01", "--object-offset", "0",
            "--object-offset-yaw-deg", "0"]  # fmt: skip
    # a crashed run finished this row before dying: the rerun reuses it instead of recomputing
    ns = build_parser().parse_args(args)
    from dexcanvas_core.sim.synthesis import PerturbationRanges

    ranges = PerturbationRanges(size=0.05, mass=0.05, friction=0.05, hand=0.01,
                                object_offset_m=0.0, object_offset_yaw_rad=0.0)  # fmt: skip
    work = tmp_path / "syn.lance.work"
    work.mkdir()
    sim = _sim_config(ns)
    (work / "settings.json").write_text(json.dumps(
        {"dataset": str(src), "expand": 2, "seed": 7, "sim": sim.as_dict(),
         "ranges": dataclasses.asdict(ranges)}))  # fmt: skip
    uuid, kept, _ = _synth_row((str(src), 0, 2, 7, sim, ranges, str(work)))
    assert kept >= 1
    done = json.loads((work / f"{uuid}.json").read_text())
    done[0]["reused"] = True  # marks the checkpoint so the test sees it was not recomputed
    (work / f"{uuid}.json").write_text(json.dumps(done))
    rc = dexcanvas_main(args)
    assert rc == 0, capsys.readouterr().err
    rows = list(open_dataset(out).iter_trajectories())
    assert len(rows) == kept and all(r.is_generated and r.seed_uuid == short.uuid for r in rows)
    assert len({r.uuid for r in rows}) == kept
    report = json.loads((tmp_path / "syn.lance.report.json").read_text())
    assert report["summary"]["rollouts"] == 2 and report["summary"]["kept"] == kept
    assert report["rollouts"][0].get("reused") is True  # not recomputed
    assert not work.exists()  # cleaned up once the final dataset is written
    assert "kept" in capsys.readouterr().out
    # a leftover work dir with other settings is refused
    work.mkdir()
    (work / "settings.json").write_text(json.dumps({"expand": 99}))
    rc = dexcanvas_main([*args, "--overwrite"])
    assert rc == 2 and "other settings" in capsys.readouterr().err


def test_reference_lowpass_removes_fit_noise_and_keeps_scripted_motion(demo):
    geom = object_geometry(demo.object.name)
    ref = build_reference(demo, geom)
    smooth = lowpass_reference(ref, 4.0)
    # the scripted (minimum-jerk) motion passes almost unchanged
    assert np.abs(smooth.hinges - ref.hinges).max() < 0.03
    assert np.abs(smooth.wrist_pos - ref.wrist_pos).max() < 2e-3  # 1.5 mm at phase changes
    assert np.abs(smooth.wrist_euler - ref.wrist_euler).max() < 0.01
    # its world rotation stays the Euler angles' (one orientation, two views)
    from scipy.spatial.transform import Rotation

    R = np.einsum(
        "ij,tjk->tik", smooth.R_base, Rotation.from_euler("XYZ", smooth.wrist_euler).as_matrix()
    )
    np.testing.assert_allclose(smooth.wrist_rot, R, atol=1e-9)
    # white noise on the targets (a fit's jitter) is cut to well under half
    rng = np.random.default_rng(0)
    noisy = dataclasses.replace(ref, hinges=ref.hinges + rng.normal(0, 0.02, ref.hinges.shape))
    err_before = np.abs(noisy.hinges - ref.hinges)[30:-30].std()
    err_after = np.abs(lowpass_reference(noisy, 4.0).hinges - ref.hinges)[30:-30].std()
    assert err_after < 0.3 * err_before
    assert lowpass_reference(ref, None) is ref
    with pytest.raises(ValidationError, match="cutoff"):
        lowpass_reference(ref, 90.0)  # above Nyquist at 120 Hz
    with pytest.raises(ValidationError, match="reference_lowpass_hz"):
        SimConfig(reference_lowpass_hz=-1.0).validate()


@pytest.mark.filterwarnings("ignore:lance is not fork-safe")  # Ray forks, then execs
def test_synthesize_on_local_ray_equals_in_process(tmp_path, demo):
    """``dexcanvas synthesize --ray-address local``: the same rollouts as without Ray."""
    src = tmp_path / "src.lance"
    write_dataset([demo.slice(150, 300)], src)
    base = ["synthesize", "--dataset", str(src), "--expand", "1", "--tracker", "open_loop",
            "--seed", "7", "--size", "0.05", "--mass", "0.05", "--friction", "0.05",
            "--hand-scale", "0.01", "--object-offset", "0",
            "--object-offset-yaw-deg", "0"]  # fmt: skip
    assert dexcanvas_main([*base, "--out", str(tmp_path / "a.lance")]) == 0
    ray_args = [*base, "--out", str(tmp_path / "b.lance"), "--ray-address", "local"]
    assert dexcanvas_main(ray_args) == 0
    a = list(open_dataset(tmp_path / "a.lance").iter_trajectories())
    b = list(open_dataset(tmp_path / "b.lance").iter_trajectories())
    assert [t.uuid for t in a] == [t.uuid for t in b] and a
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.object.pos, y.object.pos)
        np.testing.assert_array_equal(x.hand.joint_pos, y.hand.joint_pos)


def test_cli_simulate_all_rows_on_the_pool_and_on_ray_gives_the_same_dataset(tmp_path, demo):
    """``dexcanvas simulate --dataset D --all``: every row through the force pipeline as jobs,
    on two local processes and as tasks of a private local Ray; the same rows, bit for bit, and
    every row's metrics in the report; a rerun after an interruption reuses finished rows."""
    from dexcanvas_core.cli import main
    from dexcanvas_core.sim.run import _simulate_row

    src = tmp_path / "src.lance"
    write_dataset([dataclasses.replace(demo.slice(230, 300), uuid=f"clip-{i}") for i in range(3)],
                  src)  # fmt: skip
    base = ["simulate", "--dataset", str(src), "--all", "--tracker", "open_loop", "--no-plot"]
    pool, ray_out = tmp_path / "pool.lance", tmp_path / "ray.lance"
    assert main([*base, "--workers", "2", "--out", str(pool)]) == 0
    assert main([*base, "--ray-address", "local", "--out", str(ray_out)]) == 0
    a = {t.uuid: t for t in open_dataset(pool).iter_trajectories()}
    b = {t.uuid: t for t in open_dataset(ray_out).iter_trajectories()}
    assert sorted(a) == sorted(b) == ["clip-0", "clip-1", "clip-2"]
    for u in a:
        np.testing.assert_array_equal(a[u].object_wrench_world, b[u].object_wrench_world)
        np.testing.assert_array_equal(a[u].contacts.finger_totals(), b[u].contacts.finger_totals())
    report = json.loads((tmp_path / "pool.lance.report.json").read_text())
    assert report["summary"]["rollouts"] == 3 and len(report["rollouts"]) == 3
    # an interrupted run: row 0 finished (marked), the rerun keeps it and does the others
    out = tmp_path / "resumed.lance"
    work = tmp_path / "resumed.lance.work"
    work.mkdir()
    from dexcanvas_core.cli import _sim_config
    from dexcanvas_core.cli_parser import build_parser

    sim = _sim_config(build_parser().parse_args([*base, "--out", str(out)]))
    (work / "settings.json").write_text(
        json.dumps({"dataset": str(src), "sim": sim.as_dict(), "all": True})
    )
    uuid, _, _ = _simulate_row((str(src), 0, sim, str(work)))
    done = json.loads((work / f"{uuid}.json").read_text())
    done[0]["reused"] = True
    (work / f"{uuid}.json").write_text(json.dumps(done))
    assert main([*base, "--out", str(out)]) == 0
    rows = json.loads((tmp_path / "resumed.lance.report.json").read_text())["rollouts"]
    assert [r.get("reused", False) for r in rows] == [True, False, False]
