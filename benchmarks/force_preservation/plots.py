"""The PNG of strict success by variant and hand."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.force_preservation.config import (
    LABELS,
    NOT_IMPLEMENTED,
    RUN_VARIANTS,
    TARGET_CORRELATION,
    TARGET_SUCCESS,
    VARIANTS,
)
from dexcanvas_core.safe_io import atomic_path
from retarget.human_forces import HUMAN_REPLAY_SEED


def plot_success(
    per_hand: dict, scope_aggs: dict, path: Path, ceilings: dict | None = None
) -> Path:
    """Grouped bars: strict success [%] per hand (and per scope), one bar per variant; with
    ``ceilings`` (hand or scope → :func:`replay_ceiling` of (d)), a second panel: (d)'s force
    profile correlation on its successful runs next to the human replay's on the same runs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = {**per_hand, **scope_aggs}
    names = list(groups)
    run_v = list(RUN_VARIANTS)
    width = 0.8 / len(VARIANTS)
    x = np.arange(len(names))
    size = (max(6.0, 1.3 * len(names) + 2), 4.2)
    if ceilings:
        fig, (ax, ax2) = plt.subplots(
            2, 1, figsize=(size[0], 2 * size[1] + 0.8), gridspec_kw={"hspace": 0.55}
        )
    else:
        fig, ax = plt.subplots(figsize=size)
    for k, v in enumerate(VARIANTS):
        xs = x - 0.4 + (k + 0.5) * width
        if v in NOT_IMPLEMENTED:
            for xi in xs:
                ax.text(
                    xi, 1.5, "n/a", rotation=90, ha="center", va="bottom", fontsize=7, color="0.4"
                )
            ax.bar(
                xs,
                np.zeros(len(names)),
                width,
                label=f"{LABELS[v]}: not implemented",
                color="0.85",
                hatch="//",
            )
            continue
        vals = [groups[n][v]["success_rate"] for n in names]
        h = [100 * (s or 0.0) for s in vals]
        bars = ax.bar(xs, h, width, label=LABELS[v], color=f"C{run_v.index(v)}")
        for b, s in zip(bars, vals, strict=True):
            label = "–" if s is None else f"{100 * s:.0f}"
            ax.text(
                b.get_x() + b.get_width() / 2,
                b.get_height() + 1,
                label,
                ha="center",
                va="bottom",
                fontsize=6,
            )
    ax.axhline(100 * TARGET_SUCCESS, color="k", lw=0.8, ls="--")
    _target_label(ax, 100 * TARGET_SUCCESS, f"target (d)\nor (e) {100 * TARGET_SUCCESS:.0f} %")
    ax.set_xticks(x, names)
    ax.set_ylim(0, 110)
    ax.set_ylabel("strict success [%] (no frame > 5 cm)")
    ax.set_title("force preservation: re-simulated strict success by variant and hand")
    ax.legend(fontsize=7, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.1))
    if ceilings:
        _plot_ceiling(ax2, names, ceilings)
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, bbox_inches="tight", format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    return path


def _target_label(ax, y: float, text: str) -> None:
    """Name a target line in the right margin, clear of the bars' value labels."""
    ax.text(1.005, y, text, transform=ax.get_yaxis_transform(), ha="left", va="center", fontsize=7)


def _plot_ceiling(ax, names: list[str], ceilings: dict) -> None:
    """(d)'s whole-demonstration force correlation and the human replay's, on the same runs."""
    key = "force_profile_correlation_mean"
    x = np.arange(len(names))
    for k, (label, side, color) in enumerate(
        (("(d) + forces", "ours", f"C{list(RUN_VARIANTS).index('d')}"),
         (f"human replay (MPC seed {HUMAN_REPLAY_SEED} vs 0)", "replay", "0.55"))
    ):  # fmt: skip
        vals = [ceilings.get(n, {}).get(side, {}).get(key) for n in names]
        bars = ax.bar(x - 0.2 + 0.4 * k, [v or 0.0 for v in vals], 0.4, label=label, color=color)
        for b, v in zip(bars, vals, strict=True):
            text = "–" if v is None else f"{v:.2f}"
            xc = b.get_x() + b.get_width() / 2
            ax.text(xc, b.get_height() + 0.01, text, ha="center", va="bottom", fontsize=6)
    runs = [ceilings.get(n, {}).get("runs", 0) for n in names]
    ax.set_xticks(x, [f"{n}\n({r} runs)" for n, r in zip(names, runs, strict=True)])
    ax.axhline(TARGET_CORRELATION, color="k", lw=0.8, ls="--")
    _target_label(ax, TARGET_CORRELATION, f"target {TARGET_CORRELATION:g}")
    ax.set_ylim(0, 1.1)
    ax.set_ylabel("force profile correlation")
    ax.set_title("per-finger force correlation on (d)'s successful runs: ours and the human's own")
    ax.legend(fontsize=7, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.22))
