"""The run configuration, conditions, targets, and the runs planned per pair."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.sim.pipeline import SimConfig
from dexcanvas_core.sim.tracker import TrackingConfig
from dexcanvas_core.taxonomy import heavy_variant

NAME = "force_pipeline"
"""The benchmark's name: its results folder ``benchmarks/results/<NAME>/``."""
PLOTS_DIR = "force_plots"
"""Plot folder, next to the JSON output."""

CONDITIONS = ("clean", "mocap", "mocap_size")
HEAVY = "clean_heavy"
"""Run label of the clean demonstration simulated with the heavy object variant."""
TRACKERS = ("mpc", "open_loop")
VERSION_DISTS = ("dexcanvas-retarget", "mujoco", "numpy", "scipy", "torch")

MOCAP_NOISE_MM = 1.0
"""Per-axis marker noise σ [mm] of the mocap conditions."""
MOCAP_DROPOUT = 0.1
"""Probability that a marker sample is missing (single-frame dropouts)."""
SIZE_PERTURBATION = 0.2
"""``mocap_size``: object size × (1 + 0.2) on even pairs, × (1 − 0.2) on odd ones."""

# The paper's targets (reported against, not enforced).
TARGET_SUCCESS = {"clean": 0.90, "mocap": 0.90, "mocap_size": 0.80}
TARGET_COMPUTE_S = 5.0
TARGET_NEWTON_EULER = 0.05
TARGET_WEIGHT = 0.03


@dataclass(frozen=True)
class BenchConfig:
    """One benchmark run."""

    n_pairs: int = 32
    """Pairs (demonstrations); ≥ 21 covers every manipulation type."""
    conditions: tuple[str, ...] = CONDITIONS
    """Conditions to run, a subset of ``CONDITIONS``."""
    workers: int = 2
    """Worker processes (one thread each)."""
    tracker: str = "mpc"
    """``mpc`` (sampling MPC) or ``open_loop``."""
    out: Path | None = None
    """JSON output; ``None``: ``benchmarks/results/force_pipeline/<date>-<commit>.json``
    (``benchmarks._common.result_path``). Plots go to ``force_plots/`` next to it."""
    seed: int = 0
    """Seed of the pair selection, the demonstrations and the marker streams."""
    plots: int = 4
    """Force plots for every run of the first ``plots`` pairs."""
    heavy: bool = True
    """Also run the clean demonstration with the heavy object variant (when one exists)."""
    tracking: tuple[tuple[str, object], ...] = ()
    """``TrackingConfig`` fields overridden in every run (ablations: ``--set
    grip_force_min_n=2``); recorded in the JSON's ``sim_config``."""

    def validate(self) -> BenchConfig:
        if self.n_pairs < 1:
            raise ValidationError(f"n_pairs must be ≥ 1, got {self.n_pairs}", field="n_pairs")
        bad = [c for c in self.conditions if c not in CONDITIONS]
        if bad or not self.conditions:
            raise ValidationError(
                f"unknown condition(s) {bad or '(none)'}; available: {', '.join(CONDITIONS)}",
                field="conditions",
            )
        if self.workers < 1:
            raise ValidationError(f"workers must be ≥ 1, got {self.workers}", field="workers")
        if self.tracker not in TRACKERS:
            raise ValidationError(
                f"unknown tracker {self.tracker!r}; available: {', '.join(TRACKERS)}",
                field="tracker",
            )
        if self.plots < 0:
            raise ValidationError(f"plots must be ≥ 0, got {self.plots}", field="plots")
        tracking_config(self)  # unknown fields and bad values fail here, before any run
        return self


def tracking_config(cfg: BenchConfig):
    """The runs' ``TrackingConfig``: the defaults with ``cfg.tracking``'s overrides (names
    checked, numbers for numeric fields, booleans for flags; ``None`` where the field allows
    it). Range checks stay with the code that uses the field."""

    fields = {f.name: f for f in dataclasses.fields(TrackingConfig)}
    bad = [k for k, _ in cfg.tracking if k not in fields]
    if bad:
        raise ValidationError(
            f"unknown TrackingConfig field(s) {', '.join(bad)}; available: "
            f"{', '.join(sorted(fields))}",
            field="tracking",
        )
    defaults = TrackingConfig()
    for k, v in cfg.tracking:
        d = getattr(defaults, k)
        optional = "None" in str(fields[k].type)
        if v is None and optional:
            continue
        number = isinstance(v, (int, float)) and not isinstance(v, bool)
        if isinstance(d, bool) and not isinstance(v, bool):
            raise ValidationError(f"{k} takes True or False, got {v!r}", field="tracking")
        if isinstance(d, (int, float)) and not isinstance(d, bool) and not number:
            raise ValidationError(
                f"{k} takes a number{' or None' if optional else ''}, got {v!r}", field="tracking"
            )
    return dataclasses.replace(defaults, **dict(cfg.tracking))


# ------------------------------------------------------------------------------------- plan
def object_scale(condition: str, i: int) -> float:
    """The object size factor of pair ``i`` in ``condition``."""
    if condition != "mocap_size":
        return 1.0
    return 1.0 + SIZE_PERTURBATION if i % 2 == 0 else 1.0 - SIZE_PERTURBATION


def plan_runs(i: int, pair, cfg: BenchConfig) -> list[tuple[str, object]]:
    """``[(condition, SimConfig)]`` of pair ``i``, in report order."""

    base = SimConfig(tracker=cfg.tracker, tracking=tracking_config(cfg))
    runs = [
        (c, dataclasses.replace(base, object_scale=object_scale(c, i)))
        for c in CONDITIONS
        if c in cfg.conditions
    ]
    heavy = heavy_variant(pair.object.id)
    if cfg.heavy and "clean" in cfg.conditions and heavy is not None:
        runs.append((HEAVY, dataclasses.replace(base, object_id=heavy.id)))
    return runs
