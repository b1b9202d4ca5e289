"""``retarget export``: a run as files robot-learning code loads directly.

Formats (each in its module):

- ``mujoco`` (:mod:`retarget.export.mujoco`): a directory with the re-simulation's scene as a
  self-contained MJCF (hand + object + table, one ``<key>`` per frame) and ``trajectory.npz``;
- ``robomimic`` (:mod:`retarget.export.robomimic`): one HDF5 file, ``data/demo_0/{obs, actions,
  rewards, dones, states}``;
- ``lerobot`` (:mod:`retarget.export.lerobot`): a LeRobot v3.0 dataset directory (parquet and
  meta), state = ``q_sim``, action = ``q_command``.

What is exported is an :class:`~retarget.export.source.ExportSource`
(:func:`~retarget.export.source.load_export_source`). Outputs are written whole or not at all:
a directory is built beside ``out`` and renamed into place, a file is renamed over it
(:mod:`dexcanvas_core.safe_io`), under ``out``'s lock.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal, get_args

from dexcanvas_core.safe_io import atomic_dir, atomic_path, check_output, output_lock
from retarget.export.lerobot import write_lerobot
from retarget.export.mujoco import write_mujoco
from retarget.export.robomimic import write_robomimic
from retarget.export.source import ExportError, ExportSource, load_export_source

__all__ = [
    "FORMATS",
    "ExportConfig",
    "ExportError",
    "ExportSource",
    "export",
    "load_export_source",
    "run_export",
]

Format = Literal["mujoco", "robomimic", "lerobot"]
FORMATS: tuple[str, ...] = get_args(Format)
"""The values of ``--format``."""

_KIND = {"mujoco": "dir", "robomimic": "file", "lerobot": "dir"}
"""What each format writes at ``out``: a directory or one file."""


@dataclass(frozen=True)
class ExportConfig:
    """``retarget export``: one run to one format."""

    run_dir: Path | None
    """The ``retarget run`` directory to export (``None``: ``dataset`` and ``row``)."""
    format: Format
    """``mujoco``, ``robomimic`` or ``lerobot``."""
    out: Path
    """Output: a directory (``mujoco``, ``lerobot``) or an HDF5 file (``robomimic``)."""
    overwrite: bool = False
    """Replace an existing ``out``."""
    dataset: Path | None = None
    """A robot dataset (``retarget batch``) instead of ``run_dir``."""
    row: int | None = None
    """The row of ``dataset`` to export."""

    def validate(self) -> ExportConfig:
        if self.format not in FORMATS:
            raise ExportError(f"unknown format {self.format!r}; available: {', '.join(FORMATS)}")
        if (self.dataset is None) != (self.row is None):
            raise ExportError("--dataset and --row go together")
        return self


def export(source: ExportSource, fmt: str, out: str | Path, *, overwrite: bool = False) -> Path:
    """Write ``source`` as format ``fmt`` at ``out`` (a directory for ``mujoco`` and
    ``lerobot``, a file for ``robomimic``), whole or not at all; return ``out``.

    Raises:
        ExportError: an unknown format.
        dexcanvas_core.safe_io.OutputError: ``out`` exists without ``overwrite``, is of the
            wrong kind, cannot be written, or is being written by another process.
    """
    if fmt not in FORMATS:
        raise ExportError(f"unknown format {fmt!r}; available: {', '.join(FORMATS)}")
    kind = _KIND[fmt]
    out = check_output(out, overwrite=overwrite, kind=kind)
    with output_lock(out):
        check_output(out, overwrite=overwrite, kind=kind)  # again, under the lock
        if fmt == "robomimic":
            with atomic_path(out, suffix=".hdf5") as tmp:
                write_robomimic(source, tmp)
        else:
            with atomic_dir(out) as tmp:
                (write_mujoco if fmt == "mujoco" else write_lerobot)(source, tmp)
    return out


def run_export(cfg: ExportConfig) -> Path:
    """``retarget export``: load the source of ``cfg`` and :func:`export` it; return the
    output path."""
    cfg.validate()
    source = load_export_source(cfg.run_dir, dataset=cfg.dataset, row=cfg.row)
    return export(source, cfg.format, cfg.out, overwrite=cfg.overwrite)
