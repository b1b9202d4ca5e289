"""The ``Trajectory`` schema: one demonstration as typed numpy arrays, mirroring a DexCanvas
Lance row.

* :mod:`.trajectory` — :class:`Trajectory`: identity, metadata, tracks, contacts, checks,
  slicing and resampling;
* :mod:`.tracks` — :class:`HandTrack`, :class:`ObjectTrack`, :class:`ObjectMove`, the
  ``urdf_dof`` layouts;
* :mod:`.contacts` — :class:`Contacts` and the contact part names and force groups;
* :mod:`.arrays` — the array checks they share.
"""

from dexcanvas_core.trajectory.contacts import (
    CONTACT_PAIR_FIELDS,
    CONTACT_PARTS,
    CONTACT_TOTAL_FIELDS,
    FORCE_GROUPS,
    Contacts,
    part_group,
)
from dexcanvas_core.trajectory.tracks import (
    URDF_DOF_NAMES_26,
    URDF_DOF_NAMES_28,
    HandTrack,
    ObjectMove,
    ObjectTrack,
)
from dexcanvas_core.trajectory.trajectory import Trajectory

__all__ = [
    "CONTACT_PAIR_FIELDS",
    "CONTACT_PARTS",
    "CONTACT_TOTAL_FIELDS",
    "FORCE_GROUPS",
    "URDF_DOF_NAMES_26",
    "URDF_DOF_NAMES_28",
    "Contacts",
    "HandTrack",
    "ObjectMove",
    "ObjectTrack",
    "Trajectory",
    "part_group",
]
