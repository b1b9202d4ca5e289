"""``retarget batch``: rows of a dataset × hands, resumable after kill -9, the same on Ray as on
the local pool, failed jobs recorded with their reasons; ``retarget.retarget`` in memory."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import lance
import numpy as np
import pytest

import retarget
from dexcanvas_core import load_demonstration
from retarget.batch import BatchConfig, run_batch
from retarget.cli import main
from retarget.robot_dataset import (
    ROBOT_SCHEMA_VERSION,
    ROBOT_SCHEMA_VERSION_KEY,
    TENSOR_COLUMNS,
    read_robot_rows,
)

ROOT = Path(__file__).resolve().parents[1]
SMALL = dict(hands=("panda", "allegro"), limit=2, max_frames=60, progress=False)
"""Four fast jobs: two demonstrations cropped to half a second, two fast hands."""
TIMING = ("setup_s", "ms_per_frame")
"""Metrics that measure time, so differ between two runs of the same job."""
IN_HAND_ROW = 37
"""A built-in row of an in-hand type (rolling): the one-actuator Panda gripper cannot do it."""


def by_key(path) -> dict:
    return {(r["uuid"], r["hand"], str(r["method"])): r for r in read_robot_rows(path)}


def assert_same_rows(a, b) -> None:
    ra, rb = by_key(a), by_key(b)
    assert sorted(ra) == sorted(rb)
    for key, x in ra.items():
        y = rb[key]
        for name in TENSOR_COLUMNS:
            if x[name] is None:
                assert y[name] is None, (key, name)
            else:
                np.testing.assert_array_equal(x[name], y[name], err_msg=f"{key} {name}")
        for name in ("status", "success", "joint_names", "config", "model_hash", "source_row"):
            assert x[name] == y[name], (key, name)
        mx = {k: v for k, v in x["metrics"].items() if k not in TIMING}
        my = {k: v for k, v in y["metrics"].items() if k not in TIMING}
        assert mx == my, key


@pytest.fixture(scope="module")
def pool_run(tmp_path_factory) -> Path:
    """The four small jobs, uninterrupted, on the local spawn pool."""
    out = tmp_path_factory.mktemp("pool") / "B.lance"
    summary = run_batch(BatchConfig(out=out, workers=2, **SMALL))
    assert summary["ran"] == 4 and summary["failed"] == 0
    return out


def test_api_in_memory():
    human = load_demonstration("cube2/tripod").slice(0, 30)
    out = retarget.retarget(human, "panda", w_contacts=150.0, calibrate_iterations=0)
    assert out.robot.q_command.shape == (30, 8)
    assert out.metrics["retarget_overrides"] == {"w_contacts": 150.0}
    assert out.success == out.metrics["success"]
    with pytest.raises(retarget.RetargetError, match="no_such_field"):
        retarget.retarget(human, "panda", no_such_field=1)


def test_pool_rows_and_schema(pool_run):
    rows = read_robot_rows(pool_run)
    assert len(rows) == 4
    assert {r["hand"] for r in rows} == {"panda", "allegro"}
    meta = lance.dataset(str(pool_run)).schema.metadata
    assert meta[ROBOT_SCHEMA_VERSION_KEY] == ROBOT_SCHEMA_VERSION.encode()
    for r in rows:
        T, n = r["frames"], len(r["joint_names"])
        assert r["status"] == "ok" and r["reason"] is None and T == 60
        assert r["q"].shape == r["q_command"].shape == r["q_sim"].shape == (T, n)
        assert r["tip_pos_world"].shape == (T, len(r["tip_sites"]), 3)
        assert r["finger_force_world"].shape == (T, len(r["force_parts"]), 3)
        assert r["object_pos_sim"].shape == (T, 3)
        assert r["method"] == {"forces": False, "refine": False, "overrides": {},
                               "max_frames": 60}  # fmt: skip
        assert len(r["model_hash"]) == 64 and r["model_source"]
        assert r["metrics"]["hand"] == r["hand"] and r["config"]["w_contacts"] == 200.0


def test_resume_skips_finished_rows(pool_run, tmp_path):
    again = run_batch(BatchConfig(out=pool_run, workers=2, **SMALL))
    assert again["ran"] == 0 and again["skipped"] == 4 and again["rows"] == 4
    assert len(read_robot_rows(pool_run)) == 4


def test_kill9_then_rerun_gives_the_same_rows(pool_run, tmp_path):
    out = tmp_path / "K.lance"
    cmd = [sys.executable, "-m", "retarget.cli", "batch", "--hands", "panda,allegro",
           "--limit", "2", "--max-frames", "60", "--workers", "1", "--commit-every", "1",
           "--quiet", "--out", str(out)]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(cmd, env=env, start_new_session=True)
    try:
        deadline = time.monotonic() + 300
        # version 1 is the empty dataset; version 2 the first committed row
        while not (out.exists() and (out / "_versions").is_dir() and _version(out) >= 2):
            assert proc.poll() is None, "the batch ended before its first commit"
            assert time.monotonic() < deadline
            time.sleep(0.1)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the batch and its pool's worker
        proc.wait()
    done = len(read_robot_rows(out))
    assert 1 <= done < 4
    rerun = run_batch(BatchConfig(out=out, workers=2, **SMALL))
    assert rerun["ran"] == 4 - done and rerun["rows"] == 4
    assert_same_rows(out, pool_run)


def _version(path: Path) -> int:
    try:
        return lance.dataset(str(path)).version
    except (OSError, ValueError):
        return 0


@pytest.mark.filterwarnings("ignore:lance is not fork-safe")  # Ray forks, then execs
def test_local_ray_equals_pool(pool_run, tmp_path):
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        out = tmp_path / "R.lance"
        summary = run_batch(BatchConfig(out=out, ray_address="local", **SMALL))
        assert summary["ran"] == 4 and summary["failed"] == 0
        assert ray.is_initialized()  # a Ray the caller started is left running
    finally:
        ray.shutdown()
    assert_same_rows(out, pool_run)


def test_failed_job_recorded_with_reason(tmp_path, capsys):
    out = tmp_path / "F.lance"
    args = ["batch", "--hands", "panda", "--rows", f"0,{IN_HAND_ROW}", "--max-frames", "60",
            "--workers", "2", "--out", str(out)]  # fmt: skip
    assert main(args) == 3  # the batch ran; one job failed
    printed = capsys.readouterr().out
    assert "1 failed job(s)" in printed and "cannot perform" in printed
    rows = {r["source_row"]: r for r in read_robot_rows(out)}
    assert rows[0]["status"] == "ok"
    failed = rows[IN_HAND_ROW]
    assert failed["status"] == "failed" and "cannot perform 'rolling'" in failed["reason"]
    assert failed["q"] is None
    skipped = run_batch(BatchConfig(out=out, hands=("panda",), rows=(0, IN_HAND_ROW),
                                    max_frames=60, progress=False))  # fmt: skip
    assert skipped["ran"] == 0 and skipped["failed"] == 1
    retried = run_batch(BatchConfig(out=out, hands=("panda",), rows=(0, IN_HAND_ROW),
                                    max_frames=60, progress=False, retry_failed=True))  # fmt: skip
    assert retried["ran"] == 1 and retried["rows"] == 2
    assert len(read_robot_rows(out)) == 2  # replaced, not duplicated


@pytest.mark.parametrize(
    "extra",
    [["--hands", "no_such_hand"], ["--hands", "panda", "--set", "no_such_field=1"],
     ["--hands", "panda", "--types", "no_such_type"]],
)  # fmt: skip
def test_bad_input_exits_2_before_any_work(tmp_path, extra):
    out = tmp_path / "X.lance"
    assert main(["batch", "--quiet", "--out", str(out), *extra]) == 2
    assert not out.exists()


def test_not_a_robot_dataset_is_refused(tmp_path, capsys):
    out = tmp_path / "human.lance"
    lance.write_dataset(read_table_stub(), str(out))
    assert main(["batch", "--hands", "panda", "--quiet", "--out", str(out)]) == 2
    assert "not a robot trajectory dataset" in capsys.readouterr().err


def read_table_stub():
    import pyarrow as pa

    return pa.table({"x": [1]})


@pytest.mark.slow
def test_acceptance_shadow_allegro_limit_4(tmp_path):
    out = tmp_path / "B.lance"
    args = ["batch", "--hands", "shadow,allegro", "--limit", "4", "--quiet", "--out", str(out)]
    assert main(args) == 0
    rows = read_robot_rows(out, columns=["uuid", "hand", "status"])
    assert len(rows) == 8 and {r["status"] for r in rows} == {"ok"}
    assert len({(r["uuid"], r["hand"]) for r in rows}) == 8
