"""dexcanvas_core.mano: exact MANO against smplx, the skeleton path, the chumpy-free loader."""

from __future__ import annotations

import pickle
import sys
import types

import numpy as np
import pytest
import scipy.sparse
import torch

from dexcanvas_core.errors import DexCanvasError, UnknownNameError, ValidationError
from dexcanvas_core.keypoints import FINGERS, MANO21, MANO_PARENTS
from dexcanvas_core.mano import (
    BONE_NAMES,
    FINGER_BONES,
    MANO_TIP_VERTEX_IDS,
    HandSkeleton,
    ManoLayer,
    axis_angle_to_matrix,
    load_mano_model,
    measure_bone_lengths,
    mirror_axis_angle,
)

V, J = 778, 16


def _f32(a: np.ndarray) -> np.ndarray:
    """Values exactly representable in float32 (smplx casts model arrays through float32)."""
    return np.asarray(a, dtype=np.float32).astype(np.float64)


def random_mano_dict(seed: int) -> dict:
    """A random model with the official MANO keys, shapes and types (not a real hand)."""
    rng = np.random.default_rng(seed)
    v_template = _f32(rng.normal(scale=0.04, size=(V, 3)))
    rows, cols, vals = [], [], []
    for j in range(J):
        idx = rng.choice(V, size=12, replace=False)
        w = rng.uniform(0.2, 1.0, size=12)
        rows += [j] * 12
        cols += idx.tolist()
        vals += (w / w.sum()).tolist()
    J_regressor = scipy.sparse.csc_matrix((_f32(vals), (rows, cols)), shape=(J, V))
    weights = np.zeros((V, J))
    for v in range(V):
        idx = rng.choice(J, size=3, replace=False)
        w = rng.uniform(0.1, 1.0, size=3)
        weights[v, idx] = w / w.sum()
    components, _ = np.linalg.qr(rng.normal(size=(45, 45)))
    kintree = np.array([[4294967295, *MANO_PARENTS[1:]], list(range(J))], dtype=np.int64)
    return {
        "v_template": v_template,
        "shapedirs": _f32(rng.normal(scale=0.003, size=(V, 3, 10))),
        "posedirs": _f32(rng.normal(scale=0.003, size=(V, 3, 135))),
        "J_regressor": J_regressor,
        "weights": _f32(weights),
        "kintree_table": kintree,
        "f": rng.integers(0, V, size=(1538, 3)).astype(np.uint32),
        "hands_components": _f32(components),
        "hands_mean": _f32(rng.normal(scale=0.3, size=45)),
        "J": J_regressor @ v_template,
        "bs_style": "lbs",
        "bs_type": "lrotmin",
    }


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mano_models")
    for seed, name in ((0, "MANO_RIGHT.pkl"), (1, "MANO_LEFT.pkl")):
        with (folder / name).open("wb") as f:
            pickle.dump(random_mano_dict(seed), f, protocol=2)
    return folder


def random_params(B: int, seed: int, scale: float = 0.6):
    g = torch.Generator().manual_seed(seed)
    f64 = torch.float64
    return {
        "betas": torch.randn(B, 10, generator=g, dtype=f64),
        "global_orient": torch.randn(B, 3, generator=g, dtype=f64) * 1.5,
        "hand_pose": torch.randn(B, 45, generator=g, dtype=f64) * scale,
        "transl": torch.randn(B, 3, generator=g, dtype=f64) * 0.3,
    }


# -- exact path vs smplx ------------------------------------------------------------------------


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("flat_hand_mean", [True, False])
def test_exact_matches_smplx(model_dir, side, flat_hand_mean):
    import smplx  # a dev dependency: the reference MANO implementation

    ours = ManoLayer(side=side, model_dir=model_dir, flat_hand_mean=flat_hand_mean)
    assert ours.exact
    ref = smplx.MANO(
        model_path=str(model_dir),
        is_rhand=side == "right",
        use_pca=False,
        flat_hand_mean=flat_hand_mean,
        num_betas=10,
        dtype=torch.float64,
    )
    params = random_params(8, seed=3)
    expected = ref(**params)
    got = ours(**params)
    assert got.vertices.shape == (8, V, 3)
    assert got.joints.shape == (8, J, 3) and got.keypoints.shape == (8, 21, 3)
    torch.testing.assert_close(got.vertices, expected.vertices, atol=1e-5, rtol=0)
    torch.testing.assert_close(got.joints, expected.joints[:, :J], atol=1e-5, rtol=0)
    tip_ids = [MANO_TIP_VERTEX_IDS[f] for f in FINGERS]
    torch.testing.assert_close(
        got.keypoints[:, J:], expected.vertices[:, tip_ids], atol=1e-5, rtol=0
    )
    # float32 inputs give float32 outputs close to the float64 reference.
    got32 = ours(**{k: v.float() for k, v in params.items()})
    assert got32.vertices.dtype == torch.float32
    torch.testing.assert_close(got32.vertices.double(), expected.vertices, atol=1e-4, rtol=0)


def test_exact_from_env_and_wrist_convention(model_dir, monkeypatch):
    monkeypatch.setenv("MANO_MODEL_DIR", str(model_dir))
    layer = ManoLayer()
    assert layer.exact and layer.faces.shape == (1538, 3)
    betas = torch.randn(1, 10, dtype=torch.float64)
    transl = torch.tensor([[0.1, -0.2, 0.3]], dtype=torch.float64)
    rest = layer(betas=betas)
    posed = layer(
        betas=betas, global_orient=torch.tensor([[0.3, -1.0, 2.0]]).double(), transl=transl
    )
    # The global orientation turns the hand about the shaped rest wrist J0; then transl is added.
    torch.testing.assert_close(posed.joints[:, 0], rest.joints[:, 0] + transl)


# -- chumpy-free loading ------------------------------------------------------------------------


def _fake_chumpy(monkeypatch):
    """Install a throw-away ``chumpy`` package with the two node types MANO files use."""
    root = types.ModuleType("chumpy")
    ch = types.ModuleType("chumpy.ch")
    reordering = types.ModuleType("chumpy.reordering")

    class Ch:
        def __init__(self, x):
            self.x = x
            self._dirty_vars = set()

    class Select:
        def __init__(self, a, idxs, preferred_shape):
            self.a, self.idxs, self.preferred_shape = a, idxs, preferred_shape

    Ch.__module__, Ch.__qualname__ = "chumpy.ch", "Ch"
    Select.__module__, Select.__qualname__ = "chumpy.reordering", "Select"
    ch.Ch, reordering.Select = Ch, Select
    root.ch, root.reordering = ch, reordering
    for name, module in (("chumpy", root), ("chumpy.ch", ch), ("chumpy.reordering", reordering)):
        monkeypatch.setitem(sys.modules, name, module)
    return Ch, Select, ch


@pytest.mark.parametrize("protocol", [0, 2])  # 0: copy_reg._reconstructor path, as in old pickles
def test_chumpy_objects_load_without_chumpy(model_dir, tmp_path, monkeypatch, protocol):
    data = random_mano_dict(0)
    plain_shapedirs, plain_weights = data["shapedirs"], data["weights"]
    with monkeypatch.context() as m:
        Ch, Select, fake_module = _fake_chumpy(m)
        # Like the released files: shapedirs is a Select over a Ch holding a larger array.
        wide = np.concatenate([plain_shapedirs, np.zeros((V, 3, 10))], axis=2)  # (V, 3, 20)
        flat_idx = np.arange(wide.size).reshape(wide.shape)[:, :, :10].ravel()
        data["shapedirs"] = Select(Ch(wide), flat_idx, (V, 3, 10))
        data["weights"] = Ch(plain_weights)
        blob = pickle.dumps(data, protocol=protocol)
    assert sys.modules.get("chumpy.ch") is not fake_module  # the loader runs without it
    (tmp_path / "MANO_RIGHT.pkl").write_bytes(blob)

    model = load_mano_model(tmp_path / "MANO_RIGHT.pkl")
    np.testing.assert_array_equal(model.shapedirs, plain_shapedirs)
    np.testing.assert_array_equal(model.weights, plain_weights)
    params = random_params(3, seed=5)
    a = ManoLayer(model_dir=tmp_path)(**params)
    b = ManoLayer(model_dir=model_dir)(**params)
    torch.testing.assert_close(a.vertices, b.vertices, atol=1e-12, rtol=0)


class _Evil:
    def __reduce__(self):
        import os

        return (os.getcwd, ())


def test_loader_refuses_unexpected_globals(tmp_path):
    data = random_mano_dict(0)
    data["payload"] = _Evil()
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_bytes(pickle.dumps(data, protocol=2))
    with pytest.raises(DexCanvasError, match=r"refusing to load global posix\.getcwd|os\.getcwd"):
        load_mano_model(path)


def test_loader_checks_shapes(tmp_path):
    data = random_mano_dict(0)
    data["posedirs"] = data["posedirs"][:, :, :100]
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_bytes(pickle.dumps(data))
    with pytest.raises(ValidationError, match=r"'posedirs'.*\(778, 3, 135\), got \(778, 3, 100\)"):
        load_mano_model(path)


# -- skeleton path ------------------------------------------------------------------------------


def subject_lengths() -> np.ndarray:
    """Default bone lengths × 1.1, with a different extra factor per finger."""
    lengths = HandSkeleton.default().bone_lengths() * 1.1
    for k, finger in enumerate(FINGERS):
        lengths[list(FINGER_BONES[finger])] *= 1.0 + 0.04 * (k - 2)
    return lengths


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_skeleton_keeps_bone_lengths(side, dtype):
    lengths = subject_lengths()
    layer = ManoLayer(side=side, bone_lengths=lengths)
    assert not layer.exact
    np.testing.assert_allclose(layer.skeleton.bone_lengths(), lengths, atol=1e-12)
    params = {k: v.to(dtype) for k, v in random_params(64, seed=11, scale=0.8).items()}
    out = layer(**params)
    assert out.vertices is None and out.keypoints.dtype == dtype
    kp = out.keypoints.double().numpy()
    per_frame = np.stack([measure_bone_lengths(kp[t]) for t in range(kp.shape[0])])  # (T, 20)
    tol = 1e-9 if dtype == torch.float64 else 1e-6
    assert np.abs(per_frame - lengths).max() < tol  # acceptance: < 1 mm for every bone
    measured = measure_bone_lengths(kp)
    for finger in FINGERS:
        idx = list(FINGER_BONES[finger])
        np.testing.assert_allclose(measured[idx], lengths[idx], atol=1e-3)
    # A skeleton rebuilt from the measured lengths has the same bones.
    rebuilt = HandSkeleton.from_keypoints(kp, side=side)
    np.testing.assert_allclose(rebuilt.bone_lengths(), lengths, atol=tol)


def test_bone_length_formats_and_order():
    sk = HandSkeleton.default()
    assert BONE_NAMES == MANO21[1:]
    by_finger = sk.bone_lengths_by_finger()
    assert list(by_finger) == list(FINGERS)
    np.testing.assert_allclose(
        HandSkeleton.from_bone_lengths(by_finger).bone_lengths(), sk.bone_lengths()
    )
    named = dict(zip(BONE_NAMES, sk.bone_lengths(), strict=True))
    np.testing.assert_allclose(
        HandSkeleton.from_bone_lengths(named).rest_keypoints, sk.rest_keypoints
    )
    # Buchholz proportions scale with hand length.
    a = HandSkeleton.anthropometric(0.19)
    np.testing.assert_allclose(
        a.bone_lengths_by_finger()["middle"], np.array([0.446, 0.266, 0.170, 0.108]) * 0.19
    )
    # Openpose order converts before measuring.
    from dexcanvas_core.keypoints import convert_keypoints

    op = convert_keypoints(sk.rest_keypoints, "mano21", "openpose21")
    np.testing.assert_allclose(measure_bone_lengths(op, order="openpose21"), sk.bone_lengths())


def test_skeleton_template_frame_conventions():
    kp = HandSkeleton.default().rest_keypoints
    wrist, middle_tip, thumb_tip, pinky_tip = kp[0], kp[MANO21.index("middle_tip")], kp[16], kp[20]
    assert middle_tip[0] < wrist[0] - 0.15  # fingers along -x
    assert thumb_tip[2] > 0 > pinky_tip[2]  # thumb on +z
    np.testing.assert_allclose(wrist, [0.09566993, 0.00638343, 0.00618631])


def test_skeleton_zero_pose_and_betas():
    layer = ManoLayer()
    rest = layer.skeleton.rest_keypoints
    out = layer.forward_numpy(hand_pose=np.zeros((1, 45)))
    np.testing.assert_allclose(out.keypoints[0], rest, atol=1e-12)
    betas = np.zeros((1, 10))
    betas[0, 0] = 1.0
    scaled = layer.forward_numpy(betas=betas, hand_pose=np.zeros((1, 45))).keypoints[0]
    s = np.exp(layer.beta0_scale_per_unit)
    np.testing.assert_allclose(scaled, rest[0] + s * (rest - rest[0]), atol=1e-12)
    # flat_hand_mean=False adds MANO's mean pose.
    curled = ManoLayer(flat_hand_mean=False)
    np.testing.assert_allclose(
        curled.forward_numpy(hand_pose=np.zeros((1, 45))).keypoints,
        layer.forward_numpy(hand_pose=curled.hands_mean.numpy()[None]).keypoints,
        atol=1e-12,
    )


def test_left_is_mirror_of_right():
    right, left = ManoLayer("right"), ManoLayer("left")
    mirror = np.array([-1.0, 1.0, 1.0])
    zero_r = right.forward_numpy(hand_pose=np.zeros((1, 45))).keypoints
    zero_l = left.forward_numpy(hand_pose=np.zeros((1, 45))).keypoints
    np.testing.assert_allclose(zero_l, zero_r * mirror, atol=1e-12)
    # A mirrored pose gives the mirrored hand.
    p = {k: v.numpy() for k, v in random_params(5, seed=2).items()}
    out_r = right.forward_numpy(
        global_orient=p["global_orient"], hand_pose=p["hand_pose"], transl=p["transl"]
    )
    out_l = left.forward_numpy(
        global_orient=mirror_axis_angle(p["global_orient"]),
        hand_pose=mirror_axis_angle(p["hand_pose"]),
        transl=p["transl"] * mirror,
    )
    np.testing.assert_allclose(out_l.keypoints, out_r.keypoints * mirror, atol=1e-12)


# -- autograd, numpy path, pose layouts ---------------------------------------------------------


@pytest.mark.parametrize("exact", [False, True])
@pytest.mark.parametrize("zero_pose", [False, True])
def test_gradients_match_finite_differences(model_dir, exact, zero_pose):
    layer = ManoLayer(model_dir=model_dir) if exact else ManoLayer()
    p = random_params(2, seed=7)
    hand_pose = torch.zeros_like(p["hand_pose"]) if zero_pose else p["hand_pose"]
    hand_pose.requires_grad_(True)
    betas = p["betas"].clone().requires_grad_(True)

    def keypoints(hp, b):
        return layer(
            betas=b, global_orient=p["global_orient"], hand_pose=hp, transl=p["transl"]
        ).keypoints

    assert torch.autograd.gradcheck(keypoints, (hand_pose, betas), eps=1e-6, atol=1e-6)


def test_rodrigues_matches_scipy():
    from scipy.spatial.transform import Rotation

    aa = np.concatenate([np.random.default_rng(0).normal(size=(50, 3)) * 2, np.full((1, 3), 1e-5)])
    R = axis_angle_to_matrix(torch.as_tensor(aa)).numpy()
    np.testing.assert_allclose(R, Rotation.from_rotvec(aa).as_matrix(), atol=1e-12)


@pytest.mark.parametrize("exact", [False, True])
def test_numpy_path_equals_torch_path(model_dir, exact):
    layer = ManoLayer(model_dir=model_dir) if exact else ManoLayer()
    p = random_params(4, seed=9)
    t = layer(**p)
    n = layer.forward_numpy(**{k: v.numpy() for k, v in p.items()})
    assert isinstance(n.keypoints, np.ndarray) and n.keypoints.dtype == np.float64
    np.testing.assert_allclose(n.keypoints, t.keypoints.detach().numpy(), atol=1e-12)
    np.testing.assert_allclose(n.joints, t.joints.detach().numpy(), atol=1e-12)
    if exact:
        np.testing.assert_allclose(n.vertices, t.vertices.detach().numpy(), atol=1e-12)


def test_48d_pose_layout_and_betas_broadcast():
    layer = ManoLayer()
    p = random_params(3, seed=4)
    pose48 = torch.cat([p["global_orient"], p["hand_pose"]], dim=1)
    a = layer(hand_pose=pose48, transl=p["transl"], betas=p["betas"][:1])
    b = layer(
        global_orient=p["global_orient"],
        hand_pose=p["hand_pose"],
        transl=p["transl"],
        betas=p["betas"][0],
    )
    torch.testing.assert_close(a.keypoints, b.keypoints)


# -- errors -------------------------------------------------------------------------------------


def test_bad_inputs_raise_clear_errors(tmp_path):
    layer = ManoLayer()
    ok = torch.zeros(2, 45)
    with pytest.raises(
        ValidationError, match=r"hand_pose must have shape \(B, 45\) or \(B, 48\), got \(2, 44\)"
    ):
        layer(hand_pose=torch.zeros(2, 44))
    with pytest.raises(
        ValidationError, match=r"global_orient must have shape \(B, 3\) with B = 2, got \(2, 4\)"
    ):
        layer(global_orient=torch.zeros(2, 4), hand_pose=ok)
    with pytest.raises(ValidationError, match=r"batch size.*hand_pose: 2.*transl: 3"):
        layer(hand_pose=ok, transl=torch.zeros(3, 3))
    with pytest.raises(ValidationError, match=r"betas must have shape \(B, 10\).*got \(2, 9\)"):
        layer(hand_pose=ok, betas=torch.zeros(2, 9))
    bad = ok.clone()
    bad[1, 7] = float("nan")
    with pytest.raises(ValidationError, match="hand_pose has NaN or inf"):
        layer(hand_pose=bad)
    with pytest.raises(ValidationError, match="transl has NaN or inf"):
        layer.forward_numpy(hand_pose=np.zeros((1, 45)), transl=np.array([[0.0, np.inf, 0.0]]))
    with pytest.raises(ValidationError, match="global_orient is also given"):
        layer(hand_pose=torch.zeros(2, 48), global_orient=torch.zeros(2, 3))
    with pytest.raises(ValidationError, match="floating-point"):
        layer(hand_pose=torch.zeros(2, 45, dtype=torch.int64))
    with pytest.raises(DexCanvasError, match=r"MANO model file not found: .*MANO_LEFT\.pkl"):
        ManoLayer(side="left", model_dir=tmp_path)
    with pytest.raises(DexCanvasError, match="is not a folder"):
        ManoLayer(model_dir=tmp_path / "nowhere")
    with pytest.raises(UnknownNameError, match="unknown hand side 'centre'"):
        ManoLayer(side="centre")
    with pytest.raises(ValidationError, match=r"bone_lengths must have shape \(20,\)"):
        ManoLayer(bone_lengths=np.ones(19))
    with pytest.raises(ValidationError, match="cannot be combined with model_dir"):
        ManoLayer(model_dir=tmp_path, bone_lengths=np.full(20, 0.03))
    with pytest.raises(
        ValidationError,
        match=r"keypoints must have shape \(T, 21, 3\) or \(21, 3\), got \(4, 20, 3\)",
    ):
        measure_bone_lengths(np.zeros((4, 20, 3)))


def test_missing_env_model_falls_back_to_skeleton(tmp_path, monkeypatch):
    monkeypatch.setenv("MANO_MODEL_DIR", str(tmp_path))
    assert not ManoLayer().exact
