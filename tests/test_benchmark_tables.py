"""``benchmarks.force_preservation``: success by contact error and light / heavy success
by wrench feasibility, from hand-made rows."""

from __future__ import annotations

import pytest
from rich.console import Console

from benchmarks.force_preservation.aggregate import (
    WRENCH_FEASIBLE,
    by_contact_error,
    correlation_by_reach,
    heavy_vs_light_by_wrench,
)
from benchmarks.force_preservation.tables import contact_error_table, reach_table, wrench_table
from benchmarks.retarget_speed_quality import DEX, OURS, target_checks, targets_table


def _row(variant, index, success, contact_err=None, **extra):
    r = {"hand": "shadow", "index": index, "object_id": "cube2", "variant": variant}
    r.update(success=success, **extra)
    if contact_err is not None:
        r["contact_err_mean_m"] = contact_err
    return r


def test_runs_are_binned_by_variant_d_contact_error():
    # (d)'s contact error places each run, also (c)'s and (e)'s (which carry none or their own).
    err = {0: 0.001, 1: 0.0015, 2: 0.004, 3: 0.02}
    rows = [_row("d", i, s, err[i]) for i, s in ((0, True), (1, False), (2, True), (3, False))]
    rows += [_row("c", i, s, contact_err=0.5) for i, s in ((0, False), (1, False), (2, True))]
    rows += [_row("e", i, True) for i in range(4)]
    rows += [_row("e", 9, True), _row("d", 5, False, skipped="no human forces")]
    t = by_contact_error(rows)
    d = {b["bin"]: (b["runs"], b["success_rate"]) for b in t["d"]}
    assert d == {"0–2 mm": (2, 0.5), "2–5 mm": (1, 1.0), "5–10 mm": (0, None), "> 10 mm": (1, 0.0)}
    c = {b["bin"]: (b["runs"], b["success_rate"]) for b in t["c"]}
    assert c["0–2 mm"] == (2, 0.0) and c["2–5 mm"] == (1, 1.0) and c["> 10 mm"] == (0, None)
    # (e)'s run 9 has no (d) row: in no bin
    assert sum(b["runs"] for b in t["e"]) == 4


def test_light_and_heavy_are_split_by_d_wrench_feasibility():
    """(d)'s ``wrench_feasible_fraction`` puts each (hand, pair, object) on one side of
    ``WRENCH_FEASIBLE``; (e) follows its (d) run; a run without (d) or without the fraction is
    on neither side; light and heavy are counted apart, with their pairing."""

    def row(variant, index, oid, success, frac=None, **extra):
        heavy = oid.endswith("h")
        r = _row(variant, index, success, pair=f"p{index}", **extra)
        r.update(object_id=oid, object_variant="heavy" if heavy else "light")
        r["heavy_version_of"] = oid[:-1] if heavy else None
        if frac is not None:
            r["wrench_feasible_fraction"] = frac
        return r

    hi, lo = WRENCH_FEASIBLE, WRENCH_FEASIBLE - 0.01
    rows = [
        row("d", 0, "cube2", True, hi), row("d", 0, "cube2h", True, hi),
        row("d", 1, "cube2", True, lo), row("d", 1, "cube2h", False, 0.3),
        row("d", 2, "cube2", False, 1.0), row("d", 3, "cube2h", False),  # no fraction
        row("e", 1, "cube2h", True), row("e", 2, "cube2", True), row("e", 7, "cube2", True),
        row("d", 4, "cube2", False, skipped="no human forces"),
    ]  # fmt: skip
    t = heavy_vs_light_by_wrench(rows)
    f, s = t["d"]["feasible"], t["d"]["short"]
    assert (f["light_runs"], f["light_success_rate"]) == (2, 0.5)
    assert (f["heavy_runs"], f["heavy_success_rate"]) == (1, 1.0)
    assert (f["paired_runs"], f["paired_light_success_rate"]) == (1, 1.0)
    assert (s["light_runs"], s["light_success_rate"]) == (1, 1.0)
    assert (s["heavy_runs"], s["heavy_success_rate"]) == (1, 0.0)
    e = t["e"]
    assert e["short"]["heavy_runs"] == 1 and e["short"]["heavy_success_rate"] == 1.0
    assert e["feasible"]["light_runs"] == 1 and e["feasible"]["heavy_runs"] == 0
    console = Console(width=160, record=True)
    console.print(wrench_table("shadow", t))
    text = console.export_text()
    assert "can carry" in text and "falls short" in text and "50 (2)" in text


def test_contact_error_table_renders_every_bin():
    rows = [_row("d", 0, True, 0.001), _row("c", 0, False), _row("e", 0, True)]
    console = Console(width=120, record=True)
    console.print(contact_error_table("shadow", by_contact_error(rows)))
    text = console.export_text()
    assert "0–2 mm" in text and "> 10 mm" in text and "100 (1)" in text


def test_speed_target_reports_the_ratio_to_dex_retargeting():
    """``benchmarks.retarget_speed_quality``: the ms/frame target is absolute (met or not by
    the machine), so the same run's ratio to dex-retargeting's time is reported beside it."""
    agg = {
        "ms_per_frame": 0.6,
        "keypoint_err_mean_m": 0.016,
        "penetration_max_m": 0.001,
        "success_rate": 0.5,
        "success_loose_rate": 0.8,
    }
    overall = {OURS: agg, DEX: {**agg, "ms_per_frame": 2.0, "success_rate": 0.2}}
    checks = target_checks(overall)
    speed = next(c for c in checks if "ms/frame" in c["target"])
    assert not speed["met"] and speed["ratio"] == 0.3 and speed["dex_ms_per_frame"] == 2.0
    strict = next(c for c in checks if "strict" in c["target"])
    assert strict["met"] and strict["ratio"] == 2.5
    console = Console(width=150, record=True)
    console.print(targets_table(checks))
    assert "0.600 ms (0.30× dex-retargeting's 2.000)" in console.export_text()


def test_fingers_are_pooled_by_reach_with_the_human_replay_on_the_same_fingers():
    """Single fingers of successful (d) / (e) runs, binned by ``contact_reach_m``; the human
    replay's correlation of the same finger beside them; failed runs, fingers without a profile
    or without a reach (a baseline's) left out; no contact target: its own bin."""

    def finger(corr, reach="absent"):
        f = {"profile_correlation": corr}
        if reach != "absent":
            f["contact_reach_m"] = reach
        return f

    rows = [
        _row("d", 0, True, force_per_finger={
            "thumb": finger(0.9, 0.001), "index": finger(0.5, 0.007), "ring": finger(0.1, None),
            "pinky": finger(None, 0.001),
        }),
        _row("d", 1, True, force_per_finger={"thumb": finger(0.7, 0.002), "index": finger(0.2)}),
        _row("d", 2, False, force_per_finger={"thumb": finger(0.0, 0.001)}),
        _row("e", 0, True, force_per_finger={"thumb": finger(0.8, 0.03)}),
    ]  # fmt: skip
    human = [
        {"index": 0, "object_id": "cube2", "replay": {"force_per_finger": {
            "thumb": {"profile_correlation": 0.95}, "index": {"profile_correlation": 0.6}}}},
        {"index": 1, "object_id": "cube2", "replay": {}},
    ]  # fmt: skip
    t = correlation_by_reach(rows, human)
    d = {b["bin"]: b for b in t["d"]}
    assert d["0–3 mm"]["fingers"] == 2 and d["0–3 mm"]["correlation"] == pytest.approx(0.8)
    assert d["0–3 mm"]["replay_fingers"] == 1 and d["0–3 mm"]["replay_correlation"] == 0.95
    assert (d["5–10 mm"]["fingers"], d["5–10 mm"]["replay_correlation"]) == (1, 0.6)
    assert d["no target"]["fingers"] == 1 and d["no target"]["correlation"] == pytest.approx(0.1)
    assert d["3–5 mm"]["correlation"] is None and d["> 20 mm"]["fingers"] == 0
    assert {b["bin"]: b["fingers"] for b in t["e"]}["> 20 mm"] == 1
    console = Console(width=160, record=True)
    console.print(reach_table("shadow", t))
    text = console.export_text()
    assert "0.80 (2)" in text and "0.95 (1)" in text and "no target" in text
