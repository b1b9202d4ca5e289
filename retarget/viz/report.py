"""``retarget report RUN_DIR [RUN_DIR …]``: one HTML page per set of runs, readable offline.

For every run: its metrics, stills (``snapshots.json`` of the run directory, rendered there
first when missing), the per-finger force plot (human vs robot) and the object-error plot; for
all runs together: a summary table and the per-type contact heatmap. Images are embedded
(``data:`` URIs), so the page is one file that needs no network and no other file; the only
links are relative ones to each run's ``scene.html`` (the animated 3-D scene), when it exists.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import json
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from dexcanvas_core.errors import DexCanvasError
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.safe_io import atomic_write_text, check_output, output_lock
from dexcanvas_core.sim.signal import CAPTURE_SMOOTH_S
from retarget.force_scores import REACH_M
from retarget.hands import get_hand
from retarget.validate import servo_summary
from retarget.viz import plots
from retarget.viz.contacts import human_contacts
from retarget.viz.data import load_human_for_run, load_run, scene_data
from retarget.viz.errors import RendererUnavailableError, VizError, require
from retarget.viz.resim import record_resimulation
from retarget.viz.snapshot import MANIFEST, SnapshotConfig, check_renderer, choose_frames, draw

log = logging.getLogger(__name__)

REPORT_NAME = "report.html"
PLOTS_DIR = "plots"


@dataclass(frozen=True)
class ReportConfig:
    """One ``retarget report``."""

    run_dirs: tuple[Path, ...]
    """Run directories (``retarget run``); one or more."""
    out: Path | None = None
    """The HTML file; default ``<run>/report.html`` for one run, else ``report.html`` in the
    runs' common parent directory."""
    snapshots: bool = True
    """Render stills into a run directory that has none (``retarget snapshot``'s defaults)."""
    renderer: Literal["auto", "chromium", "mujoco"] = "auto"
    plot_format: Literal["png", "svg"] = "png"
    overwrite: bool = False
    """Replace an existing report file; without it one is refused before any work."""

    def validate(self) -> ReportConfig:
        if not self.run_dirs:
            raise VizError("give at least one run directory")
        if self.plot_format not in ("png", "svg"):
            raise VizError(f"plot format must be png or svg, got {self.plot_format!r}")
        return self

    def output_path(self) -> Path:
        if self.out is not None:
            return Path(self.out)
        dirs = [Path(d).resolve() for d in self.run_dirs]
        if len(dirs) == 1:
            return dirs[0] / REPORT_NAME
        return Path(os.path.commonpath(dirs)) / REPORT_NAME


@dataclass
class RunSection:
    """What the report shows of one run."""

    run_dir: Path
    metrics: dict
    notes: list[str] = field(default_factory=list)
    stills: list[tuple[str, Path]] = field(default_factory=list)
    """(caption, PNG)"""
    plots: list[tuple[str, Path]] = field(default_factory=list)
    scene_html: Path | None = None
    heatmap_entry: tuple[str, np.ndarray | None, np.ndarray | None] | None = None


def _section(run_dir: Path, cfg: ReportConfig) -> RunSection:
    run = load_run(run_dir)
    m = run.metrics
    sec = RunSection(run_dir=run.run_dir, metrics=m)
    hand = get_hand(m["hand"])
    obj, typ = m["pair"].split("/", 1)
    geometry = object_geometry(obj)
    try:
        human = load_human_for_run(run)
    except (VizError, DexCanvasError) as e:
        human = None
        sec.notes.append(f"demonstration not available ({e}): no human data, no stills")
    sim = None
    if human is not None:
        sim = record_resimulation(
            hand, geometry, run.arrays["q_command"], human, metrics=run.metrics
        )
        hc = human_contacts(human, geometry)
        if hc.source.startswith("inferred"):
            sec.notes.append(
                "the demonstration has no contact records: human contacts are inferred from its "
                "keypoints (hand capsules within 2 mm of the object) and it has no forces"
            )
        sec.heatmap_entry = (typ, hc.part_frequency(), sim.contacts.part_frequency())
    # -- plots
    plot_dir = run.run_dir / PLOTS_DIR
    ext = f".{cfg.plot_format}"
    t = run.timestamp - run.timestamp[0]
    forces = plots.finger_forces(run.arrays, hand, human)
    title = f"{m['hand']} · {m['pair']}"
    sec.plots.append(
        (
            "contact force per finger (human vs robot)"
            + (", and the force matching's plan" if forces["plan"] is not None else ""),
            plots.plot_finger_forces(
                plot_dir / f"forces{ext}",
                t,
                forces["robot"],
                forces["human"],
                title=title,
                plan=forces["plan"],
                notes=force_notes(m),
            ),
        )
    )
    sec.plots.append(
        (
            "object error",
            plots.plot_object_error(
                plot_dir / f"object_error{ext}",
                t,
                run.arrays["object_pos_err"],
                run.arrays["object_rot_err"],
                title=title,
            ),
        )
    )
    if "finger_servo_err" in run.arrays:  # (runs written before it was recorded: none)
        sec.plots.append(
            (
                "servo tracking error",
                plots.plot_servo_tracking(
                    plot_dir / f"servo{ext}",
                    t,
                    run.arrays["finger_servo_err"],
                    hand.robot_fingers,
                    run.arrays["wrist_pos_tracking_err"],
                    human_fingers=hand.robot_to_human,
                    title=title,
                ),
            )
        )
    # -- stills
    manifest = _read_manifest(run.run_dir)
    if manifest is None and cfg.snapshots and human is not None:
        scfg = SnapshotConfig(out=run.run_dir, run_dir=run.run_dir, renderer=cfg.renderer)
        try:
            renderer = check_renderer(cfg.renderer)
            data = scene_data(run, human, hand=hand, sim=sim)
            with output_lock(run.run_dir, where="inside"):
                draw(
                    hand,
                    data,
                    choose_frames(scfg, run.num_frames),
                    run.run_dir,
                    cfg=scfg,
                    renderer=renderer,
                    run_dir=run.run_dir,
                )
            manifest = _read_manifest(run.run_dir)
        except RendererUnavailableError as e:
            sec.notes.append(f"no stills: {e}")
    if manifest is not None:
        for t_frame, name, time_s in zip(
            manifest["frames"], manifest["files"], manifest["times_s"], strict=True
        ):
            sec.stills.append((f"frame {t_frame} · {time_s:.2f} s", run.run_dir / name))
        if manifest.get("scene_html") and (run.run_dir / manifest["scene_html"]).is_file():
            sec.scene_html = run.run_dir / manifest["scene_html"]
        sec.notes.append(f"stills rendered by {manifest['renderer']}, {manifest['layout']} layout")
    return sec


def force_notes(m: dict) -> dict[str, str]:
    """Per human finger of a force-matched run (``metrics.json``'s ``force_per_finger``): its
    force profile correlation with the human's, its share of the hand's load and its reach (how
    far the plan keeps it from the human's contact), for the force plot's panels (with the
    human replay's, ``--human-replay``, where the run has one); empty for other runs and for
    fingers the human never loaded."""
    out = {}
    replay = (m.get("human_replay") or {}).get("force_per_finger") or {}
    for f, v in (m.get("force_per_finger") or {}).items():
        if v.get("profile_correlation") is None:
            continue
        text = f"profile correlation {v['profile_correlation']:.2f}"
        if (r := replay.get(f, {}).get("profile_correlation")) is not None:
            text += f" (human replay {r:.2f})"
        if v.get("load_share") is not None:
            text += f" · {100 * v['load_share']:.0f} % of the human hand's force"
        if "contact_reach_m" in v:  # runs of older versions have none
            d = v["contact_reach_m"]
            text += (
                " · no contact target in the plan"
                if d is None
                else f" · plan {1000 * d:.0f} mm from the human's contact"
            )
        out[f] = text
    return out


def _read_manifest(run_dir: Path) -> dict | None:
    path = run_dir / MANIFEST
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text())
    except ValueError as e:
        raise VizError(f"{path}: cannot read it as JSON: {e}") from e
    if not all((run_dir / f).is_file() for f in manifest.get("files", [])):
        return None  # stills were moved or deleted: render them again
    return manifest


def run_report(cfg: ReportConfig) -> Path:
    """Write the report (module docstring); return its path."""
    cfg = cfg.validate()
    require("matplotlib", "PIL", *(["meshcat"] if cfg.snapshots else []))
    out = check_output(cfg.output_path(), overwrite=cfg.overwrite, kind="file")
    sections = [_section(Path(d), cfg) for d in cfg.run_dirs]
    heatmap = None
    entries = [s.heatmap_entry for s in sections if s.heatmap_entry is not None]
    if entries:
        heatmap = plots.plot_contact_heatmap(
            out.parent / PLOTS_DIR / f"contact_heatmap.{cfg.plot_format}"
            if len(sections) > 1
            else sections[0].run_dir / PLOTS_DIR / f"contact_heatmap.{cfg.plot_format}",
            entries,
        )
    with output_lock(out):
        atomic_write_text(out, render_html(sections, heatmap, out))
    return out


# ---------------------------------------------------------------------------- HTML

_CSS = """
body { font-family: system-ui, sans-serif; margin: 24px auto; max-width: 1100px; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 0.9em; margin: 0.5em 0; }
td, th { border: 1px solid #ddd; padding: 3px 8px; text-align: left; }
th { background: #f4f4f4; }
.ok { color: #1e8449; font-weight: bold; } .fail { color: #c0392b; font-weight: bold; }
.stills { display: flex; flex-wrap: wrap; gap: 8px; }
figure { margin: 0; } figcaption { font-size: 0.8em; color: #555; }
img { max-width: 100%; border: 1px solid #eee; }
.stills img { width: 360px; }
.note { font-size: 0.85em; color: #555; }
"""


def _img(path: Path, alt: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode()
    mime = "image/svg+xml" if path.suffix.lower() == ".svg" else "image/png"
    return f'<img alt="{html.escape(alt)}" src="data:{mime};base64,{data}">'


def _fmt(value, scale: float = 1.0, unit: str = "", digits: int = 1) -> str:
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    try:
        return f"{scale * float(value):.{digits}f}{unit}"
    except (TypeError, ValueError):
        return html.escape(str(value))


def metrics_rows(m: dict) -> list[tuple[str, str]]:
    """The metrics table of one run: (label, formatted value)."""
    ok = m.get("success")
    rows = [
        (
            "success (no frame with object error > 5 cm)",
            f'<span class="{"ok" if ok else "fail"}">{"yes" if ok else "no"}</span>',
        ),
        ("loose success (mean < 10 cm and < 0.5 rad)", _fmt(m.get("success_loose"))),
        ("first failing frame", _fmt(m.get("first_failure_frame"), digits=0)),
        (
            "object position error max / mean",
            f"{_fmt(m.get('object_pos_err_max_m'), 100)} / "
            f"{_fmt(m.get('object_pos_err_mean_m'), 100, ' cm')}",
        ),
        ("object rotation error mean", _fmt(m.get("object_rot_err_mean_rad"), 180 / np.pi, "°")),
        ("keypoint error mean", _fmt(m.get("keypoint_err_mean_m"), 1000, " mm")),
        ("contact error mean", _fmt(m.get("contact_err_mean_m"), 1000, " mm")),
        ("contact frames", _fmt(m.get("contact_frames"), digits=0)),
        (
            "penetration max (kinematic / simulation)",
            f"{_fmt(m.get('penetration_max_m'), 1000)} / "
            f"{_fmt(m.get('sim_penetration_max_m'), 1000, ' mm')}",
        ),
        ("speed", f"{_fmt(m.get('ms_per_frame'), digits=2)} ms/frame ({m.get('backend', '?')})"),
        ("frames", f"{m.get('frames')} at {_fmt(m.get('fps'), digits=0)} Hz"),
        (
            "demonstration",
            f"{html.escape(str(m.get('uuid')))} ({html.escape(str(m.get('dataset')))})",
        ),
    ]
    if (servo := servo_summary(m)) is not None:
        rows.append(("servo tracking error mean (simulation − command)", html.escape(servo, False)))
    forces = m.get("finger_force_mean_n") or {}
    if forces:
        rows.append(
            (
                "mean contact force per robot finger",
                ", ".join(f"{html.escape(k)} {v:.2f} N" for k, v in forces.items()),
            )
        )
    if m.get("force_profile_correlation_mean") is not None:
        rows.append(
            (
                "force matching: correlation with the human (whole clip / contact frames / "
                f"whole clip over {1e3 * CAPTURE_SMOOTH_S:.0f} ms, the demonstration's "
                "bandwidth)",
                f"{_fmt(m['force_profile_correlation_mean'], digits=2)} / "
                f"{_fmt(m.get('force_correlation_mean'), digits=2)} / "
                f"{_fmt(m.get('force_profile_correlation_mean_smoothed'), digits=2)}",
            )
        )
    if "fingers_reached" in m:
        rows.append(
            (
                "force matching: fingers whose plan reaches the human's contact "
                f"(≤ {1000 * REACH_M:.0f} mm), their correlation",
                f"{m['fingers_reached']} of {m['fingers_scored']}, "
                f"{_fmt(m.get('force_profile_correlation_mean_reached'), digits=2)}",
            )
        )
    if (hr := m.get("human_replay")) is not None:
        value = (
            f"{_fmt(hr.get('force_profile_correlation_mean'), digits=2)} / "
            f"{_fmt(hr.get('force_correlation_mean'), digits=2)} / "
            f"{_fmt(hr.get('force_profile_correlation_mean_smoothed'), digits=2)}"
            if hr.get("success")
            else f"lost the object at frame {_fmt(hr.get('failed_at_frame'), digits=0)}"
        )
        rows.append(
            (f"human replay (MPC seed {hr.get('mpc_seed')}): the human against itself", value)
        )
    return rows


def render_html(sections: list[RunSection], heatmap: Path | None, out: Path) -> str:
    """The report page (images embedded)."""
    esc = html.escape
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        f"<title>retarget report: {esc(', '.join(s.metrics['pair'] for s in sections))}</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>Retargeting report</h1>",
        f"<p class='note'>{len(sections)} run(s) · written "
        f"{_dt.datetime.now().strftime('%Y-%m-%d %H:%M')} by retarget report</p>",
    ]
    if len(sections) > 1:
        parts.append(
            "<h2>Summary</h2><table><tr><th>run</th><th>hand</th><th>pair</th>"
            "<th>success</th><th>object err max</th><th>keypoint err</th>"
            "<th>ms/frame</th></tr>"
        )
        for s in sections:
            m = s.metrics
            ok = m.get("success")
            parts.append(
                f"<tr><td>{esc(s.run_dir.name)}</td><td>{esc(m['hand'])}</td>"
                f"<td>{esc(m['pair'])}</td><td class='{'ok' if ok else 'fail'}'>"
                f"{'yes' if ok else 'no'}</td>"
                f"<td>{_fmt(m.get('object_pos_err_max_m'), 100, ' cm')}</td>"
                f"<td>{_fmt(m.get('keypoint_err_mean_m'), 1000, ' mm')}</td>"
                f"<td>{_fmt(m.get('ms_per_frame'), digits=2)}</td></tr>"
            )
        parts.append("</table>")
    if heatmap is not None:
        parts.append("<h2>Contacts per hand part</h2>")
        parts.append(
            f"<figure>{_img(heatmap, 'contact heatmap')}<figcaption>Fraction of "
            "frames in which each hand part touches the object, per manipulation type "
            "(mean over runs); robot bodies are mapped onto the 16 human parts."
            "</figcaption></figure>"
        )
    for s in sections:
        m = s.metrics
        parts.append(
            f"<h2>{esc(m['hand'])} · {esc(m['pair'])} "
            f"<span class='note'>({esc(str(s.run_dir))})</span></h2>"
        )
        parts.append("<table>")
        parts.extend(f"<tr><th>{esc(k)}</th><td>{v}</td></tr>" for k, v in metrics_rows(m))
        parts.append("</table>")
        if s.stills:
            parts.append("<div class='stills'>")
            for cap, png in s.stills:
                parts.append(
                    f"<figure>{_img(png, cap)}<figcaption>{esc(cap)}</figcaption></figure>"
                )
            parts.append("</div>")
        if s.scene_html is not None:
            rel = os.path.relpath(s.scene_html, out.parent)
            parts.append(
                f"<p><a href='{esc(Path(rel).as_posix())}'>open the animated 3-D scene"
                "</a> (plays at the demonstration's frame rate; works offline)</p>"
            )
        for cap, path in s.plots:
            parts.append(f"<figure>{_img(path, cap)}<figcaption>{esc(cap)}</figcaption></figure>")
        parts.extend(f"<p class='note'>{esc(n)}</p>" for n in s.notes)
    parts.append("</body></html>")
    return "\n".join(parts)
