"""A meshcat server that listens on 127.0.0.1 only: ``python -m retarget.viz._meshcat_server``.

meshcat 0.3.2 binds its ZeroMQ socket to 127.0.0.1 but its web server (tornado) to every
interface: ``ZMQWebSocketBridge`` calls ``app.listen(port)`` without an address, and its command
line has no host option. This module runs the same bridge with ``listen`` bound to
``127.0.0.1``. It prints ``zmq_url=…`` and ``web_url=…`` (the lines meshcat's own launcher
reads) and exits when its parent process dies.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

HOST = "127.0.0.1"


def _exit_with_parent() -> None:
    """Ask Linux to send SIGTERM when the parent dies (and exit if it already has)."""
    parent = os.getppid()
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: the parent's context manager still ends us
        pass
    if os.getppid() != parent or parent == 1:
        sys.exit(0)


def make_bridge(host: str = HOST):
    """The meshcat ``ZMQWebSocketBridge`` with both its sockets bound to ``host``."""
    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    class LocalBridge(ZMQWebSocketBridge):
        def make_app(self):
            app = super().make_app()
            listen = app.listen

            def listen_on_host(port, **kwargs):
                return listen(port, address=self.host, **kwargs)

            app.listen = listen_on_host
            return app

    return LocalBridge(host=host)


def main() -> None:
    _exit_with_parent()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    bridge = make_bridge()
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    # meshcat logs websocket events on stderr: keep it, the parent drains or discards it.
    try:
        bridge.run()
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
