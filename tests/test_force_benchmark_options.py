"""``benchmarks.force_preservation``: variant selection, ``--set`` overrides and the
human-simulation cache, on a short real demonstration."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from benchmarks.force_preservation import aggregate, cache, cli, config, jobs, plots, tables
from dexcanvas_core.example import example_trajectories
from dexcanvas_core.sim.pipeline import SimConfig, simulate
from dexcanvas_core.trajectory import Contacts, HandTrack, ObjectMove, ObjectTrack, Trajectory
from retarget.human_forces import HUMAN_REPLAY_SEED, human_sim_config


@pytest.fixture(scope="module")
def traj():
    return next(t for t in example_trajectories(seed=0) if t.scene == "cube2").slice(100, 160)


def test_calibration_iterations_default_as_retarget_run_forces():
    """(d) is calibrated as ``retarget run --forces`` is: the same number of iterates."""
    from retarget.force_calibration import ForceCalibrationConfig
    from retarget.pipeline import RunConfig

    n = ForceCalibrationConfig().iterations
    assert config.BenchConfig.calibrate_iterations == RunConfig.calibrate_iterations == n


def test_cache_key_follows_the_demonstration_object_and_tracker(traj):
    key = cache.human_cache_key(traj, "cube2", "mpc")
    assert key == cache.human_cache_key(traj, "cube2", "mpc")  # stable
    assert key != cache.human_cache_key(traj, "cube2h", "mpc")
    assert key != cache.human_cache_key(traj, "cube2", "open_loop")
    moved = copy.deepcopy(traj)
    moved.object.pos[5, 2] += 1e-4  # a tenth of a millimetre on one frame
    assert key != cache.human_cache_key(moved, "cube2", "mpc")


def _assert_identical(a, b, where="trajectory"):
    """``a`` and ``b`` hold the same values: arrays of the same dtype, shape and bits,
    recursively through the trajectory's dataclasses, lists and dicts."""
    if isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, where
        if a.dtype == object:
            assert a.tolist() == b.tolist(), where
        else:
            assert a.tobytes() == b.tobytes(), where
    elif isinstance(a, Trajectory | HandTrack | ObjectTrack | ObjectMove | Contacts):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            _assert_identical(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, list | tuple):
        assert len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_identical(x, y, f"{where}[{k}]")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _assert_identical(a[k], b[k], f"{where}[{k!r}]")
    else:
        assert a == b, where


def test_cache_round_trip_is_exact_and_a_corrupt_entry_is_simulated_again(tmp_path, traj):
    """A force-annotated demonstration (contacts, per-point forces, object wrench, solver
    settings) comes back from the cache bit for bit; the record as it was, marked cached."""
    sim = simulate(traj, SimConfig(tracker="open_loop"))
    assert sim.success and sim.trajectory.contacts.num_pairs > 0
    annotated = sim.trajectory
    assert annotated.contacts.force_world is not None
    res = {"record": {"success": True, "wall_s": 1.5, "failed_at_frame": None}}
    cache.store_human_sim(tmp_path, "k", {**res, "trajectory": annotated})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k.json", "k.npz"]  # no temporaries
    back = cache.load_human_sim(tmp_path, "k")
    assert back["record"] == {**res["record"], "cached": True}
    _assert_identical(annotated, back["trajectory"])
    # a failed simulation: its record only
    cache.store_human_sim(tmp_path, "f", {"record": {"success": False}, "trajectory": None})
    assert not (tmp_path / "f.npz").exists()
    assert cache.load_human_sim(tmp_path, "f") == {
        "record": {"success": False, "cached": True},
        "trajectory": None,
    }
    assert cache.load_human_sim(tmp_path, "absent") is None
    (tmp_path / "k.json").write_text('{"record": {"succ')  # truncated
    assert cache.load_human_sim(tmp_path, "k") is None
    (tmp_path / "f.json").write_text(  # its arrays are missing
        '{"format": 1, "record": {}, "trajectory": {"array": "t", "scalar": false}}'
    )
    assert cache.load_human_sim(tmp_path, "f") is None
    # nothing but the trajectory's own classes is rebuilt from a cache file
    with pytest.raises(TypeError, match="not a trajectory class"):
        cache.encode(SimConfig(), {})
    assert cache.decode(cache.encode((1, [2.5, "x"], {"a": None}), {}), {}) == (
        1,
        [2.5, "x"],
        {"a": None},
    )


def test_variant_selection_is_checked_and_refinement_brings_its_input():
    assert config.BenchConfig(variants=("e",)).computed_variants() == ("d", "e")
    assert config.BenchConfig(variants=("c", "a")).computed_variants() == ("a", "c")
    with pytest.raises(SystemExit, match="--variants"):
        config.BenchConfig(variants=("x",)).validate()


def test_set_refuses_an_unknown_retarget_field():
    with pytest.raises(SystemExit, match="unknown RetargetConfig field"):
        cli.main(["--set", "no_such_weight=1", "--n-pairs", "1"])


def test_refine_set_refuses_an_unknown_refinement_field():
    with pytest.raises(SystemExit, match="--refine-set: unknown RefineConfig field"):
        cli.main(["--refine-set", "no_such_gain=1", "--n-pairs", "1"])


def test_hand_job_runs_only_the_requested_variants_with_the_overrides(traj):
    base = {"hand": "shadow", "index": 0, "pair": "cube2/tripod", "object_id": "cube2"}
    base.update(object_variant="light", frames=traj.num_frames, human_forces=False)
    job = (base, traj, None, "free", ("c",), {}, {}, 6)
    rows = {r["variant"]: r for r in jobs._hand_job(job)}
    assert set(rows) == set(config.RUN_VARIANTS)
    assert all(rows[v]["skipped"] == config.NOT_REQUESTED for v in ("a", "b", "d", "e"))
    assert "error" not in rows["c"] and "success" in rows["c"]
    # an override reaches our retargeter: a refused value fails (c) with the config's message
    bad = {r["variant"]: r for r in jobs._hand_job((*job[:5], {"iterations": 0}, {}, 6))}
    assert "iterations must be >= 1" in bad["c"]["error"]
    # and a valid one changes the solution
    light = {r["variant"]: r for r in jobs._hand_job((*job[:5], {"w_contacts": 1.0}, {}, 6))}
    assert light["c"]["contact_err_mean_m"] != rows["c"]["contact_err_mean_m"]


def test_targets_do_not_compare_with_a_variant_that_was_not_run():
    rows = []
    for i, ok in enumerate((True, False, True)):
        key = {"hand": "shadow", "pair": f"p{i}", "object_id": "cube2", "object_variant": "light"}
        rows.append({**key, "variant": "d", "success": ok, "frames": 10})
        rows.append({**key, "variant": "a", "skipped": config.NOT_REQUESTED, "frames": 10})
    agg = aggregate.aggregate_variants(rows)
    hv = aggregate.heavy_vs_light(rows)
    checks = {c["target"]: c for c in aggregate.target_checks("five", rows, agg, hv)}
    vs_dex = next(c for t, c in checks.items() if "(a)'s" in t)
    assert vs_dex["met"] is None and vs_dex["value"][1] is None
    assert agg["d"]["success_rate"] == 2 / 3
    # (e) was not run either: its success target is not measured (not "met" nor "not met")
    assert checks["(e) strict success ≥ 85 %"]["met"] is None
    # with (a) run and failing everywhere, the same check is measured and met
    for r in rows:
        if r["variant"] == "a":
            del r["skipped"]
            r["success"] = False
    checks = aggregate.target_checks("five", rows, aggregate.aggregate_variants(rows), hv)
    assert next(c for c in checks if "(a)'s" in c["target"])["met"] is True
    # (e) run on the same pairs, lifting all three: its success target is measured and met
    rows += [{**r, "variant": "e", "success": True} for r in rows if r["variant"] == "d"]
    agg = aggregate.aggregate_variants(rows)
    e = next(c for c in aggregate.target_checks("five", rows, agg, aggregate.heavy_vs_light(rows))
             if c["target"].startswith("(e) strict"))  # fmt: skip
    assert e["met"] is True and e["value"] == 1.0 and e["runs"] == 3
    # (e)'s rows carry no forces yet: its correlation target is not measured; with forces on
    # its successful runs (the refined simulation's), it is, over those runs only
    hv = aggregate.heavy_vs_light(rows)
    corr_e = next(c for c in aggregate.target_checks("five", rows, agg, hv)
                  if "successful (e)" in c["target"] and c["name"] == "correlation")  # fmt: skip
    assert corr_e["met"] is None
    for r, c in zip((r for r in rows if r["variant"] == "e"), (0.9, 0.7, 0.95), strict=True):
        r["force_profile_correlation_mean"] = c
    rows.append({**rows[-1], "pair": "p3", "success": False, "force_profile_correlation_mean": 0.0})
    agg = aggregate.aggregate_variants(rows)
    hv = aggregate.heavy_vs_light(rows)
    corr_e = next(c for c in aggregate.target_checks("five", rows, agg, hv)
                  if "successful (e)" in c["target"] and c["name"] == "correlation")  # fmt: skip
    assert corr_e["value"] == pytest.approx(0.85) and corr_e["met"] is True


def test_replay_has_its_own_cache_key_and_the_first_keeps_its_own(traj):
    first = cache.human_cache_key(traj, "cube2", "mpc")
    assert cache.human_cache_key(traj, "cube2", "mpc", None) == first  # caches stay valid
    replay = cache.human_cache_key(traj, "cube2", "mpc", HUMAN_REPLAY_SEED)
    assert replay != first and replay == cache.human_cache_key(
        traj, "cube2", "mpc", HUMAN_REPLAY_SEED
    )
    assert human_sim_config("cube2", "mpc", HUMAN_REPLAY_SEED).mpc.seed == HUMAN_REPLAY_SEED
    assert config.BenchConfig().replays()
    assert not config.BenchConfig(human_tracker="open_loop").replays()
    assert not config.BenchConfig(human_replay=False).replays()


def _finger(corr, profile, share, smoothed=None):
    f = {"correlation": corr, "profile_correlation": profile, "load_share": share}
    return f if smoothed is None else {**f, "profile_correlation_smoothed": smoothed}


def test_replay_ceiling_compares_the_same_runs_and_fingers(tmp_path):
    """The ceiling covers only the variant's successful runs that have a scored replay, and
    only the fingers each run scores (a four-finger hand's, with its load shares)."""
    human = [
        {"index": 0, "object_id": "cube2", "replay": {"force_per_finger": {
            "thumb": _finger(0.9, 0.95, 0.5, 0.97), "index": _finger(0.5, 0.7, 0.4, 0.8),
            "pinky": _finger(0.1, 0.2, 0.1, 0.3)}}},
        {"index": 1, "object_id": "cube2", "replay": {"success": False}},  # not scored
        {"index": 2, "object_id": "cube2h", "replay": {"force_per_finger": {
            "thumb": _finger(0.6, 0.8, 0.6, 0.9), "index": _finger(None, None, 0.0)}}},
    ]  # fmt: skip
    base = {"hand": "leap", "variant": "d", "success": True}
    rows = [
        {**base, "index": 0, "object_id": "cube2",
         "force_correlation_mean": 0.6, "force_profile_correlation_mean": 0.75,
         "force_profile_correlation_mean_smoothed": 0.86,
         "force_per_finger": {"thumb": _finger(0.8, 0.9, 0.55), "index": _finger(0.4, 0.6, 0.03),
                              "middle": _finger(None, None, 0.0)}},
        {**base, "index": 1, "object_id": "cube2", "force_per_finger": {
            "thumb": _finger(0.8, 0.9, 1.0)}},  # its replay failed
        {**base, "index": 2, "object_id": "cube2h", "force_per_finger": {
            "thumb": _finger(0.2, 0.3, 1.0), "index": _finger(0.1, 0.1, 0.2)},
         "force_correlation_mean": 0.15, "force_profile_correlation_mean": 0.2,
         "force_profile_correlation_mean_smoothed": 0.3},
        {**base, "index": 0, "object_id": "cube2", "success": False,
         "force_per_finger": {"thumb": _finger(0.0, 0.0, 1.0)}},  # failed: not compared
        {**base, "index": 0, "object_id": "cube2", "variant": "e", "success": True,
         "force_per_finger": {"thumb": _finger(0.0, 0.0, 1.0)}},  # another variant
    ]  # fmt: skip
    for r in rows:
        r.update(pair=f"p{r['index']}", object_variant="light", frames=10)
    c = aggregate.replay_ceiling(rows, human, "d")
    assert c["runs"] == 2
    # run 0: thumb and index (the pinky is not the run's); run 2: the thumb only
    assert c["replay"]["force_correlation_mean"] == pytest.approx(np.mean([(0.9 + 0.5) / 2, 0.6]))
    assert c["replay"]["force_profile_correlation_mean"] == pytest.approx(
        np.mean([(0.95 + 0.7) / 2, 0.8])
    )
    # load-bearing by the run's shares: run 0's index carries 3 % there, so the thumb only
    assert c["replay"]["force_correlation_mean_load_bearing"] == pytest.approx(np.mean([0.9, 0.6]))
    assert c["ours"]["force_correlation_mean"] == pytest.approx(np.mean([0.6, 0.15]))
    # band-limited: the replay's smoothed correlations on the same fingers
    assert c["replay"]["force_profile_correlation_mean_smoothed"] == pytest.approx(
        np.mean([(0.97 + 0.8) / 2, 0.9])
    )
    ce = aggregate.replay_ceiling(rows, human, "e")  # (e)'s one successful run, its thumb
    assert ce["runs"] == 1 and ce["replay"]["force_correlation_mean"] == pytest.approx(0.9)
    # the targets carry it, and the table shows it
    agg = aggregate.aggregate_variants(rows)
    checks = aggregate.target_checks("four", rows, agg, aggregate.heavy_vs_light(rows), {"d": c})
    prof = next(x for x in checks if "successful (d)" in x["target"] and x["name"] == "correlation")
    assert prof["human_replay"] == c["replay"]["force_profile_correlation_mean"]
    assert prof["same_runs"] == c["ours"]["force_profile_correlation_mean"]
    assert prof["human_replay_runs"] == 2
    assert prof["smoothed_value"] == pytest.approx(np.mean([0.86, 0.3]))
    assert prof["human_replay_smoothed"] == pytest.approx(np.mean([(0.97 + 0.8) / 2, 0.9]))
    e = next(x for x in checks if "successful (e)" in x["target"] and x["name"] == "correlation")
    assert "human_replay" not in e  # no (e) ceiling given
    from rich.console import Console

    con = Console(record=True, width=200)
    con.print(tables.targets_table("four", checks))
    con.print(tables.variants_table("leap", agg, c))
    text = con.export_text()
    assert "human replay 0.81" in text and "same 2 runs: 0.47" in text
    assert "over 50 ms 0.58 (same runs 0.58; human replay 0.89)" in text
    assert "human replay (MPC seed 1 vs 0)" in text
    # the plot's second panel: (d) against the replay per hand
    png = plots.plot_success({"leap": agg}, {}, tmp_path / "fp.png", {"leap": c})
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and not list(tmp_path.glob(".*"))


def test_human_heavy_vs_light_counts_the_force_pipeline_and_its_replays():
    light, heavy = {"object_variant": "light"}, {"object_variant": "heavy", "heavy_version_of": "c"}
    human = [
        {"index": 0, **light, "success": True, "replay": {"success": True}},
        {"index": 0, **heavy, "success": True, "replay": {"success": False}},
        {"index": 1, **light, "success": False},  # no replay: not reproduced
        {"index": 1, **heavy, "success": True, "replay": {"success": True}},
        {"index": 2, **light, "success": True, "replay": {"success": True}},
    ]
    hv = aggregate.human_heavy_vs_light(human)
    assert hv["first"]["light_runs"] == 3 and hv["first"]["light_success_rate"] == 2 / 3
    assert hv["first"]["heavy_success_rate"] == 1.0
    assert hv["first"]["paired_runs"] == 2 and hv["first"]["paired_light_success_rate"] == 0.5
    assert hv["replay"]["light_runs"] == 2 and hv["replay"]["light_success_rate"] == 1.0
    assert hv["replay"]["heavy_success_rate"] == 0.5
    assert hv["replay"]["paired_runs"] == 1  # only demonstration 0 was replayed with both
    assert aggregate.human_heavy_vs_light([h for h in human if "replay" not in h])["replay"] is None
