import numpy as np
import pytest

from dexcanvas_core.demos.feasibility import feasibility
from dexcanvas_core.example import EXAMPLE_PAIRS, OPERATORS, example_trajectories
from dexcanvas_core.mano import HandSkeleton, measure_bone_lengths
from dexcanvas_core.taxonomy import Pair


@pytest.fixture(scope="module")
def trajs():
    return list(example_trajectories(seed=0))


def test_covers_pairs_and_operators_and_validates(trajs):
    assert len(trajs) == len(EXAMPLE_PAIRS) * len(OPERATORS)
    assert {f"{t.scene}/{t.gesture}" for t in trajs} == {str(Pair.parse(p)) for p in EXAMPLE_PAIRS}
    assert all(feasibility(p).feasible for p in EXAMPLE_PAIRS)  # pairs a human hand can do
    for t in trajs:
        t.validate()
        assert t.is_generated


def test_deterministic(trajs):
    again = list(example_trajectories(seed=0))
    for a, b in zip(trajs, again, strict=False):
        np.testing.assert_array_equal(a.hand.joint_pos, b.hand.joint_pos)
    other = next(example_trajectories(seed=1))
    assert not np.allclose(other.object.pos, trajs[0].object.pos)


def test_hand_size_follows_operator(trajs):
    base = HandSkeleton.default("right").bone_lengths()
    for t in trajs:
        measured = measure_bone_lengths(t.hand.joint_pos)
        np.testing.assert_allclose(measured, base * OPERATORS[t.operator], atol=1e-4)


def test_object_moves_only_in_its_segment_and_with_the_hand(trajs):
    for t in trajs:
        m = t.object_move[0]
        z = t.object.pos[:, 2]
        still = np.r_[0 : m.start_frame, m.end_frame + 1 : t.num_frames]
        assert np.ptp(z[still]) < 1e-6
        assert z.max() - z[0] > 0.07  # lifted ~8 cm
        # While lifted, the wrist keeps its offset to the object (a rigid hold).
        mid = (m.start_frame + m.end_frame) // 2
        lo = m.start_frame + 10
        d_mid = t.hand.joint_pos[mid, 0] - t.object.pos[mid]
        d_lo = t.hand.joint_pos[lo, 0] - t.object.pos[lo]
        np.testing.assert_allclose(d_mid, d_lo, atol=2e-3)
