"""Helpers of the fault-injection suite (``tests/test_fault_injection.py``): run a command line
in-process or as a child process, check the exit contract (``dexcanvas_core.exits``), and
fingerprint files to prove that a refused command lost nothing."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dexcanvas_core.exits import EXIT_USAGE

REPO = Path(__file__).resolve().parents[1]


@dataclass
class Outcome:
    """What a command line did: its exit code and what it printed."""

    rc: int
    out: str
    err: str

    def error_lines(self) -> list[str]:
        return [line for line in self.err.splitlines() if ": error:" in line]


def call(main: Callable[[list[str]], int], argv: Sequence[object], capsys) -> Outcome:
    """``main(argv)`` in-process; argparse's usage errors (``SystemExit``) become exit codes."""
    capsys.readouterr()
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as e:
        rc = e.code if isinstance(e.code, int) else 1
    captured = capsys.readouterr()
    return Outcome(rc, captured.out, captured.err)


def assert_refused(o: Outcome, where: str, *needles: str, code: int = EXIT_USAGE) -> str:
    """Check the exit contract of a refusal: ``code``, no traceback, stderr exactly one line
    ``<where>: error: …`` holding every needle (case-insensitive); returns that line."""
    assert "Traceback" not in o.err, o.err
    assert o.rc == code, (o.rc, o.err[-2000:])
    lines = [line for line in o.err.splitlines() if line.strip()]
    assert len(lines) == 1, o.err  # the error line alone: no warnings, no continuation
    line = lines[0]
    assert line.startswith(f"{where}: error: "), line
    for n in needles:
        assert n.lower() in line.lower(), (n, line)
    return line


def assert_clean(o: Outcome) -> None:
    """A clean refusal or a success: exit 0 or 2, never an internal error or a traceback."""
    assert "Traceback" not in o.err, o.err
    assert o.rc in (0, EXIT_USAGE), (o.rc, o.err[-2000:])
    if o.rc == EXIT_USAGE:
        assert len(o.error_lines()) == 1 or "usage:" in o.err, o.err


def digest(path: Path) -> dict[str, str]:
    """Content fingerprint of a file or of every file under a directory (relative names)."""
    path = Path(path)
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    return {
        str(p.relative_to(path) if p != path else p.name): hashlib.sha256(
            p.read_bytes()
        ).hexdigest()
        for p in files
    }


def leftovers(directory: Path) -> list[str]:
    """Temporary files a writer left behind (``*.tmp*`` names)."""
    return sorted(p.name for p in Path(directory).rglob("*") if ".tmp" in p.name)


def assert_run_outputs_whole(out: Path, frames: int | None = None) -> None:
    """A run directory's final files are absent or complete: the npz opens with every array
    readable, metrics.json parses (and covers ``frames``)."""
    import json

    npz, metrics = out / "robot_trajectory.npz", out / "metrics.json"
    if npz.exists():
        with np.load(npz, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        assert "q" in arrays
        if frames is not None:
            assert arrays["q"].shape[0] == frames
    if metrics.exists():
        m = json.loads(metrics.read_text())
        if frames is not None:
            assert m["frames"] == frames


def child_env(**extra: str) -> dict[str, str]:
    """Environment of a child command line: this checkout first on the path."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env.update(extra)
    return env


def spawn(module: str, argv: Sequence[object], cwd: Path, **env: str) -> subprocess.Popen:
    """Start ``python -m <module> argv…`` as a child process (text pipes)."""
    return subprocess.Popen(
        [sys.executable, "-m", module, *map(str, argv)],
        cwd=cwd,
        env=child_env(**env),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def finish(p: subprocess.Popen, timeout: float = 120) -> Outcome:
    out, err = p.communicate(timeout=timeout)
    return Outcome(p.returncode, out, err)


def wait_for(predicate: Callable[[], bool], p: subprocess.Popen, timeout: float = 60) -> bool:
    """Poll ``predicate`` until it holds (True) or ``p`` ends or time runs out (False)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and p.poll() is None:
        if predicate():
            return True
        time.sleep(0.05)
    return False


def kill(p: subprocess.Popen, sig: int = signal.SIGKILL) -> Outcome:
    """Send ``sig`` to the child and collect it."""
    if p.poll() is None:
        p.send_signal(sig)
    return finish(p)
