"""``NAME=VALUE`` overrides of a configuration dataclass, as the shell gives them
(``retarget run --set``, the benchmarks' ``--set``)."""

from __future__ import annotations

import argparse
import ast


def parse_override(text: str) -> tuple[str, object]:
    """``"name=value"`` → ``(name, value)``, the value a Python literal (``2``, ``True``,
    ``(0.001, 0.004)``, ``None``); an ``argparse`` type for ``--set``."""
    name, sep, value = text.partition("=")
    if not sep or not name.strip():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    try:
        return name.strip(), ast.literal_eval(value.strip())
    except (ValueError, SyntaxError):
        raise argparse.ArgumentTypeError(
            f"{name.strip()}: {value.strip()!r} is not a Python literal (e.g. 2.0, True, None)"
        ) from None
