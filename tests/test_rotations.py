import numpy as np
import pytest

from dexcanvas_core import rotations as R
from dexcanvas_core.errors import ValidationError


@pytest.fixture
def aa():
    rng = np.random.default_rng(0)
    axes = rng.normal(size=(50, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    return axes * rng.uniform(0, np.pi - 1e-3, size=(50, 1))


def test_round_trips(aa):
    np.testing.assert_allclose(R.matrix_to_aa(R.aa_to_matrix(aa)), aa, atol=1e-9)
    np.testing.assert_allclose(R.quat_wxyz_to_aa(R.aa_to_quat_wxyz(aa)), aa, atol=1e-9)
    np.testing.assert_allclose(R.quat_xyzw_to_aa(R.aa_to_quat_xyzw(aa)), aa, atol=1e-9)
    np.testing.assert_allclose(R.euler_XYZ_to_aa(R.aa_to_euler_XYZ(aa)), aa, atol=1e-9)
    m = R.aa_to_matrix(aa)
    np.testing.assert_allclose(R.quat_wxyz_to_matrix(R.matrix_to_quat_wxyz(m)), m, atol=1e-12)
    np.testing.assert_allclose(R.quat_xyzw_to_matrix(R.matrix_to_quat_xyzw(m)), m, atol=1e-12)


def test_quaternion_conventions_are_what_names_say():
    aa = np.array([0.0, 0.0, np.pi / 2])  # 90° about z
    w = np.cos(np.pi / 4)
    np.testing.assert_allclose(R.aa_to_quat_wxyz(aa), [w, 0, 0, w], atol=1e-12)
    np.testing.assert_allclose(R.aa_to_quat_xyzw(aa), [0, 0, w, w], atol=1e-12)
    np.testing.assert_allclose(R.quat_wxyz_to_xyzw([1, 2, 3, 4]), [2, 3, 4, 1])
    np.testing.assert_allclose(R.quat_xyzw_to_wxyz([2, 3, 4, 1]), [1, 2, 3, 4])
    # Rodrigues by hand: x axis rotated 90° about z is the y axis.
    np.testing.assert_allclose(R.aa_to_matrix(aa) @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_euler_XYZ_is_intrinsic():
    e = np.array([0.3, -0.2, 0.5])
    rx, ry, rz = (R.aa_to_matrix(np.eye(3)[i] * e[i]) for i in range(3))
    np.testing.assert_allclose(R.aa_to_matrix(R.euler_XYZ_to_aa(e)), rx @ ry @ rz, atol=1e-12)


def test_batch_shapes_are_kept(aa):
    x = aa.reshape(5, 10, 3)
    assert R.aa_to_matrix(x).shape == (5, 10, 3, 3)
    assert R.aa_to_quat_wxyz(x).shape == (5, 10, 4)
    assert R.aa_to_matrix(aa[0]).shape == (3, 3)


def test_slerp_midpoint_and_endpoints():
    t = np.array([0.0, 1.0])
    aa = np.array([[0, 0, 0], [0, 0, 1.0]])
    out = R.slerp_aa(t, aa, np.array([0.0, 0.25, 1.0]))
    np.testing.assert_allclose(out, [[0, 0, 0], [0, 0, 0.25], [0, 0, 1.0]], atol=1e-12)
    # Shortest arc: 170° → -170° about z goes through 180°, not through 0.
    aa2 = np.array([[0, 0, np.deg2rad(170)], [0, 0, np.deg2rad(-170)]])
    mid = R.slerp_aa(t, aa2, np.array([0.5]))
    assert np.isclose(np.linalg.norm(mid), np.pi, atol=1e-9)


def test_bad_input_messages():
    with pytest.raises(
        ValidationError, match=r"axis-angle must have shape \(\.\.\., 3\), got \(4,\)"
    ):
        R.aa_to_matrix(np.zeros(4))
    with pytest.raises(ValidationError, match="NaN"):
        R.aa_to_quat_wxyz([np.nan, 0, 0])
    with pytest.raises(ValidationError, match="zero norm"):
        R.quat_wxyz_to_aa([0, 0, 0, 0])
