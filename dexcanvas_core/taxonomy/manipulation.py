"""The 21 DexCanvas manipulation types.

DexCanvas (Xu et al. 2025, arXiv 2510.15786) organises its demonstrations into 21 manipulation
types after Cutkosky and Feix et al. 2016 ("The GRASP Taxonomy of Human Grasp Types"): three
grasp groups — power, intermediate, precision — each split by thumb position (abducted /
adducted) and by how many digits (thumb included) hold the object, plus four in-hand
manipulations.

Where each fact comes from (the paper's own list of type names was not reachable in the stored
copies searched; only its abstract was):

* **Structure** — group, thumb position and digit count of every leaf: the taxonomy figure
  "DexCanvas 21 Manipulation Types" on the project page (repository
  ``dexCanvas/dexcanvas.github.io``, ``assets/images/paper/figure_taxonomy.png``). It draws 20
  grasps: power–abducted 2, 3, 4, 5 (two drawings: scissors, cylinder); power–adducted 5;
  intermediate–abducted 2 (pen, chopsticks); intermediate–adducted 2, 3; precision–abducted 2
  (two drawings), 3, 4, 5; precision–adducted 5; in-hand rolling, sliding, finger transfer,
  rotation.
* **Names** — the Feix GRASP name whose pictogram matches each drawing (our reading of the
  figure), in snake_case. ``lateral_pinch`` keeps Cutkosky's name for Feix's "Lateral".
* **extension_type** — the 21st type: not drawn in the figure, but DexCanvas-format rows carry
  the label ``Extension-Type`` (gesture 10). Feix classes it power, thumb abducted, five digits.
* **Gesture codes** — DexCanvas-format Lance rows store ``gesture`` as a string whose leading
  number is a stable action id (``"001-Palmar-Pinch"``, ``"018-Lateral"``, ``"020-Rolling"``,
  ``"021-Sliding"``; older rows carry just ``"01"``), as seen in public training code that reads
  them (test fixtures and run logs found by code search). Codes 1, 9, 10, 18, 20, 21 are tied to
  names there; every other code is unknown here and left ``None``. Such rows also use
  ``"002-Prismatic-3-Finger"`` and codes 3, 4, 11 whose place among the 21 types is unresolved;
  looking them up raises :class:`UnknownNameError`.
* **Feix ids** — the numbering of Feix et al. 2016 (1 Large Diameter … 33 Inferior Pincer).
"""

from __future__ import annotations

import operator
import re
from dataclasses import dataclass
from typing import Literal, get_args

from dexcanvas_core.errors import UnknownNameError, ValidationError
from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.taxonomy._lookup import build_index, compact_key, lookup

Group = Literal["power", "intermediate", "precision", "in_hand"]
Thumb = Literal["abducted", "adducted"]

GROUPS: tuple[Group, ...] = get_args(Group)
"""The four groups in the paper's order."""

THUMB_POSITIONS: tuple[Thumb, ...] = get_args(Thumb)

_SNAKE = re.compile(r"[a-z][a-z0-9]*(?:_[a-z0-9]+)*")
_CODE = re.compile(r"0*(\d+)")
_LABEL = re.compile(r"0*(\d+)[\s_\-:.]+(.*)")


@dataclass(frozen=True)
class ManipulationType:
    """One manipulation type of the DexCanvas taxonomy.

    Attributes:
        name: canonical snake_case name (Feix GRASP name where one exists), e.g. ``"tripod"``.
        group: ``"power"``, ``"intermediate"``, ``"precision"`` or ``"in_hand"``.
        thumb: thumb position for the grasp groups, ``None`` for in-hand manipulation.
        fingers: digits holding the object, a subset of ``thumb, index, middle, ring, pinky`` in
            that order. For grasps their count is the "N fingers" of the paper's figure.
        description: one sentence on the hand posture.
        gesture_code: the public release's numeric ``gesture`` id, ``None`` where unknown.
        feix_id: number in Feix et al. 2016 (1–33), ``None`` for in-hand manipulation.
        aliases: other accepted spellings (Feix / Cutkosky / figure names); lookups also ignore
            case, spaces, hyphens and underscores.
    """

    name: str
    group: Group
    thumb: Thumb | None
    fingers: tuple[str, ...]
    description: str
    gesture_code: int | None = None
    feix_id: int | None = None
    aliases: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        where = f"manipulation type {self.name!r}"
        if not isinstance(self.name, str) or not _SNAKE.fullmatch(self.name):
            raise ValidationError(f"{where}: name must be snake_case", field="name")
        if self.group not in GROUPS:
            raise ValidationError(
                f"{where}: group {self.group!r} is not one of {', '.join(GROUPS)}", field="group"
            )
        if self.group == "in_hand":
            if self.thumb is not None:
                raise ValidationError(f"{where}: in-hand types have thumb=None", field="thumb")
        elif self.thumb not in THUMB_POSITIONS:
            raise ValidationError(
                f"{where}: thumb must be 'abducted' or 'adducted' for a grasp, got {self.thumb!r}",
                field="thumb",
            )
        fingers = tuple(self.fingers)
        if not fingers:
            raise ValidationError(f"{where}: fingers must not be empty", field="fingers")
        unknown = [f for f in fingers if f not in FINGERS]
        if unknown:
            raise ValidationError(
                f"{where}: unknown fingers {unknown}; valid: {', '.join(FINGERS)}", field="fingers"
            )
        if list(fingers) != sorted(set(fingers), key=FINGERS.index):
            raise ValidationError(
                f"{where}: fingers must be unique and in the order {', '.join(FINGERS)}",
                field="fingers",
            )
        for attr in ("gesture_code", "feix_id"):
            value = getattr(self, attr)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int)):
                raise ValidationError(f"{where}: {attr} must be an int or None", field=attr)
            if value is not None and value < 1:
                raise ValidationError(f"{where}: {attr} must be positive", field=attr)
        object.__setattr__(self, "fingers", fingers)
        object.__setattr__(self, "aliases", tuple(self.aliases))

    @property
    def n_fingers(self) -> int:
        """Number of digits holding the object (thumb included)."""
        return len(self.fingers)

    @property
    def is_grasp(self) -> bool:
        """True for the power, intermediate and precision groups."""
        return self.group != "in_hand"

    def __str__(self) -> str:
        return self.name


_ALL5 = FINGERS
_TI = ("thumb", "index")
_TIM = ("thumb", "index", "middle")
_TIMR = ("thumb", "index", "middle", "ring")

# Catalogue order: group, then thumb abducted before adducted, then digit count (figure order).
# fmt: off
_TYPES: tuple[ManipulationType, ...] = (
    # ---- power ---------------------------------------------------------------------------
    ManipulationType(
        "ring", "power", "abducted", _TI,
        "Thumb and index finger encircle a large cylinder; the other fingers rest off it.",
        feix_id=31, aliases=("ring_grasp",),
    ),
    ManipulationType(
        "sphere_3_finger", "power", "abducted", _TIM,
        "Sphere held against the palm by the thumb, index and middle fingers.",
        feix_id=28, aliases=("three_finger_sphere", "power_sphere_3_finger"),
    ),
    ManipulationType(
        "sphere_4_finger", "power", "abducted", _TIMR,
        "Sphere held against the palm by the thumb, index, middle and ring fingers.",
        feix_id=26, aliases=("four_finger_sphere", "power_sphere_4_finger"),
    ),
    ManipulationType(
        "large_diameter", "power", "abducted", _ALL5,
        "Whole hand wraps a large cylinder against the palm, the thumb opposing the fingers.",
        gesture_code=9, feix_id=1, aliases=("large_diameter_heavy_wrap", "large_wrap"),
    ),
    ManipulationType(
        "distal_type", "power", "abducted", _ALL5,
        "Scissors-like grip: thumb and fingers act through the object's loops with the distal "
        "phalanges.",
        feix_id=19, aliases=("distal",),
    ),
    ManipulationType(
        "extension_type", "power", "abducted", _ALL5,
        "Flat object held between the abducted thumb and the pads of the extended fingers.",
        gesture_code=10, feix_id=18, aliases=("extension",),
    ),
    ManipulationType(
        "adducted_thumb", "power", "adducted", _ALL5,
        "Cylinder wrapped by the four fingers against the palm, the thumb adducted along it.",
        feix_id=4, aliases=("adducted_thumb_wrap",),
    ),
    # ---- intermediate ----------------------------------------------------------------------
    ManipulationType(
        "writing_tripod", "intermediate", "abducted", _TI,
        "Pen-like object pinched by thumb and index pads, resting on the side of the middle "
        "finger.",
        feix_id=20, aliases=("writing", "pen_grip"),
    ),
    ManipulationType(
        "tripod_variation", "intermediate", "abducted", _TI,
        "Chopstick-like grip: a stick steered by thumb and index, supported by the middle and "
        "ring fingers.",
        feix_id=21, aliases=("chopsticks", "chopstick_grip"),
    ),
    ManipulationType(
        "lateral_pinch", "intermediate", "adducted", _TI,
        "Thumb pad presses the object against the radial side of the index finger (key grip).",
        gesture_code=18, feix_id=16, aliases=("lateral", "key_pinch", "key_grip"),
    ),
    ManipulationType(
        "lateral_tripod", "intermediate", "adducted", _TIM,
        "Small object held between the thumb and the sides of the index and middle fingers.",
        feix_id=25,
    ),
    # ---- precision -------------------------------------------------------------------------
    ManipulationType(
        "palmar_pinch", "precision", "abducted", _TI,
        "Thin object pinched between the pads of the thumb and the index finger.",
        gesture_code=1, feix_id=9, aliases=("thumb_index_finger", "pad_pinch"),
    ),
    ManipulationType(
        "inferior_pincer", "precision", "abducted", _TI,
        "Small sphere pinched between thumb and index pads, the other fingers extended.",
        feix_id=33, aliases=("pincer",),
    ),
    ManipulationType(
        "tripod", "precision", "abducted", _TIM,
        "Object held at the fingertips of the thumb, index and middle fingers.",
        feix_id=14, aliases=("precision_tripod",),
    ),
    ManipulationType(
        "quadpod", "precision", "abducted", _TIMR,
        "Object held from above at the fingertips of the thumb, index, middle and ring fingers.",
        feix_id=27,
    ),
    ManipulationType(
        "precision_sphere", "precision", "abducted", _ALL5,
        "Sphere held from above at the fingertips of all five digits.",
        feix_id=13,
    ),
    ManipulationType(
        "parallel_extension", "precision", "adducted", _ALL5,
        "Flat object held between the adducted thumb and the extended fingers, pads parallel.",
        feix_id=22,
    ),
    # ---- in-hand manipulation --------------------------------------------------------------
    ManipulationType(
        "rolling", "in_hand", None, _TI,
        "Object rolled between the thumb and index finger pads.",
        gesture_code=20, aliases=("roll", "finger_rolling"),
    ),
    ManipulationType(
        "sliding", "in_hand", None, _TIM,
        "Object slid along the fingers while the thumb presses it against them.",
        gesture_code=21, aliases=("slide",),
    ),
    ManipulationType(
        "finger_transfer", "in_hand", None, _TIMR,
        "Object passed between finger contacts to a new place in the hand without releasing it.",
        aliases=("transfer",),
    ),
    ManipulationType(
        "rotation", "in_hand", None, _TIM,
        "Object turned about its own axis by alternating fingertip contacts (twirling).",
        aliases=("rotate", "in_hand_rotation", "twirl"),
    ),
)
# fmt: on

MANIPULATION_TYPES: dict[str, ManipulationType] = {t.name: t for t in _TYPES}
"""The 21 types by canonical name, in catalogue order (group, thumb, digit count)."""

_BY_SPELLING = build_index(((t, (t.name, *t.aliases)) for t in _TYPES), "manipulation type")
_BY_CODE: dict[int, ManipulationType] = {
    t.gesture_code: t for t in _TYPES if t.gesture_code is not None
}
if len(_BY_CODE) != sum(t.gesture_code is not None for t in _TYPES):  # pragma: no cover
    raise RuntimeError("duplicate gesture codes in the manipulation catalogue")


def _by_code(code: int, original: object) -> ManipulationType:
    try:
        return _BY_CODE[code]
    except KeyError:
        valid = [f"{c:02d}" for c in _BY_CODE]
        raise UnknownNameError("manipulation type gesture code", original, valid) from None


def manipulation_type(name_or_code: str | int | ManipulationType) -> ManipulationType:
    """Look a manipulation type up by name, alias, gesture code or release label.

    Accepts a canonical name or alias in any case and with any separators (``"Palmar-Pinch"``,
    ``"lateral"``), the release's numeric gesture code as an int or a numeric string (``1``,
    ``"01"``), a release label ``"<code>-<Name>"`` (``"001-Palmar-Pinch"``), or a
    :class:`ManipulationType` (returned as is).

    Raises:
        UnknownNameError: unknown name or code; the message suggests close matches.
        ValidationError: a value that is neither a string nor an int, or a release label whose
            code and name disagree.

    >>> from dexcanvas_core import manipulation_type
    >>> manipulation_type("001-Palmar-Pinch").name, manipulation_type(1).name
    ('palmar_pinch', 'palmar_pinch')
    """
    if isinstance(name_or_code, ManipulationType):
        return name_or_code
    if not isinstance(name_or_code, str):
        # ints and integer-like numpy scalars are gesture codes; bools and the rest are errors.
        if isinstance(name_or_code, bool) or not hasattr(name_or_code, "__index__"):
            raise ValidationError(
                "a manipulation type is given by name (str) or gesture code (int), got "
                f"{type(name_or_code).__name__} {name_or_code!r}"
            )
        return _by_code(operator.index(name_or_code), name_or_code)
    text = name_or_code.strip()
    digits = _CODE.fullmatch(text)
    if digits:
        return _by_code(int(digits.group(1)), name_or_code)
    label = _LABEL.fullmatch(text)
    if label:
        code, rest = int(label.group(1)), label.group(2)
        by_name = lookup(_BY_SPELLING, rest) if compact_key(rest) else None
        by_code = _BY_CODE.get(code)
        if by_code is not None and by_name is not None and by_code is not by_name:
            raise ValidationError(
                f"gesture label {name_or_code!r} is inconsistent: code {code} is "
                f"{by_code.name!r} but the name reads {by_name.name!r}",
                field="gesture",
            )
        found = by_code or by_name
        if found is None:
            raise UnknownNameError("manipulation type", name_or_code, MANIPULATION_TYPES)
        return found
    found = lookup(_BY_SPELLING, text)
    if found is None:
        raise UnknownNameError("manipulation type", text.lower(), MANIPULATION_TYPES)
    return found


def types_in_group(group: str) -> tuple[ManipulationType, ...]:
    """All types of one group (``"power"``, ``"intermediate"``, ``"precision"``, ``"in_hand"``).

    ``"in-hand"`` and ``"In hand"`` are accepted for ``"in_hand"``. Returns the types in
    catalogue order.
    """
    if not isinstance(group, str):
        raise ValidationError(f"a manipulation group is a string, got {type(group).__name__}")
    key = compact_key(group)
    match = next((g for g in GROUPS if compact_key(g) == key), None)
    if match is None:
        raise UnknownNameError("manipulation group", group.strip().lower(), GROUPS)
    return tuple(t for t in _TYPES if t.group == match)
