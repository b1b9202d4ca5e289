"""The run configuration, modes, capture sets, targets and the hands run."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from benchmarks._common import PAGES, RESULTS, is_five_finger
from dexcanvas_core.capture.stress import StressMotion
from retarget.hands import available_hands, get_hand

NAME = "real_motion"
"""The benchmark's name: its results folder ``benchmarks/results/<NAME>/``."""
DEFAULT_WORK = RESULTS / "real_motion_work"
PAGE = PAGES / "real_motion.md"

MODES = ("keypoints", "forces", "forces_refine")
MANO = "mano"
ALL_MODES = (*MODES, MANO)
MODE_FLAGS = {"keypoints": "", "forces": "--forces", "forces_refine": "--forces --refine"}

STRICT_M = 0.05
"""A frame whose object position error exceeds this [m] fails the run (DexCanvas rule)."""

STRESS_PAIRS = ("cube2/tripod", "cube1/large_diameter", "cylinder3/adducted_thumb")
"""Built-in pick-and-place demonstrations whose five-finger grasp lifts the object. (Objects
made of several primitives, e.g. ``mayonnaisebottle``, are not exported as one closed mesh where
their parts touch at vertices: ``mesh_check`` skips them, saying so.)"""

DEXYCB_ITEMS = {
    "006": "mustard bottle",
    "011": "banana",
    "019": "pitcher base",
    "024": "bowl",
    "035": "power drill",
    "037": "scissors",
    "052": "extra-large clamp",
}
"""DexYCB objects (YCB id prefix) that are DexCanvas items."""

CAPTURE_SETS = {
    "mano-npz": (
        "mano-npz",
        "mano-npz captures (*.npz, the keys of dexcanvas_core/capture/arrays.py; "
        "dexcanvas_core.capture.export.write_mano_npz writes them)",
    ),
    "dexycb": (
        "ho3d",
        "DexYCB HO3D-style meta pickles (github Shurui8860/dexYCB_dataloader)",
    ),
    "taco": (
        "taco",
        "TACO source data (taco2024.github.io: <sequence>.pkl hand and object tracks with "
        "their <sequence>.obj object meshes)",
    ),
}
"""``--captures`` sub-directory → (format, what it holds and where it comes from)."""

DEFAULT_DENSITY = 500.0
"""[kg/m³] mass from the mesh volume for captured objects nothing else gives a mass to."""

# The targets (reported against, not enforced).
TARGET_MANO = 0.80
TARGET_REFINE = 0.70
TARGET_WRIST_M = 0.005

# MANO failure reasons (module docstring).


def stress_motions() -> tuple:
    """The stress cases made of each demonstration (module docstring)."""

    return (
        StressMotion("carry", peak_speed=1.5, distance_m=0.3),
        StressMotion("transport", peak_speed=2.0, distance_m=0.45),
        StressMotion("transport", peak_speed=2.5, distance_m=0.7, direction=(1.0, 0.0)),
        StressMotion("transport", peak_speed=3.0, distance_m=1.0, direction=(1.0, 1.0)),
        StressMotion("tool_use", peak_speed=4.0, angle_rad=math.radians(60), direction=(1, 0)),
        StressMotion("fast_lift", time_scale=3.0),
    )


# ------------------------------------------------------------------------------------ main
@dataclass(frozen=True)
class BenchConfig:
    captures: Path | None = None
    models: Path | None = None
    per_object: int = 1
    density: float = DEFAULT_DENSITY
    hands: tuple[str, ...] | None = None
    modes: tuple[str, ...] = ALL_MODES
    cases: tuple[str, ...] = ()
    limit: int | None = None
    pairs: tuple[str, ...] = STRESS_PAIRS
    originals: bool = False
    workers: int = 1
    work: Path = DEFAULT_WORK
    out: Path | None = None
    """JSON output; ``None``: ``benchmarks/results/real_motion/<date>-<commit>.json``."""
    page: Path | None = PAGE
    retry_errors: bool = False

    def validate(self) -> BenchConfig:
        bad = [m for m in self.modes if m not in ALL_MODES]
        if bad:
            raise SystemExit(f"unknown mode(s) {bad}; choose from {', '.join(ALL_MODES)}")
        if self.workers < 1 or self.per_object < 1:
            raise SystemExit("--workers and --per-object must be >= 1")
        if self.limit is not None and self.limit < 1:
            raise SystemExit("--limit must be >= 1")
        return self


def resolve_hands(names) -> tuple[list[str], list[str]]:
    """``(hands, five-finger hands among them)``; default: every five-finger hand."""

    hands = list(names) if names else list(available_hands())
    five = [h for h in hands if is_five_finger(get_hand(h))]
    return (hands if names else five), five
