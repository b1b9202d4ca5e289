"""An (object, manipulation type) pair, written ``object/manipulation_type``."""

from __future__ import annotations

from dataclasses import dataclass

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.taxonomy.manipulation import ManipulationType, manipulation_type
from dexcanvas_core.taxonomy.object_lookup import object_spec
from dexcanvas_core.taxonomy.objects import ObjectSpec

SEPARATOR = "/"
_EXAMPLE = "'cube2/tripod'"


@dataclass(frozen=True)
class Pair:
    """One object manipulated with one manipulation type, e.g. ``cube2/tripod``.

    ``str(pair)`` gives the canonical spelling ``"<object id>/<type name>"``, which
    :meth:`parse` reads back.

    >>> from dexcanvas_core import Pair
    >>> pair = Pair.parse("Cube 2/Tripod")
    >>> str(pair), pair.object.id, pair.manipulation_type.name
    ('cube2/tripod', 'cube2', 'tripod')
    """

    object: ObjectSpec
    manipulation_type: ManipulationType

    def __post_init__(self) -> None:
        if not isinstance(self.object, ObjectSpec):
            raise ValidationError(
                f"Pair.object must be an ObjectSpec, got {type(self.object).__name__}; "
                "use Pair.of(...) or Pair.parse(...) to build a pair from names",
                field="object",
            )
        if not isinstance(self.manipulation_type, ManipulationType):
            raise ValidationError(
                "Pair.manipulation_type must be a ManipulationType, got "
                f"{type(self.manipulation_type).__name__}; use Pair.of(...) or Pair.parse(...)",
                field="manipulation_type",
            )

    @classmethod
    def of(
        cls,
        object_id: str | ObjectSpec,
        manipulation: str | int | ManipulationType,
    ) -> Pair:
        """Build a pair from an object id and a manipulation type name, alias or code."""
        return cls(object_spec(object_id), manipulation_type(manipulation))

    @classmethod
    def parse(cls, text: str) -> Pair:
        """Parse ``"object/manipulation_type"`` (e.g. ``"cube2/tripod"``, ``"Cube2H/Lateral"``).

        Raises:
            ValidationError: not a string, no ``/``, more than one ``/``, or an empty part.
            UnknownNameError: an unknown object or manipulation type (with close matches).
        """
        if not isinstance(text, str):
            raise ValidationError(
                f"a pair is a string like {_EXAMPLE}, got {type(text).__name__} {text!r}",
                field="pair",
            )
        parts = text.split(SEPARATOR)
        if len(parts) != 2:
            problem = (
                "has no '/'"
                if len(parts) == 1
                else f"has {len(parts) - 1} '/' separators, expected exactly one"
            )
            raise ValidationError(
                f"malformed pair {text!r}: {problem}; write object/manipulation_type, "
                f"e.g. {_EXAMPLE}",
                field="pair",
            )
        obj, kind = (p.strip() for p in parts)
        for part, what in ((obj, "object"), (kind, "manipulation type")):
            if not part:
                raise ValidationError(
                    f"malformed pair {text!r}: the {what} part is empty; write "
                    f"object/manipulation_type, e.g. {_EXAMPLE}",
                    field="pair",
                )
        return cls.of(obj, kind)

    def __str__(self) -> str:
        return f"{self.object.id}{SEPARATOR}{self.manipulation_type.name}"
