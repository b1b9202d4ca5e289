"""Progress bars of long steps (rich), or nothing."""

from __future__ import annotations

from collections.abc import Callable

from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    TimeElapsedColumn,
)
from rich.progress import (
    Progress as _RichProgress,
)


class Progress:
    """A context of rich progress bars, one per :meth:`task`; with ``enabled`` False it shows
    nothing and :meth:`task` returns ``None`` (callers skip their updates)."""

    def __init__(self, enabled: bool = True):
        self.enabled = enabled
        self._p = None

    def __enter__(self) -> Progress:
        if self.enabled:
            self._p = _RichProgress(
                "[progress.description]{task.description}",
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                transient=False,
            )
            self._p.__enter__()
        return self

    def __exit__(self, *exc) -> bool:
        if self._p is not None:
            self._p.__exit__(*exc)
        return False

    def task(self, name: str, total: int) -> Callable[[int, int], None] | None:
        """A bar named ``name`` of ``total`` steps: ``update(done, total)``; ``None`` when
        disabled or outside the context."""
        if self._p is None:
            return None
        tid = self._p.add_task(name, total=total)
        return lambda done, _total: self._p.update(tid, completed=done)
