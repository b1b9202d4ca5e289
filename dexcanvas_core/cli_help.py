"""What both command lines (``dexcanvas``, ``retarget``) share for their ``--help`` and their
dataset option.

* :class:`HelpFormatter` keeps the line breaks of descriptions and epilogs (the examples) and
  appends ``(default: X)`` to every option that has a default worth saying (not ``None``, not
  an off switch, not already said in its help).
* :func:`examples_epilog` and :data:`EXIT_CODES_EPILOG`: the text under the options.
* :func:`add_dataset_option`: ``--dataset PATH`` everywhere, with the value ``builtin`` for the
  built-in demonstrations; :func:`dataset_from_args` also takes the positional path that
  ``info``, ``validate`` and ``export`` accepted before (deprecated).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.exits import (
    EXIT_FAILED,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
)

BUILTIN = "builtin"
"""The ``--dataset`` value naming the built-in demonstrations."""

EXIT_CODES_EPILOG = f"""\
exit codes:
  {EXIT_OK:<4} done (for commands that validate: the result passed)
  {EXIT_INTERNAL:<4} internal error (a bug): stderr names the file holding the traceback
  {EXIT_USAGE:<4} bad input or usage: one line naming the value and the fix; nothing written
  {EXIT_FAILED:<4} ran to the end but the result failed validation; the summary says why
  {EXIT_INTERRUPTED:<4} interrupted (Ctrl-C): outputs finished before it are kept"""
"""The exit contract (:mod:`dexcanvas_core.exits`) as the top-level ``--help`` shows it."""


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Raw description and epilog (the examples keep their lines); ``(default: X)`` after
    the help of every option whose default is worth saying."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "default" in text or not action.option_strings:
            return text
        d = action.default
        if d is None or d is argparse.SUPPRESS or isinstance(d, bool) or d in ([], ()):
            return text
        if isinstance(d, float):
            shown = f"{d:.6g}"  # 29.999999999999996 (from radians) reads 30
        elif isinstance(d, str | int):
            shown = "%(default)s"
        else:
            shown = str(d).replace("%", "%%")
        return f"{text} (default: {shown})" if text else f"(default: {shown})"

    def _format_action(self, action: argparse.Action) -> str:
        # argparse prints no help line for an option without help; give it the default.
        if not action.help and self._get_help_string(action):
            action = _with_help(action, self._get_help_string(action))
        return super()._format_action(action)


def _with_help(action: argparse.Action, text: str) -> argparse.Action:
    clone = argparse.Action.__new__(type(action))
    clone.__dict__.update(action.__dict__)
    clone.help = text
    return clone


def examples_epilog(*lines: str) -> str:
    """An ``examples:`` block of command lines, one a line (``#`` lines are comments)."""
    return "examples:\n" + "\n".join(f"  {line}" for line in lines)


def dataset_value(text: str) -> Path | str:
    """``--dataset`` argument: :data:`BUILTIN` for ``builtin``, else a path (``./builtin`` for
    a directory of that name)."""
    return BUILTIN if text == BUILTIN else Path(text)


def add_dataset_option(
    p: argparse.ArgumentParser | argparse._ArgumentGroup,
    *,
    required: bool = False,
    what: str = "DexCanvas-layout Lance dataset (directory *.lance)",
    note: str | None = None,
) -> None:
    """``--dataset PATH|builtin``: the one spelling of the dataset option; ``note`` replaces
    the bracketed tail of its help (``required`` or ``default: the built-in
    demonstrations``)."""
    tail = note or ("required" if required else "default: the built-in demonstrations")
    p.add_argument(
        "--dataset",
        type=dataset_value,
        default=None,
        required=required,
        metavar="PATH",
        help=f"{what}, or 'builtin' for the built-in demonstrations ({tail})",
    )


def add_legacy_dataset_positional(p: argparse.ArgumentParser) -> None:
    """The positional dataset path ``info``, ``validate`` and ``export`` took before
    ``--dataset`` (deprecated; :func:`dataset_from_args` merges the two)."""
    p.add_argument(
        "legacy_path",
        nargs="?",
        type=dataset_value,
        default=None,
        metavar="PATH",
        help="deprecated spelling of --dataset PATH",
    )


def dataset_from_args(args: argparse.Namespace) -> Path | str:
    """The dataset of a command taking ``--dataset`` or the deprecated positional path: a
    ``Path`` or :data:`BUILTIN`.

    Raises:
        ValidationError: neither given, or both.
    """
    legacy = getattr(args, "legacy_path", None)
    if legacy is not None and args.dataset is not None:
        raise ValidationError(
            f"the dataset is given twice ({legacy} and --dataset {args.dataset}); "
            "give --dataset PATH only",
            field="dataset",
        )
    value = args.dataset if args.dataset is not None else legacy
    if value is None:
        raise ValidationError(
            "no dataset given; pass --dataset PATH (a *.lance directory) or --dataset builtin",
            field="dataset",
        )
    return value
