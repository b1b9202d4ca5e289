"""Safe outputs (dexcanvas_core.safe_io and its users): whole files or none, one writer per
output, checks before any work, ``--overwrite``, and MuJoCo's log kept out of the cwd."""

import json
import logging
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import mujoco
import numpy as np
import pytest

from dexcanvas_core import cli as dexcanvas_cli
from dexcanvas_core.safe_io import (
    LOCK_NAME,
    OutputBusyError,
    OutputError,
    OutputExistsError,
    atomic_path,
    atomic_write_text,
    check_output,
    output_lock,
)
from dexcanvas_core.sim import mujoco_log
from retarget import cli as retarget_cli
from retarget.outputs import RUN_FILES, open_run_dir
from retarget.viz.snapshot import MANIFEST

ROOT = Path(__file__).resolve().parents[1]
RUN = ["run", "--hand", "panda", "--pair", "cube2/tripod", "--quiet"]
"""A fast ``retarget run`` (panda on the built-in cube2/tripod: a few seconds)."""


def _env() -> dict:
    return dict(
        os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    )


def _retarget(*args, **kw) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "retarget.cli", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(), cwd=ROOT, **kw,
    )  # fmt: skip


def _valid_run(d: Path) -> dict:
    with np.load(d / "robot_trajectory.npz") as z:
        assert z["q_command"].shape[1] == 8
    return json.loads((d / "metrics.json").read_text())


# ---------------------------------------------------------------------------- atomic files


def test_atomic_path_unique_hidden_temps_replaced_whole(tmp_path):
    target = tmp_path / "out.npz"
    with atomic_path(target) as a, atomic_path(target) as b:
        assert a != b and a.parent == b.parent == tmp_path
        assert a.name.startswith(".out.npz.") and a.name.endswith(".tmp")
        assert oct(a.stat().st_mode & 0o777) == oct(0o644)  # not world-writable
        with open(a, "wb") as f:  # a file object: np.savez would append ".npz" to a name
            np.savez(f, x=np.arange(3))
        b.write_bytes(b"inner")
    with np.load(target) as z:  # the outer block renamed last: its file, whole
        assert z["x"].tolist() == [0, 1, 2]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.npz"]


def test_atomic_path_removes_temp_and_keeps_old_on_error(tmp_path):
    target = tmp_path / "metrics.json"
    atomic_write_text(target, "old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("writer failed")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json"]


# ---------------------------------------------------------------------------- the lock


def test_lock_refused_while_another_process_holds_it(tmp_path):
    out = tmp_path / "data.parquet"
    holder = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(f"""
            import sys
            from dexcanvas_core.safe_io import output_lock
            with output_lock({str(out)!r}):
                print("held", flush=True)
                sys.stdin.readline()
        """)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=_env(),
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(OutputBusyError, match=rf"another process \(pid {holder.pid}"):
            with output_lock(out):
                pass
    finally:
        holder.communicate("\n", timeout=30)
    with output_lock(out) as lock:  # released with its holder; re-entrant here
        with output_lock(out):
            assert lock.exists()
    assert not lock.exists()


def test_lock_of_a_killed_holder_is_free(tmp_path):
    out = tmp_path / "ds.lance"
    holder = subprocess.Popen(
        [sys.executable, "-c", "from dexcanvas_core.safe_io import output_lock\n"
         f"with output_lock({str(out)!r}):\n    print('held', flush=True)\n"
         "    import time; time.sleep(60)"],
        stdout=subprocess.PIPE, text=True, env=_env(),
    )  # fmt: skip
    assert holder.stdout.readline().strip() == "held"
    holder.kill()
    holder.wait()
    with output_lock(out):  # the kernel dropped the dead holder's lock
        pass


# ---------------------------------------------------------------------------- preflight


def test_check_output_refusals(tmp_path, monkeypatch):
    f = tmp_path / "a.parquet"
    f.write_text("x")
    with pytest.raises(
        OutputExistsError, match=r"--parquet .*a\.parquet already exists; pass --overwrite"
    ):
        check_output(f, overwrite=False, what="--parquet")
    assert check_output(f, overwrite=True) == f
    with pytest.raises(OutputError, match="is a file; give a directory"):
        check_output(f, overwrite=True, kind="dir")
    with pytest.raises(OutputError, match="is a directory; give a file name"):
        check_output(tmp_path, overwrite=True, kind="file")
    with pytest.raises(OutputError, match="is a file, not a directory"):
        check_output(f / "sub" / "x.json", overwrite=False)
    with pytest.raises(OutputError, match=r"only \d+ MiB free .*at least \d+ MiB"):
        check_output(tmp_path / "new", overwrite=False, min_free_bytes=1 << 62)
    run = tmp_path / "run"
    run.mkdir()
    assert check_output(run, overwrite=False, kind="dir", contents=RUN_FILES) == run  # empty
    (run / "metrics.json").write_text("{}")
    with pytest.raises(OutputExistsError, match=r"already holds metrics\.json"):
        check_output(run, overwrite=False, kind="dir", contents=RUN_FILES)
    # stills of a run into its own directory do not replace the run
    with open_run_dir(run, overwrite=False, contents=(MANIFEST,)) as d:
        assert (d / LOCK_NAME).exists()
    assert not (run / LOCK_NAME).exists()
    ro = tmp_path / "ro"
    ro.mkdir()
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: Path(p) != ro)  # root writes anywhere
    with pytest.raises(OutputError, match=r"cannot write in .*ro"):
        check_output(ro / "out", overwrite=False, kind="dir")


# ---------------------------------------------------------------------------- retarget run


@pytest.fixture(scope="module")
def concurrent(tmp_path_factory):
    """Two ``retarget run``s started together on one ``--out``."""
    out = tmp_path_factory.mktemp("concurrent") / "run"
    procs = [_retarget(*RUN, "--out", str(out))]
    time.sleep(0.2)
    procs.append(_retarget(*RUN, "--out", str(out)))
    results = [(p.wait(timeout=300), *p.communicate()) for p in procs]
    return out, results


def test_two_runs_on_one_out_never_corrupt(concurrent):
    out, results = concurrent
    codes = sorted(rc for rc, _, _ in results)
    assert codes in ([0, 0], [0, 2]), results
    for rc, _, err in results:
        if rc == 2:
            assert err.count("\n") == 1 and "Traceback" not in err
            assert "being written by another process" in err or "--overwrite" in err
    _valid_run(out)
    assert sorted(os.listdir(out)) == ["metrics.json", "robot_trajectory.npz"]


def test_run_refuses_existing_run_without_overwrite(concurrent, capsys):
    out, _ = concurrent
    before = (out / "metrics.json").read_text()
    assert retarget_cli.main([*RUN, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--out {out} already holds" in err and "--overwrite" in err
    assert (out / "metrics.json").read_text() == before
    assert retarget_cli.main([*RUN, "--out", str(out), "--overwrite"]) == 0
    assert _valid_run(out)["hand"] == "panda"


def test_bad_out_refused_before_work_without_traceback(tmp_path):
    f = tmp_path / "file"
    f.write_text("not a directory")
    t0 = time.perf_counter()
    for out, msg in ((f, "is a file; give a directory"), (f / "sub", "is a file, not a directory")):
        p = _retarget(*RUN, "--out", str(out))
        rc = p.wait(timeout=120)
        _, err = p.communicate()
        assert rc == 2 and msg in err and "Traceback" not in err, err
    assert time.perf_counter() - t0 < 30  # refused at the start, not after the run


def test_read_only_out_refused_before_work(tmp_path, monkeypatch, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    if os.geteuid() == 0:  # root writes into read-only directories: fake what a user sees
        monkeypatch.setattr(os, "access", lambda p, mode, **kw: Path(p) != ro)
    else:
        ro.chmod(0o555)
    calls = []
    monkeypatch.setattr("retarget.run.run_pipeline", lambda cfg: calls.append(cfg))
    assert retarget_cli.main([*RUN, "--out", str(ro / "run")]) == 2
    err = capsys.readouterr().err
    assert "cannot write in" in err and str(ro) in err and calls == []


def test_kill_during_write_leaves_no_partial_file(tmp_path):
    """kill -9 while the npz is being written: no final file; the hidden temporary may stay."""
    out = tmp_path / "run"
    script = textwrap.dedent(f"""
        import sys, time
        import numpy as np
        savez = np.savez_compressed
        def stuck(f, **arrays):  # the run's npz: half written, then the process hangs
            if "q_command" not in arrays:
                return savez(f, **arrays)
            f.write(b"PK partial zip")
            f.flush()
            print("writing", flush=True)
            time.sleep(120)
        np.savez_compressed = stuck
        from retarget.cli import main
        sys.exit(main({[*RUN, "--out", str(out)]!r}))
    """)
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True,
                         env=_env(), cwd=ROOT)  # fmt: skip
    try:
        assert p.stdout.readline().strip() == "writing"
    finally:
        os.kill(p.pid, signal.SIGKILL)
        p.wait()
    names = sorted(os.listdir(out))
    assert not any(n in names for n in RUN_FILES), names
    assert all(n.startswith(".") for n in names), names  # hidden temp and lock file only
    assert retarget_cli.main([*RUN, "--out", str(out)]) == 0  # the stale lock is no obstacle


# ---------------------------------------------------------------------------- dexcanvas export


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    out = tmp_path_factory.mktemp("safe_export") / "ex.lance"
    assert dexcanvas_cli.main(["example", "--out", str(out)]) == 0
    return out


def test_export_overwrite(example, tmp_path, capsys):
    import pyarrow.parquet as pq

    out = tmp_path / "x.parquet"
    args = ["export", str(example), "--parquet", str(out)]
    assert dexcanvas_cli.main([*args, "--objects", "cube2"]) == 0
    assert dexcanvas_cli.main(args) == 2
    assert "already exists; pass --overwrite" in capsys.readouterr().err
    assert pq.read_table(out).num_rows == 3  # untouched
    assert dexcanvas_cli.main([*args, "--overwrite"]) == 0
    assert pq.read_table(out).num_rows == 18
    assert dexcanvas_cli.main(["export", str(example), "--parquet", str(tmp_path)]) == 2
    assert "is a directory; give the path of a file" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.parquet"]


# ---------------------------------------------------------------------------- MuJoCo's log


def test_mujoco_warnings_go_to_logging_not_cwd(tmp_path, monkeypatch, caplog):
    monkeypatch.chdir(tmp_path)
    assert mujoco.get_mju_user_warning() is mujoco_log._warning
    m = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint/><geom size='.1'/></body></worldbody></mujoco>"
    )
    d = mujoco.MjData(m)
    d.qvel[:] = 1e20  # "Nan, Inf or huge value in QVEL"
    with caplog.at_level(logging.WARNING, logger="dexcanvas_core.mujoco"):
        for _ in range(3):
            mujoco.mj_step(m, d)
    assert d.warning[mujoco.mjtWarning.mjWARN_BADQVEL].number >= 1  # still counted
    assert any("huge value" in r.getMessage() for r in caplog.records)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_keypoints_overwrite(tmp_path, capsys):
    from dexcanvas_core import load_demonstration

    np.save(tmp_path / "kp.npy", load_demonstration("cube2/tripod").hand.joint_pos[:10])
    out = tmp_path / "kp_run"
    args = ["keypoints", "--hand", "leap", "--input", str(tmp_path / "kp.npy"), "--fps", "120"]
    assert retarget_cli.main([*args, "--out", str(out)]) == 0
    assert retarget_cli.main([*args, "--out", str(out)]) == 2
    assert "already holds" in capsys.readouterr().err
    assert retarget_cli.main([*args, "--out", str(out), "--overwrite"]) == 0
    assert sorted(os.listdir(out)) == ["metrics.json", "robot_trajectory.npz"]
