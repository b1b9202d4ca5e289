"""``--objects MANIFEST`` and ``--objects-dir DIR``: the options of every command that builds a
scene (``retarget run/snapshot/report``, ``dexcanvas simulate/synthesize/demos``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from dexcanvas_core.objects.manifest import MANIFEST_ENV, OBJECTS_DIR_ENV
from dexcanvas_core.taxonomy import use_objects


def add_object_options(p: argparse.ArgumentParser) -> None:
    """Add ``--objects`` and ``--objects-dir`` to a sub-command's parser."""
    g = p.add_argument_group("objects beyond the built-in catalogue")
    g.add_argument(
        "--objects",
        dest="objects_manifest",
        type=Path,
        default=None,
        metavar="MANIFEST",
        help=(
            "TOML objects manifest: [<id>] mesh = 'x.obj', mass_kg = ..., optional friction, "
            f"scale, inertia_diag (default: ${MANIFEST_ENV})"
        ),
    )
    g.add_argument(
        "--objects-dir",
        type=Path,
        default=None,
        metavar="DIR",
        help=(
            "directory of object models <id>.obj|stl|ply|glb (e.g. the release's models of the "
            f"YCB-style items) used instead of the built-in shapes (default: ${OBJECTS_DIR_ENV})"
        ),
    )


def use_object_options(args: argparse.Namespace) -> dict:
    """Put the parsed options in use (checked now: a bad manifest stops before any work)."""
    manifest = getattr(args, "objects_manifest", None)
    objects_dir = getattr(args, "objects_dir", None)
    return use_objects(manifest, objects_dir)
