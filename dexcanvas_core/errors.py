"""One exception hierarchy for the human side of the toolkit.

Every error names the bad value and, where there is a finite set of valid ones, lists them.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class DexCanvasError(Exception):
    """Base class of every error raised by ``dexcanvas_core``."""


class UnknownNameError(DexCanvasError, KeyError):
    """A name (object, manipulation type, operator, hand, …) that is not in its catalogue."""

    def __init__(self, kind: str, name: object, valid: Iterable[str], hint: str = ""):
        self.kind = kind
        self.name = name
        self.valid = sorted(valid)
        close = difflib.get_close_matches(str(name), self.valid, n=3, cutoff=0.5)
        near = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
        listed = ", ".join(self.valid)
        super().__init__(f"unknown {kind} {name!r}{near} (available: {listed}){hint}")

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable.
        return str(self.args[0])


class ValidationError(DexCanvasError, ValueError):
    """An array or field with a wrong shape, dtype, or non-finite / out-of-range values."""

    def __init__(self, message: str, *, field: str | None = None):
        self.field = field
        super().__init__(message)


class DatasetError(DexCanvasError):
    """A dataset that is missing, partial or corrupt, or a row that breaks the schema.

    The message names the dataset, and the row and field when known.
    """

    def __init__(
        self,
        message: str,
        *,
        dataset: str | None = None,
        row: int | None = None,
        field: str | None = None,
    ):
        self.dataset = dataset
        self.row = row
        self.field = field
        where = []
        if dataset is not None:
            where.append(f"dataset {dataset}")
        if row is not None:
            where.append(f"row {row}")
        if field is not None:
            where.append(f"field {field!r}")
        prefix = ", ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)


class MissingDependencyError(DexCanvasError, ImportError):
    """An optional dependency that a feature needs is not installed."""

    def __init__(self, package: str, feature: str, extra: str | None = None):
        fix = f"pip install 'dexcanvas-retarget[{extra}]'" if extra else f"pip install {package}"
        super().__init__(
            f"{feature} needs the package {package!r}, which is not installed; run: {fix}"
        )
