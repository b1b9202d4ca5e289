"""The benchmark's run configuration, its variants, constants and targets, and the objects a pair is
run with."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from dexcanvas_core.taxonomy import heavy_variant
from retarget.hands import available_hands
from retarget.pipeline import RunConfig

NAME = "force_preservation"
"""The benchmark's name: its results folder ``benchmarks/results/<NAME>/``."""
NOT_REQUESTED = "not requested (--variants)"
TRACKERS = ("mpc", "open_loop")
VERSION_DISTS = (
    "dexcanvas-retarget",
    "dex-retargeting",
    "mujoco",
    "pin",
    "numpy",
    "qpsolvers",
    "daqp",
    "matplotlib",
)

VARIANTS = ("a", "b", "c", "d", "e")
LABELS = {
    "a": "(a) dex-retargeting",
    "b": "(b) ours: keypoints",
    "c": "(c) + contacts",
    "d": "(d) + forces",
    "e": "(e) + refinement",
}
NOT_IMPLEMENTED: dict[str, str] = {}
"""Variants the library cannot run yet: a row in every table, no numbers."""
RUN_VARIANTS = tuple(v for v in VARIANTS if v not in NOT_IMPLEMENTED)
HUMAN_METRICS = ("success", "success_loose", "failed_at_frame", "frames", "frames_tracked",
                 "object_pos_err_max_m", "object_pos_err_mean_m", "mass_kg", "compute_s",
                 "compute_s_per_demo_s", "hold_weight_ratio", "contact_frames")  # fmt: skip
"""Force-pipeline metrics kept per human simulation (``SimResult.metrics``)."""
FIVE_FINGER = "five-finger hands"
ALL_HANDS = "all hands"

# The targets (reported against, not enforced).
TARGET_SUCCESS = 0.85
TARGET_RATIO = 2.0
TARGET_CORRELATION = 0.8
TARGET_FORCE_PCT_WEIGHT = 0.15


@dataclass(frozen=True)
class BenchConfig:
    """One benchmark run."""

    hands: tuple[str, ...] | None = None
    """Hands to run; ``None``: every registered hand."""
    n_pairs: int = 20
    """Demonstration pairs (light objects as generated), spread over the four groups."""
    max_frames: int | None = None
    """Crop each demonstration to this many frames (around the start of the object motion)."""
    human_tracker: str = "mpc"
    """Force pipeline tracker: ``mpc`` (sampling MPC) or ``open_loop`` (fast, less successful)."""
    heavy: bool = True
    """Also run pairs whose object has a heavy variant with that variant."""
    workers: int = 2
    """Worker processes (one thread each)."""
    out: Path | None = None
    """JSON output; ``None``: ``benchmarks/results/force_preservation/<date>-<commit>.json``
    (``benchmarks._common.result_path``)."""
    plot: Path | None = None
    """PNG of strict success by variant and hand; ``None``: the JSON path with ``.png``."""
    operator: str = "operator1"
    seed: int = 0
    dex_wrist: str = "free"
    """dex-retargeting's wrist: ``free`` (optimised) or ``fixed`` (the human wrist pose)."""
    variants: tuple[str, ...] = ("a", "b", "c", "d", "e")
    """Variants to run; the others' rows are marked skipped ("not requested"). (e) refines
    (d)'s output, so asking for (e) runs (d) too."""
    overrides: dict = field(default_factory=dict)
    """``RetargetConfig`` fields changed for our variants (b)–(e) (``--set NAME=VALUE``); each
    variant's defining fields win (b: no contacts, no squeeze; d: force matching)."""
    refine_overrides: dict = field(default_factory=dict)
    """``RefineConfig`` fields changed for variant (e)'s refinement (``--refine-set
    NAME=VALUE``)."""
    calibrate_iterations: int = RunConfig.calibrate_iterations
    """Variant (d)'s force calibration (``retarget.force_calibration``,
    ``ForceCalibrationConfig.iterations``, as ``retarget run --forces``): 0 re-simulates the
    planned commands only."""
    human_cache: Path | None = None
    """Directory of cached human simulations (``--human-cache``): a (demonstration, object,
    tracker) simulated once is read back on later runs instead of simulated again."""
    human_replay: bool = True
    """Simulate every (pair, object) a second time with another seed of the force pipeline's
    sampling MPC (``HUMAN_REPLAY_SEED``) and score its per-finger forces against the first's as the
    robots' are (``retarget.metrics.human_replay_metrics``): the ceiling of the force correlation
    (``--no-human-replay``: skip; never with the deterministic ``open_loop`` tracker)."""

    def replays(self) -> bool:
        """Whether this run simulates the human replays (``mpc`` only)."""
        return self.human_replay and self.human_tracker == "mpc"

    def validate(self) -> BenchConfig:
        if self.n_pairs < 1:
            raise SystemExit(f"--n-pairs must be >= 1, got {self.n_pairs}")
        if self.max_frames is not None and self.max_frames < 2:
            raise SystemExit(f"--max-frames must be >= 2, got {self.max_frames}")
        if self.human_tracker not in TRACKERS:
            raise SystemExit(
                f"unknown --human-tracker {self.human_tracker!r}; available: {', '.join(TRACKERS)}"
            )
        if self.workers < 1:
            raise SystemExit(f"--workers must be >= 1, got {self.workers}")
        if self.calibrate_iterations < 0:
            raise SystemExit(
                f"--calibrate-iterations must be >= 0, got {self.calibrate_iterations}"
            )
        if self.dex_wrist not in ("free", "fixed"):
            raise SystemExit(f"--dex-wrist must be free or fixed, got {self.dex_wrist!r}")
        bad_v = [v for v in self.variants if v not in RUN_VARIANTS]
        if bad_v or not self.variants:
            raise SystemExit(
                f"--variants: unknown or none {', '.join(bad_v)}; choose from "
                f"{' '.join(RUN_VARIANTS)}"
            )
        bad = [h for h in self.hands or () if h not in available_hands()]
        if bad:
            raise SystemExit(
                f"unknown hand(s) {', '.join(bad)}; available: {', '.join(available_hands())}"
            )
        return self

    def plot_path(self) -> Path:
        return Path(self.plot) if self.plot is not None else Path(self.out).with_suffix(".png")

    def computed_variants(self) -> tuple[str, ...]:
        """The requested variants plus what they need: (e) needs (d)."""
        want = set(self.variants) | ({"d"} if "e" in self.variants else set())
        return tuple(v for v in RUN_VARIANTS if v in want)


def object_plan(pair, heavy: bool) -> list[dict]:
    """The objects a pair is run with: the demonstration's own, then its heavy variant."""

    spec = pair.object
    out = [
        {
            "object_id": spec.id,
            "object_variant": "heavy" if spec.heavy else "light",
            "heavy_version_of": None,
        }
    ]
    h = heavy_variant(spec.id) if heavy and not spec.heavy else None
    if h is not None:
        out.append({"object_id": h.id, "object_variant": "heavy", "heavy_version_of": spec.id})
    return out
