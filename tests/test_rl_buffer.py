"""RLTrajectoryBuffer: per-env trajectories and timesteps, done flags, seeded resets, devices."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from public_layout import public_row, write_public_dataset
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_flatten

from dexcanvas_core.errors import DexCanvasError, UnknownNameError, ValidationError
from dexcanvas_core.loaders import DexCanvasDataset, RLTrajectoryBuffer

LENGTHS = (5, 8, 1, 11)

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


@pytest.fixture(scope="module")
def ds(tmp_path_factory):
    rng = np.random.default_rng(0)
    rows = [public_row(rng, uuid=f"t{i}", T=T) for i, T in enumerate(LENGTHS)]
    rows[2]["contact"] = None  # one trajectory without contacts
    path = tmp_path_factory.mktemp("rl") / "rl.lance"
    write_public_dataset(path, rows)
    return DexCanvasDataset(path)


@pytest.fixture(scope="module")
def samples(ds):
    return [ds[i] for i in range(len(ds))]


def frame(samples, field, traj_ids, timesteps):
    """Expected [E, ...] frames, gathered on the host from the loader samples."""
    return torch.stack(
        [
            samples[int(j)][field][int(t)]
            for j, t in zip(traj_ids.cpu(), timesteps.cpu(), strict=True)
        ]
    )


@pytest.mark.parametrize("device", DEVICES)
def test_observations_are_each_envs_frame_after_k_steps(ds, samples, device):
    buf = RLTrajectoryBuffer(ds, num_envs=32, device=device, seed=1)
    assert buf.fields == ("finger_pose", "wrist_pose", "object_pose")  # t2 has no contacts
    traj = buf.traj_ids.clone()
    assert len(set(traj.tolist())) > 1
    last = torch.tensor(LENGTHS, device=device)[traj] - 1
    for k in range(13):
        obs = buf.get_observations()
        t_expected = torch.clamp(torch.full_like(traj, k), max=last)
        assert torch.equal(obs["timesteps"], t_expected)
        assert torch.equal(obs["traj_ids"], traj)
        for f in buf.fields:
            assert obs[f].shape == (32, *samples[0][f].shape[1:])
            torch.testing.assert_close(
                obs[f].cpu(), frame(samples, f, traj, t_expected), rtol=0, atol=0
            )
        buf.advance_timesteps()


@pytest.mark.parametrize("device", DEVICES)
def test_done_is_first_true_at_the_last_frame_and_clamps(ds, device):
    buf = RLTrajectoryBuffer(ds, num_envs=4, device=device)
    buf.reset_envs(traj_ids=[0, 1, 2, 3])
    lengths = torch.tensor(LENGTHS, device=device)
    # a length-1 trajectory is done at once; the others are not
    assert buf.done.tolist() == [False, False, True, False]
    first_done = [None] * 4
    for step in range(1, 15):
        done = buf.advance_timesteps()
        assert done.dtype == torch.bool and done.shape == (4,)
        assert torch.equal(done, buf.timesteps >= lengths - 1)
        for e in range(4):
            if done[e] and first_done[e] is None:
                first_done[e] = step
        assert torch.equal(
            buf.timesteps, torch.clamp(torch.full_like(lengths, step), max=lengths - 1)
        )
    # done first at step L-1, i.e. when the env shows frame L-1 (the last)
    assert first_done == [4, 7, 1, 10]
    assert buf.done.all()


def test_reset_changes_only_the_selected_envs(ds, samples):
    buf = RLTrajectoryBuffer(ds, num_envs=64, seed=5)
    for _ in range(3):
        buf.advance_timesteps()
    t_before, j_before = buf.timesteps.clone(), buf.traj_ids.clone()
    obs_before = buf.get_observations()
    sel = torch.tensor([1, 3, 40])
    buf.reset_envs(sel)
    others = torch.ones(64, dtype=torch.bool)
    others[sel] = False
    assert (buf.timesteps[sel] == 0).all()
    assert torch.equal(buf.timesteps[others], t_before[others])
    assert torch.equal(buf.traj_ids[others], j_before[others])
    obs = buf.get_observations()
    for f in buf.fields:
        assert torch.equal(obs[f][others], obs_before[f][others])
        torch.testing.assert_close(
            obs[f][sel], frame(samples, f, buf.traj_ids[sel], torch.zeros(3))
        )
    # observations handed out earlier are not changed by later steps
    assert torch.equal(obs_before["timesteps"], t_before)
    # over many resets, the selected envs do get new trajectories
    changed = torch.zeros(3, dtype=torch.bool)
    for _ in range(20):
        buf.reset_envs(sel)
        changed |= buf.traj_ids[sel] != j_before[sel]
        assert torch.equal(buf.traj_ids[others], j_before[others])
    assert changed.all()


def test_mask_and_index_resets_agree(ds):
    a = RLTrajectoryBuffer(ds, num_envs=16, seed=2)
    b = RLTrajectoryBuffer(ds, num_envs=16, seed=2)
    for _ in range(4):
        da, db = a.advance_timesteps(), b.advance_timesteps()
        a.reset_envs(da)
        b.reset_envs(torch.nonzero(db).squeeze(-1))
        assert torch.equal(a.traj_ids, b.traj_ids) and torch.equal(a.timesteps, b.timesteps)
    assert a.reset_envs([]) is None  # resetting nothing is allowed


def run_episodes(ds, seed: int, steps: int = 30) -> list[list[int]]:
    buf = RLTrajectoryBuffer(ds, num_envs=48, seed=seed)
    out = [buf.traj_ids.tolist()]
    for _ in range(steps):
        buf.reset_envs(buf.advance_timesteps())
        out.append(buf.traj_ids.tolist())
    return out


def test_same_seed_same_sequence_different_seed_different(ds):
    a = run_episodes(ds, seed=11)
    assert run_episodes(ds, seed=11) == a
    assert run_episodes(ds, seed=12) != a
    assert a[0] != a[-1]  # resets do draw new trajectories


@pytest.mark.parametrize("device", DEVICES)
def test_every_tensor_lives_on_the_requested_device(ds, device):
    buf = RLTrajectoryBuffer(ds, num_envs=8, device=device)
    dev = torch.device(device)
    tensors = [
        buf.lengths,
        buf.offsets,
        buf.traj_ids,
        buf.timesteps,
        buf.done,
        *buf.frames.values(),
    ]
    tensors += list(buf.get_observations().values())
    tensors += [buf.advance_timesteps()]
    tensors += list(buf.get_future(3).values())
    buf.reset_envs(buf.done)
    tensors += [buf.traj_ids, buf.timesteps, buf.env_lengths]
    assert all(t.device.type == dev.type for t in tensors)


def test_get_future_gives_the_next_frames_clamped(ds, samples):
    buf = RLTrajectoryBuffer(ds, num_envs=4)
    buf.reset_envs(traj_ids=[0, 1, 2, 3])
    buf.advance_timesteps()
    buf.advance_timesteps()  # t = [2, 2, 0, 2]
    fut = buf.get_future(4)
    assert fut["finger_pose"].shape == (4, 4, 45)
    for e, L in enumerate(LENGTHS):
        t = int(buf.timesteps[e])
        want_t = [min(t + k, L - 1) for k in range(1, 5)]
        for f in buf.fields:
            torch.testing.assert_close(fut[f][e], samples[e][f][want_t], rtol=0, atol=0)
        assert fut["future_valid"][e].tolist() == [t + k <= L - 1 for k in range(1, 5)]
    with pytest.raises(ValidationError):
        buf.get_future(0)


def test_contact_force_is_loaded_when_every_trajectory_has_it(ds, samples):
    buf = RLTrajectoryBuffer(ds, num_envs=4, max_trajectories=2)
    assert buf.num_trajectories == 2
    assert buf.fields[-1] == "contact_force"
    obs = buf.get_observations()
    assert obs["contact_force"].shape == (4, 6, 3)
    torch.testing.assert_close(
        obs["contact_force"], frame(samples, "contact_force", buf.traj_ids, buf.timesteps)
    )
    with pytest.raises(ValidationError, match=r"contact_force.*missing from 1 of 4"):
        RLTrajectoryBuffer(ds, num_envs=4, fields=("finger_pose", "contact_force"))


def test_frames_and_trajectory_field(ds, samples):
    buf = RLTrajectoryBuffer(ds, num_envs=2, fields=("timestamp", "finger_pose", "wrist_pose"))
    assert buf.frames["finger_pose"].shape == (sum(LENGTHS), 45)
    assert buf.frames["timestamp"].dtype == torch.float64
    for j in range(len(LENGTHS)):
        for f in buf.fields:
            assert torch.equal(buf.trajectory_field(f, j), samples[j][f])
    with pytest.raises(UnknownNameError):
        buf.trajectory_field("object_pose", 0)


def test_accepts_trajectories(ds):
    trajs = list(ds.iter_trajectories())
    buf = RLTrajectoryBuffer(trajs, num_envs=3, fields=["object_pose"])
    assert buf.fields == ("object_pose",)
    assert buf.lengths.tolist() == list(LENGTHS)
    assert buf.uuids == ("t0", "t1", "t2", "t3")


def test_inputs_are_validated(ds):
    for bad in (0, -3, 2.5, True):
        with pytest.raises(ValidationError, match="num_envs"):
            RLTrajectoryBuffer(ds, num_envs=bad)
    with pytest.raises(DexCanvasError, match="no trajectory"):
        RLTrajectoryBuffer([], num_envs=4)
    with pytest.raises(UnknownNameError, match="did you mean 'finger_pose'"):
        RLTrajectoryBuffer(ds, num_envs=4, fields=["finger_pos"])
    buf = RLTrajectoryBuffer(ds, num_envs=4)
    with pytest.raises(ValidationError, match=r"outside 0\.\.3"):
        buf.reset_envs([0, 4])
    with pytest.raises(ValidationError, match=r"outside 0\.\.3"):
        buf.reset_envs(torch.tensor([-1]))
    with pytest.raises(ValidationError, match="integer"):
        buf.reset_envs(torch.tensor([0.0, 1.0]))
    with pytest.raises(ValidationError, match="shape"):
        buf.reset_envs(torch.ones(5, dtype=torch.bool))
    with pytest.raises(ValidationError, match="traj_ids holds 9"):
        buf.reset_envs([0], traj_ids=[9])
    before = buf.traj_ids.clone()
    with pytest.raises(ValidationError):
        buf.reset_envs([0, 1], traj_ids=[1])
    assert torch.equal(buf.traj_ids, before)  # a failed reset changes nothing


# -- no host round trips in the per-step methods ----------------------------------------------

# aten ops that read device memory on the host (.item(), bool(), int()) or whose output shape
# depends on the data (so a GPU must synchronise to size it).
HOST_SYNC_OPS = {
    "aten::_local_scalar_dense", "aten::item", "aten::is_nonzero", "aten::equal",
    "aten::nonzero", "aten::nonzero_static", "aten::masked_select", "aten::_unique",
    "aten::_unique2", "aten::unique_dim", "aten::unique_consecutive",
}  # fmt: skip


class HostSyncGuard(TorchDispatchMode):
    """Records every aten op; flags host reads, data-dependent shapes, boolean indexing and
    tensors on other devices."""

    def __init__(self, device: torch.device):
        super().__init__()
        self.device = device
        self.ops: list[str] = []
        self.violations: list[str] = []

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        name = func._schema.name
        self.ops.append(name)
        if name in HOST_SYNC_OPS:
            self.violations.append(name)
        if name in ("aten::index", "aten::index_put", "aten::index_put_"):
            indices = args[1] if len(args) > 1 else []
            if any(isinstance(i, torch.Tensor) and i.dtype == torch.bool for i in indices):
                self.violations.append(f"{name} with a boolean mask")
        out = func(*args, **kwargs)
        flat, _ = tree_flatten((args, kwargs, out))
        for t in flat:
            if isinstance(t, torch.Tensor) and t.device.type != self.device.type and t.ndim:
                self.violations.append(f"{name} touches a tensor on {t.device}")
        return out


@pytest.fixture
def no_host_reads(monkeypatch):
    """Make every Python-level route from a tensor to the host raise."""

    def forbid(name):
        def raiser(self, *a, **k):
            raise AssertionError(f"host read: Tensor.{name}")

        return raiser

    def install():
        for name in ("item", "tolist", "numpy", "cpu", "__array__", "__bool__", "__int__",
                     "__float__", "__index__"):  # fmt: skip
            monkeypatch.setattr(torch.Tensor, name, forbid(name))

    return install


def step_many(buf: RLTrajectoryBuffer, n: int) -> None:
    for _ in range(n):
        buf.get_observations()
        buf.get_future(2)
        buf.reset_envs(buf.advance_timesteps())


@pytest.mark.parametrize("device", DEVICES)
def test_per_step_methods_stay_on_device(ds, device, no_host_reads):
    buf = RLTrajectoryBuffer(ds, num_envs=16, device=device)
    guard = HostSyncGuard(torch.device(device))
    no_host_reads()
    with torch.inference_mode(), guard:
        step_many(buf, 12)
    assert "aten::index_select" in guard.ops and "aten::randint" in guard.ops
    assert guard.violations == []
    if torch.device(device).type == "cuda":
        torch.cuda.set_sync_debug_mode("error")
        try:
            step_many(buf, 3)
        finally:
            torch.cuda.set_sync_debug_mode(0)


def test_the_guards_do_catch_host_reads(ds, no_host_reads):
    """The checks above can fail: each of these typical mistakes is caught."""
    x = torch.arange(6)
    for mistake in (
        lambda: x.sum().item(),
        lambda: bool((x > 3).any()),
        lambda: x.nonzero(),
        lambda: x[x > 2],
    ):
        guard = HostSyncGuard(torch.device("cpu"))
        with guard:
            mistake()
        assert guard.violations, mistake
    no_host_reads()
    for mistake in (
        lambda: x.numpy(),
        lambda: x.tolist(),
        lambda: int(x[0]),
        lambda: np.asarray(x),
    ):
        with pytest.raises(AssertionError, match="host read"):
            mistake()


def test_buffer_keeps_working_after_inference_mode(ds):
    buf = RLTrajectoryBuffer(ds, num_envs=8, seed=4)
    ref = RLTrajectoryBuffer(ds, num_envs=8, seed=4)
    with torch.inference_mode():
        step_many(buf, 5)
    step_many(buf, 5)
    step_many(ref, 10)
    assert torch.equal(buf.traj_ids, ref.traj_ids) and torch.equal(buf.timesteps, ref.timesteps)
