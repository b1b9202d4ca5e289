"""``python -m benchmarks.force_pipeline --set FIELD=VALUE``: ablation overrides of the tracker."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

import benchmarks.retarget_speed_quality as bench
from benchmarks._common import config_overrides, parse_override
from benchmarks.force_pipeline.config import BenchConfig, tracking_config
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.example import example_trajectories
from dexcanvas_core.sim.tracker import TrackingConfig
from dexcanvas_core.taxonomy import Pair
from retarget.baselines import DexRetargetingBaseline
from retarget.config import RetargetConfig
from retarget.hands import get_hand


def test_override_parses_python_literals():
    assert parse_override("grip_force_min_n=2") == ("grip_force_min_n", 2)
    assert parse_override(" grip = False ") == ("grip", False)
    assert parse_override("grip_force_floor_n=None") == ("grip_force_floor_n", None)
    assert parse_override("grip_load_clear_m=(0.001, 0.004)") == (
        "grip_load_clear_m",
        (0.001, 0.004),
    )
    for bad in ("grip_force_min_n", "=2", "grip_force_min_n=two"):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_override(bad)


def test_overrides_reach_the_tracking_config():
    cfg = BenchConfig(tracking=(("grip_force_min_n", 2), ("grip_force_floor_n", None)))
    tc = tracking_config(cfg)
    assert tc.grip_force_min_n == 2 and tc.grip_force_floor_n is None
    assert tracking_config(BenchConfig()).grip_force_floor_n == TrackingConfig().grip_force_floor_n


@pytest.mark.parametrize(
    "override, message",
    [
        (("grip_force_mn_n", 2.0), "unknown TrackingConfig field"),
        (("grip_force_min_n", "2"), "takes a number"),
        (("grip_force_min_n", None), "takes a number"),
        (("grip", 1), "True or False"),
    ],
)
def test_bad_overrides_fail_before_any_run(override, message):
    with pytest.raises(ValidationError, match=message):
        BenchConfig(tracking=(override,)).validate()


def test_retarget_benchmark_set_checks_names_and_values_before_any_run():
    """``python -m benchmarks.retarget_speed_quality --set``: RetargetConfig ablations of ours."""
    pairs = [parse_override("w_posture=1e-5"), parse_override("use_self_collision=False")]
    assert config_overrides(pairs, RetargetConfig) == {
        "w_posture": 1e-5,
        "use_self_collision": False,
    }
    for argv, message in (
        (["--set", "w_postur=0"], "unknown RetargetConfig field"),
        (["--set", "w_posture=-1"], "must be finite and >= 0"),
        (["--set", "grip='squeeze'"], "GripConfig.mode: unknown value 'squeeze'"),
    ):
        with pytest.raises(SystemExit, match=message):
            bench.main([*argv, "--out", "/nonexistent/never-written.json"])


def test_retarget_benchmark_times_each_pair_repeatedly_and_keeps_the_median():
    """``--timing-repeats``: both methods timed N times on the same pair, alternating; the
    row's time is the median of the N, the minimum beside it; the outputs are the first run's
    (every repeat computes the same)."""

    hand = get_hand("allegro")
    traj = next(t for t in example_trajectories(seed=0) if t.scene == "cube2").slice(100, 130)
    rows = bench.run_one(
        hand, Pair.parse("cube2/tripod"), traj, DexRetargetingBaseline(hand), timing_repeats=3
    )
    once = bench.run_one(hand, Pair.parse("cube2/tripod"), traj, DexRetargetingBaseline(hand))
    for r, r1 in zip(rows, once, strict=True):
        runs = r["solve_time_s_runs"]
        assert len(runs) == 3 and len(r1["solve_time_s_runs"]) == 1 and min(runs) > 0
        assert r["solve_time_s"] == pytest.approx(float(np.median(runs)))
        assert r["ms_per_frame"] == pytest.approx(1e3 * np.median(runs) / 30)
        assert r["ms_per_frame_min"] == pytest.approx(1e3 * min(runs) / 30)
        assert r["keypoint_err_mean_m"] == pytest.approx(r1["keypoint_err_mean_m"])
    agg = bench.aggregate(rows)
    assert agg[bench.OURS]["ms_per_frame_min"] <= agg[bench.OURS]["ms_per_frame"]
    assert bench._ms({"ms_per_frame": 1.0, "ms_per_frame_min": 0.8}) == "1.000 (min 0.800)"
    assert bench._ms({"ms_per_frame": 1.0, "ms_per_frame_min": 1.0}) == "1.000"
    with pytest.raises(SystemExit, match="--timing-repeats"):
        bench.BenchConfig(timing_repeats=0).validate()
