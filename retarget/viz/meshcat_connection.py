"""The meshcat server of a scene and the connection to it.

:func:`meshcat_server` starts meshcat's own bridge as a child process bound to 127.0.0.1
(``python -m retarget.viz._meshcat_server``), checks it after start
(:func:`listening_addresses`) and ends it with its process group when the ``with`` block ends,
also on errors; :func:`connect` opens a ``meshcat.Visualizer`` on it.
"""

from __future__ import annotations

import contextlib
import ipaddress
import os
import select
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from retarget.viz._process import managed_process
from retarget.viz.errors import VizError
from retarget.viz.meshcat_geoms import import_meshcat


@dataclass(frozen=True)
class MeshcatServer:
    """A running meshcat server (see :func:`meshcat_server`)."""

    zmq_url: str
    web_url: str
    pid: int


def listening_addresses(pid: int) -> list[tuple[str, int]]:
    """``(ip, port)`` of every TCP socket process ``pid`` listens on (Linux ``/proc``)."""
    inodes = set()
    fd_dir = Path(f"/proc/{pid}/fd")
    for fd in fd_dir.iterdir():
        with contextlib.suppress(OSError):
            target = os.readlink(fd)
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    out = []
    for table, v6 in (("tcp", False), ("tcp6", True)):
        path = Path(f"/proc/{pid}/net/{table}")
        if not path.exists():
            continue
        for line in path.read_text().splitlines()[1:]:
            cols = line.split()
            if len(cols) < 10 or cols[3] != "0A" or cols[9] not in inodes:  # 0A: LISTEN
                continue
            addr_hex, port_hex = cols[1].split(":")
            raw = bytes.fromhex(addr_hex)
            # /proc prints each 32-bit word of the address in host (little-endian) order.
            words = b"".join(raw[i : i + 4][::-1] for i in range(0, len(raw), 4))
            ip = ipaddress.IPv6Address(words) if v6 else ipaddress.IPv4Address(words)
            out.append((str(ip), int(port_hex, 16)))
    return out


def _read_lines(proc: subprocess.Popen, n: int, deadline: float) -> list[str]:
    """The first ``n`` lines the process prints (unbuffered reads, so select() stays exact)."""
    fd = proc.stdout.fileno()
    buf = b""
    while buf.count(b"\n") < n:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise VizError("the meshcat server did not start within its time limit")
        ready, _, _ = select.select([fd], [], [], remaining)
        if ready:
            chunk = os.read(fd, 4096)
            if not chunk:
                raise VizError(f"the meshcat server exited at start (code {proc.wait()})")
            buf += chunk
    return [line.strip() for line in buf.decode().splitlines()[:n]]


@contextlib.contextmanager
def meshcat_server(timeout_s: float = 30.0) -> Iterator[MeshcatServer]:
    """Start a meshcat server on 127.0.0.1; stop it (and its children) when the block ends.

    Raises :class:`VizError` if it does not come up, or listens anywhere but on loopback.
    """
    with (
        tempfile.TemporaryFile() as errlog,
        managed_process(
            [sys.executable, "-u", "-m", "retarget.viz._meshcat_server"],
            stdout=subprocess.PIPE,
            stderr=errlog,
        ) as proc,
    ):
        deadline = time.monotonic() + timeout_s
        try:
            urls = dict(line.split("=", 1) for line in _read_lines(proc, 2, deadline))
        except (VizError, ValueError) as e:
            errlog.seek(0)
            tail = errlog.read().decode(errors="replace").strip().splitlines()[-5:]
            raise VizError(f"{e}: {' | '.join(tail)}") from None
        addresses = listening_addresses(proc.pid) if Path("/proc/self/fd").is_dir() else []
        public = [a for a in addresses if not ipaddress.ip_address(a[0]).is_loopback]
        if public:
            raise VizError(f"the meshcat server listens beyond this machine: {public}")
        yield MeshcatServer(zmq_url=urls["zmq_url"], web_url=urls["web_url"], pid=proc.pid)


def connect(server: MeshcatServer, timeout_s: float = 60.0):
    """A ``meshcat.Visualizer`` talking to ``server`` (requests time out after ``timeout_s``)."""
    import zmq

    meshcat = import_meshcat()
    from meshcat.visualizer import ViewerWindow

    class Window(ViewerWindow):
        # meshcat's own window prints the URL and waits forever on a dead server.
        def __init__(self, zmq_url: str, web_url: str):
            self.server_proc = None
            self.zmq_url = zmq_url
            self.web_url = web_url
            self.connect_zmq()

        def connect_zmq(self):
            self.zmq_socket = self.context.socket(zmq.REQ)
            self.zmq_socket.setsockopt(zmq.LINGER, 0)
            self.zmq_socket.setsockopt(zmq.RCVTIMEO, int(1000 * timeout_s))
            self.zmq_socket.setsockopt(zmq.SNDTIMEO, int(1000 * timeout_s))
            self.zmq_socket.connect(self.zmq_url)

        def close(self):
            self.zmq_socket.close(linger=0)

    return meshcat.Visualizer(window=Window(server.zmq_url, server.web_url))
