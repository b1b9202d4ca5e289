"""Optical mocap → MANO: marker layout, synthetic marker streams, readers, and the fitter.

* ``layout``: the 14 hand markers (anatomical landmarks on MANO bones) and 4 markers per object;
* ``frames``: the fixed mocap → MANO world transform (``MocapFrame``);
* ``stream``: ``MarkerStream``, labelled markers as a mocap system delivers them;
* ``render``: ``render_markers``, the stream of a demonstration with noise, dropouts, occlusion
  gaps and label swaps;
* ``readers`` / ``writers``: C3D (``ezc3d``) and CSV files; ``mapping``: the marker-name mapping
  file;
* ``rigid``: weighted Kabsch and robust object registration;
* ``calibrate``: subject calibration (hand size or bone lengths, marker offsets);
* ``model`` / ``fit``: the marker model and the batched Levenberg–Marquardt hand fit;
* ``gaps``: gap filling and low-pass filtering of marker trajectories;
* ``pipeline``: ``fit_markers`` (markers → ``Trajectory`` + per-frame flags) and ``run_fit``
  (``dexcanvas fit MARKERS --out PATH``); its settings in ``options`` (``FitOptions``), its
  stages (object, hand) in ``stages``, its results in ``results`` (``FitFlags``, ``MocapFit``).
"""

from dexcanvas_core.mocap.calibrate import (
    CALIBRATION_MODES,
    CalibrationError,
    SubjectCalibration,
    calibrate_subject,
    nominal_calibration,
)
from dexcanvas_core.mocap.fit import AnatomicalPrior, HandFitter, SolverOptions
from dexcanvas_core.mocap.frames import MocapFrame
from dexcanvas_core.mocap.gaps import fill_gaps, lowpass
from dexcanvas_core.mocap.layout import (
    DORSUM_MARKERS,
    HAND_MARKER_NAMES,
    HAND_MARKERS,
    MARKER_NAMES,
    OBJECT_MARKER_NAMES,
    HandMarker,
    hand_marker_rest_positions,
    object_marker_positions,
    object_marker_table,
)
from dexcanvas_core.mocap.mapping import MarkerFileError, MarkerMapping, load_mapping
from dexcanvas_core.mocap.model import HandMarkerModel
from dexcanvas_core.mocap.options import FitOptions
from dexcanvas_core.mocap.pipeline import FitConfig, FitReport, fit_markers, run_fit
from dexcanvas_core.mocap.readers import read_c3d, read_csv, read_markers
from dexcanvas_core.mocap.render import render_markers
from dexcanvas_core.mocap.results import (
    FIT_INFO_COLUMN,
    FIT_QUALITY_COLUMN,
    FitFlags,
    MocapFit,
    fit_flags,
)
from dexcanvas_core.mocap.rigid import ObjectRegistration, kabsch, register_object
from dexcanvas_core.mocap.sequence import fit_sequence
from dexcanvas_core.mocap.stages import MarkerDataError
from dexcanvas_core.mocap.stream import MarkerStream, MarkerTruth
from dexcanvas_core.mocap.writers import write_c3d, write_csv

__all__ = [
    "CALIBRATION_MODES",
    "DORSUM_MARKERS",
    "FIT_INFO_COLUMN",
    "FIT_QUALITY_COLUMN",
    "HAND_MARKERS",
    "HAND_MARKER_NAMES",
    "MARKER_NAMES",
    "OBJECT_MARKER_NAMES",
    "AnatomicalPrior",
    "CalibrationError",
    "FitConfig",
    "FitFlags",
    "FitOptions",
    "FitReport",
    "HandFitter",
    "HandMarker",
    "HandMarkerModel",
    "MarkerDataError",
    "MarkerFileError",
    "MarkerMapping",
    "MarkerStream",
    "MarkerTruth",
    "MocapFit",
    "MocapFrame",
    "ObjectRegistration",
    "SolverOptions",
    "SubjectCalibration",
    "calibrate_subject",
    "fill_gaps",
    "fit_flags",
    "fit_markers",
    "fit_sequence",
    "hand_marker_rest_positions",
    "kabsch",
    "load_mapping",
    "lowpass",
    "nominal_calibration",
    "object_marker_positions",
    "object_marker_table",
    "read_c3d",
    "read_csv",
    "read_markers",
    "register_object",
    "render_markers",
    "run_fit",
    "write_c3d",
    "write_csv",
]
