"""Robot hand registry: every model compiles, steps cleanly, honours its couplings and frames."""

import dataclasses
import importlib.util
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dexcanvas_core.keypoints import FINGERS, MANO21
from retarget.cli import main
from retarget.errors import HandModelError, UnknownHandError
from retarget.hands import (
    WRIST_JOINTS,
    WRIST_SITE,
    available_hands,
    get_hand,
    register,
    unregister,
    wrist_qpos_from_mano,
)

ROOT = Path(__file__).resolve().parents[1]
BUILTIN = {"shadow", "allegro", "leap", "ability", "inspire", "svh", "panda"}
HANDS = available_hands()


@pytest.fixture(scope="module", params=HANDS)
def hand(request):
    h = get_hand(request.param)
    h.compile()  # cached on the hand: compiled once per test session
    return h


def _angle_deg(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(
        np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))
    )


def _noisy_rollout(hand, seconds=1.0, seed=0):
    """Step under random position targets (new ones every 20 ms); return model, data."""
    m = hand.compile()
    d = mujoco.MjData(m)
    d.qpos[:] = hand.default_qpos(m)
    mujoco.mj_forward(m, d)
    rng = np.random.default_rng(seed)
    c0 = hand.default_ctrl(m)
    lo, hi = m.actuator_ctrlrange.T
    for i in range(round(seconds / m.opt.timestep)):
        if i % 10 == 0:
            ctrl = c0.copy()
            ctrl[:3] += rng.normal(0.0, 0.02, 3)  # wrist [m]
            ctrl[3:6] += rng.normal(0.0, 0.1, 3)  # wrist [rad]
            ctrl[6:] = rng.uniform(lo[6:], hi[6:])  # fingers anywhere in range
            d.ctrl[:] = np.clip(ctrl, lo, hi)
        mujoco.mj_step(m, d)
    return m, d


def _joint_equality_errors(m, d) -> list[float]:
    errs = []
    for e in range(m.neq):
        if m.eq_type[e] != mujoco.mjtEq.mjEQ_JOINT or m.eq_obj2id[e] < 0:
            continue
        c = m.eq_data[e]
        q1 = d.qpos[m.jnt_qposadr[m.eq_obj1id[e]]]
        q2 = d.qpos[m.jnt_qposadr[m.eq_obj2id[e]]]
        errs.append(abs(q1 - (c[0] + c[1] * q2 + c[2] * q2**2 + c[3] * q2**3)))
    return errs


# ------------------------------------------------------------------------------ registry


def test_registry_lists_every_builtin_hand():
    assert BUILTIN <= set(HANDS)
    assert get_hand("Shadow") is get_hand("shadow")  # case-insensitive


def test_unknown_hand_names_close_matches():
    with pytest.raises(UnknownHandError) as e:
        get_hand("shdow")
    msg = str(e.value)
    assert "unknown hand 'shdow'" in msg and "did you mean 'shadow'" in msg
    assert all(n in msg for n in BUILTIN)
    assert isinstance(e.value, KeyError)


def test_register_a_plugin_hand():
    leap = get_hand("leap")
    custom = dataclasses.replace(leap, name="leap_plugin", description="a copy")
    register(custom)
    try:
        assert "leap_plugin" in available_hands() and get_hand("LEAP_PLUGIN") is custom
        with pytest.raises(Exception, match="already registered"):
            register(dataclasses.replace(leap, name="leap_plugin"))
    finally:
        unregister("leap_plugin")
    assert "leap_plugin" not in available_hands()


# ------------------------------------------------------------------------------ models


def test_compiles_with_floating_wrist(hand):
    m = hand.compile()
    for i, name in enumerate(WRIST_JOINTS):
        j = m.joint(name)
        kind = mujoco.mjtJoint.mjJNT_SLIDE if i < 3 else mujoco.mjtJoint.mjJNT_HINGE
        assert j.id == i and m.jnt_type[i] == kind and m.jnt_qposadr[i] == i
        assert np.allclose(m.jnt_axis[i], np.eye(3)[i % 3])
        act = m.actuator(f"{name}_act")
        assert act.id == i and m.actuator_trnid[i, 0] == i
        assert m.actuator_gainprm[i, 0] > 0 and m.actuator_forcelimited[i]
    assert m.nu == len(WRIST_JOINTS) + len(hand.actuators)
    for a in hand.actuators:
        assert m.actuator(f"{a.joint}_act").trnid[0] == m.joint(a.joint).id
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and m.opt.timestep <= 0.0025


def test_fingertip_sites_and_collision_geoms(hand):
    m = hand.compile()
    parts = hand.hand_parts(m)
    for human in FINGERS:
        robot = hand.fingers[human]
        if robot is None:
            continue
        assert m.site(f"{robot}_tip_site").id >= 0
        bodies = {m.body(b).id for b in parts[robot]}
        geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] in bodies and m.geom_contype[g]]
        assert geoms, f"{hand.name}: finger {robot} has no collision geom"
        tip_body = int(m.site_bodyid[m.site(f"{robot}_tip_site").id])
        tip_geoms = [g for g in geoms if m.geom_bodyid[g] == tip_body]
        assert all(m.geom_condim[g] == 4 for g in tip_geoms)
        assert all(m.geom(g).name.endswith("_collision") or "_collision_" in m.geom(g).name
                   for g in geoms)  # fmt: skip
    assert parts["palm"], "every hand has a palm part"


def test_correspondence(hand):
    m = hand.compile()
    assert set(hand.fingers) == set(FINGERS)
    for human, robot in hand.fingers.items():
        assert robot is None or robot in hand.robot_fingers, (human, robot)
    assert hand.fingers["thumb"] is not None and hand.fingers["index"] is not None
    if len(set(hand.robot_fingers)) == 4:  # four-finger hands drop the little finger
        assert hand.fingers["pinky"] is None
    km = hand.keypoint_map
    assert set(km) <= set(MANO21) and km["wrist"] == WRIST_SITE
    for human, robot in hand.fingers.items():
        if robot is not None:
            assert km[f"{human}_tip"] == f"{robot}_tip_site"
    for site in km.values():
        assert m.site(site).id >= 0


def test_gripper_maps_thumb_against_index_and_middle():
    panda = get_hand("panda")
    assert panda.fingers == {
        "thumb": "left", "index": "right", "middle": "right", "ring": None, "pinky": None
    }  # fmt: skip


def test_steps_one_second_of_noisy_control_without_warnings(hand):
    m, d = _noisy_rollout(hand)
    warnings = {mujoco.mjtWarning(i).name: int(d.warning[i].number)
                for i in range(len(d.warning)) if d.warning[i].number}  # fmt: skip
    assert warnings == {}, f"{hand.name}: {warnings}"
    assert np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all() and np.isfinite(d.qacc).all()
    assert max(_joint_equality_errors(m, d), default=0.0) < 0.03  # [rad] even under noise


def test_couplings_hold_at_a_held_posture(hand):
    """Drive the leaders to mid-range and hold: every joint coupling holds to a few mrad."""
    m = hand.compile()
    d = mujoco.MjData(m)
    d.qpos[:] = hand.default_qpos(m)
    lo, hi = m.actuator_ctrlrange.T
    d.ctrl[:] = hand.default_ctrl(m)
    d.ctrl[6:] = 0.5 * (lo[6:] + hi[6:])
    for _ in range(300):
        mujoco.mj_step(m, d)
    assert max(_joint_equality_errors(m, d), default=0.0) < 5e-3
    # the followers did move with their leaders
    for e in range(m.neq):
        if m.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT and abs(m.eq_data[e, 1]) > 0:
            j = m.eq_obj2id[e]
            moved = abs(d.qpos[m.jnt_qposadr[j]] - hand.default_qpos(m)[m.jnt_qposadr[j]])
            assert moved > 0.2 * (m.jnt_range[j, 1] - m.jnt_range[j, 0]), m.joint(j).name


def test_shadow_distal_joints_follow_the_tendon():
    shadow = get_hand("shadow")
    m = shadow.compile()
    d = mujoco.MjData(m)
    d.qpos[:] = shadow.default_qpos(m)
    d.ctrl[:] = shadow.default_ctrl(m)
    d.ctrl[m.actuator("FFJ1_act").id] = 1.0  # only J1 is actuated
    for _ in range(400):
        mujoco.mj_step(m, d)
    j1, j0 = d.joint("FFJ1").qpos[0], d.joint("FFJ0").qpos[0]
    assert j1 > 0.5 and j0 > 0.5  # the unactuated DIP moved with the PIP
    assert abs(0.00705 * j0 - 0.00805 * j1) <= 0.001 + 2e-4  # T_FFJ1c range, small slack
    _, d2 = _noisy_rollout(shadow, seconds=0.5, seed=1)
    for f in ("FF", "MF", "RF", "LF"):
        length = d2.ten_length[m.tendon(f"T_{f}J1c").id]
        assert abs(length) <= 0.001 + 5e-4


def test_inspire_linkages_are_equalities():
    m = get_hand("inspire").compile()
    eqs = {m.equality(e).name for e in range(m.neq)}
    assert {"th_mcp_coupling", "th_ip_coupling"} | {f"{f}_pip_coupling" for f in
                                                      ("ff", "mf", "rf", "lf")} == eqs  # fmt: skip
    assert m.nu - len(WRIST_JOINTS) == 6 and m.njnt - len(WRIST_JOINTS) == 12


def test_wrist_frame_alignment_with_mano(hand):
    """Open hand at the identity wrist pose: fingers along MANO -x, palm normal -y, thumb +z."""
    T = hand.T_mano_robot_wrist
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3)) and np.isclose(np.linalg.det(T), 1)
    m = hand.compile()
    d = mujoco.MjData(m)
    d.qpos[:] = hand.default_qpos(m)
    mujoco.mj_kinematics(m, d)
    root = m.body(hand.root_body).id
    assert np.allclose(d.xpos[root], T[:3, 3])
    assert np.allclose(d.xmat[root].reshape(3, 3), T[:3, :3])
    wrist = d.site(WRIST_SITE).xpos
    tips = {f: d.site(s).xpos - wrist for f, s in hand.tip_site_names.items()}
    thumb = hand.fingers["thumb"]
    others = sorted({r for h, r in hand.fingers.items() if r and h != "thumb" and r != thumb})
    distal = np.mean([tips[f] for f in (others if len(others) > 1 else tips)], axis=0)
    km = hand.keypoint_map
    if "index1" in km:  # radial: index MCP minus the last MCP on the little-finger side
        last = next(k for k in ("pinky1", "ring1", "middle1") if k in km)
        radial = d.site(km["index1"]).xpos - d.site(km[last]).xpos
    else:  # gripper: thumb finger minus index finger
        radial = tips[thumb] - tips[hand.fingers["index"]]
    radial = radial - distal * (radial @ distal) / (distal @ distal)
    volar = np.cross(radial, distal)
    assert _angle_deg(distal, [-1, 0, 0]) < 30, hand.name
    assert _angle_deg(volar, [0, -1, 0]) < 30, hand.name
    assert tips[thumb][2] > 0.01, f"{hand.name}: thumb not on MANO's +z side"


def test_mano_wrist_pose_drives_the_floating_base():
    leap = get_hand("leap")
    m = leap.compile()
    d = mujoco.MjData(m)
    R = Rotation.from_rotvec([0.3, -0.5, 0.8]).as_matrix()
    p = np.array([0.1, -0.2, 0.3])
    d.qpos[:] = leap.default_qpos(m)
    d.qpos[:6] = wrist_qpos_from_mano(R, p)
    d.ctrl[:] = leap.default_ctrl(m)
    d.ctrl[:6] = d.qpos[:6]
    for _ in range(250):
        mujoco.mj_step(m, d)
    assert np.allclose(d.site(WRIST_SITE).xpos, p, atol=2e-3)
    assert np.allclose(d.site(WRIST_SITE).xmat.reshape(3, 3), R, atol=2e-2)
    root = m.body(leap.root_body).id
    T_world_root = np.eye(4)
    T_world_root[:3, :3], T_world_root[:3, 3] = R, p
    T_world_root = T_world_root @ leap.T_mano_robot_wrist
    assert np.allclose(d.xpos[root], T_world_root[:3, 3], atol=3e-3)


def test_hand_scale_is_plausible(hand):
    assert 0.5 < hand.scale < 2.0


def test_fingertip_geoms_touch_an_object(hand):
    """A sphere at the index fingertip site touches the finger with a condim-4 contact."""
    m0 = hand.compile()
    d0 = mujoco.MjData(m0)
    d0.qpos[:] = hand.default_qpos(m0)
    mujoco.mj_kinematics(m0, d0)
    site = hand.tip_site_names[hand.fingers["index"]]
    spec = hand.build_spec()
    ball = spec.worldbody.add_body(name="probe", pos=d0.site(site).xpos.copy())
    ball.add_geom(name="probe_geom", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.012, 0, 0])
    m = spec.compile()
    d = mujoco.MjData(m)
    d.qpos[:] = hand.default_qpos(m)
    mujoco.mj_forward(m, d)
    probe = m.geom("probe_geom").id
    dims = [d.contact[i].dim for i in range(d.ncon) if probe in d.contact[i].geom]
    assert 4 in dims, f"{hand.name}: contacts with the probe {dims}"


def test_self_collision_variant_starts_free_and_steps(hand):
    m = hand.build_spec(self_collision=True).compile()
    d = mujoco.MjData(m)
    d.qpos[:] = hand.default_qpos(m)
    mujoco.mj_forward(m, d)
    assert d.ncon == 0  # resting contacts (palm vs finger bases) are excluded
    for _ in range(100):
        mujoco.mj_step(m, d)
    assert not any(d.warning[i].number for i in range(len(d.warning)))


def test_hand_descriptions_are_validated():
    leap = get_hand("leap")
    with pytest.raises(HandModelError, match="'index4' is not a MANO21 joint keypoint"):
        dataclasses.replace(leap, name="typo", joint_sites={"index4": leap.joint_sites["index1"]})
    with pytest.raises(HandModelError, match=r"pinky.*no entry in tip_sites"):
        dataclasses.replace(leap, name="typo", fingers={**leap.fingers, "pinky": "lf"})


def test_missing_model_is_a_clear_error():
    def broken():
        raise FileNotFoundError("no such file: nowhere.xml")

    bad = dataclasses.replace(get_hand("leap"), name="broken_hand", loader=broken)
    with pytest.raises(HandModelError, match=r"broken_hand.*nowhere\.xml"):
        bad.compile()


# ------------------------------------------------------------------------------ robots/


def test_every_robots_folder_has_readme_and_licence():
    folders = [p for p in (ROOT / "robots").iterdir() if p.is_dir() and not p.name.startswith(".")]
    assert {"leap", "inspire"} <= {p.name for p in folders}
    for p in folders:
        assert (p / "README.md").is_file() and (p / "LICENSE").is_file(), p


@pytest.mark.parametrize("name,xml", [("leap", "leap_right.xml"), ("inspire", "inspire_right.xml")])
def test_authored_models_match_their_derivation(name, xml):
    path = ROOT / "robots" / name / "derive.py"
    spec = importlib.util.spec_from_file_location(f"derive_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.to_mjcf() == (ROOT / "robots" / name / xml).read_text()


# ------------------------------------------------------------------------------ CLI


def test_cli_hands_table_and_json(capsys):
    assert main(["hands"]) == 0
    out = capsys.readouterr().out
    assert all(n in out for n in HANDS)
    assert main(["hands", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["name"] for r in rows} == set(HANDS)
    shadow = next(r for r in rows if r["name"] == "shadow")
    assert shadow["dof_fingers"] == 24 and shadow["actuators_fingers"] == 20
    assert shadow["source"] == "gymnasium-robotics" and shadow["licence"]
    assert shadow["wrist_offset"] and shadow["wrist_weight"] == 1.0
    panda = next(r for r in rows if r["name"] == "panda")
    assert not panda["wrist_offset"] and panda["wrist_weight"] == 0.0


def test_cli_errors_are_one_line_with_exit_2(capsys):
    def broken():
        raise FileNotFoundError("nowhere.xml")

    register(dataclasses.replace(get_hand("leap"), name="broken_cli", loader=broken))
    try:
        assert main(["hands"]) == 2
    finally:
        unregister("broken_cli")
    err = capsys.readouterr().err.strip()
    assert err.startswith("retarget hands: error:") and "broken_cli" in err and "\n" not in err


def test_cli_without_command_prints_help(capsys):
    assert main([]) == 0
    assert "hands" in capsys.readouterr().out
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
