"""Fault injection: bad inputs, faults and misuses against the command lines and the Python API.

Every case checks the exit contract of :mod:`dexcanvas_core.exits` — bad input is exit 2 with
one line ``<prog> <command>: error: …`` naming the thing and the fix, a run that fails
validation is exit 3, Ctrl-C is 130, never a traceback — and that nothing is lost: a refused
command leaves earlier outputs byte for byte, an interrupted or concurrent one never leaves a
corrupt final file. A generated corpus (``hypothesis``: shapes, dtypes, NaN/inf, unit scale,
truncation) goes through ``retarget keypoints``, ``Trajectory(...).validate()`` and
``dexcanvas validate``: a clean result or the package's error, never exit 1.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
from pathlib import Path

import numpy as np
import pytest
from faults import (
    assert_clean,
    assert_refused,
    assert_run_outputs_whole,
    call,
    digest,
    finish,
    kill,
    leftovers,
    spawn,
    wait_for,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dexcanvas_core.cli import main as dexcanvas
from dexcanvas_core.errors import DexCanvasError, ValidationError
from dexcanvas_core.example import example_trajectories
from dexcanvas_core.exits import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from dexcanvas_core.io import open_dataset, write_dataset
from dexcanvas_core.io.reader import build_filter
from dexcanvas_core.trajectory import HandTrack, ObjectTrack, Trajectory
from retarget.cli import main as retarget
from retarget.errors import RetargetError
from retarget.keypoint_input import keypoints_to_trajectory
from retarget.pipeline import RunConfig
from retarget.retargeter import Retargeter
from retarget.run import run_retarget

CORPUS = settings(
    max_examples=12,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
"""Small and deterministic: the corpus is the same on every machine and run."""


# ------------------------------------------------------------------------------ fixtures


@pytest.fixture(autouse=True)
def no_internal_errors(tmp_path_factory, monkeypatch):
    """Tracebacks of internal errors (exit 1) land in a fresh directory that must stay empty."""
    logs = tmp_path_factory.mktemp("logs")
    monkeypatch.setenv("DEXCANVAS_LOG_DIR", str(logs))
    yield
    written = sorted(p.name for p in logs.iterdir())
    assert not written, f"internal error(s), tracebacks in {logs}: {written}"


@pytest.fixture
def no_work(monkeypatch):
    """Retargeting fails loudly (an internal error, exit 1) if a command starts it: a refusal
    must come before the work."""

    def work(*args, **kwargs):
        raise AssertionError("the retargeting started before the inputs were checked")

    monkeypatch.setattr(Retargeter, "retarget", work)


def _cube2() -> Trajectory:
    return next(t for t in example_trajectories(seed=0) if t.scene == "cube2")


@pytest.fixture(scope="module")
def clip() -> Trajectory:
    """30 frames of a scripted cube2/tripod demonstration (hand closing on the cube)."""
    return _cube2().slice(100, 130)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory, clip) -> Path:
    path = tmp_path_factory.mktemp("data") / "clip.lance"
    write_dataset([clip], path)
    return path


def _run_argv(dataset: Path, out: Path, *extra) -> list:
    return ["run", "--hand", "allegro", "--pair", "cube2/tripod", "--dataset", dataset,
            "--out", out, "--quiet", *extra]  # fmt: skip


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory, dataset) -> Path:
    """A complete ``retarget run`` directory (allegro on the 30-frame clip)."""
    out = tmp_path_factory.mktemp("runs") / "run"
    assert retarget([str(a) for a in _run_argv(dataset, out)]) == EXIT_OK
    return out


@pytest.fixture(scope="module")
def keypoints_m(clip) -> np.ndarray:
    """(30, 21, 3) [m] MANO21 keypoints of the clip."""
    return np.asarray(clip.hand.joint_pos, dtype=np.float64)


def _scaled(traj: Trajectory, factor: float, frames=slice(None)) -> Trajectory:
    """``traj`` with every position (hand translation and keypoints, object) multiplied by
    ``factor`` on ``frames``."""
    h, o = traj.hand, traj.object

    def mul(a):
        a = np.array(a, dtype=np.float64)
        a[frames] *= factor
        return a

    hand = dataclasses.replace(h, global_pos=mul(h.global_pos), joint_pos=mul(h.joint_pos))
    obj = ObjectTrack(o.name, mul(o.pos), o.rot_aa)
    return dataclasses.replace(traj, hands=[hand], objects=[obj], contacts=None)


def _moved(traj: Trajectory, frame: int, offset_m: float) -> Trajectory:
    """``traj`` with the hand at frame ``frame`` moved by ``offset_m`` along x (an outlier)."""
    h = traj.hand
    gp, kp = np.array(h.global_pos, np.float64), np.array(h.joint_pos, np.float64)
    gp[frame, 0] += offset_m
    kp[frame, :, 0] += offset_m
    return dataclasses.replace(
        traj, hands=[dataclasses.replace(h, global_pos=gp, joint_pos=kp)], contacts=None
    )


def _write(tmp_path: Path, name: str, *trajs: Trajectory) -> Path:
    path = tmp_path / name
    write_dataset(list(trajs), path, validate=False)
    return path


# --------------------------------------------------------------------- tracebacks → exit 2


def test_run_out_is_an_existing_file(dataset, tmp_path, no_work, capsys):
    out = tmp_path / "taken"
    out.write_text("keep me")
    o = call(retarget, _run_argv(dataset, out), capsys)
    assert_refused(o, "retarget run", str(out))
    assert out.read_text() == "keep me"


def test_run_out_below_a_file(dataset, tmp_path, no_work, capsys):
    (tmp_path / "file").write_text("keep me")
    out = tmp_path / "file" / "run"
    o = call(retarget, _run_argv(dataset, out), capsys)
    assert_refused(o, "retarget run", str(tmp_path / "file"))
    assert (tmp_path / "file").read_text() == "keep me"


def test_run_out_in_a_read_only_directory(dataset, tmp_path, no_work, capsys, monkeypatch):
    ro = tmp_path / "ro"
    ro.mkdir()
    if os.geteuid() == 0:  # root writes into read-only directories: fake what a user sees
        monkeypatch.setattr(os, "access", lambda p, mode, **kw: Path(p) != ro)
    ro.chmod(0o555)
    try:
        o = call(retarget, _run_argv(dataset, ro / "run"), capsys)
    finally:
        ro.chmod(0o755)
    assert_refused(o, "retarget run", str(ro))
    assert not list(ro.iterdir())


@pytest.mark.parametrize("suffix", [".npy", ".npz"])
def test_keypoints_empty_file(suffix, tmp_path, capsys):
    path = tmp_path / f"empty{suffix}"
    path.write_bytes(b"")
    argv = ["keypoints", "--hand", "allegro", "--input", path, "--fps", "30",
            "--out", tmp_path / "out"]  # fmt: skip
    assert_refused(call(retarget, argv, capsys), "retarget keypoints", str(path))
    assert not (tmp_path / "out").exists()


def _half(path: Path) -> None:
    b = path.read_bytes()
    path.write_bytes(b[: len(b) // 2])


RUN_CORRUPTIONS = {
    "npz cut in half": ("robot_trajectory.npz", _half),
    "npz empty": ("robot_trajectory.npz", lambda p: p.write_bytes(b"")),
    "npz not a zip": ("robot_trajectory.npz", lambda p: p.write_text("q,timestamp\n1,2\n")),
    "npz of a scalar q": (
        "robot_trajectory.npz",
        lambda p: np.savez(p.with_suffix(""), **{k: np.float64(1) for k in _npz_keys()}),
    ),
    "metrics cut in half": ("metrics.json", _half),
    "metrics a list": ("metrics.json", lambda p: p.write_text("[]")),
}


def _npz_keys():
    from retarget.viz.data import _NPZ_KEYS

    return _NPZ_KEYS


@pytest.mark.parametrize("fault", sorted(RUN_CORRUPTIONS))
@pytest.mark.parametrize("command", ["report", "snapshot"])
def test_report_and_snapshot_of_a_damaged_run(command, fault, run_dir, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(run_dir, run)
    name, damage = RUN_CORRUPTIONS[fault]
    damage(run / name)
    before = digest(run)
    if command == "report":
        argv = ["report", run, "--no-snapshots"]
    else:
        argv = ["snapshot", "--run", run, "--out", tmp_path / "stills", "--renderer", "mujoco"]
    line = assert_refused(call(retarget, argv, capsys), f"retarget {command}", name)
    assert "retarget run" in line  # the fix: write the run again
    assert digest(run) == before and not (tmp_path / "stills").exists()


def test_export_to_a_directory(dataset, tmp_path, capsys):
    target = tmp_path / "exports"
    target.mkdir()
    (target / "old.parquet").write_text("keep me")
    o = call(dexcanvas, ["export", dataset, "--parquet", target], capsys)
    assert_refused(o, "dexcanvas export", str(target), "directory", ".parquet")
    assert digest(target) == {"old.parquet": digest(target / "old.parquet")["old.parquet"]}
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("fps", ["0", "-30", "nan", "inf", "1e-6"])
def test_keypoints_implausible_fps(fps, keypoints_m, tmp_path, capsys):
    np.save(tmp_path / "kp.npy", keypoints_m)
    argv = ["keypoints", "--hand", "allegro", "--input", tmp_path / "kp.npy", "--fps", fps,
            "--out", tmp_path / "out"]  # fmt: skip
    assert_refused(call(retarget, argv, capsys), "retarget keypoints", "--fps")
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------- silent overwrite or loss


def test_export_refuses_an_existing_parquet_without_overwrite(dataset, tmp_path, capsys):
    import pyarrow.parquet as pq

    out = tmp_path / "x.parquet"
    out.write_text("keep me")
    o = call(dexcanvas, ["export", dataset, "--parquet", out], capsys)
    assert_refused(o, "dexcanvas export", str(out), "--overwrite")
    assert out.read_text() == "keep me"
    o = call(dexcanvas, ["export", dataset, "--parquet", out, "--overwrite"], capsys)
    assert o.rc == EXIT_OK, o.err
    assert pq.read_table(out).num_rows == 1


@pytest.mark.parametrize("limit", ["-1", "0"])
def test_synthesize_limit_below_one(limit, dataset, tmp_path, capsys):
    out = tmp_path / "syn.lance"
    argv = ["synthesize", "--dataset", dataset, "--out", out, "--expand", "1", "--limit", limit]
    assert_refused(call(dexcanvas, argv, capsys), "dexcanvas synthesize", "--limit", limit)
    assert not out.exists() and not out.with_name(out.name + ".work").exists()


def test_run_refuses_an_earlier_run_without_overwrite(dataset, run_dir, tmp_path, no_work, capsys):
    out = tmp_path / "earlier"
    shutil.copytree(run_dir, out)
    before = digest(out)
    o = call(retarget, _run_argv(dataset, out), capsys)
    assert_refused(o, "retarget run", str(out), "--overwrite")
    assert digest(out) == before


def test_keypoints_refuses_an_earlier_output_without_overwrite(keypoints_m, tmp_path, capsys):
    np.save(tmp_path / "kp.npy", keypoints_m)
    out = tmp_path / "out"
    argv = ["keypoints", "--hand", "allegro", "--input", tmp_path / "kp.npy", "--fps", "120",
            "--out", out]  # fmt: skip
    assert call(retarget, argv, capsys).rc == EXIT_OK
    before = digest(out)
    assert_refused(call(retarget, argv, capsys), "retarget keypoints", "--overwrite")
    assert digest(out) == before
    assert call(retarget, [*argv, "--overwrite"], capsys).rc == EXIT_OK


# ---------------------------------------------------------------------- unclear messages


def test_corrupt_builtin_cache_says_how_to_rebuild(tmp_path, monkeypatch, no_work, capsys):
    from dexcanvas_core.builtin import builtin_demonstration_path
    from dexcanvas_core.taxonomy import Pair

    monkeypatch.setenv("DEXCANVAS_CACHE_DIR", str(tmp_path / "cache"))
    path = builtin_demonstration_path(Pair.parse("cube2/tripod"))
    for f in (path / "data").iterdir():
        _half(f)
    argv = ["run", "--hand", "allegro", "--pair", "cube2/tripod", "--out", tmp_path / "run"]
    assert_refused(call(retarget, argv, capsys), "retarget run", "dexcanvas cache rebuild")


@pytest.fixture(scope="module")
def c3d_file(tmp_path_factory) -> Path:
    """The clip's markers as a C3D file in millimetres (as a Vicon export)."""
    import ezc3d

    from dexcanvas_core.mocap import render_markers

    s = render_markers(_cube2().slice(100, 220), noise_mm=0.0, dropout=0.0, gap_rate=0.0,
                       swap_rate=0.0, seed=1)  # fmt: skip
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [s.fps]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(s.labels)
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, len(s.labels), s.num_frames))
    pts[:3] = np.transpose(s.positions, (2, 1, 0))
    c["data"]["points"] = pts
    path = tmp_path_factory.mktemp("mocap") / "take.c3d"
    c.write(str(path))
    return path


def test_fit_of_a_truncated_c3d(c3d_file, tmp_path, capsys):
    trunc = tmp_path / "trunc.c3d"
    trunc.write_bytes(c3d_file.read_bytes()[: c3d_file.stat().st_size // 2])
    out = tmp_path / "fit.lance"
    o = call(dexcanvas, ["fit", trunc, "--out", out, "--object", "cube2"], capsys)
    line = assert_refused(o, "dexcanvas fit", str(trunc))
    assert "truncat" in line or "120" in line  # said as such, or against the header's count
    assert not out.exists()


def test_fit_in_metres_of_millimetre_markers_names_the_unit(c3d_file, tmp_path, capsys):
    out = tmp_path / "fit.lance"
    argv = ["fit", c3d_file, "--out", out, "--object", "cube2", "--units", "m"]
    line = assert_refused(call(dexcanvas, argv, capsys), "dexcanvas fit", "--units mm")
    assert "degrees stored as radians" not in line
    assert not out.exists()


def test_failed_resimulation_is_exit_3(clip, tmp_path, capsys):
    """The object 20 cm from the hand: the robot grasps air, the object is lost."""
    far = _cube2().slice(120, 220)
    obj = far.object
    pos = np.array(obj.pos, np.float64) + np.array([0.2, 0.0, 0.0])
    far = dataclasses.replace(far, objects=[ObjectTrack(obj.name, pos, obj.rot_aa)], contacts=None)
    data = _write(tmp_path, "far.lance", far)
    out = tmp_path / "run"
    o = call(retarget, _run_argv(data, out), capsys)
    assert "Traceback" not in o.err
    assert o.rc == EXIT_FAILED, o.err
    m = json.loads((out / "metrics.json").read_text())
    assert m["success"] is False
    assert_run_outputs_whole(out, frames=100)


def test_library_rejects_wrong_types(keypoints_m, dataset, no_work):
    with pytest.raises(RetargetError, match="fps"):
        keypoints_to_trajectory(keypoints_m, fps="120")
    with pytest.raises(ValidationError, match="fps"):
        dataclasses.replace(_cube2(), fps="120").validate()
    with pytest.raises((RetargetError, DexCanvasError), match="index"):
        run_retarget(RunConfig(hand="allegro", pair="cube2/tripod", dataset=dataset, index="0"))


def test_build_filter_refuses_a_string_for_a_list():
    with pytest.raises(ValidationError, match=r"write \['cube2'\]"):
        build_filter(objects="cube2")
    with pytest.raises(ValidationError, match="operators"):
        build_filter(operators="operator1")
    assert build_filter(objects=["cube2"]) == "index.scene IN ('cube2')"


def test_benchmark_human_cache_runs_no_pickle(tmp_path):
    """A cache entry holding a pickle (``--human-cache DIR`` from someone else) is not run."""
    from benchmarks.force_preservation.cache import FORMAT, load_human_sim

    marker = tmp_path / "ran"

    class Payload:
        def __reduce__(self):
            return (Path.touch, (marker,))

    np.save(tmp_path / "x.npy", np.array([Payload()], dtype=object), allow_pickle=True)
    with open(tmp_path / "k.npz", "wb") as fh:
        import zipfile

        with zipfile.ZipFile(fh, "w") as z:
            z.write(tmp_path / "x.npy", "t.npy")
    record = {"format": FORMAT, "record": {}, "trajectory": {"__array__": "t"}}
    (tmp_path / "k.json").write_text(json.dumps(record))
    assert load_human_sim(tmp_path, "k") is None
    assert not marker.exists()


# -------------------------------------------------------------- implausible input data


@pytest.fixture(scope="module")
def mm_dataset(tmp_path_factory, clip) -> Path:
    """The clip in millimetres (every position × 1000)."""
    return _write(tmp_path_factory.mktemp("mm"), "mm.lance", _scaled(clip, 1000.0))


@pytest.fixture(scope="module")
def outlier_dataset(tmp_path_factory, clip) -> Path:
    """The clip with the hand 10⁶ m away at frame 7."""
    return _write(tmp_path_factory.mktemp("outlier"), "outlier.lance", _moved(clip, 7, 1e6))


def test_validate_names_a_dataset_in_millimetres(mm_dataset, capsys):
    o = call(dexcanvas, ["validate", mm_dataset], capsys)
    assert "Traceback" not in o.err and o.rc == EXIT_FAILED, (o.rc, o.err)
    assert "0 of 1 rows valid" in o.out and "mm" in o.out


def test_validate_names_an_outlier_frame(outlier_dataset, capsys):
    o = call(dexcanvas, ["validate", outlier_dataset], capsys)
    assert "Traceback" not in o.err and o.rc == EXIT_FAILED, (o.rc, o.err)
    assert "0 of 1 rows valid" in o.out and "frame 7" in o.out


@pytest.mark.parametrize("which", ["mm", "outlier"])
def test_run_refuses_implausible_data(which, mm_dataset, outlier_dataset, tmp_path, no_work,
                                      capsys):  # fmt: skip
    data = {"mm": mm_dataset, "outlier": outlier_dataset}[which]
    o = call(retarget, _run_argv(data, tmp_path / "run"), capsys)
    line = assert_refused(o, "retarget run", "--allow-implausible")
    assert ("mm" in line) if which == "mm" else ("frame 7" in line)
    assert not (tmp_path / "run").exists()


@pytest.fixture(scope="module")
def blowup(tmp_path_factory, mm_dataset):
    """``retarget run --allow-implausible`` on the millimetre dataset, from a scratch
    directory: (exit code, its output directory, the working directory)."""
    cwd = tmp_path_factory.mktemp("cwd")
    out = tmp_path_factory.mktemp("blowup") / "run"
    here = os.getcwd()
    os.chdir(cwd)
    try:
        rc = retarget([str(a) for a in _run_argv(mm_dataset, out, "--allow-implausible")])
    finally:
        os.chdir(here)
    return rc, out, cwd


def test_forced_millimetres_fail_validation_with_mujoco_warnings_recorded(blowup):
    """Millimetre data forced through (``--allow-implausible``) ends as a failed validation
    (exit 3), never a success; MuJoCo's warnings are part of metrics.json (a dict per type,
    empty when the solver did not complain; ``tests/test_plausibility.py`` blows one up)."""
    rc, out, _ = blowup
    assert rc == EXIT_FAILED
    m = json.loads((out / "metrics.json").read_text())
    assert m["success"] is False
    assert isinstance(m["mujoco_warnings"], dict)


def test_mujoco_log_never_lands_in_the_working_directory(blowup):
    _, _, cwd = blowup
    assert not (cwd / "MUJOCO_LOG.TXT").exists()


@pytest.mark.parametrize(
    "case, units, needle",
    [("mm data, no --units", "m", "--units mm"), ("metre data, --units mm", "mm", "--units m"),
     ("all zero", "m", "keypoints")],
)  # fmt: skip
def test_keypoints_implausible_units(case, units, needle, keypoints_m, tmp_path, capsys):
    kp = {"mm data, no --units": 1000.0 * keypoints_m, "metre data, --units mm": keypoints_m,
          "all zero": np.zeros_like(keypoints_m)}[case]  # fmt: skip
    np.save(tmp_path / "kp.npy", kp)
    argv = ["keypoints", "--hand", "allegro", "--input", tmp_path / "kp.npy", "--fps", "120",
            "--units", units, "--out", tmp_path / "out"]  # fmt: skip
    line = assert_refused(call(retarget, argv, capsys), "retarget keypoints", needle)
    assert "qp solver" not in line.lower()
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------- concurrency, kill -9, Ctrl-C


def test_two_concurrent_runs_on_one_out(dataset, tmp_path):
    out = tmp_path / "run"
    argv = _run_argv(dataset, out)
    procs = [spawn("retarget.cli", argv, tmp_path) for _ in range(2)]
    done = [finish(p) for p in procs]
    for o in done:
        assert "Traceback" not in o.err and o.rc in (EXIT_OK, 2), (o.rc, o.err)
        if o.rc == 2:
            assert len(o.error_lines()) == 1 and str(out) in o.err, o.err
    assert EXIT_OK in [o.rc for o in done]
    assert_run_outputs_whole(out, frames=30)
    assert leftovers(tmp_path) == []


def test_kill_9_during_run_leaves_no_corrupt_file(dataset, tmp_path):
    out = tmp_path / "run"
    p = spawn("retarget.cli", _run_argv(dataset, out), tmp_path)
    wait_for(lambda: out.is_dir() and any(out.iterdir()), p, timeout=60)  # it began writing
    kill(p)
    assert_run_outputs_whole(out, frames=30)


@pytest.fixture(scope="module")
def four_rows(tmp_path_factory) -> Path:
    rows = [t.slice(100, 160) for t in example_trajectories(seed=0) if t.scene == "cube2"]
    rows += [dataclasses.replace(r, uuid=r.uuid + "-b") for r in rows[:1]]
    return _write(tmp_path_factory.mktemp("syn"), "rows.lance", *rows[:4])


def test_synthesize_interrupted_then_killed_then_resumed(four_rows, tmp_path):
    """Ctrl-C keeps the finished rows (exit 130), kill -9 keeps them too, and the resumed run
    ends with every rollout exactly once."""
    out = tmp_path / "syn.lance"
    work = out.with_name(out.name + ".work")
    argv = ["synthesize", "--dataset", four_rows, "--out", out, "--expand", "2",
            "--samples", "4"]  # fmt: skip

    def rows_done(n):
        return lambda: len([p for p in work.glob("*.json") if p.name != "settings.json"]) >= n

    p = spawn("dexcanvas_core.cli", argv, tmp_path)
    assert wait_for(rows_done(1), p)
    o = kill(p, signal.SIGINT)
    assert o.rc == EXIT_INTERRUPTED and "Traceback" not in o.err, (o.rc, o.err)
    assert "interrupted" in o.err and not out.exists()
    first = rows_done(1)()
    p = spawn("dexcanvas_core.cli", argv, tmp_path)
    wait_for(rows_done(2), p)
    assert first
    o = kill(p)
    if o.rc == -signal.SIGKILL:  # killed before the end: nothing final written; resume
        assert not out.exists()
        o = finish(spawn("dexcanvas_core.cli", argv, tmp_path))
    assert o.rc == EXIT_OK, o.err
    report = json.loads(out.with_name(out.name + ".report.json").read_text())
    pairs = sorted((r["uuid"], r["index"]) for r in report["rollouts"])
    uuids = [t.uuid for t in open_dataset(four_rows).iter_trajectories()]
    assert pairs == sorted((u, i) for u in uuids for i in range(2))
    kept = [t.uuid for t in open_dataset(out).iter_trajectories()]
    assert len(kept) == len(set(kept)) == report["summary"]["kept"]
    assert not work.exists()


# ------------------------------------------------------------------------ --help teaches


def _leaf_parsers(parser, prefix=()):
    import argparse

    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield prefix, parser
        return
    for name, sub in subs[0].choices.items():
        yield from _leaf_parsers(sub, (*prefix, name))


@pytest.mark.parametrize("module", ["dexcanvas_core.cli", "retarget.cli"])
def test_every_command_has_a_description_an_example_and_its_defaults(module):
    import argparse
    import importlib

    parser = importlib.import_module(module).build_parser()
    missing = []
    for names, p in _leaf_parsers(parser):
        cmd = " ".join((parser.prog, *names))
        if not p.description:
            missing.append(f"{cmd}: no description")
        if not (p.epilog and cmd in p.epilog):
            missing.append(f"{cmd}: no example epilog")
        text = " ".join(p.format_help().split())  # the help as shown, defaults included
        for a in p._actions:
            if a.required or a.help in (None, argparse.SUPPRESS) or not a.option_strings:
                continue
            if a.default in (None, False, argparse.SUPPRESS, []):
                continue
            shown = " ".join(a.help.split())  # the option's own help, then its default
            at = text.find(shown, text.find(a.option_strings[-1], text.find("options:")))
            after = text[at + len(shown) :] if at >= 0 else ""
            if "default" not in shown and not after.lstrip().startswith("(default:"):
                missing.append(f"{cmd} {a.option_strings[-1]}: default not shown")
    assert not missing, "\n".join(missing)


@pytest.mark.parametrize(
    "argv", [["info", "--json"], ["validate"], ["export", "--parquet", "{tmp}/x.parquet"]]
)
def test_one_dataset_spelling(argv, dataset, tmp_path, capsys):
    argv = [a.format(tmp=tmp_path) for a in argv]
    o = call(dexcanvas, [argv[0], "--dataset", dataset, *argv[1:]], capsys)
    assert o.rc == EXIT_OK, o.err


def test_cache_commands(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("DEXCANVAS_CACHE_DIR", str(tmp_path / "cache"))
    o = call(dexcanvas, ["cache", "path"], capsys)
    assert o.rc == EXIT_OK and str(tmp_path / "cache") in o.out, o
    for sub in ("rebuild", "clear"):
        assert call(dexcanvas, ["cache", sub, "--help"], capsys).rc == EXIT_OK


# ----------------------------------------------------------------- the generated corpus


def _keypoint_faults():
    """A keypoint array fault: (frames kept, dtype, NaN/inf injection, unit scale, shape)."""
    return st.fixed_dictionaries(
        {
            "frames": st.integers(0, 4),
            "dtype": st.sampled_from(["float64", "float32", "float16", "int64", "object"]),
            "poison": st.sampled_from([None, np.nan, np.inf, -np.inf, 1e300]),
            "scale": st.sampled_from([1.0, 1000.0, 100.0, 1e-3, 0.0]),
            "shape": st.sampled_from(["ok", "flat63", "20 keypoints", "xyz first", "4-d"]),
            "container": st.sampled_from([".npy", ".npz", ".csv", ".npz-other-key"]),
            "cut": st.sampled_from([None, 0.5, 0.9]),
        }
    )


def _faulty_keypoints(kp: np.ndarray, f: dict) -> np.ndarray:
    a = kp[: f["frames"]] * f["scale"]
    if f["poison"] is not None and a.size:
        a = a.copy()
        a[(a.shape[0] - 1, 3, 1)] = f["poison"]
    a = {
        "ok": a,
        "flat63": a.reshape(a.shape[0], 63),
        "20 keypoints": a[:, :20],
        "xyz first": np.moveaxis(a, -1, 0),
        "4-d": a[None],
    }[f["shape"]]
    return a.astype(f["dtype"]) if f["dtype"] != "object" else a.astype(object)


def _save_keypoints(a: np.ndarray, path: Path, container: str, cut) -> Path:
    if container == ".csv":
        path = path.with_suffix(".csv")
        if a.size:
            np.savetxt(path, a.reshape(a.shape[0], -1), delimiter=",", fmt="%s")
        else:
            path.write_text("")
    elif container == ".npy":
        path = path.with_suffix(".npy")
        np.save(path, a)
    else:
        path = path.with_suffix(".npz")
        key = "keypoints" if container == ".npz" else "kp"
        np.savez(path, **{key: a})
    if cut is not None:
        b = path.read_bytes()
        path.write_bytes(b[: int(len(b) * cut)])
    return path


@CORPUS
@given(f=_keypoint_faults())
def test_corpus_keypoints_cli(f, keypoints_m, tmp_path_factory, capsys):
    """Any keypoint file: ``retarget keypoints`` retargets it (exit 0) or says why not
    (exit 2, one line); never an internal error."""
    d = tmp_path_factory.mktemp("kp")
    a = _faulty_keypoints(keypoints_m, f)
    path = _save_keypoints(a, d / "kp", f["container"], f["cut"])
    argv = ["keypoints", "--hand", "allegro", "--input", path, "--fps", "120",
            "--out", d / "out"]  # fmt: skip
    o = call(retarget, argv, capsys)
    assert_clean(o)
    if o.rc == EXIT_OK:
        with np.load(d / "out" / "robot_trajectory.npz") as z:
            assert np.isfinite(z["q"]).all()


@settings(CORPUS, max_examples=3)
@given(f=_keypoint_faults())
def test_corpus_keypoints_in_millimetres_are_refused(f, keypoints_m, tmp_path_factory, capsys):
    """A well-formed keypoint file in millimetres read as metres is refused as such."""
    d = tmp_path_factory.mktemp("kpmm")
    clean = {**f, "poison": None, "scale": 1000.0, "shape": "ok", "dtype": "float64",
             "cut": None, "frames": max(2, f["frames"]), "container": ".npy"}  # fmt: skip
    path = _save_keypoints(_faulty_keypoints(keypoints_m, clean), d / "kp", ".npy", None)
    argv = ["keypoints", "--hand", "allegro", "--input", path, "--fps", "120",
            "--out", d / "out"]  # fmt: skip
    assert_refused(call(retarget, argv, capsys), "retarget keypoints", "--units mm")


def _trajectory_faults():
    return st.fixed_dictionaries(
        {
            "frames": st.integers(0, 5),
            "field": st.sampled_from(
                [
                    "global_pos",
                    "global_rot_aa",
                    "hand_pose",
                    "joint_pos",
                    "obj_pos",
                    "obj_rot",
                    "timestamp",
                ]
            ),
            "fault": st.sampled_from(
                [
                    "none",
                    "nan",
                    "inf",
                    "drop frame",
                    "extra axis",
                    "float16",
                    "int",
                    "strings",
                    "x1000",
                    "degrees",
                    "reverse time",
                ]
            ),
            "fps": st.sampled_from([120.0, 0.0, -1.0, float("nan"), 60.0]),
        }
    )


def _faulty_trajectory(base: Trajectory, f: dict) -> dict:
    """The keyword arguments of a ``Trajectory`` (and its tracks) with one field broken."""
    T = f["frames"]
    b = base.slice(0, T) if T else base.slice(0, 1)
    h, o = b.hand, b.object
    fields = {
        "global_pos": np.array(h.global_pos, np.float64),
        "global_rot_aa": np.array(h.global_rot_aa, np.float64),
        "hand_pose": np.array(h.hand_pose, np.float64),
        "joint_pos": np.array(h.joint_pos, np.float64),
        "obj_pos": np.array(o.pos, np.float64),
        "obj_rot": np.array(o.rot_aa, np.float64),
        "timestamp": np.array(b.timestamp, np.float64),
    }
    if T == 0:
        fields = {k: v[:0] for k, v in fields.items()}
    a = fields[f["field"]]
    fault = f["fault"]
    if fault in ("nan", "inf") and a.size:
        a.flat[a.size // 2] = np.nan if fault == "nan" else np.inf
    elif fault == "drop frame":
        a = a[1:]
    elif fault == "extra axis":
        a = a[..., None]
    elif fault == "float16":
        a = a.astype(np.float16)
    elif fault == "int":
        a = a.astype(np.int64)
    elif fault == "strings":
        a = a.astype(str)
    elif fault == "x1000":
        a = a * 1000.0
    elif fault == "degrees":
        a = np.degrees(a)
    elif fault == "reverse time":
        a = a[::-1].copy()
    fields[f["field"]] = a
    return fields


def _make(fields: dict, fps: float, uuid: str = "corpus") -> Trajectory:
    hand = HandTrack(
        "right",
        global_pos=fields["global_pos"],
        global_rot_aa=fields["global_rot_aa"],
        hand_pose=fields["hand_pose"],
        joint_pos=fields["joint_pos"],
    )
    obj = ObjectTrack("cube2", fields["obj_pos"], fields["obj_rot"])
    return Trajectory(
        uuid=uuid, timestamp=fields["timestamp"], fps=fps, hands=[hand], objects=[obj],
        scene="cube2", gesture="tripod",
    )  # fmt: skip


@pytest.fixture(scope="module")
def base_trajectory() -> Trajectory:
    return _cube2().slice(100, 110)


@settings(CORPUS, max_examples=60)
@given(f=_trajectory_faults())
def test_corpus_trajectory_validate(f, base_trajectory):
    """Constructing and validating any broken trajectory gives a valid one or the package's
    ``ValidationError`` naming a field; never a numpy or Python exception."""
    fields = _faulty_trajectory(base_trajectory, f)
    try:
        _make(fields, f["fps"]).validate()
    except ValidationError as e:
        assert str(e) and "\n" not in str(e)


@settings(CORPUS, max_examples=3)
@given(f=_trajectory_faults())
def test_corpus_trajectory_implausible_units_are_refused(f, base_trajectory):
    """Positions in millimetres are refused by ``validate()`` (frame and field named)."""
    fields = _faulty_trajectory(base_trajectory, {**f, "fault": "none", "frames": 5})
    for k in ("global_pos", "joint_pos", "obj_pos"):
        fields[k] = fields[k] * 1000.0
    with pytest.raises(ValidationError, match=r"mm|unit|millimetre"):
        _make(fields, 120.0).validate()


@settings(CORPUS, max_examples=6)
@given(f=_trajectory_faults())
def test_corpus_dexcanvas_validate(f, base_trajectory, tmp_path_factory, capsys):
    """A written dataset holding a broken row: ``dexcanvas validate`` says valid (exit 0) or
    lists the bad row (exit 3); never an internal error."""
    fields = _faulty_trajectory(base_trajectory, f)
    try:  # the layout stores the rate as a whole number: a finite one (the API corpus has the rest)
        traj = _make(fields, f["fps"] if np.isfinite(f["fps"]) else 120.0)
    except ValidationError:
        return  # not constructible: the corpus test above covers the message
    path = tmp_path_factory.mktemp("ds") / "d.lance"
    try:
        write_dataset([traj], path, validate=False)
    except DexCanvasError:
        return  # refused at writing, with the package's error
    o = call(dexcanvas, ["validate", path], capsys)
    assert "Traceback" not in o.err
    assert o.rc in (EXIT_OK, EXIT_FAILED), (o.rc, o.err)
    assert ("1 of 1 rows valid" in o.out) == (o.rc == EXIT_OK)
