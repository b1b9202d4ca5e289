"""The registry of robot hands behind ``--hand``.

Built-in hands are discovered, not listed: every module of ``retarget.hands`` (other than
``base``, ``build``, ``model``, ``registry``, ``sources`` and private modules) that defines
``HAND = HandModel(...)`` is registered on first use. Plugins register theirs with
:func:`register`, or through the entry-point group
``dexcanvas_retarget.hands`` (each entry point names a ``HandModel`` object).
"""

from __future__ import annotations

import importlib
import logging
import pkgutil
import threading
from importlib.metadata import entry_points
from pathlib import Path

from retarget.errors import RetargetError, UnknownHandError
from retarget.hands.model import HandModel

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "dexcanvas_retarget.hands"
_SKIP = {"base", "build", "model", "registry", "sources"}
_PACKAGE = __name__.rpartition(".")[0]
"""``retarget.hands``: found by its folder and name, so this module does not import it."""

_hands: dict[str, HandModel] = {}
_loaded = False
_lock = threading.Lock()


def register(hand: HandModel, *, replace: bool = False) -> HandModel:
    """Add ``hand`` under ``hand.name`` (lower case). Returns it, so it can decorate a factory.

    >>> import dataclasses
    >>> mine = register(dataclasses.replace(get_hand("leap"), name="my_leap"))
    >>> get_hand("my_leap") is mine
    True
    >>> unregister("my_leap")
    """
    if not isinstance(hand, HandModel):
        raise RetargetError(f"register() needs a HandModel, got {type(hand).__name__}")
    key = hand.name.lower()
    if not key or key != key.strip() or " " in key:
        raise RetargetError(f"hand name {hand.name!r} must be one non-empty word")
    existing = _hands.get(key)
    if existing is not None and existing is not hand and not replace:
        raise RetargetError(f"a hand named {key!r} is already registered (pass replace=True)")
    _hands[key] = hand
    return hand


def unregister(name: str) -> None:
    """Remove a hand (plugins and tests)."""
    _hands.pop(name.lower(), None)


def _load_builtin() -> None:
    global _loaded
    with _lock:
        if _loaded:
            return
        for info in pkgutil.iter_modules([str(Path(__file__).parent)]):
            if info.name in _SKIP or info.name.startswith("_"):
                continue
            module = importlib.import_module(f"{_PACKAGE}.{info.name}")
            hand = getattr(module, "HAND", None)
            if isinstance(hand, HandModel) and hand.name.lower() not in _hands:
                register(hand)
        try:
            for ep in entry_points(group=ENTRY_POINT_GROUP):
                try:
                    register(ep.load())
                except Exception as e:  # a broken plugin must not hide the built-in hands
                    log.warning("hand plugin %s could not be loaded: %s", ep.name, e)
        except Exception as e:  # pragma: no cover - importlib.metadata failures are exotic
            log.warning("hand plugins could not be listed: %s", e)
        _loaded = True


def available_hands() -> list[str]:
    """Registered hand names, sorted.

    >>> available_hands()
    ['ability', 'allegro', 'inspire', 'leap', 'panda', 'shadow', 'svh']
    """
    _load_builtin()
    return sorted(_hands)


def get_hand(name: str) -> HandModel:
    """The hand registered as ``name`` (case-insensitive).

    Raises :class:`~retarget.errors.UnknownHandError` naming close matches and every hand.

    >>> hand = get_hand("Shadow")
    >>> hand.name, hand.fingers["index"]
    ('shadow', 'ff')
    """
    _load_builtin()
    hand = _hands.get(str(name).strip().lower())
    if hand is None:
        raise UnknownHandError(name, _hands)
    return hand


def hands_table() -> list[dict]:
    """One summary row per hand (compiles every model once): what ``retarget hands`` prints."""
    return [get_hand(n).summary() for n in available_hands()]
