"""dexcanvas_core: the human side of dexcanvas-retarget.

Taxonomy and objects, the ``Trajectory`` schema, Lance I/O, data loaders and the RL trajectory
buffer, MANO-compatible hand kinematics. Never imports ``retarget``.

The names below are the public API; each is imported on first use, so ``import dexcanvas_core``
stays cheap (torch, Lance and SciPy load only when a name that needs them is used).

* demonstrations: :func:`load_demonstration`, :class:`DexCanvasDataset`,
  :func:`make_dataloader`, :class:`RLTrajectoryBuffer`, :func:`open_dataset`,
  :func:`builtin_demonstration_path`, :func:`builtin_pair_path`;
* one demonstration: :class:`Trajectory`;
* taxonomy: :class:`Pair`, :func:`object_spec`, :func:`manipulation_type`;
* object shapes: :class:`ObjectGeometry`, :func:`object_geometry`;
* the hand: :class:`ManoLayer`, :class:`HandSkeleton`, :class:`HandModel`, :func:`hand_model`.

>>> import dexcanvas_core as dc
>>> traj = dc.load_demonstration("cube2/tripod")  # built-in, generated on first use
>>> traj.scene, traj.gesture
('cube2', 'tripod')
"""

from importlib import import_module

__version__ = "0.1.0"

_EXPORTS: dict[str, str] = {
    "DexCanvasDataset": "dexcanvas_core.loaders.dataset",
    "HandModel": "dexcanvas_core.mano.hand_model",
    "HandSkeleton": "dexcanvas_core.mano.skeleton",
    "ManoLayer": "dexcanvas_core.mano.layer",
    "ObjectGeometry": "dexcanvas_core.objects.geometry",
    "Pair": "dexcanvas_core.taxonomy.pair",
    "RLTrajectoryBuffer": "dexcanvas_core.loaders.rl_buffer",
    "Trajectory": "dexcanvas_core.trajectory.trajectory",
    "builtin_demonstration_path": "dexcanvas_core.builtin",
    "builtin_pair_path": "dexcanvas_core.builtin",
    "hand_model": "dexcanvas_core.mano.hand_model",
    "load_demonstration": "dexcanvas_core.loaders.selection",
    "make_dataloader": "dexcanvas_core.loaders.collate",
    "manipulation_type": "dexcanvas_core.taxonomy.manipulation",
    "object_geometry": "dexcanvas_core.objects.geometry",
    "object_spec": "dexcanvas_core.taxonomy.object_lookup",
    "open_dataset": "dexcanvas_core.io.reader",
}
"""Public name → the module defining it."""

__all__ = ["__version__", *sorted(_EXPORTS)]


def __getattr__(name: str):
    """Import a public name on first use (PEP 562); it is then cached in the module."""
    try:
        module = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'dexcanvas_core' has no attribute {name!r}") from None
    value = getattr(import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
