"""The torch forward kinematics agrees with the Pinocchio kinematics of the same hand model."""

import numpy as np
import pytest
import torch

from retarget.errors import RetargetError
from retarget.hands import available_hands, get_hand
from retarget.kinematics import PinocchioKinematics
from retarget.torch_fk import TorchHandFK


@pytest.mark.parametrize("name", available_hands())
def test_matches_pinocchio_on_random_configurations(name):
    hand = get_hand(name)
    model = hand.compile()
    fk = TorchHandFK(hand, dtype=torch.float64)
    kin = PinocchioKinematics(model)
    sites = [*hand.tip_site_names.values(), *hand.keypoint_map.values()]
    rng = np.random.default_rng(0)
    lo = np.where(model.jnt_limited, model.jnt_range[:, 0], -1.0)
    hi = np.where(model.jnt_limited, model.jnt_range[:, 1], 1.0)
    q = rng.uniform(lo, hi, size=(8, model.nq))
    p = fk.site_positions(torch.tensor(q), sites).numpy()
    for b in range(q.shape[0]):
        kin.forward(q[b])
        want = np.stack([kin.site_position(s) for s in sites])
        # pytorch-kinematics parses the URDF origins through its own transforms: ~1e-8 m.
        np.testing.assert_allclose(p[b], want, atol=1e-6)


def test_gradients_flow_and_errors():
    fk = TorchHandFK(get_hand("allegro"), dtype=torch.float64)
    q = torch.zeros((3, fk.nq), dtype=torch.float64, requires_grad=True)
    p = fk.site_positions(q, ["ff_tip_site"])
    p.sum().backward()
    assert q.grad is not None and torch.isfinite(q.grad).all() and q.grad.abs().sum() > 0
    with pytest.raises(RetargetError, match=r"shape \(B, 22\)"):
        fk.site_positions(torch.zeros(3, 5))
    with pytest.raises(RetargetError, match="unknown site"):
        fk.site_positions(torch.zeros(1, fk.nq, dtype=torch.float64), ["nope"])
