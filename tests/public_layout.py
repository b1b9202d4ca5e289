"""Build small datasets in the public DexCanvas Lance layout with pyarrow/lance directly.

This deliberately does not use ``dexcanvas_core.io``: the reader is tested against the layout,
not against its own writer. Types are spelled out here as a public writer lays them out.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from dexcanvas_core.mano import HandSkeleton


def f3():
    return pa.list_(pa.float32(), 3)


def public_schema(dof: int = 26, extra_meta: bool = True, extra_column: bool = True) -> pa.Schema:
    pair = pa.struct(
        [(n, f3()) for n in ("force_normal", "pos_world", "pos_wrist", "pos_joint", "pos_object")]
    )
    record = pa.struct(
        [
            ("hand_name", pa.string()),
            ("joint_name", pa.string()),
            ("object_name", pa.string()),
            ("total_force_world", f3()),
            ("total_force_wrist", f3()),
            ("total_force_joint", f3()),
            ("total_force_object", f3()),
            ("contact_pairs", pa.list_(pair)),
        ]
    )
    move = pa.struct(
        [("object_name", pa.string()), ("start_frame", pa.int64()), ("end_frame", pa.int64())]
    )
    meta_fields = [
        ("data_fps", pa.int64()),
        ("total_frames", pa.int64()),
        ("gesture", pa.string()),
        ("hand_names", pa.list_(pa.string())),
        ("hand_slots", pa.list_(pa.string())),
        ("object_names", pa.list_(pa.string())),
        ("mano_hand_shapes", pa.list_(pa.list_(pa.float32(), 10))),
        ("trajectory_info", pa.struct([("object_move", pa.list_(move))])),
    ]
    if extra_meta:
        meta_fields.append(("capture_notes", pa.string()))
    hand = pa.struct(
        [
            ("hand_name", pa.string()),
            ("mano_global_pos", pa.list_(f3())),
            ("mano_global_rot_aa", pa.list_(f3())),
            ("mano_hand_pose", pa.list_(pa.list_(pa.float32(), 48))),
            ("mano_joint_pos", pa.list_(pa.list_(f3(), 21))),
            ("urdf_dof", pa.list_(pa.list_(pa.float32(), dof))),
            ("urdf_dof_target", pa.list_(pa.list_(pa.float32(), dof))),
        ]
    )
    fields = [
        ("index", pa.struct([
            ("uuid", pa.string()), ("seed_uuid", pa.string()), ("capMachine", pa.string()),
            ("operator", pa.string()), ("scene", pa.string()), ("is_generated", pa.bool_()),
        ])),
        ("trajectory_metadata", pa.struct(meta_fields)),
        ("timestamp", pa.list_(pa.float64())),
        ("hands", pa.list_(hand)),
        ("objects", pa.list_(pa.struct([("rot_aa", pa.list_(f3())), ("pos", pa.list_(f3()))]))),
        ("contact", pa.list_(pa.list_(record))),
    ]  # fmt: skip
    if extra_column:
        fields.append(("quality_score", pa.float64()))
    return pa.schema(fields)


PARTS = ("palm", "index_dip", "thumb_ip", "middle_pip")


def public_row(
    rng: np.random.Generator,
    *,
    uuid: str,
    T: int = 30,
    fps: int = 120,
    scene: str = "cube2",
    gesture: str = "tripod",
    operator: str = "operator1",
    dof: int = 26,
    extra_meta: bool = True,
    extra_column: bool = True,
) -> dict:
    """One row as Python values in the public layout (random but valid numbers)."""
    f = lambda *shape: rng.normal(size=shape).astype(np.float32)  # noqa: E731
    small = lambda *shape: (0.3 * rng.uniform(-1, 1, size=shape)).astype(np.float32)  # noqa: E731

    def walk(T: int, start) -> np.ndarray:
        """A random walk of 2 mm steps from ``start`` [m] (human speeds: the plausibility
        checks refuse a hand or object jumping by metres between frames)."""
        return (np.asarray(start) + 2e-3 * np.cumsum(f(T, 3), axis=0)).astype(np.float32)

    rest = HandSkeleton.default("right").rest_keypoints  # a hand-sized skeleton
    contact = []
    for _t in range(T):
        frame = []
        for part in PARTS[: int(rng.integers(0, len(PARTS) + 1))]:
            n_pairs = int(rng.integers(1, 4))
            frame.append(
                {
                    "hand_name": "right",
                    "joint_name": part,
                    "object_name": scene,
                    **{k: f(3).tolist() for k in ("total_force_world", "total_force_wrist",
                                                   "total_force_joint", "total_force_object")},
                    "contact_pairs": [
                        {k: f(3).tolist() for k in ("force_normal", "pos_world", "pos_wrist",
                                                     "pos_joint", "pos_object")}
                        for _ in range(n_pairs)
                    ],
                }
            )  # fmt: skip
        contact.append(frame)
    meta = {
        "data_fps": fps,
        "total_frames": T,
        "gesture": gesture,
        "hand_names": ["right"],
        "hand_slots": ["right"],
        "object_names": [scene],
        "mano_hand_shapes": [f(10).tolist()],
        "trajectory_info": {
            "object_move": [{"object_name": scene, "start_frame": T // 4, "end_frame": 3 * T // 4}]
        },
    }
    if extra_meta:
        meta["capture_notes"] = f"take {uuid}"
    row = {
        "index": {
            "uuid": uuid, "seed_uuid": "", "capMachine": "mocap-A", "operator": operator,
            "scene": scene, "is_generated": False,
        },
        "trajectory_metadata": meta,
        "timestamp": (np.arange(T) / fps + 12.5).tolist(),
        "hands": [{
            "hand_name": "right",
            "mano_global_pos": (wrist := walk(T, (0.3, 0.0, 0.2))).tolist(),
            "mano_global_rot_aa": small(T, 3).tolist(),
            "mano_hand_pose": small(T, 48).tolist(),
            "mano_joint_pos": (rest + wrist[:, None] + 1e-3 * f(T, 21, 3)).tolist(),
            "urdf_dof": f(T, dof).tolist(),
            "urdf_dof_target": f(T, dof).tolist(),
        }],
        "objects": [{"rot_aa": small(T, 3).tolist(), "pos": walk(T, (0.2, 0.0, 0.03)).tolist()}],
        "contact": contact,
    }  # fmt: skip
    if extra_column:
        row["quality_score"] = float(rng.uniform())
    return row


def write_public_dataset(path, rows: list[dict], schema: pa.Schema | None = None) -> None:
    import lance

    schema = schema or public_schema()
    table = pa.Table.from_pylist(rows, schema=schema)
    lance.write_dataset(table, str(path), mode="create")
