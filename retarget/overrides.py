"""``NAME=VALUE`` overrides of a configuration dataclass, as the shell gives them
(``retarget run --set``, the benchmarks' ``--set``)."""

from __future__ import annotations

import argparse
import ast
import dataclasses

from retarget.errors import RetargetError


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


def build_config(config_cls, overrides: dict, option: str = "--set", reserved=None, **fixed):
    """``config_cls(**overrides, **fixed)``, validated (``validate()`` where it has one).

    ``overrides`` come from the shell's ``option``; ``reserved`` maps the fields that have their
    own option (``{"force_matching": "--forces"}``) to it. An unknown field, a reserved one or a
    value the config refuses raises ``RetargetError`` naming ``option`` and the field."""
    names = {f.name for f in dataclasses.fields(config_cls)}
    reserved = reserved or {}
    over = dict(overrides)
    bad = sorted(set(over) - names)
    if bad:
        raise RetargetError(
            f"{option}: unknown {config_cls.__name__} field(s) {', '.join(bad)}; available: "
            f"{', '.join(sorted(names - set(reserved)))}"
        )
    own = sorted(set(over) & set(reserved))
    if own:
        uses = "; ".join(f"{k} is the run's own option, use {reserved[k]}" for k in own)
        raise RetargetError(f"{option}: {uses}")
    try:
        cfg = config_cls(**over, **fixed)
        return cfg.validate() if hasattr(cfg, "validate") else cfg
    except Exception as e:  # the config's own checks, e.g. a negative weight
        raise RetargetError(f"{option}: {config_cls.__name__} refuses {over}: {e}") from None
