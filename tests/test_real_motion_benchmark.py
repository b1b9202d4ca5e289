"""``benchmarks.real_motion``: the cases it builds, its resumable job store, strict success
inside the contact window, the MANO pipeline's failure reasons and the missing-captures notes.
Nothing here reads real captures or runs a hand."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console
from test_capture_import import capture_arrays

import benchmarks.real_motion.aggregate as rm_aggregate
import benchmarks.real_motion.cases as rm_cases
import benchmarks.real_motion.config as rm_config
import benchmarks.real_motion.jobs as rm_jobs
import benchmarks.real_motion.tables as rm_tables
from dexcanvas_core.capture.formats.mano_npz import read_mano_npz
from dexcanvas_core.capture.stress import StressMotion
from dexcanvas_core.taxonomy import clear_objects


@pytest.fixture(autouse=True)
def _no_objects():
    clear_objects()
    yield
    clear_objects()


def _console() -> Console:
    return Console(file=io.StringIO(), width=200)


def _case(name="stress/x", window=(10, 19), frames=30, uuid="u1") -> rm_cases.Case:
    return rm_cases.Case(
        name=name,
        source="stress",
        dataset="/nowhere.lance",
        index=0,
        uuid=uuid,
        object="testbox",
        frames=frames,
        fps=120.0,
        window=window,
    )


# ----------------------------------------------------------------------------------- cases
def test_stress_cases_are_written_imported_once_and_listed(tmp_path):
    src = dict(capture_arrays(), fps=np.float64(120.0))
    motions = (
        StressMotion("carry", peak_speed=1.5, distance_m=0.3),
        StressMotion("fast_lift", time_scale=3.0),
    )
    reports = rm_cases.write_stress_captures(
        {"testbox/tripod": src}, motions, tmp_path / "npz", True
    )
    names = [r["name"] for r in reports]
    assert names == [
        "testbox-tripod__original",
        "testbox-tripod__carry-0.3m-1.5mps",
        "testbox-tripod__fast_lift-x3",
    ]
    carry = reports[1]
    assert carry["peak_speed_mps"] >= 1.5 * 0.95  # the whole clip: the move, or its own lift
    assert carry["inserted_frames"] > 0 and carry["motion"] == "carry-0.3m-1.5mps"
    files = sorted((tmp_path / "npz").glob("*.npz"))
    assert [f.stem for f in files] == sorted(names)
    assert [n for n, _, _ in read_mano_npz(tmp_path / "npz")] == sorted(names)

    out = tmp_path / "stress.lance"
    paths = [tmp_path / "npz" / f"{n}.npz" for n in names]
    fresh, stamp = rm_cases.import_once("mano-npz", paths, out)
    assert fresh and len(stamp["sequences"]) == 3
    assert rm_cases.import_once("mano-npz", paths, out)[0] is False  # the same inputs: reused
    assert (
        rm_cases.import_once("mano-npz", paths[:2], out)[0] is True
    )  # other inputs: imported again
    rm_cases.import_once("mano-npz", paths, out)

    extra = {r["name"]: {k: v for k, v in r.items() if k != "name"} for r in reports}
    cases = rm_cases.cases_of_dataset(out, "stress", extra)
    assert [c.name for c in cases] == [f"stress/{n}" for n in names]
    by = {c.name.split("/", 1)[1]: c for c in cases}
    c = by["testbox-tripod__carry-0.3m-1.5mps"]
    assert c.index == names.index("testbox-tripod__carry-0.3m-1.5mps")
    assert c.frames == len(src["wrist_pos"]) + carry["inserted_frames"]
    assert c.window == (10, 39 + carry["inserted_frames"])  # the contact window, moved
    assert c.info["peak_speed_mps"] == carry["peak_speed_mps"]
    assert rm_cases.Case.from_dict(json.loads(json.dumps(c.as_dict()))) == c
    # the filters
    assert [x.name for x in rm_cases.filter_cases(cases, ["carry", "fast"], None)] == names_with(
        cases, ("carry", "fast")
    )
    assert len(rm_cases.filter_cases(cases, [], 2)) == 2


def names_with(cases, subs):
    return [c.name for c in cases if any(s in c.name for s in subs)]


def test_stress_motions_are_the_issues():
    got = [m.name for m in rm_config.stress_motions()]
    assert got == [
        "carry-0.3m-1.5mps",
        "transport-0.45m-2mps",
        "transport-0.7m-2.5mps",
        "transport-1m-3mps",
        "tool_use-60deg-4radps",
        "fast_lift-x3",
    ]


# ---------------------------------------------------------------------------- missing data
def test_missing_captures_are_named_with_where_to_get_them(tmp_path):
    readers = {"mano-npz": None, "ho3d": None, "taco": None}
    found, notes = rm_cases.find_real_captures(tmp_path, None, 1, readers=readers)
    assert found == []
    text = "\n".join(notes)
    assert (
        "DexYCB HO3D-style meta pickles (github Shurui8860/dexYCB_dataloader) not found under "
        f"{tmp_path / 'dexycb'}" in text
    )
    assert f"not found under {tmp_path / 'taco'}" in text
    assert f"not found under {tmp_path / 'mano-npz'}" in text
    # a format without a reader here is skipped, and said so
    _, notes = rm_cases.find_real_captures(tmp_path, None, 1, readers={"mano-npz": None})
    assert any("format 'ho3d' has no reader" in n for n in notes)
    assert any("format 'taco' has no reader" in n for n in notes)
    assert "no --captures" in rm_cases.find_real_captures(None, None, 1, readers=readers)[1][0]


def _dexycb_tree(root: Path, objects: dict[str, str]) -> None:
    for rel in objects:
        meta = root / rel / "meta"
        meta.mkdir(parents=True)
        (meta / "0000.pkl").write_bytes(b"")


def test_dexycb_selection_takes_dexcanvas_items_round_robin_over_subjects(tmp_path):
    objects = {
        "subj-a/s1": "011_banana",
        "subj-a/s2": "011_banana",
        "subj-a/s3": "002_master_chef_can",
        "subj-b/s4": "011_banana",
        "subj-b/s5": "037_scissors",
        "subj-c/s6": "052_extra_large_clamp",
    }
    _dexycb_tree(tmp_path / "dexycb", objects)

    def name_of(seq):
        return objects[f"{seq.parent.name}/{seq.name}"]

    rel = [
        f"{p.parent.name}/{p.name}" for p in rm_cases.select_dexycb(tmp_path / "dexycb", 2, name_of)
    ]
    assert rel == ["subj-a/s1", "subj-b/s4", "subj-b/s5", "subj-c/s6"]
    rel = [
        f"{p.parent.name}/{p.name}" for p in rm_cases.select_dexycb(tmp_path / "dexycb", 5, name_of)
    ]
    assert rel == ["subj-a/s1", "subj-b/s4", "subj-a/s2", "subj-b/s5", "subj-c/s6"]
    # found, but no YCB models: said so
    readers = {"mano-npz": None, "ho3d": None, "taco": None}
    found, notes = rm_cases.find_real_captures(
        tmp_path,
        None,
        1,
        readers=readers,
        select=lambda d, n: rm_cases.select_dexycb(d, n, name_of),
    )
    assert any("no YCB models: give --models DIR" in n for n in notes)
    found, _ = rm_cases.find_real_captures(
        tmp_path,
        tmp_path,
        1,
        readers=readers,
        select=lambda d, n: rm_cases.select_dexycb(d, n, name_of),
    )
    assert [(label, fmt, len(p)) for label, fmt, p in found] == [("dexycb", "ho3d", 3)]


# ------------------------------------------------------------------------------- job store
def test_job_store_records_atomically_and_a_rerun_skips_finished_jobs(tmp_path):
    store = rm_jobs.JobStore(tmp_path)
    case = _case()
    mano, hand = rm_jobs.plan_jobs([case], ["shadow"], ("keypoints", "mano"), tmp_path)
    assert [s["key"] for s in mano] == ["mano/mano/stress/x"]
    assert [s["key"] for s in hand] == ["keypoints/shadow/stress/x"]
    key = hand[0]["key"]
    assert store.done(key) is None
    rec = {
        "key": key,
        "uuid": "u1",
        "case": "stress/x",
        "hand": "shadow",
        "mode": "keypoints",
        "success": True,
        "strict_success": True,
    }
    p = store.save(rec)
    assert p.parent == store.dir and not [f for f in store.dir.iterdir() if f.name.startswith(".")]
    assert store.done(key, "u1") == rec
    assert store.done(key, "another capture") is None  # the case changed: run again
    # a write that crashed before its rename leaves a temporary file: ignored
    (store.dir / f".{store.path(mano[0]['key']).name}.tmp-999").write_text('{"key": "mano/')
    assert store.done(mano[0]["key"]) is None
    store.path(mano[0]["key"]).write_text('{"key": "mano/ma')  # a torn file: not finished
    assert store.done(mano[0]["key"]) is None
    # an error is finished unless asked to retry it
    store.save({**rec, "key": "forces/shadow/stress/x", "error": "RuntimeError: boom"})
    assert store.done("forces/shadow/stress/x") is not None
    assert store.done("forces/shadow/stress/x", retry_errors=True) is None

    # a rerun with every job finished runs nothing (no process pool is started)
    store.save({**rec, "key": mano[0]["key"], "mode": "mano", "hand": "mano"})
    sched = rm_jobs.Scheduler(store)
    console = _console()
    sched.run(mano, hand, workers=1, console=console)
    assert "2 finished before" in console.file.getvalue()
    assert set(sched.records) == {key, mano[0]["key"]}


def test_force_modes_wait_for_the_mano_job_and_fail_without_human_forces(tmp_path):
    store = rm_jobs.JobStore(tmp_path)
    case = _case()
    _, hand = rm_jobs.plan_jobs([case], ["shadow"], ("forces",), tmp_path)
    sched = rm_jobs.Scheduler(store)
    assert sched.ready(hand[0]) is None  # its MANO job has not run yet
    mano_key = rm_jobs.job_key(rm_config.MANO, rm_config.MANO, case.name)
    sched.records[mano_key] = {"key": mano_key, "success": True, "human_dataset": "/h.lance"}
    assert sched.ready(hand[0])["human_dataset"] == "/h.lance"
    sched.records[mano_key] = {"key": mano_key, "success": False, "failed_at_frame": 12}
    rec = sched.ready(hand[0])
    assert rec["strict_success"] is False and "lost the object at frame 12" in rec["skipped"]
    assert store.done(hand[0]["key"], case.uuid) == rec


# --------------------------------------------------------------------------------- metrics
def test_strict_success_counts_only_the_contact_window():
    err = np.full(30, 0.01)
    err[3] = 0.2  # before the window: the approach
    err[25] = 0.3  # after it: the release
    w = rm_aggregate.window_check(err, (10, 19))
    assert w == {"ok": True, "max_m": 0.01, "first_bad_frame": None}
    err[14] = 0.051
    w = rm_aggregate.window_check(err, (10, 19))
    assert not w["ok"] and w["first_bad_frame"] == 14 and w["max_m"] == pytest.approx(0.051)
    assert rm_aggregate.window_check(err, None)["first_bad_frame"] == 3  # no window: the clip
    assert rm_aggregate.window_check(err, (20, 99))["first_bad_frame"] == 25  # clipped to the clip
    err[14] = math.nan
    assert not rm_aggregate.window_check(err, (10, 19))["ok"]
    # trackers that stop at their failure: kept through the window's end or not
    assert rm_aggregate.kept_through_window(True, None, (10, 19), 30)
    assert rm_aggregate.kept_through_window(False, 20, (10, 19), 30)
    assert not rm_aggregate.kept_through_window(False, 19, (10, 19), 30)
    assert not rm_aggregate.kept_through_window(False, 4, (10, 19), 30)


def test_retarget_record_uses_the_refinement_where_the_open_loop_failed():
    case = _case()
    err = np.full(30, 0.01)
    err[12] = 0.08
    arrays = {"object_pos_err": err, "wrist_pos_tracking_err": np.full(30, 0.004)}
    m = {
        "success": False,
        "first_failure_frame": 12,
        "object_pos_err_max_m": 0.08,
        "wrist_pos_tracking_err_mean_m": 0.004,
        "wrist_rot_tracking_err_mean_deg": 0.2,
        "penetration_max_m": 0.001,
        "ms_per_frame": 0.5,
    }
    rec = rm_aggregate.retarget_record(m, arrays, case)
    assert rec["strict_success"] is False and rec["window_first_failure_frame"] == 12
    assert rec["object_err_max_window_m"] == pytest.approx(0.08)
    refined = {"success": False, "failed_at_frame": 25, "object_pos_err_max_m": 0.06}
    rec = rm_aggregate.retarget_record({**m, "refine": refined}, arrays, case)
    assert rec["strict_success"] is True and rec["strict_from"] == "refined"
    assert rec["object_err_max_window_m"] == 0.06
    refined["failed_at_frame"] = 15
    assert (
        rm_aggregate.retarget_record({**m, "refine": refined}, arrays, case)["strict_success"]
        is False
    )


def test_mano_failure_phase():
    assert rm_aggregate.failure_phase(54, (10, 59), 60) == "in the window"
    assert rm_aggregate.failure_phase(54, (56, 59), 60) == "before the window"
    assert rm_aggregate.failure_phase(54, (0, 50), 60) == "after the window"


def test_summary_targets_and_page():
    recs = []
    for i in range(10):
        ok = i < 8
        recs.append(
            {
                "key": f"mano/mano/c{i}",
                "case": f"c{i}",
                "hand": "mano",
                "mode": "mano",
                "success": ok,
                "strict_success": ok,
                "object_err_max_window_m": 0.01,
                "failed_at_frame": None if ok else 50,
                "failure": None if ok else {"reason": "slip"},
            }
        )
        for h in ("shadow", "svh"):
            recs.append(
                {
                    "key": f"forces_refine/{h}/c{i}",
                    "case": f"c{i}",
                    "hand": h,
                    "mode": "forces_refine",
                    "success": i < 6,
                    "strict_success": i < 7,
                    "wrist_pos_err_mean_m": 0.004,
                    "object_err_max_window_m": 0.02,
                    "penetration_max_m": 0.001,
                    "ms_per_frame": 0.5,
                    "wall_s": 3.0,
                }
            )
    recs.append(
        {
            "key": "forces_refine/shadow/c10",
            "case": "c10",
            "hand": "shadow",
            "mode": "forces_refine",
            "success": False,
            "strict_success": False,
            "error": "RuntimeError: boom",
        }
    )
    s = rm_aggregate.summarize(recs, ["shadow", "svh"], ["shadow", "svh"])
    per = s["per_hand_mode"]
    assert per["mano"]["strict_success_rate"] == pytest.approx(0.8)
    assert per["mano"]["failure_reasons"] == {"slip": 2}
    assert per["shadow/forces_refine"]["strict_success_rate"] == pytest.approx(7 / 11)
    assert per["shadow/forces_refine"]["errors"] == 1
    assert per["five-finger/forces_refine"]["runs"] == 21
    t = {
        (c["target"].split(" ")[0] + " " + c["target"].split(" ")[-2], c.get("scope")): c["met"]
        for c in s["targets"]
    }
    assert t[("MANO 80", None)] is True
    assert t[("--forces 70", "svh")] is True and t[("--forces 70", "shadow")] is False
    assert t[("--forces mm", "five-finger hands")] is True
    doc = {
        "cases": [
            {"name": f"c{i}", "frames": 100, "window": [1, 2], "info": {}} for i in range(11)
        ],
        "hands": ["shadow", "svh"],
        "records": recs,
        "summary": s,
        "config": {"modes": ["forces_refine", "mano"]},
        "notes": ["x missing"],
    }
    page = rm_tables.page_markdown(doc, Path("benchmarks/results/real_motion/x.json"))
    assert "| c9 | ✗ 2.0 | ✗ 2.0 | ✗ slip @50 |" in page
    assert "| c0 | ✓ 2.0 | ✓ 2.0 | ✓ 1.0 |" in page
    assert "- x missing" in page and "`forces_refine/shadow/c10`: RuntimeError: boom" in page
    rm_tables.print_tables(doc, _console())
