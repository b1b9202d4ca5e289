"""DexCanvas taxonomy: the 21 manipulation types, the 29 objects, and object/type pairs.

>>> from dexcanvas_core.taxonomy import Pair, manipulation_type, object_spec
>>> str(Pair.parse("cube2/tripod"))
'cube2/tripod'
>>> manipulation_type("001-Palmar-Pinch").name
'palmar_pinch'
>>> object_spec("Cube 2").size_m
(0.05,)
>>> object_spec("cube2h").id
'cube2H'

Sources and estimates are documented in :mod:`.manipulation` and :mod:`.objects` (the paper's
object table has 29 rows although its text says "30-object set").
"""

from dexcanvas_core.taxonomy.manipulation import (
    GROUPS,
    MANIPULATION_TYPES,
    THUMB_POSITIONS,
    Group,
    ManipulationType,
    Thumb,
    manipulation_type,
    types_in_group,
)
from dexcanvas_core.taxonomy.object_lookup import (
    add_objects_manifest,
    clear_objects,
    custom_objects,
    heavy_variant,
    object_spec,
    use_objects,
)
from dexcanvas_core.taxonomy.objects import (
    HEAVY_BASES,
    OBJECTS,
    SHAPES,
    SIZE_LAYOUT,
    ObjectSpec,
    Shape,
    Source,
)
from dexcanvas_core.taxonomy.pair import Pair

__all__ = [
    "GROUPS",
    "HEAVY_BASES",
    "MANIPULATION_TYPES",
    "OBJECTS",
    "SHAPES",
    "SIZE_LAYOUT",
    "THUMB_POSITIONS",
    "Group",
    "ManipulationType",
    "ObjectSpec",
    "Pair",
    "Shape",
    "Source",
    "Thumb",
    "add_objects_manifest",
    "clear_objects",
    "custom_objects",
    "heavy_variant",
    "manipulation_type",
    "object_spec",
    "types_in_group",
    "use_objects",
]
