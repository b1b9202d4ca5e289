"""``benchmarks/force_preservation.py``: success by contact error, from hand-made rows."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from force_preservation import by_contact_error, contact_error_table


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


def test_contact_error_table_renders_every_bin():
    from rich.console import Console

    rows = [_row("d", 0, True, 0.001), _row("c", 0, False), _row("e", 0, True)]
    console = Console(width=120, record=True)
    console.print(contact_error_table("shadow", by_contact_error(rows)))
    text = console.export_text()
    assert "0–2 mm" in text and "> 10 mm" in text and "100 (1)" in text


def test_speed_target_reports_the_ratio_to_dex_retargeting():
    """``retarget_speed_quality``: the ms/frame target is absolute (met or not by the machine),
    so the same run's ratio to dex-retargeting's time is reported beside it."""
    from retarget_speed_quality import DEX, OURS, target_checks, targets_table
    from rich.console import Console

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
