"""Arrow schema of the DexCanvas Lance layout, and the contract version this toolkit writes.

The layout mirrors the public DexCanvas release (see DESIGN.md): one trajectory per row, nested
``index`` and ``trajectory_metadata`` structs, per-frame ``hands[]`` and ``objects[]`` lists and
the per-frame ``contact`` records. The toolkit's additions are extra top-level columns
(``object_wrench_world``, ``contact_solver``, ``table``) and an extra per-point field
(``contact_pairs[].force_world``); readers of the public layout ignore them.
"""

from __future__ import annotations

import dataclasses

import pyarrow as pa

from dexcanvas_core.table import Table

SCHEMA_VERSION_KEY = b"dexcanvas_retarget_schema"
"""Schema-metadata key naming the contract version of datasets this toolkit writes."""
SCHEMA_VERSION = "1.0"
SUPPORTED_MAJOR = 1


def f32xn(n: int) -> pa.DataType:
    return pa.list_(pa.float32(), n)


F3 = f32xn(3)

CONTACT_PAIR = pa.struct(
    [
        ("force_normal", F3),
        ("pos_world", F3),
        ("pos_wrist", F3),
        ("pos_joint", F3),
        ("pos_object", F3),
    ]
)
CONTACT_PAIR_EXT = pa.struct([*CONTACT_PAIR, ("force_world", F3)])

CONTACT_RECORD_FIELDS = [
    ("hand_name", pa.string()),
    ("joint_name", pa.string()),
    ("object_name", pa.string()),
    ("total_force_world", F3),
    ("total_force_wrist", F3),
    ("total_force_joint", F3),
    ("total_force_object", F3),
]


def contact_type(with_force_world: bool) -> pa.DataType:
    pair = CONTACT_PAIR_EXT if with_force_world else CONTACT_PAIR
    return pa.list_(
        pa.list_(pa.struct([*CONTACT_RECORD_FIELDS, ("contact_pairs", pa.list_(pair))]))
    )


INDEX = pa.struct(
    [
        ("uuid", pa.string()),
        ("seed_uuid", pa.string()),
        ("capMachine", pa.string()),
        ("operator", pa.string()),
        ("scene", pa.string()),
        ("is_generated", pa.bool_()),
    ]
)

OBJECT_MOVE = pa.struct(
    [("object_name", pa.string()), ("start_frame", pa.int64()), ("end_frame", pa.int64())]
)

TRAJECTORY_METADATA = pa.struct(
    [
        ("data_fps", pa.int64()),
        ("total_frames", pa.int64()),
        ("gesture", pa.string()),
        ("hand_names", pa.list_(pa.string())),
        ("hand_slots", pa.list_(pa.string())),
        ("object_names", pa.list_(pa.string())),
        ("mano_hand_shapes", pa.list_(f32xn(10))),
        ("trajectory_info", pa.struct([("object_move", pa.list_(OBJECT_MOVE))])),
    ]
)


def hand_type(urdf_dof: int) -> pa.DataType:
    """One element of ``hands``; ``urdf_dof`` is 26 or 28."""
    return pa.struct(
        [
            ("hand_name", pa.string()),
            ("mano_global_pos", pa.list_(F3)),
            ("mano_global_rot_aa", pa.list_(F3)),
            ("mano_hand_pose", pa.list_(f32xn(48))),
            ("mano_joint_pos", pa.list_(pa.list_(F3, 21))),
            ("urdf_dof", pa.list_(f32xn(urdf_dof))),
            ("urdf_dof_target", pa.list_(f32xn(urdf_dof))),
        ]
    )


OBJECT = pa.struct([("rot_aa", pa.list_(F3)), ("pos", pa.list_(F3))])

TABLE = pa.struct([pa.field(f.name, pa.float64()) for f in dataclasses.fields(Table)])
"""The ``table`` column (this toolkit's addition): the :class:`~dexcanvas_core.table.Table` a
trajectory was performed on, one float64 child per field (lengths [m], yaw [rad]); null or
absent: the default table."""

REQUIRED_COLUMNS = ("index", "trajectory_metadata", "timestamp", "hands", "objects")


def default_schema(
    *,
    urdf_dof: int = 26,
    contact: bool = True,
    contact_force_world: bool = False,
    wrench: bool = False,
    table: bool = False,
) -> pa.Schema:
    """The schema this toolkit writes when no source schema is given (``table``: with the
    ``table`` column, :data:`TABLE`)."""
    fields = [
        pa.field("index", INDEX),
        pa.field("trajectory_metadata", TRAJECTORY_METADATA),
        pa.field("timestamp", pa.list_(pa.float64())),
        pa.field("hands", pa.list_(hand_type(urdf_dof))),
        pa.field("objects", pa.list_(OBJECT)),
    ]
    if contact:
        fields.append(pa.field("contact", contact_type(contact_force_world)))
    if wrench:
        fields.append(pa.field("object_wrench_world", pa.list_(f32xn(6))))
        fields.append(pa.field("contact_solver", pa.string()))
    if table:
        fields.append(pa.field("table", TABLE))
    return pa.schema(fields, metadata={SCHEMA_VERSION_KEY: SCHEMA_VERSION.encode()})
