"""Lance (and Parquet) I/O for DexCanvas-layout datasets."""

from dexcanvas_core.io.reader import (
    DatasetInfo,
    LanceTrajectories,
    build_filter,
    open_dataset,
    row_to_trajectory,
)
from dexcanvas_core.io.schema import SCHEMA_VERSION, SCHEMA_VERSION_KEY, default_schema
from dexcanvas_core.io.writer import export_parquet, trajectories_to_batch, write_dataset

__all__ = [
    "SCHEMA_VERSION",
    "SCHEMA_VERSION_KEY",
    "DatasetInfo",
    "LanceTrajectories",
    "build_filter",
    "default_schema",
    "export_parquet",
    "open_dataset",
    "row_to_trajectory",
    "trajectories_to_batch",
    "write_dataset",
]
