"""The exit contract of the command lines (``dexcanvas``, ``retarget``).

=====  =================================================================================
code   meaning
=====  =================================================================================
0      done (and, for commands that validate, the result passed)
1      internal error: a bug; one line on stderr says where the full traceback was written
2      bad input or usage: one line ``<prog> <command>: error: <what, the value, the fix>``;
       nothing was written
3      the command ran to the end but its result failed validation (a re-simulation that
       lost the object, a dataset with invalid rows); the summary says why
130    interrupted (Ctrl-C): outputs finished before the interruption are kept, and said
=====  =================================================================================
"""

from __future__ import annotations

import os
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path

from dexcanvas_core.cache import cache_dir
from dexcanvas_core.errors import DexCanvasError

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_USAGE = 2
EXIT_FAILED = 3
EXIT_INTERRUPTED = 130


def traceback_dir() -> Path:
    """Where internal errors' tracebacks are written: ``$DEXCANVAS_LOG_DIR``, else ``logs/`` in
    the cache directory."""
    env = os.environ.get("DEXCANVAS_LOG_DIR")
    return Path(env).expanduser() if env else cache_dir() / "logs"


def write_traceback(prog: str, command: str, exc: BaseException) -> Path | None:
    """Write ``exc``'s traceback to a new file in :func:`traceback_dir`; its path, or ``None``
    when even that failed."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    try:
        d = traceback_dir()
        d.mkdir(parents=True, exist_ok=True)
        path = d / f"{prog}-{command or 'main'}-{stamp}-{os.getpid()}.log"
        text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
        path.write_text(f"{prog} {command} {' '.join(sys.argv[1:])}\n\n{text}")
        return path
    except OSError:
        return None


def run_command(
    prog: str,
    command: str,
    fn: Callable[[], int | None],
    errors: tuple[type[BaseException], ...] = (DexCanvasError,),
) -> int:
    """Run one sub-command under the exit contract (module doc): ``fn()``'s code (``None`` is
    0); an error of ``errors`` → its message, 2; an ``OSError`` reading or writing a file → the
    file and the reason, 2; Ctrl-C → 130; anything else → a one-line note and the traceback
    file, 1."""
    where = f"{prog} {command}".strip()
    try:
        code = fn()
        return EXIT_OK if code is None else int(code)
    except errors as e:
        print(f"{where}: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(
            f"{where}: interrupted; outputs already completed are kept (each file is written "
            "whole or not at all)",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    except OSError as e:
        name = f" {e.filename!s}" if getattr(e, "filename", None) else ""
        print(f"{where}: error: cannot access{name}: {e.strerror or e}", file=sys.stderr)
        return EXIT_USAGE
    except Exception as e:  # a bug: say so briefly and keep the traceback
        path = write_traceback(prog, command, e)
        where_tb = f"; the traceback is in {path}" if path else ""
        print(
            f"{where}: internal error: {type(e).__name__}: {e}{where_tb} (please report it)",
            file=sys.stderr,
        )
        return EXIT_INTERNAL
