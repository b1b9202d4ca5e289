"""MuJoCo's warnings go to Python ``logging`` (logger ``dexcanvas_core.mujoco``), not to a file.

MuJoCo's default warning handler prints the warning and appends it to ``MUJOCO_LOG.TXT`` in the
current directory. Importing this module replaces that handler, once per process, with one that
logs the message as a warning; every module of the toolkit that creates MuJoCo models or data
imports it. Counting warnings per run reads ``MjData.warning``, which this does not change.
"""

from __future__ import annotations

import logging

import mujoco

log = logging.getLogger("dexcanvas_core.mujoco")


def _warning(message: str) -> None:
    log.warning("MuJoCo: %s", message)


def install() -> None:
    """Route MuJoCo's warnings to :data:`log` (idempotent)."""
    if mujoco.get_mju_user_warning() is not _warning:
        mujoco.set_mju_user_warning(_warning)


install()
