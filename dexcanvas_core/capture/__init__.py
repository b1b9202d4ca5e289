"""Importing real captures: other datasets' sequences into the DexCanvas layout.

* ``arrays``: the ``mano-npz`` keys and their checks; ``capture``: the normalised
  :class:`Capture`; ``world``: its up axis, mirroring, the table check;
* ``convert``: a capture as a :class:`~dexcanvas_core.trajectory.Trajectory` (kinematics,
  resampling, object motion, the table);
* ``formats``: the readers (``mano-npz`` and published datasets' formats);
* ``importer``: ``dexcanvas import`` (meshes and their manifest next to the dataset).
"""

from dexcanvas_core.capture.arrays import KEYS, capture_from_arrays
from dexcanvas_core.capture.capture import Capture
from dexcanvas_core.capture.convert import capture_to_trajectory
from dexcanvas_core.capture.importer import (
    ImportConfig,
    ImportResult,
    dataset_objects_manifest,
    run_import,
    use_dataset_objects,
)

__all__ = [
    "KEYS",
    "Capture",
    "ImportConfig",
    "ImportResult",
    "capture_from_arrays",
    "capture_to_trajectory",
    "dataset_objects_manifest",
    "run_import",
    "use_dataset_objects",
]
