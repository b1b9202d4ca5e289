"""The scale benchmark's arithmetic on a fabricated result (``benchmarks.scale_report``), and its
command line's ``--help``."""

import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks import scale_report as sr

ROOT = Path(__file__).resolve().parent.parent


def _row(hand, pair, demo_s, cpu, iterates=None):
    row = {"hand": hand, "pair": pair, "demo_s": demo_s, "cpu_s": cpu}
    if iterates is not None:
        row["calibration"] = {"iterations": len(iterates) - 1, "iterates": iterates}
    return row


def _it(success, fe, me):
    return {"success": success, "force_error": fe, "match_error": me}


ITS = [_it(True, 0.5, 0.9), _it(True, 0.4, 0.7), _it(False, 0.1, 0.1), _it(True, 0.3, 0.5),
       _it(True, 0.35, 0.6), _it(True, 0.2, 0.3)]  # fmt: skip
"""Iterates 0..5: the best successful one is 5; among 0..2, 1 (2 lost the object)."""


@pytest.fixture
def rows():
    a = {"human_forces": 8.0, "retarget": 0.4, "resim": 0.2, "retarget_f": 0.4, "resim_f": 0.2,
         "calibrate": 2.0}  # fmt: skip
    b = {"retarget": 1.2, "resim": 0.6, "retarget_f": 1.2, "resim_f": 0.6, "calibrate": 6.0}
    return [_row("shadow", "p", 2.0, a, ITS), _row("allegro", "p", 2.0, b, ITS)]


def test_throughput_pools_demo_seconds_over_cpu_seconds(rows):
    tp = sr.throughput(rows)
    assert tp["human_forces"] == pytest.approx(
        {"demo_s_per_cpu_s": 0.25, "cpu_s_per_demo_s": 4.0, "runs": 1}
    )
    assert tp["retarget"]["cpu_s_per_demo_s"] == pytest.approx(1.6 / 4.0)
    assert tp["calibrate"]["cpu_s_per_demo_s"] == pytest.approx(2.0)
    assert tp["calibrate"]["cpu_s_per_demo_s_per_iterate"] == pytest.approx(2.0 / 5)
    assert "refine" not in tp


def test_chosen_iterate_follows_the_calibration_rule():
    assert sr.chosen_iterate(ITS, 5) == 5
    assert sr.chosen_iterate(ITS, 2) == 1
    assert sr.chosen_iterate([_it(False, 0.1, 0.1)], 0) == 0


def test_calibration_cut_compares_the_choices(rows):
    cut = sr.calibration_cut(rows, 2)
    assert cut["iterations"] == [5, 2]
    assert cut["success"] == [2, 2]
    assert cut["force_error_mean"] == pytest.approx([0.2, 0.4])
    assert cut["runs"][0]["chosen"] == [5, 1]


def _batch(engine, workers, wall, task_s=1.0, n=4, noop=0.002):
    return {"engine": engine, "workers": workers, "wall_s": wall, "noop_roundtrip_s": noop,
            "jobs": [{"wall_s": task_s}] * n, "load": [1.0, 1.0, 1.0], "start_s": 1.0}  # fmt: skip


def test_scaling_summary_speedup_efficiency_and_ray_overhead():
    batches = [_batch("pool", 1, 4.0), _batch("pool", 2, 2.5), _batch("ray", 1, 4.4),
               _batch("ray", 2, 2.9)]  # fmt: skip
    s = sr.scaling_summary(batches)
    assert s["speedup"]["pool 2"] == pytest.approx(1.6)
    assert s["efficiency_2"] == pytest.approx(0.8)
    o = s["ray_overhead"]["2"]
    assert o["per_task_s"] == pytest.approx(0.1)
    assert o["share_of_task"] == pytest.approx(0.1)
    assert o["noop_share_of_task"] == pytest.approx(0.002)
    b = {**_batch("pool", 2, 2.5), "jobs": [{"wall_s": 1.0, "cpu_s": 0.5}] * 4}
    assert sr.cpu_share(b) == pytest.approx(2.0 / 5.0)


def test_projection_arithmetic(rows):
    tp = sr.throughput(rows)
    scaling = {"efficiency_2": 0.5, "ray_overhead": {"2": {"per_task_s": 0.0}}}
    p = sr.project(tp, scaling, cores=(64,), fewer_iterates=2)
    demo_s = sr.RELEASE_HOURS * 3600
    no_f = demo_s * sr.RELEASE_HANDS * (0.4 + 0.2)  # retarget + resim per demo-s
    v = p["variants"]["no_forces"]
    assert v["cpu_hours"] == pytest.approx(no_f / 3600)
    assert v["wall_hours"]["64"] == pytest.approx(no_f / (64 * 0.5) / 3600)
    assert v["met"] == (v["wall_hours"]["64"] <= 1.0)
    assert v["cores_for_target"] == pytest.approx(no_f / (3600 * 0.5))
    assert v["wall_hours_on_64_perfect"] == pytest.approx(no_f / 64 / 3600)
    assert v["cores_for_target_perfect"] == pytest.approx(no_f / 3600)
    f = demo_s * 4.0 + demo_s * sr.RELEASE_HANDS * (0.6 + 2.0)  # human once + hand stages
    assert p["variants"]["forces"]["cpu_hours"] == pytest.approx(f / 3600)
    f2 = demo_s * 4.0 + demo_s * sr.RELEASE_HANDS * (0.6 + 2 * 0.4)
    assert p["variants"]["forces_2_iterates"]["cpu_hours"] == pytest.approx(f2 / 3600)
    assert sum(p["forces_cost_shares"].values()) == pytest.approx(1.0)
    # Ray's overhead per task is added in proportion to the task's CPU time
    scaling["ray_overhead"]["2"]["per_task_s"] = 1.0
    q = sr.project(tp, scaling, cores=(64,))["variants"]["no_forces"]
    task = demo_s / sr.RELEASE_SEQUENCES * 0.6
    assert q["ray_overhead_share"] == pytest.approx(1.0 / task)
    assert q["wall_hours"]["64"] == pytest.approx(v["wall_hours"]["64"] * (1 + 1.0 / task))


def test_help():
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.scale", "--help"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    assert "--workers" in out and "--ray" in out and "--quick" in out


def test_targets_from_a_record(rows):
    batches = [_batch("pool", 1, 4.0), _batch("pool", 2, 2.0), _batch("ray", 1, 4.0),
               _batch("ray", 2, 2.2 + 0.2)]  # fmt: skip
    sc = sr.scaling_summary(batches)
    for b in batches:
        b["jobs"] = [{"wall_s": 1.0, "cpu_s": b["wall_s"] * b["workers"] / 4}] * 4  # full cores
    doc = {"scaling": sc, "batches": batches,
           "projection": sr.project(sr.throughput(rows), sc, cores=(64,))}  # fmt: skip
    met = {t["target"]: t["met"] for t in sr.targets(doc)}
    assert met["Ray overhead ≤ 5 % of task time"] is False  # 0.1 s of a 1 s task
    assert met["2 workers ≥ 1.8× one (pool)"] is True
    assert met["2 workers ≥ 1.8× one (ray)"] is False  # 4.0 / 2.4
    assert met["no_forces: ≤ 1 h on 64 cores"] is doc["projection"]["variants"]["no_forces"]["met"]
    batches[1]["jobs"] = [{"wall_s": 1.0, "cpu_s": 0.5}] * 4  # 2 of 4 core-seconds: contended
    assert {t["target"]: t["met"] for t in sr.targets(doc)}["2 workers ≥ 1.8× one (pool)"] is None
