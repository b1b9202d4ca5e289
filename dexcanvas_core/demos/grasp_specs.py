"""What each manipulation type's grasp is made of: which hand parts touch the object, on which
side, in which zone of the part, and the posture the fingers take (``GRASP_SPECS``, one
:class:`GraspSpec` per type, solved by :mod:`.grasp`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from dexcanvas_core.taxonomy import MANIPULATION_TYPES

Side = Literal["volar", "radial", "any", "up"]
Posture = Literal["curl", "extend", "relax"]
Approach = Literal["top", "side"]


@dataclass(frozen=True)
class ContactSpec:
    """One hand part that touches the object in a manipulation type.

    Attributes:
        capsule: name in ``hand.CAPSULES`` (``"index_dip"``, ``"thumb_ip"``…) or ``"palm"``
            (any of the palm's capsules).
        side: which side of the part faces the object: ``"volar"`` (the pad), ``"radial"``
            (thumb side of a finger, lateral pinches), ``"any"``, or ``"up"`` (table-supported
            types: the contact must be on the object's upper half, pressing down).
        zone: fraction range along the capsule where the contact may lie (``(0.3, 1.0)`` = the
            distal 70 %).
        required: required contacts are checked in every contact frame; optional ones (a
            supporting finger side, the palm in some power grasps) are pulled towards the
            surface but enter the contact schedule only when the grasp achieves them.
    """

    capsule: str
    side: Side = "volar"
    zone: tuple[float, float] = (0.3, 1.0)
    required: bool = True

    @property
    def finger(self) -> str:
        return self.capsule.split("_", 1)[0]


@dataclass(frozen=True)
class GraspSpec:
    """How a manipulation type holds an object (used by the optimiser and the scripts)."""

    type_name: str
    contacts: tuple[ContactSpec, ...]
    """The parts that touch the object (pads, sides, the palm)."""
    approach: Approach | Literal["auto"] = "auto"
    """Wrist approach: from above, from the side (subject's side), or ``auto`` (side for
    objects taller than wide, else top)."""
    palm: Literal["contact", "clear", "free"] = "free"
    """The palm touches the object (power), keeps 8 mm off it (precision) or is free."""
    posture: Posture = "relax"
    """Natural posture of the fingers that do not take part."""
    thumb: Literal["abducted", "adducted"] = "abducted"
    """Initial thumb posture (opposed, or along the index)."""
    opposition: bool = True
    """False for table-supported types (rolling, sliding): no force closure needed."""
    closure: float = 0.55
    """Initial flexion (0 open … 1 fist) of the contact fingers."""
    shape: tuple[float, float, float] | None = None
    """Initial (MCP, PIP, DIP) flexion [rad] of the contact fingers, overriding ``closure``."""


def _pads(*fingers: str, side: Side = "volar", required: bool = True) -> tuple[ContactSpec, ...]:
    return tuple(
        ContactSpec(f"{f}_ip" if f == "thumb" else f"{f}_dip", side, required=required)
        for f in fingers
    )


_PALM = (ContactSpec("palm", "any", (0.2, 1.0)),)
_PALM_OPT = (ContactSpec("palm", "any", (0.2, 1.0), required=False),)
_T, _I, _M, _R, _P = "thumb", "index", "middle", "ring", "pinky"

# fmt: off
GRASP_SPECS: dict[str, GraspSpec] = {s.type_name: s for s in (
    # power: the object rests against the palm
    GraspSpec("ring", (*_pads(_T, _I), *_PALM_OPT), "auto", "free", "curl", closure=0.7),
    GraspSpec("sphere_3_finger", (*_pads(_T, _I, _M), *_PALM), "top", "contact", "curl",
              closure=0.6),
    GraspSpec("sphere_4_finger", (*_pads(_T, _I, _M, _R), *_PALM), "top", "contact", "curl",
              closure=0.6),
    GraspSpec("large_diameter", (*_pads(_T, _I, _M, _R, _P), *_PALM), "auto", "contact",
              closure=0.7),
    GraspSpec("distal_type", (*_pads(_T, _M, _R, side="any"),
                              *_pads(_I, _P, side="any", required=False)),
              "top", "free", "relax", closure=0.5),
    GraspSpec("extension_type", _pads(_T, _I, _M, _R, _P), "top", "clear", "extend",
              shape=(1.0, 0.25, 0.1)),
    GraspSpec("adducted_thumb", (*_pads(_I, _M, _R, _P), *_pads(_T, side="any", required=False),
                                 *_PALM), "auto", "contact", thumb="adducted", closure=0.75),
    # intermediate
    GraspSpec("writing_tripod", (*_pads(_T, _I), ContactSpec("middle_dip", "radial",
                                                              required=False)),
              "top", "clear", "curl", closure=0.45),
    GraspSpec("tripod_variation", (*_pads(_T, _I), *_pads(_M, _R, required=False)),
              "top", "clear", "curl", closure=0.45),
    GraspSpec("lateral_pinch", (*_pads(_T), ContactSpec("index_pip", "radial", (0.0, 1.0))),
              "top", "clear", "curl", thumb="adducted", closure=0.8),
    GraspSpec("lateral_tripod", (*_pads(_T), ContactSpec("index_dip", "radial", (0.0, 1.0)),
                                 ContactSpec("middle_dip", "any", (0.0, 1.0))),
              "top", "clear", "curl", thumb="adducted", closure=0.6),
    # precision: fingertips only, palm off the object
    GraspSpec("palmar_pinch", _pads(_T, _I), "top", "clear", "curl", closure=0.45),
    GraspSpec("inferior_pincer", _pads(_T, _I), "top", "clear", "extend", closure=0.45),
    GraspSpec("tripod", _pads(_T, _I, _M), "top", "clear", "curl", closure=0.45),
    GraspSpec("quadpod", _pads(_T, _I, _M, _R), "top", "clear", "curl", closure=0.45),
    GraspSpec("precision_sphere", _pads(_T, _I, _M, _R, _P), "top", "clear", closure=0.45),
    GraspSpec("parallel_extension", _pads(_T, _I, _M, _R, _P), "top", "clear", "extend",
              thumb="adducted", shape=(1.2, 0.15, 0.1)),
    # in-hand manipulation: the grasp the motion starts from
    GraspSpec("rolling", _pads(_T, _I, side="up"), "top", "clear", "curl", opposition=False,
              closure=0.3),
    GraspSpec("sliding", _pads(_T, _I, _M, side="up"), "top", "clear", "curl",
              opposition=False, closure=0.3),
    GraspSpec("finger_transfer", _pads(_T, _I, _M, _R), "top", "clear", "curl", closure=0.45),
    GraspSpec("rotation", _pads(_T, _I, _M), "top", "clear", "curl", closure=0.45),
)}
# fmt: on

if set(GRASP_SPECS) != set(MANIPULATION_TYPES):  # pragma: no cover - catalogue consistency
    raise RuntimeError("GRASP_SPECS must cover the 21 manipulation types")
