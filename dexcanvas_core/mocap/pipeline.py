"""Markers → ``Trajectory``: the whole fit of one capture, and ``run_fit`` (``dexcanvas fit``).

``fit_markers(stream)`` runs, in order:

1. **World frame**: every marker goes through the stream's fixed mocap → MANO world transform
   (``MocapFrame``: axes, origin, unit).
2. **Object** (when the stream has ``obj1`` … ``obj4``): per-frame rigid registration with
   label-swap repair and outlier rejection (``rigid.register_object``) on the raw markers; the
   cleaned markers are gap-filled and low-passed and registered again. Frames with fewer than 3
   markers get a pose interpolated from their neighbours (slerp) and are flagged; an object that
   never shows 3 markers is an error.
3. **Hand, pass 1** on the raw markers (palm swaps repaired by rigid registration first), with a
   provisional hand size from the palm markers' spread: ``sequence.fit_sequence`` — wrist from the
   palm markers, key frames fitted from cold starts, every frame warm-started from them.
4. **Hand marker repair**: in frames with a marker residual above its threshold (``outlier_mm``,
   or 5 σ of that marker's pass-1 residuals if larger), swapping suspect labels pairwise and
   dropping the worst marker are tried (batched re-solves); a swap that brings every residual
   under its threshold is applied, else such a removal; both are flagged.
5. **Subject calibration** (``calibrate``) on the calibration segment (default: the first
   second) of the cleaned markers, starting from the pass-1 poses; then held fixed. If the
   segment has no usable frame the whole capture is tried, and failing that the palm-marker
   size estimate is kept (mode ``"palm"``, logged).
6. **Gaps and noise**: short gaps (≤ ``max_gap_frames``) are spline-filled, longer ones flagged;
   every contiguous run is low-passed (zero-phase Butterworth, ``lowpass_hz``) when the noise
   estimated from pass 1 is at least ``lowpass_min_noise_mm``.
7. **Hand, pass 2** on the cleaned markers with the calibrated hand, warm-started from pass 1
   (where a finger marker is inside a long gap, the finger's start and temporal prior are
   interpolated across the gap). Frames left with fewer than 3 usable hand markers get
   parameters interpolated from their neighbours and are flagged.

The output trajectory has one ``object_move`` segment: the frames in which the object is
displaced from its initial pose (``move_threshold_mm`` / ``move_threshold_deg``).

Per-frame quality flags (:class:`~.results.FitFlags`) travel with the result and are stored in
the written dataset as one extra column ``fit_quality`` (a struct of per-frame lists); the
calibration and the settings go to the column ``mocap_fit``. Nothing is dropped: the output has
one frame per input frame, and every frame whose values are not a direct fit says so.
"""

from __future__ import annotations

import json
import logging
import math
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pyarrow as pa
import torch

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.io import write_dataset
from dexcanvas_core.mano.skeleton import BETA0_SCALE_PER_UNIT
from dexcanvas_core.mocap.calibrate import SubjectCalibration
from dexcanvas_core.mocap.frames import UNITS_M
from dexcanvas_core.mocap.layout import HAND_MARKER_NAMES, OBJECT_MARKER_NAMES
from dexcanvas_core.mocap.options import FitOptions
from dexcanvas_core.mocap.readers import read_markers
from dexcanvas_core.mocap.results import FIT_INFO_COLUMN, FIT_QUALITY_COLUMN, FitFlags, MocapFit
from dexcanvas_core.mocap.stages import MarkerDataError, fit_hand, fit_object
from dexcanvas_core.mocap.stream import MarkerStream
from dexcanvas_core.plausibility import check_hand_scale
from dexcanvas_core.rotations import rotation_angle_between_aa
from dexcanvas_core.safe_io import check_output
from dexcanvas_core.taxonomy import object_spec
from dexcanvas_core.trajectory import HandTrack, ObjectMove, ObjectTrack, Trajectory

log = logging.getLogger(__name__)


@contextmanager
def _torch_threads(n: int):
    old = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(old)


# -- the whole capture --------------------------------------------------------------------------


def fit_markers(
    stream: MarkerStream,
    *,
    options: FitOptions | None = None,
    object_id: str | None = None,
    uuid: str | None = None,
    operator: str = "",
    gesture: str = "",
) -> MocapFit:
    """Fit a capture: object poses, subject calibration, hand parameters, quality flags.

    Args:
        stream: the labelled markers (``readers.read_markers`` or ``render_markers``).
        options: fit settings (``FitOptions``).
        object_id: catalogue id of the object (overrides ``stream.object_id``).
        uuid, operator, gesture: identity fields of the output trajectory.

    Raises:
        MarkerDataError: the object never shows 3 markers, object markers without an object
            id, an object id without object markers, or a hand that is never observable.
    """
    opts = (options or FitOptions()).validate()
    t_start = time.perf_counter()
    T = stream.num_frames
    times = stream.times
    fps = stream.fps
    obj_id = object_id or stream.object_id
    if stream.has_object_markers and obj_id is None:
        raise MarkerDataError(
            "the stream has object markers (obj1..obj4) but no object id; pass object_id "
            "(e.g. 'cube2') or set \"object\" in the mapping file"
        )
    if obj_id is not None:
        obj_id = object_spec(obj_id).id
        if not stream.has_object_markers:
            raise MarkerDataError(
                f"object {obj_id!r} was given but the stream has none of the object markers "
                f"{', '.join(OBJECT_MARKER_NAMES)}"
            )
    present = [n for n in HAND_MARKER_NAMES if n in stream.labels]
    if not present:
        raise MarkerDataError(
            f"the stream has none of the 14 hand markers ({', '.join(HAND_MARKER_NAMES)})"
        )
    absent = [n for n in HAND_MARKER_NAMES if n not in stream.labels]
    if absent:
        log.warning("hand markers absent from the capture (fitted without them): %s", absent)
    world_all = stream.positions_world()
    nan_frame = ~np.isfinite(world_all).all(-1).any(1)
    hand_world = stream.hand_world()

    with _torch_threads(opts.threads), torch.no_grad():
        obj = None
        t_obj = time.perf_counter()
        if obj_id is not None:
            obj = fit_object(stream.object_world(), obj_id, times, fps, opts)
        t_obj = time.perf_counter() - t_obj
        hand = fit_hand(hand_world, times, fps, stream.side, opts, opts.calibration)
    fit_seconds = time.perf_counter() - t_start

    x = hand["x"]
    obj_vis = obj["visible"] if obj else np.zeros(T, np.int64)
    n_layout = len(HAND_MARKER_NAMES) + (len(OBJECT_MARKER_NAMES) if obj else 0)
    false = np.zeros(T, bool)
    flags = FitFlags(
        residual_mm=hand["residual_mm"],
        max_residual_mm=hand["max_residual_mm"],
        object_residual_mm=obj["residual_mm"] if obj else np.full(T, np.nan),
        hand_markers_visible=hand["visible"],
        object_markers_visible=obj_vis,
        missing_markers=n_layout - hand["visible"] - obj_vis,
        interpolated=hand["marker_interp"]
        | hand["pose_short"]
        | (obj["marker_interp"] | obj["pose_short"] if obj else false),
        long_gap=hand["marker_long"]
        | hand["pose_long"]
        | (obj["marker_long"] | obj["pose_long"] if obj else false),
        hand_interpolated=hand["hand_lost"],
        object_interpolated=(obj["pose_short"] | obj["pose_long"]) if obj else false,
        swapped=hand["swapped"] | (obj["swapped"] if obj else false),
        outliers=hand["outliers"] + (obj["outliers"] if obj else 0),
        nan_frame=nan_frame,
    )
    cal: SubjectCalibration = hand["calibration"]
    betas = np.zeros(10, np.float32)
    betas[0] = math.log(cal.scale) / BETA0_SCALE_PER_UNIT
    side = stream.side
    track = HandTrack(
        name=side,
        global_pos=x[:, 3:6],
        global_rot_aa=x[:, :3],
        hand_pose=np.concatenate([x[:, :3], x[:, 6:]], axis=1),
        joint_pos=hand["keypoints"],
        betas=betas,
    )
    objects = [ObjectTrack(obj_id, obj["pos"], obj["rot_aa"])] if obj else []
    moves = _object_moves(obj_id, obj["pos"], obj["rot_aa"], opts) if obj else []
    info = {
        "source": stream.source,
        "mocap_frame": stream.frame.to_dict(),
        "ignored_labels": list(stream.ignored_labels),
        "absent_markers": absent,
        "object_id": obj_id,
        "calibration": cal.to_dict(),
        "options": opts.to_dict(),
        "noise_sigma_estimate_mm": hand["sigma_hat_mm"],
        "lowpass_hz": {"hand": hand["lowpass_hz"], "object": obj["lowpass_hz"] if obj else None},
        "outlier_threshold_mm": hand["threshold_mm"],
        "fit_seconds": fit_seconds,
        "mean_iterations": float(np.mean(hand["iterations"])),
        "timings_s": {"object": t_obj, **hand["timings"]},
    }
    if uuid:
        uid = uuid
    elif stream.source.startswith("render:"):
        uid = "mocap-" + stream.source.split(":", 1)[1]
    else:
        uid = "mocap-" + (Path(stream.source).stem or "capture")
    traj = Trajectory(
        uuid=uid,
        timestamp=times.copy(),
        fps=float(fps),
        hands=[track],
        objects=objects,
        gesture=gesture,
        operator=operator,
        scene=obj_id or "",
        object_move=moves,
        cap_machine="dexcanvas-mocap-fit",
        is_generated=False,
        extras={
            FIT_QUALITY_COLUMN: flags.to_arrow(),
            FIT_INFO_COLUMN: pa.scalar(json.dumps(info, default=_json_default)),
        },
    )
    unit = next((k for k, v in UNITS_M.items() if math.isclose(v, stream.frame.unit_m)), None)
    check_hand_scale(track.joint_pos, f"{stream.source}", "the fitted hand", units=unit)
    traj.validate()
    log.info(
        "fitted %d frames in %.2f s (%.0f frames/s); %s",
        T,
        fit_seconds,
        T / max(fit_seconds, 1e-9),
        flags.summary(),
    )
    return MocapFit(traj, flags, cal, obj_id, fit_seconds, info)


def _object_moves(
    obj_id: str, pos: np.ndarray, rot_aa: np.ndarray, opts: FitOptions
) -> list[ObjectMove]:
    """The ``object_move`` segment: from the first to the last frame in which the object is
    displaced from its initial pose by more than ``move_threshold_mm`` or ``move_threshold_deg``
    (no segment if it never is)."""
    d = np.linalg.norm(pos - pos[0], axis=-1) * 1000
    a = np.rad2deg(rotation_angle_between_aa(rot_aa, np.tile(rot_aa[0], (len(rot_aa), 1))))
    moving = np.flatnonzero((d > opts.move_threshold_mm) | (a > opts.move_threshold_deg))
    if moving.size == 0:
        return []
    return [ObjectMove(obj_id, int(moving[0]), int(moving[-1]))]


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    return str(o)


# -- run_fit (the CLI's entry point) -------------------------------------------------------------


@dataclass(frozen=True)
class FitConfig:
    """``dexcanvas fit MARKERS --out PATH``: what to read, how to fit, where to write."""

    markers: Path
    """Marker file (``.c3d`` or ``.csv``)."""
    out: Path
    """Output Lance dataset (a directory, conventionally ``*.lance``)."""
    format: Literal["auto", "c3d", "csv"] = "auto"
    """File format; ``auto`` takes it from the extension."""
    mapping: Path | None = None
    """Marker-name mapping file (JSON or CSV); see ``readers``."""
    object_id: str | None = None
    """Catalogue object carrying ``obj1`` … ``obj4`` (or ``"object"`` in the mapping)."""
    fps: float | None = None
    """Frame rate [Hz], overriding the file's."""
    units: str | None = None
    """Length unit of the file (``mm``, ``cm``, ``m``), overriding the file's."""
    up: Literal["y", "z"] = "y"
    """Vertical axis of the mocap frame."""
    origin_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """World position [m] of the mocap origin."""
    side: Literal["right", "left"] | None = None
    """Hand side (default: the mapping's, else right)."""
    overwrite: bool = False
    """Replace an existing output dataset."""
    uuid: str | None = None
    operator: str = ""
    gesture: str = ""
    calibration_file: Path | None = None
    """A saved ``SubjectCalibration`` (JSON) to use instead of calibrating."""
    save_calibration: Path | None = None
    """Write the calibration used to this JSON file."""
    options: FitOptions = field(default_factory=FitOptions)

    def validate(self) -> FitConfig:
        if not Path(self.markers).exists():
            raise ValidationError(f"marker file {self.markers} does not exist", field="markers")
        check_output(self.out, overwrite=self.overwrite, kind="dir")
        if self.save_calibration is not None:
            check_output(self.save_calibration, overwrite=self.overwrite, what="--save-calibration")
        if self.fps is not None and not (math.isfinite(self.fps) and self.fps > 0):
            raise ValidationError(f"fps must be > 0, got {self.fps}", field="fps")
        self.options.validate()
        return self


@dataclass
class FitReport:
    """What ``run_fit`` did."""

    out: Path
    frames: int
    fps: float
    fit_seconds: float
    frames_per_second: float
    object_id: str | None
    calibration: dict[str, Any]
    flags: dict[str, Any]
    ignored_labels: list[str]
    absent_markers: list[str]

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["out"] = str(self.out)
        return d


def run_fit(cfg: FitConfig) -> FitReport:
    """Read a marker file, fit it and write a one-row Trajectory dataset with the flags."""
    cfg.validate()
    stream = read_markers(
        cfg.markers,
        format=cfg.format,
        mapping=cfg.mapping,
        fps=cfg.fps,
        units=cfg.units,
        up=cfg.up,
        origin_m=cfg.origin_m,
        object_id=cfg.object_id,
        side=cfg.side,
    )
    opts = cfg.options
    if cfg.calibration_file is not None:
        opts = replace(opts, calibration=SubjectCalibration.load(cfg.calibration_file))
    result = fit_markers(
        stream,
        options=opts,
        object_id=cfg.object_id,
        uuid=cfg.uuid or f"mocap-{Path(cfg.markers).stem}",
        operator=cfg.operator,
        gesture=cfg.gesture,
    )
    if cfg.save_calibration is not None:
        result.calibration.save(cfg.save_calibration)
    write_dataset([result.trajectory], cfg.out, mode="overwrite" if cfg.overwrite else "create")
    return FitReport(
        out=Path(cfg.out),
        frames=result.flags.num_frames,
        fps=stream.fps,
        fit_seconds=result.fit_seconds,
        frames_per_second=result.frames_per_second,
        object_id=result.object_id,
        calibration=result.calibration.to_dict(),
        flags=result.flags.summary(),
        ignored_labels=list(stream.ignored_labels),
        absent_markers=result.info["absent_markers"],
    )
