"""``retarget snapshot``: stills of chosen frames of a run, and its scene as one HTML file.

``run_snapshot(SnapshotConfig(out=..., hand="shadow", pair="cube2/tripod", frames=(0, 60)))``
retargets the pair (``retarget.run.run_retarget``, its outputs go into ``out``) or reads an
existing run directory (``run_dir=``), re-simulates it to record the robot's contacts
(:func:`retarget.viz.resim.record_resimulation`) and writes into ``out``:

* ``frame_<t>.png`` for every chosen frame — by default rendered by headless Chromium from a
  ``static_html()`` page of the meshcat scene at that frame, else (``renderer='mujoco'``, or
  ``'auto'`` without Chromium) by MuJoCo's offscreen renderer;
* ``scene.html`` — the meshcat scene as one self-contained page that plays the trajectory at
  its frame rate (opens offline; drag to orbit, scroll to zoom);
* ``snapshots.json`` — what was drawn: renderer, frames, files, layout, camera.

No server or browser outlives the call (``_process``), also on errors.
"""

from __future__ import annotations

import contextlib
import ctypes.util
import json
import logging
import os
import sys
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.safe_io import atomic_write_text
from retarget.hands import get_hand
from retarget.loading import load_subject
from retarget.outputs import RUN_FILES, open_run_dir
from retarget.pipeline import RunConfig, check_pair
from retarget.run import run_retarget
from retarget.viz import chromium, images, mujoco_render
from retarget.viz._process import run_process
from retarget.viz.data import RunFiles, SceneData, load_human_for_run, load_run, scene_data
from retarget.viz.errors import RendererUnavailableError, VizError, require
from retarget.viz.meshcat_connection import connect, meshcat_server
from retarget.viz.meshcat_scene import MeshcatScene
from retarget.viz.resim import record_resimulation
from retarget.viz.view import SceneOptions, frame_scene, robot_body_positions

log = logging.getLogger(__name__)

MANIFEST = "snapshots.json"
SCENE_HTML = "scene.html"
DEFAULT_NUM_FRAMES = 3
"""Frames drawn when none are chosen: first, middle, last."""
MUJOCO_TIMEOUT_S = 300.0


@dataclass(frozen=True)
class SnapshotConfig:
    """One ``retarget snapshot``."""

    out: Path
    """Output directory (created). When retargeting, the run's own files go there too."""
    hand: str | None = None
    """Registered hand (``retarget hands``); with ``pair``, retarget instead of ``run_dir``."""
    pair: str | None = None
    """``object/manipulation_type``, e.g. ``cube2/tripod``."""
    dataset: Path | None = None
    """DexCanvas-layout Lance dataset; None: the built-in demonstrations."""
    index: int = 0
    """Which demonstration of the pair (0-based)."""
    run_dir: Path | None = None
    """An existing run directory (``retarget run``) to draw instead of retargeting."""
    frames: tuple[int, ...] | None = None
    """Data frames to draw (0-based); None: ``every`` or first, middle and last."""
    every: int | None = None
    """Draw every N-th frame (from 0)."""
    renderer: Literal["auto", "chromium", "mujoco"] = "auto"
    """``auto``: Chromium when installed and working, else MuJoCo."""
    layout: Literal["overlay", "side_by_side"] = "side_by_side"
    robot: Literal["sim", "kinematic"] = "sim"
    """Draw the re-simulated robot (with its contacts) or the retargeted joint solution."""
    width: int = 800
    """[px]"""
    height: int = 600
    """[px]"""
    scene_html: bool = True
    """Also write ``scene.html`` (the animated meshcat scene)."""
    backend: Literal["pinocchio", "mink"] = "pinocchio"
    """IK backend when retargeting."""
    overwrite: bool = False
    """Replace the stills (``snapshots.json``) and, when retargeting, the run already in
    ``out``; without it either is refused before any work. Stills of a run into its own
    directory (``out == run_dir``) do not replace the run."""
    progress: bool = True

    def validate(self) -> SnapshotConfig:
        if self.run_dir is None and (
            self.hand is None or (self.pair is None and self.dataset is None)
        ):
            raise VizError(
                "give --hand and --pair (or --dataset D --index I) to retarget a demonstration, "
                "or --run RUN_DIR"
            )
        if self.run_dir is not None and (
            self.hand is not None or self.pair is not None or self.dataset is not None
        ):
            raise VizError("give either --run RUN_DIR or --hand/--pair, not both")
        if self.frames is not None and self.every is not None:
            raise VizError("give either --frames or --every, not both")
        if self.frames is not None and not self.frames:
            raise VizError("--frames names no frame")
        if self.every is not None and self.every < 1:
            raise VizError(f"--every must be at least 1, got {self.every}")
        if self.renderer not in ("auto", "chromium", "mujoco"):
            raise VizError(f"renderer must be auto, chromium or mujoco, got {self.renderer!r}")
        if self.robot not in ("sim", "kinematic"):
            raise VizError(f"robot must be 'sim' or 'kinematic', got {self.robot!r}")
        self.options().validate()
        return self

    def options(self) -> SceneOptions:
        return SceneOptions(layout=self.layout, width=self.width, height=self.height)


def parse_frames(text: str) -> tuple[int, ...]:
    """``"0,60,120"`` → ``(0, 60, 120)``; :class:`VizError` naming a bad entry."""
    out = []
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        try:
            out.append(int(item))
        except ValueError:
            raise VizError(
                f"--frames: {item!r} is not a frame number (e.g. --frames 0,60,120)"
            ) from None
    if not out:
        raise VizError("--frames names no frame (e.g. --frames 0,60,120)")
    return tuple(out)


def choose_frames(cfg: SnapshotConfig, num_frames: int) -> list[int]:
    """The frames ``cfg`` asks for, checked against ``num_frames``; duplicates removed."""
    if cfg.frames is not None:
        frames = list(dict.fromkeys(cfg.frames))
        bad = [f for f in frames if not 0 <= f < num_frames]
        if bad:
            raise VizError(
                f"frame {bad[0]} out of range: the demonstration has {num_frames} frames "
                f"(0–{num_frames - 1})"
            )
        return frames
    if cfg.every is not None:
        return list(range(0, num_frames, cfg.every))
    return sorted(set(np.linspace(0, num_frames - 1, DEFAULT_NUM_FRAMES).round().astype(int)))


def frame_png(t: int) -> str:
    return f"frame_{t:04d}.png"


# ---------------------------------------------------------------------------- renderers


def mujoco_available() -> dict[str, str | None]:
    """Backend → None if its library is present, else the package hint (a fast check; the
    render itself is the real test)."""
    libs = {"egl": ("EGL",), "osmesa": ("OSMesa",)}
    return {
        b: None if all(ctypes.util.find_library(lib) for lib in libs[b]) else hint
        for b, hint in mujoco_render.BACKENDS.items()
    }


def check_renderer(renderer: str) -> str:
    """The renderer to use for ``renderer`` (``auto`` resolved); raise
    :class:`RendererUnavailableError` naming the packages to install when there is none."""
    have_chromium = chromium.find_chromium() is not None
    mj = mujoco_available()
    have_mujoco = any(v is None for v in mj.values())
    if renderer == "chromium":
        chromium.require_chromium()
        return "chromium"
    if renderer == "mujoco":
        if not have_mujoco:
            raise RendererUnavailableError(_mujoco_missing(mj))
        return "mujoco"
    if have_chromium:
        return "chromium"
    if have_mujoco:
        return "mujoco"
    raise RendererUnavailableError(
        f"no renderer available: headless Chromium is not installed ({chromium.PACKAGE_HINT}) "
        f"and {_mujoco_missing(mj)}"
    )


def _mujoco_missing(mj: dict[str, str | None]) -> str:
    return "MuJoCo offscreen rendering has no GL library: " + "; ".join(
        f"{b} needs {hint}" for b, hint in mj.items() if hint
    )


def render_chromium(scene, frames: list[int], out_dir: Path, options: SceneOptions) -> list[Path]:
    """Stills of ``frames`` from ``scene`` (a :class:`MeshcatScene`) through headless Chromium."""
    pngs = []
    with tempfile.TemporaryDirectory(prefix="retarget-frames-") as tmp:
        for t in frames:
            page = Path(tmp) / f"frame_{t:04d}.html"
            page.write_text(scene.frame_html(t))
            png = out_dir / frame_png(t)
            chromium.screenshot(page, png, width=options.width, height=options.height)
            pngs.append(png)
    return pngs


def render_mujoco(
    hand, data: SceneData, frames: list[int], out_dir: Path, options: SceneOptions
) -> list[Path]:
    """Stills of ``frames`` through MuJoCo's offscreen renderer (``MUJOCO_GL`` backends tried
    in turn, each in a fresh child process)."""
    framing = frame_scene(data, options, robot_body_positions(hand.compile(), data.robot_qpos))
    pngs = [out_dir / frame_png(t) for t in frames]
    forced = os.environ.get("MUJOCO_GL", "").strip().lower()
    backends = [forced] if forced in mujoco_render.BACKENDS else list(mujoco_render.BACKENDS)
    errors = []
    with tempfile.TemporaryDirectory(prefix="retarget-mujoco-") as tmp:
        job = Path(tmp) / "job.npz"
        mujoco_render.write_job(job, hand, data, framing, options, frames, pngs)
        for backend in backends:
            env = dict(os.environ, MUJOCO_GL=backend)
            if backend == "egl":
                env.setdefault("PYOPENGL_PLATFORM", "egl")
            elif backend == "osmesa":
                env["PYOPENGL_PLATFORM"] = "osmesa"
            args = [sys.executable, "-m", "retarget.viz.mujoco_child", str(job)]
            try:
                r = run_process(args, timeout_s=MUJOCO_TIMEOUT_S, env=env)
            except Exception as e:
                errors.append(f"{backend}: {e}")
                continue
            if r.returncode == 0 and all(p.is_file() for p in pngs):
                log.info("rendered %d frame(s) with MUJOCO_GL=%s", len(pngs), backend)
                return pngs
            msg = (r.stderr or "").strip().splitlines()
            errors.append(
                f"{backend}: {msg[-1] if msg else f'exit {r.returncode}'} "
                f"(needs {mujoco_render.BACKENDS[backend]})"
            )
    raise RendererUnavailableError("MuJoCo offscreen rendering failed: " + "; ".join(errors))


# ---------------------------------------------------------------------------- the command


def _prepare(cfg: SnapshotConfig) -> tuple[RunFiles, object, list[int]]:
    """Load or make the run; return it, its human demonstration and the checked frames."""
    if cfg.run_dir is not None:
        run = load_run(cfg.run_dir)
        human = load_human_for_run(run)
        return run, human, choose_frames(cfg, run.num_frames)

    hand = get_hand(cfg.hand)
    rcfg = RunConfig(
        hand=cfg.hand,
        pair=cfg.pair,
        dataset=cfg.dataset,
        index=cfg.index,
        out=cfg.out,
        overwrite=cfg.overwrite,
        backend=cfg.backend,
        progress=cfg.progress,
    )
    human, subject, _ = load_subject(rcfg.pair, rcfg.dataset, rcfg.index, rcfg.progress)
    check_pair(hand, subject.manipulation_type)
    frames = choose_frames(cfg, human.num_frames)  # before the long part
    run_retarget(rcfg)
    run = load_run(cfg.out)
    if run.metrics["uuid"] != human.uuid:
        raise VizError(f"run in {cfg.out} is of {run.metrics['uuid']}, expected {human.uuid}")
    return run, human, frames


def run_snapshot(cfg: SnapshotConfig) -> dict:
    """Write the stills, ``scene.html`` and ``snapshots.json`` (module docstring); return the
    manifest."""
    cfg = cfg.validate()
    require("meshcat", "PIL")
    renderer = check_renderer(cfg.renderer)  # fail before the long part
    # The stills' directory: a run too when retargeting into it; one writer at a time.
    contents = (MANIFEST,) if cfg.run_dir is not None else (MANIFEST, *RUN_FILES)
    with open_run_dir(cfg.out, overwrite=cfg.overwrite, contents=contents) as out_dir:
        return _snapshot(cfg, renderer, out_dir)


def _snapshot(cfg: SnapshotConfig, renderer: str, out_dir: Path) -> dict:
    run, human, frames = _prepare(cfg)
    hand = get_hand(run.metrics["hand"])
    sim = None
    if cfg.robot == "sim":
        pair_object = run.metrics["pair"].split("/", 1)[0]
        sim = record_resimulation(
            hand, object_geometry(pair_object), run.arrays["q_command"], human,
            metrics=run.metrics,
        )  # fmt: skip
    data = scene_data(run, human, hand=hand, robot_source=cfg.robot, sim=sim)
    return draw(hand, data, frames, out_dir, cfg=cfg, renderer=renderer, run_dir=run.run_dir)


def draw(
    hand,
    data: SceneData,
    frames: list[int],
    out_dir: Path,
    *,
    cfg: SnapshotConfig,
    renderer: str,
    run_dir: Path | None = None,
) -> dict:
    """Render ``frames`` of ``data`` into ``out_dir`` (+ ``scene.html`` and the manifest)."""
    options = cfg.options()
    frames = [int(t) for t in data.check_frames(frames)]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    pngs: list[Path] = []
    used = renderer
    animation = None
    need_server = renderer == "chromium" or cfg.scene_html
    with meshcat_server() if need_server else contextlib.nullcontext() as server:
        if server is not None:
            vis = connect(server)
            try:
                scene = MeshcatScene(vis, data, hand, options)
                if renderer == "chromium":
                    try:
                        pngs = render_chromium(scene, frames, out_dir, options)
                        _check_not_blank(pngs, "headless Chromium")
                    except VizError as e:
                        if cfg.renderer != "auto":
                            raise
                        log.warning("Chromium failed (%s); rendering with MuJoCo instead", e)
                        used = "mujoco"
                if cfg.scene_html:
                    animation = scene.animate()  # real time: keyframe stride and clip fps
                    atomic_write_text(out_dir / SCENE_HTML, vis.static_html())
            finally:
                vis.window.close()
    if used == "mujoco":
        pngs = render_mujoco(hand, data, frames, out_dir, options)
        _check_not_blank(pngs, "MuJoCo")
    for t, png in zip(frames, pngs, strict=True):
        images.caption(png, _caption_lines(data, t, options))
    manifest = {
        "hand": data.hand_name,
        "pair": data.pair,
        "run_dir": str(run_dir) if run_dir is not None else None,
        "renderer": used,
        "frames": frames,
        "times_s": [float(data.timestamp[t] - data.timestamp[0]) for t in frames],
        "files": [p.name for p in pngs],
        "scene_html": SCENE_HTML if cfg.scene_html else None,
        "layout": options.layout,
        "robot": data.robot_source,
        "width": options.width,
        "height": options.height,
        "animation": animation,
        "options": {k: v for k, v in asdict(options).items() if k != "camera"},
    }
    atomic_write_text(out_dir / MANIFEST, json.dumps(manifest, indent=2))
    return manifest


def _check_not_blank(pngs: list[Path], who: str) -> None:
    for p in pngs:
        frac = images.content_fraction(p)
        if frac < images.MIN_CONTENT_FRACTION:
            raise VizError(f"{who} drew a blank picture {p.name} ({100 * frac:.2f} % content)")


def _caption_lines(data: SceneData, t: int, options: SceneOptions) -> list[str]:
    time_s = data.timestamp[t] - data.timestamp[0]
    robot = "re-simulated" if data.robot_source == "sim" else "retargeted joints"
    if options.layout == "side_by_side":
        where = f"left: human demonstration · right: {data.hand_name} ({robot})"
    else:
        where = f"translucent: human demonstration · solid: {data.hand_name} ({robot})"
    return [f"{data.hand_name} · {data.pair} · frame {t} ({time_s:.2f} s)", where]


def snapshot_run(
    run_dir: Path,
    *,
    frames=None,
    renderer: str = "auto",
    overwrite: bool = False,
    progress: bool = False,
) -> dict:
    """Stills of an existing run into the run directory itself (``retarget run --snapshot``);
    ``overwrite``: replace stills it already has."""
    cfg = SnapshotConfig(
        out=Path(run_dir),
        run_dir=Path(run_dir),
        renderer=renderer,
        frames=frames,
        overwrite=overwrite,
        progress=progress,
    )
    return run_snapshot(cfg)
