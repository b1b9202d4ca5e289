"""Plots of the force pipeline (matplotlib, Agg backend, PNG or SVG by file extension)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dexcanvas_core.errors import MissingDependencyError
from dexcanvas_core.safe_io import atomic_path
from dexcanvas_core.sim.physics import GRAVITY
from dexcanvas_core.trajectory import FORCE_GROUPS

FINGER_COLOURS = {
    "thumb": "#d62728",
    "index": "#1f77b4",
    "middle": "#2ca02c",
    "ring": "#9467bd",
    "pinky": "#ff7f0e",
    "palm": "#7f7f7f",
}


def _pyplot():
    try:
        import matplotlib
    except ImportError as e:  # pragma: no cover - matplotlib is a dependency of the extras
        raise MissingDependencyError(
            "plots need matplotlib: pip install 'dexcanvas-retarget[viz]'"
        ) from e
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_finger_forces(result, path: str | Path, title: str = "") -> Path:
    """Per-finger contact force magnitude over time (the DexCanvas paper's Figure 5b), with the
    object's weight and each finger's maximum, above the object position error."""
    plt = _pyplot()
    F = np.linalg.norm(result.finger_force, axis=2)  # (T, 6)
    fps = result.metrics["fps"]
    t = np.arange(F.shape[0]) / fps
    mg = result.metrics["mass_kg"] * GRAVITY
    fig, (ax, ax2) = plt.subplots(
        2, 1, figsize=(8, 5), sharex=True, gridspec_kw={"height_ratios": [3, 1]}
    )
    for k, name in enumerate(FORCE_GROUPS):
        if F[:, k].max() < 1e-3:
            continue
        ax.plot(t, F[:, k], color=FINGER_COLOURS[name], lw=1.2, label=name)
        ax.axhline(F[:, k].max(), color=FINGER_COLOURS[name], lw=0.6, ls=":")
    ax.axhline(mg, color="k", lw=0.8, ls="--", label="m·g")
    if result.hold.any():
        ax.fill_between(t, 0, 1, where=result.hold, transform=ax.get_xaxis_transform(),
                        color="0.9", label="static hold")  # fmt: skip
    ax.set_ylabel("contact force [N]")
    ax.legend(loc="upper left", fontsize=8, ncol=4)
    ax.set_title(title or result.metrics["uuid"])
    ax2.plot(t, 100 * result.object_pos_err, color="k", lw=1)
    ax2.axhline(5.0, color="r", lw=0.8, ls="--")
    ax2.set_ylabel("object err [cm]")
    ax2.set_xlabel("time [s]")
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    return path
