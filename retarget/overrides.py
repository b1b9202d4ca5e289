"""``NAME=VALUE`` overrides of a configuration dataclass, as the shell gives them
(``retarget run --set``, the benchmarks' ``--set``)."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import difflib

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
    """``config_cls`` with ``overrides`` and ``fixed`` (``fixed`` last), validated.

    A config with named settings (``RetargetConfig``: dotted paths such as ``contacts.weight``
    and the flat names of ``retarget.config.FLAT_NAMES``) is built by its ``from_overrides``;
    another by ``config_cls(**overrides, **fixed)`` and its ``validate()`` where it has one.
    ``overrides`` come from the shell's ``option``; ``reserved`` maps the settings that have
    their own option (``{"force_matching": "--forces"}``; either name of a setting) to it. An
    unknown name (with the close matches), a reserved one or a value the config refuses raises
    ``RetargetError`` naming ``option`` and the setting."""
    over = dict(overrides)
    if hasattr(config_cls, "from_overrides"):
        canonical, names = config_cls.canonical_name, config_cls.setting_names()
        aliases = config_cls.alias_names()
    else:
        names = [f.name for f in dataclasses.fields(config_cls)]
        canonical, aliases = (lambda k: k if k in names else None), []
    own_option = {canonical(k): v for k, v in (reserved or {}).items()}
    bad = [k for k in over if canonical(k) is None]
    if bad:
        close = [c for k in bad for c in difflib.get_close_matches(k, [*names, *aliases], n=3)]
        hint = f" (did you mean {', '.join(dict.fromkeys(close))}?)" if close else ""
        raise RetargetError(
            f"{option}: unknown {config_cls.__name__} field(s) {', '.join(bad)}{hint}; "
            f"available: {', '.join(sorted(n for n in names if n not in own_option))}"
        )
    own = [k for k in over if canonical(k) in own_option]
    if own:
        uses = "; ".join(
            f"{k} is the run's own option, use {own_option[canonical(k)]}" for k in own
        )
        raise RetargetError(f"{option}: {uses}")
    try:
        if hasattr(config_cls, "from_overrides"):
            return config_cls.from_overrides({**over, **fixed})
        cfg = config_cls(**over, **fixed)
        return cfg.validate() if hasattr(cfg, "validate") else cfg
    except Exception as e:  # the config's own checks, e.g. a negative weight
        raise RetargetError(f"{option}: {config_cls.__name__} refuses {over}: {e}") from None
