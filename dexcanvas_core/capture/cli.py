"""``dexcanvas import``: its options and its report (the command line of
:mod:`dexcanvas_core.capture.importer`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from dexcanvas_core.capture import ImportConfig, run_import
from dexcanvas_core.capture.importer import format_names
from dexcanvas_core.cli_help import HelpFormatter, examples_epilog
from dexcanvas_core.errors import ValidationError


def add_import_parser(sub) -> None:
    """Add the ``import`` sub-command to the ``dexcanvas`` sub-parsers ``sub``."""
    s = sub.add_parser(
        "import",
        help="import captured sequences (MANO hand + object) into a Lance dataset",
        description=(
            "Import captured hand-object sequences. FORMAT mano-npz: one .npz per sequence\n"
            "with the keys documented in the README; published formats: see --help of FORMAT.\n"
            "Object meshes and masses go to OUT.objects/manifest.toml, used by every command\n"
            "that opens OUT."
        ),
        epilog=examples_epilog(
            "dexcanvas import mano-npz grasp.npz --out real.lance",
            "dexcanvas import mano-npz captures/ --out real.lance --objects objects.toml "
            "--mirror-left --fps native",
        ),
        formatter_class=HelpFormatter,
    )
    s.add_argument("format", metavar="FORMAT", help=f"one of: {', '.join(format_names())}")
    s.add_argument("paths", nargs="+", type=Path, metavar="PATH", help="files or directories")
    s.add_argument("--out", type=Path, required=True, help="output dataset directory (*.lance)")
    s.add_argument(
        "--objects", dest="objects_manifest", type=Path, default=None, metavar="MANIFEST",
        help="objects manifest giving masses (and frictions) of the captures' objects",
    )  # fmt: skip
    s.add_argument(
        "--mirror-left", action="store_true",
        help="import left hands mirrored to right ones (the whole scene mirrored)",
    )  # fmt: skip
    s.add_argument(
        "--up", default=None,
        help="up axis of the captures' world, overriding theirs: z, y, -y, x, ...",
    )  # fmt: skip
    s.add_argument(
        "--fps", default="120", help="resample to this rate [Hz], or 'native' (default: 120)"
    )
    s.add_argument(
        "--density", type=float, default=None,
        help="estimate missing masses from the mesh volume at this density [kg/m³]",
    )  # fmt: skip
    s.add_argument(
        "--models", type=Path, default=None,
        help="object models directory, for formats that name objects without meshes",
    )  # fmt: skip
    s.add_argument("--overwrite", action="store_true", help="replace an existing output")


def _fps_option(text: str) -> float | None:
    if str(text).strip().lower() == "native":
        return None
    try:
        return float(text)
    except ValueError:
        raise ValidationError(f"--fps must be a rate in Hz or 'native', got {text!r}") from None


def run_import_command(args: argparse.Namespace):
    """``dexcanvas import``: captured sequences into a Lance dataset (+ its objects' meshes)."""
    from rich.console import Console
    from rich.progress import Progress
    from rich.table import Table

    fps = _fps_option(args.fps)
    cfg = ImportConfig(
        format=args.format,
        paths=tuple(args.paths),
        out=args.out,
        objects_manifest=args.objects_manifest,
        mirror_left=args.mirror_left,
        up=args.up,
        fps=fps,
        density=args.density,
        models_dir=args.models,
        overwrite=args.overwrite,
    )
    con = Console(stderr=True)
    with Progress(console=con, transient=True) as prog:
        task = prog.add_task("converting", total=None)
        res = run_import(cfg, progress=lambda i, n: prog.update(task, completed=i, total=n))
    t = Table(title=f"imported {len(res.sequences)} sequence(s) into {res.out}")
    for col in ("sequence", "object", "frames", "fps", "table top", "moves", "kp fit"):
        t.add_column(col)
    for r in res.sequences:
        tab = r["table"]
        t.add_row(
            r["name"] + (" (mirrored)" if r["mirrored"] else ""),
            r["object"],
            f"{r['frames_in']} → {r['frames']}",
            f"{r['fps_in']:g} → {r['fps']:g}",
            "none" if tab is None else f"{tab['top_z_m']:.3f} m",
            "-" if r["object_move"] is None else "{}–{}".format(*r["object_move"]),
            "-" if r["keypoint_fit_mm"] is None else f"{r['keypoint_fit_mm']:.1f} mm",
        )
    Console().print(t)
    objs = Table(title=f"objects ({res.manifest})")
    for col in ("object", "mesh", "extent (m)", "mass (kg)", "mass from"):
        objs.add_column(col)
    for oid, o in res.objects.items():
        objs.add_row(
            oid, o["mesh"], " × ".join(f"{v:.3f}" for v in o["extent_m"]),
            f"{o['mass_kg']:.4g}", o["mass_from"],
        )  # fmt: skip
    Console().print(objs)
    ignored = sorted({k for r in res.sequences for k in r["ignored_keys"]})
    if ignored:
        con.print(f"ignored keys (not read): {', '.join(ignored)}")
    return res
