"""Name normalisation shared by the taxonomy catalogues (private)."""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from typing import TypeVar

T = TypeVar("T")

_NOT_ALNUM = re.compile(r"[^0-9a-z]+")


def compact_key(text: str) -> str:
    """Lower-case ``text`` and drop everything but letters and digits.

    ``"Palmar-Pinch"``, ``"palmar pinch"`` and ``"palmar_pinch"`` all give ``"palmarpinch"``;
    ``"Mayonnaise Bottle"`` and ``"mayonnaisebottle"`` give ``"mayonnaisebottle"``.
    """
    return _NOT_ALNUM.sub("", text.strip().lower())


def build_index(entries: Iterable[tuple[T, Iterable[str]]], kind: str) -> dict[str, T]:
    """Map the compact key of every spelling to its entry; two entries sharing a key is a bug."""
    index: dict[str, T] = {}
    for entry, spellings in entries:
        for spelling in spellings:
            key = compact_key(spelling)
            if not key:
                raise ValueError(f"empty {kind} spelling for {entry!r}")
            previous = index.setdefault(key, entry)
            if previous is not entry:
                raise ValueError(
                    f"{kind} spelling {spelling!r} names both {previous!r} and {entry!r}"
                )
    return index


def lookup(index: Mapping[str, T], text: str) -> T | None:
    """The entry spelled ``text`` (any case, separators ignored), or ``None``."""
    return index.get(compact_key(text))
