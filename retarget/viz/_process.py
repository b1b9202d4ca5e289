"""Child processes (meshcat server, headless Chromium, MuJoCo renderer) that never outlive us.

Every child runs in its own session (``start_new_session``), so one ``killpg`` ends it and the
processes it forked. Some children daemonise helpers into other sessions (Chromium's crash
handler does), so every child also carries ``RETARGET_VIZ_TAG=<PROCESS_TAG>:<n>`` in its
environment, which its descendants inherit; on exit we end every process that carries the tag.
:func:`tagged_processes` lists what is left (tests use it to check nothing survives).
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import os
import signal
import subprocess
import time
import uuid
from collections.abc import Iterator, Sequence
from pathlib import Path

log = logging.getLogger(__name__)

TAG_ENV = "RETARGET_VIZ_TAG"
PROCESS_TAG = f"{os.getpid()}-{uuid.uuid4().hex[:12]}"
"""Tag of the children started by this Python process (a prefix of each child's tag)."""
_counter = itertools.count()


def tagged_processes(tag: str = PROCESS_TAG) -> list[int]:
    """PIDs of live processes whose environment carries a tag starting with ``tag``."""
    needle = f"{TAG_ENV}={tag}".encode()
    pids = []
    if not Path("/proc").is_dir():  # not Linux: process groups alone end the children
        return pids
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            env = (entry / "environ").read_bytes()
            state = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:  # gone, or not ours to read
            continue
        if state != "Z" and any(v.startswith(needle) for v in env.split(b"\0")):
            pids.append(int(entry.name))
    return pids


def _kill_tagged(tag: str, sig: int) -> list[int]:
    pids = tagged_processes(tag)
    for pid in pids:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, sig)
    return pids


def terminate(proc: subprocess.Popen, tag: str, grace_s: float = 3.0) -> None:
    """End ``proc``, its process group and every process carrying ``tag``; reap ``proc``."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(grace_s)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    else:  # the leader is gone; its group may not be
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(proc.pid, signal.SIGKILL)
    deadline = time.monotonic() + grace_s
    sig = signal.SIGTERM
    while _kill_tagged(tag, sig):
        if time.monotonic() > deadline:
            if sig == signal.SIGKILL:
                log.warning("processes tagged %s did not exit", tag)
                break
            sig, deadline = signal.SIGKILL, time.monotonic() + grace_s
        time.sleep(0.05)
    for stream in (proc.stdin, proc.stdout, proc.stderr):
        if stream is not None:
            stream.close()


@contextlib.contextmanager
def managed_process(
    args: Sequence[str], *, env: dict[str, str] | None = None, **popen_kwargs
) -> Iterator[subprocess.Popen]:
    """``Popen(args)`` in a new session; on leaving the block (also on error) it is ended."""
    tag = f"{PROCESS_TAG}:{next(_counter)}"
    full_env = dict(os.environ if env is None else env)
    full_env[TAG_ENV] = tag
    proc = subprocess.Popen(list(args), env=full_env, start_new_session=True, **popen_kwargs)
    try:
        yield proc
    finally:
        terminate(proc, tag)


def run_process(
    args: Sequence[str], *, timeout_s: float, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess:
    """Run ``args`` to completion (stdout/stderr captured as text) as a managed process.

    Raises ``subprocess.TimeoutExpired`` after ``timeout_s``; the process is ended either way.
    """
    with managed_process(
        args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    ) as proc:
        out, err = proc.communicate(timeout=timeout_s)
        return subprocess.CompletedProcess(list(args), proc.returncode, out, err)
