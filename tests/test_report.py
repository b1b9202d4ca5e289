"""``retarget report`` and the plots: numbers behind the plots, an offline page whose images
resolve in headless Chromium, several runs on one page, and the errors."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from system_packages import requires
from test_viz import FINGER_FORCE_N, HAS_CHROMIUM, dataset  # noqa: F401 (a fixture)

from dexcanvas_core.trajectory import FORCE_GROUPS
from retarget.cli import main
from retarget.hands import get_hand
from retarget.run import RunConfig, run_retarget
from retarget.viz import chromium, plots
from retarget.viz._process import tagged_processes
from retarget.viz.data import load_human_for_run, load_run
from retarget.viz.errors import VizError
from retarget.viz.report import metrics_rows

IMG_PROBE = """<script>
window.addEventListener("load", () => {
  const widths = Array.from(document.images).map(i => (i.complete ? i.naturalWidth : -1));
  document.body.setAttribute("data-image-widths", widths.join(","));
});
</script>"""
"""Appended to a copy of the report: records each image's decoded width in the DOM."""


@pytest.fixture(scope="module")
def runs(dataset, tmp_path_factory):  # noqa: F811 (the imported fixture)
    root = tmp_path_factory.mktemp("runs")
    out = {}
    for hand in ("shadow", "allegro"):
        cfg = RunConfig(
            hand=hand, pair="cube2/tripod", dataset=dataset, out=root / hand, progress=False
        )
        run_retarget(cfg)
        out[hand] = root / hand
    return out


@pytest.fixture(scope="module")
def report(runs):
    """The report of the shadow run, its stills rendered on the way (MuJoCo: quicker)."""
    assert main(["report", str(runs["shadow"]), "--renderer", "mujoco"]) == 0
    return runs["shadow"] / "report.html"


def test_report_is_offline_and_complete(report):
    page = report.read_text()
    assert "http://" not in page and "https://" not in page
    srcs = re.findall(r'src="([^"]*)"', page)
    assert len(srcs) == 7  # 3 stills, forces, object error, servo tracking, heatmap
    assert all(s.startswith("data:image/") for s in srcs)
    for href in re.findall(r"href='([^']*)'", page):
        assert (report.parent / href).is_file(), href  # relative links to files that exist
    assert "<script" not in page
    for text in (
        "success (no frame with object error &gt; 5 cm)",
        "keypoint error mean",
        "cube2/tripod",
        "frame 60",
    ):
        assert text in page


@requires(HAS_CHROMIUM, "headless Chromium not installed (apt-get install chromium)")
def test_report_images_resolve_in_headless_chromium(report, tmp_path):
    probe = tmp_path / "probe.html"
    probe.write_text(report.read_text().replace("</body>", IMG_PROBE + "</body>"))
    dom = chromium.dump_dom(probe)  # no network: a dead proxy, a resolver that resolves nothing
    widths = re.search(r'data-image-widths="([^"]*)"', dom)
    assert widths, dom[:500]
    values = [int(w) for w in widths.group(1).split(",")]
    assert len(values) == 7 and min(values) > 100, values
    assert tagged_processes() == []


def test_finger_forces_human_vs_robot(runs):
    run = load_run(runs["shadow"])
    human = load_human_for_run(run)
    hand = get_hand("shadow")
    f = plots.finger_forces(run.arrays, hand, human)
    robot, hum = f["robot"], f["human"]
    assert robot.shape == hum.shape == (run.num_frames, 6)
    # Robot rows: the re-simulation's force of the finger each human finger drives.
    parts = list(run.arrays["force_parts"])
    F = np.linalg.norm(run.arrays["finger_force_world"], axis=-1)
    for row, name in enumerate(FORCE_GROUPS):
        robot_name = "palm" if name == "palm" else hand.fingers[name]
        np.testing.assert_allclose(robot[:, row], F[:, parts.index(robot_name)])
    # Human rows: the records' forces, summed per finger (each record FINGER_FORCE_N).
    c = human.contacts
    for row, name in enumerate(FORCE_GROUPS):
        n = np.zeros(run.num_frames)
        for t, part in zip(c.frame, c.joint_name, strict=True):
            n[t] += part.split("_")[0] == name or (name == "palm" and part == "palm")
        assert np.all(hum[n == 0, row] == 0.0)
        touching = n > 0
        assert np.all(hum[touching, row] >= FINGER_FORCE_N[name] * 0.99)
        assert np.all(hum[touching, row] <= n[touching] * FINGER_FORCE_N[name] * 1.01)
    assert hum[:, 0].max() > 0 and hum[:, 4].max() == 0  # a tripod: thumb yes, pinky no


def test_heatmap_aggregates_runs_by_type():
    a, b, c = (np.linspace(0, 1, 16) * k for k in (0.2, 0.6, 1.0))
    types, human, robot, counts = plots.heatmap_rows(
        [("quadpod", None, c), ("tripod", a, a), ("tripod", b, None)]
    )
    assert types == ["tripod", "quadpod"]  # taxonomy order, not input order
    np.testing.assert_allclose(human[0], (a + b) / 2)
    np.testing.assert_allclose(robot[0], a)  # runs without the data do not count
    assert np.isnan(human[1]).all() and counts.tolist() == [2, 1]
    with pytest.raises(VizError, match="shape"):
        plots.heatmap_rows([("tripod", np.ones(3), None)])


def test_plots_write_png_and_svg(tmp_path):
    t = np.linspace(0, 2, 50)
    err = np.where(t > 1.5, 0.08, 0.01)
    for ext in ("png", "svg"):
        out = plots.plot_object_error(tmp_path / f"e.{ext}", t, err, 0.1 * t)
        assert out.stat().st_size > 5000
    assert (tmp_path / "e.svg").read_text().lstrip().startswith("<?xml")
    forces = np.abs(np.sin(t))[:, None] * np.arange(1, 7)
    plots.plot_finger_forces(tmp_path / "f.png", t, forces, forces * 0.5)
    entries = [("tripod", np.full(16, 0.5), np.linspace(0, 1, 16))]
    plots.plot_contact_heatmap(tmp_path / "h.png", entries)
    with pytest.raises(VizError, match="use one of"):
        plots.plot_object_error(tmp_path / "e.jpg", t, err, err)
    with pytest.raises(VizError, match="differ in length"):
        plots.plot_object_error(tmp_path / "e.png", t, err[:-1], err)
    with pytest.raises(VizError, match=r"\(T, 6\)"):
        plots.plot_finger_forces(tmp_path / "f.png", t, forces[:, :5])
    with pytest.raises(VizError, match="planned forces"):
        plots.plot_finger_forces(tmp_path / "f.png", t, forces, plan=forces[:, :5])
    notes = {"thumb": "profile correlation 0.90"}
    out = plots.plot_finger_forces(tmp_path / "p.png", t, forces, forces, plan=forces, notes=notes)
    assert out.stat().st_size > 5000
    servo = np.radians(np.abs(np.sin(t))[:, None] * [1.0, 5.0])
    out = plots.plot_servo_tracking(
        tmp_path / "s.png", t, servo, ["th", "ff"], 1e-3 * t, human_fingers={"th": "thumb"}
    )
    assert out.stat().st_size > 5000
    with pytest.raises(VizError, match=r"\(T, 2\)"):
        plots.plot_servo_tracking(tmp_path / "s.png", t, servo[:, :1], ["th", "ff"], t)


def test_report_of_several_runs(runs, capsys):
    assert main(["report", str(runs["shadow"]), str(runs["allegro"]), "--no-snapshots"]) == 0
    out = runs["shadow"].parent / "report.html"  # the runs' common parent
    assert f"report: {out}" in capsys.readouterr().out
    page = out.read_text()
    assert "<h2>Summary</h2>" in page and page.count("cube2/tripod</td>") == 2
    for hand in ("shadow", "allegro"):
        m = json.loads((runs[hand] / "metrics.json").read_text())
        assert f"{100 * m['object_pos_err_max_m']:.1f} cm" in page
    # One heatmap over both runs, each run's force, object-error and servo-tracking plots, and
    # the stills a run already has (--no-snapshots renders none for the allegro run).
    stills = sum(
        len(json.loads(m.read_text())["files"])
        for m in runs["shadow"].parent.glob("*/snapshots.json")
    )
    assert not (runs["allegro"] / "snapshots.json").exists()
    assert len(re.findall(r'src="data:image/png', page)) == 1 + 2 * 3 + stills
    assert "servo tracking error mean" in page


def test_metrics_table_units():
    rows = dict(
        metrics_rows(
            {
                "success": False,
                "object_pos_err_max_m": 0.0712,
                "object_pos_err_mean_m": 0.02,
                "keypoint_err_mean_m": 0.0175,
                "ms_per_frame": 2.5,
                "backend": "pinocchio",
                "finger_servo_err_mean_deg": {"th": 9.14, "ff": 1.0},
                "wrist_pos_tracking_err_mean_m": 0.0008,
                "wrist_rot_tracking_err_mean_deg": 0.26,
            }
        )
    )
    assert rows["servo tracking error mean (simulation − command)"] == (
        "wrist 0.8 mm / 0.3°; each finger's worst joint: th 9.1°, ff 1.0°"
    )
    assert rows["object position error max / mean"] == "7.1 / 2.0 cm"
    assert rows["keypoint error mean"] == "17.5 mm" and "no" in rows[next(iter(rows))]
    assert rows["contact error mean"] == "–"


@pytest.mark.parametrize(
    "setup, message",
    [
        (lambda d: None, "does not exist"),
        (lambda d: d.mkdir(), "has no robot_trajectory.npz or metrics.json"),
        (
            lambda d: (
                d.mkdir(),
                (d / "metrics.json").write_text("{"),
                (d / "robot_trajectory.npz").write_bytes(b""),
            ),
            "cannot read it as JSON",
        ),
    ],
)
def test_report_errors(setup, message, tmp_path, capsys):
    run_dir = tmp_path / "run"
    setup(run_dir)
    assert main(["report", str(run_dir)]) == 2
    err = capsys.readouterr().err
    assert "retarget report: error:" in err and message in err
