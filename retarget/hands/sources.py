"""Where hand models come from: files of installed packages, and this repository's ``robots/``."""

from __future__ import annotations

import importlib.util
import sysconfig
from pathlib import Path

from retarget.errors import HandModelError


def package_path(module: str, *parts: str, pip_name: str | None = None):
    """Path of a data file inside an installed package, without importing the package.

    ``importlib.util.find_spec`` locates the package directory only (importing
    ``robosuite_models`` would fail without robosuite; ``gymnasium_robotics`` prints notices).
    Raises :class:`HandModelError` naming the pip package when it is not installed.
    """
    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        spec = None
    if spec is None or not spec.submodule_search_locations:
        raise HandModelError(
            f"the package {module!r} is not installed; run: pip install {pip_name or module}"
        )
    path = Path(next(iter(spec.submodule_search_locations))).joinpath(*parts)
    if not path.exists():
        raise HandModelError(f"{path} is missing from the installed package {module!r}")
    return path


def example_robot_data_path(*parts: str):
    """Path inside example-robot-data's data tree (``cmeel.prefix/share/example-robot-data``).

    The wheel ships data only (no Python module); its files live under the ``cmeel.prefix``
    directory of site-packages.
    """
    roots = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    for root in roots:
        p = Path(root, "cmeel.prefix", "share", "example-robot-data", "robots", *parts)
        if p.exists():
            return p
    raise HandModelError(
        f"example-robot-data file robots/{'/'.join(parts)} not found; "
        "run: pip install example-robot-data"
    )


def urdf_with_mujoco_compiler(urdf_text: str, **compiler: str) -> str:
    """Insert a ``<mujoco><compiler .../></mujoco>`` extension right after ``<robot ...>``."""
    start = urdf_text.find("<robot")
    if start < 0:
        raise HandModelError("not a URDF: no <robot> element")
    end = urdf_text.index(">", start) + 1
    attrs = " ".join(f'{k}="{v}"' for k, v in compiler.items())
    return urdf_text[:end] + f"<mujoco><compiler {attrs}/></mujoco>" + urdf_text[end:]


def robots_dir():
    """The repository's ``robots/`` folder (models authored by this project)."""
    return Path(__file__).resolve().parents[2] / "robots"
