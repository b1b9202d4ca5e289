"""Read the official MANO model files (``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl``) without chumpy.

The released pickles (MANO v1.2, Python 2) store most arrays as numpy arrays, ``J_regressor`` as a
``scipy.sparse.csc_matrix``, and some arrays as *chumpy* objects: ``shapedirs`` is a
``chumpy.reordering.Select`` over a ``chumpy.ch.Ch`` (facts from public MANO loaders that read the
files without chumpy). Chumpy is unmaintained and breaks on current numpy, so this module reads the
files with a restricted :class:`pickle.Unpickler`:

* ``chumpy.*`` classes become inert stand-ins that keep their pickled state; afterwards
  ``chumpy.ch.Ch`` evaluates to its array ``x`` and ``chumpy.reordering.Select`` to
  ``a.ravel()[idxs].reshape(preferred_shape)`` (chumpy's own definition); any other chumpy node
  in a key we use is an error naming it;
* numpy arrays and dtypes, scipy sparse matrices, and a few harmless builtins (``set``,
  ``object``, …) load as usual;
* every other global is refused, so a model file cannot run code while it is read.

The files are licence-restricted: this toolkit never ships or downloads them. Point
``MANO_MODEL_DIR`` (or ``ManoLayer(model_dir=...)``) at the folder that holds them.
"""

from __future__ import annotations

import logging
import os
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from dexcanvas_core.errors import DexCanvasError, ValidationError
from dexcanvas_core.keypoints import MANO_PARENTS
from dexcanvas_core.safe_pickle import PY2_MODULES, RestrictedUnpickler

logger = logging.getLogger(__name__)

Side = Literal["right", "left"]

MANO_MODEL_DIR_ENV = "MANO_MODEL_DIR"
"""Environment variable naming the folder that holds the official MANO pickles."""

MANO_MODEL_FILES: dict[str, str] = {"right": "MANO_RIGHT.pkl", "left": "MANO_LEFT.pkl"}
"""File name of the official model of each side, as released (and as ``smplx`` expects it)."""

MANO_NUM_VERTICES = 778
MANO_NUM_JOINTS = 16
MANO_NUM_POSE_BASIS = 135  # 15 non-root joints × 9 entries of (R - I)

_KINTREE_NO_PARENT = 4294967295  # 2**32 - 1: the root's "parent" id in the official kintree_table


class _ChumpyNode:
    """Inert stand-in for a pickled chumpy object: records its class name and pickled state."""

    chumpy_class = "chumpy"
    state: Any = None

    def __new__(cls, *args: Any, **kwargs: Any) -> _ChumpyNode:
        obj = object.__new__(cls)
        obj.state = dict(kwargs)
        if args:  # a constructor-style reduce, e.g. Ch(x): keep the value as ``x``
            obj.state.setdefault("x", args[0])
        return obj

    def __setstate__(self, state: Any) -> None:
        if isinstance(state, dict):
            self.state = {**(self.state or {}), **state}
        else:
            self.state = {**(self.state or {}), "_state": state}


_CHUMPY_CLASSES: dict[str, type[_ChumpyNode]] = {}


def _chumpy_stand_in(module: str, name: str) -> type[_ChumpyNode]:
    qualified = f"{module}.{name}"
    if qualified not in _CHUMPY_CLASSES:
        _CHUMPY_CLASSES[qualified] = type(name, (_ChumpyNode,), {"chumpy_class": qualified})
    return _CHUMPY_CLASSES[qualified]


_SPARSE_CLASSES = {"csc_matrix", "csr_matrix", "coo_matrix", "csc_array", "csr_array", "coo_array"}


class _MANOUnpickler(RestrictedUnpickler):
    """Unpickler that admits only what a MANO model file needs (see the module docstring): the
    numpy and builtin globals of :class:`~dexcanvas_core.safe_pickle.RestrictedUnpickler`, chumpy
    stand-ins and scipy sparse matrices."""

    what = "a MANO model file"

    def find_class(self, module: str, name: str) -> Any:
        module = PY2_MODULES.get(module, module)
        if module == "chumpy" or module.startswith("chumpy."):
            return _chumpy_stand_in(module, name)
        if (module == "scipy.sparse" or module.startswith("scipy.sparse.")) and (
            name in _SPARSE_CLASSES
        ):
            import scipy.sparse  # the per-format modules (scipy.sparse.csc) are deprecated

            return getattr(scipy.sparse, name)
        return super().find_class(module, name)


def _evaluate(value: Any, key: str) -> Any:
    """Turn chumpy stand-ins into numpy arrays (only the node types MANO files use)."""
    if not isinstance(value, _ChumpyNode):
        return value
    kind = value.chumpy_class
    state = value.state or {}
    if kind == "chumpy.ch.Ch" and "x" in state:
        return np.asarray(_evaluate(state["x"], key))
    if kind == "chumpy.reordering.Select" and {"a", "idxs"} <= state.keys():
        source = np.asarray(_evaluate(state["a"], key))
        selected = source.ravel()[np.asarray(state["idxs"]).ravel()]
        shape = state.get("preferred_shape")
        return selected.reshape(shape) if shape is not None else selected
    raise DexCanvasError(
        f"MANO model key {key!r} holds a chumpy {kind} object, which this loader cannot evaluate "
        "(supported: chumpy.ch.Ch, chumpy.reordering.Select)"
    )


def read_model_pickle(path: str | Path) -> dict[str, Any]:
    """Read a MANO-format pickle into a dict of plain numpy / scipy values.

    Chumpy objects are evaluated for the keys :func:`load_mano_model` uses; other keys keep
    whatever the pickle holds (chumpy stand-ins included).

    Raises:
        DexCanvasError: the file is missing, not a pickle, holds an unexpected global (refused
            for safety), or is not a dict.
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            data = _MANOUnpickler(f, encoding="latin1").load()
    except FileNotFoundError as exc:
        raise DexCanvasError(f"MANO model file not found: {path}") from exc
    except (pickle.UnpicklingError, EOFError, AttributeError, ImportError, TypeError) as exc:
        raise DexCanvasError(f"cannot read MANO model file {path}: {exc}") from exc
    if not isinstance(data, dict):
        raise DexCanvasError(
            f"MANO model file {path} holds a {type(data).__name__}, expected a dict of arrays"
        )
    return data


@dataclass(frozen=True)
class ManoModelData:
    """The arrays of one MANO model (one side), as float64 / int64 numpy arrays.

    Shapes for the official files (V = 778 vertices, J = 16 joints, S = number of shape
    components, 10): ``v_template (V, 3)`` [m], ``shapedirs (V, 3, S)`` [m per unit β],
    ``posedirs (V, 3, 135)`` [m per unit of (R - I)], ``J_regressor (J, V)`` (dense),
    ``weights (V, J)``, ``parents (J,)`` (root ``-1``), ``faces (F, 3)``,
    ``hands_components (45, 45)``, ``hands_mean (45,)`` [rad]. All in the model's template frame.
    """

    path: Path
    v_template: np.ndarray
    shapedirs: np.ndarray
    posedirs: np.ndarray
    J_regressor: np.ndarray
    weights: np.ndarray
    parents: tuple[int, ...]
    faces: np.ndarray
    hands_components: np.ndarray
    hands_mean: np.ndarray

    @property
    def num_betas(self) -> int:
        return int(self.shapedirs.shape[-1])


def _array(data: dict[str, Any], key: str, path: Path, shape: tuple[int | None, ...]) -> np.ndarray:
    if key not in data:
        raise DexCanvasError(
            f"MANO model file {path} has no key {key!r} (keys: {', '.join(sorted(map(str, data)))})"
        )
    value = _evaluate(data[key], key)
    if hasattr(value, "toarray"):  # scipy sparse
        value = value.toarray()
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DexCanvasError(f"MANO model key {key!r} in {path} is not numeric: {exc}") from exc
    expected = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
    if array.ndim != len(shape) or any(
        s is not None and s != a for s, a in zip(shape, array.shape, strict=True)
    ):
        raise ValidationError(
            f"MANO model key {key!r} in {path} must have shape {expected}, got {array.shape}",
            field=key,
        )
    if not np.isfinite(array).all():
        raise ValidationError(f"MANO model key {key!r} in {path} has NaN or inf", field=key)
    return array


def _parents_from_kintree(kintree: np.ndarray, path: Path) -> tuple[int, ...]:
    """Parent index of each joint from ``kintree_table`` (row 0: parent ids, row 1: joint ids)."""
    ids = [int(i) for i in kintree[1]]
    column = {joint_id: col for col, joint_id in enumerate(ids)}
    parents = []
    for col, parent_id in enumerate(int(p) for p in kintree[0]):
        if col == 0:
            parents.append(-1)
        elif parent_id in column:
            parents.append(column[parent_id])
        else:
            raise ValidationError(
                f"kintree_table in {path}: joint {ids[col]} has unknown parent id {parent_id}",
                field="kintree_table",
            )
    return tuple(parents)


def load_mano_model(path: str | Path) -> ManoModelData:
    """Load and check one official MANO pickle (or a file with the same keys and shapes).

    Args:
        path: ``.../MANO_RIGHT.pkl`` or ``.../MANO_LEFT.pkl``.

    Raises:
        DexCanvasError: unreadable file or missing key.
        ValidationError: a key with a wrong shape or non-finite values, or a kinematic tree that
            is not MANO's (``keypoints.MANO_PARENTS``).
    """
    path = Path(path)
    data = read_model_pickle(path)
    V, J = MANO_NUM_VERTICES, MANO_NUM_JOINTS
    v_template = _array(data, "v_template", path, (V, 3))
    shapedirs = _array(data, "shapedirs", path, (V, 3, None))
    posedirs = _array(data, "posedirs", path, (V, 3, MANO_NUM_POSE_BASIS))
    J_regressor = _array(data, "J_regressor", path, (J, V))
    weights = _array(data, "weights", path, (V, J))
    kintree = _array(data, "kintree_table", path, (2, J)).astype(np.int64)
    faces = _array(data, "f", path, (None, 3)).astype(np.int64)
    hands_components = _array(data, "hands_components", path, (None, 45))
    hands_mean = _array(data, "hands_mean", path, (45,))

    parents = _parents_from_kintree(kintree, path)
    if parents != MANO_PARENTS:
        raise ValidationError(
            f"kintree_table in {path} gives parents {parents}, expected MANO's {MANO_PARENTS}",
            field="kintree_table",
        )
    if faces.size and (faces.min() < 0 or faces.max() >= V):
        raise ValidationError(f"faces in {path} index outside 0..{V - 1}", field="f")
    logger.debug("loaded MANO model %s (%d shape components)", path, shapedirs.shape[-1])
    return ManoModelData(
        path=path,
        v_template=v_template,
        shapedirs=shapedirs,
        posedirs=posedirs,
        J_regressor=J_regressor,
        weights=weights,
        parents=parents,
        faces=faces,
        hands_components=hands_components,
        hands_mean=hands_mean,
    )


def resolve_model_file(side: Side, model_dir: str | Path | None) -> Path | None:
    """Path of the official model file for ``side``, or ``None`` to use the built-in skeleton.

    ``model_dir=None`` reads ``$MANO_MODEL_DIR``; when that is unset, or set but without the
    file, the skeleton is used (logged). An explicit ``model_dir`` must hold the file.

    Raises:
        DexCanvasError: explicit ``model_dir`` that is not a folder or lacks the file.
    """
    name = MANO_MODEL_FILES[side]
    if model_dir is None:
        env = os.environ.get(MANO_MODEL_DIR_ENV)
        if not env:
            return None
        candidate = Path(env).expanduser() / name
        if candidate.is_file():
            return candidate
        logger.warning(
            "$%s=%s has no %s; using the built-in MANO-compatible skeleton for the %s hand",
            MANO_MODEL_DIR_ENV,
            env,
            name,
            side,
        )
        return None
    folder = Path(model_dir).expanduser()
    if not folder.is_dir():
        raise DexCanvasError(
            f"MANO model_dir {folder} is not a folder; it must hold the official {name} "
            f"(download it from https://mano.is.tue.mpg.de, it cannot ship with this toolkit)"
        )
    candidate = folder / name
    if not candidate.is_file():
        raise DexCanvasError(
            f"MANO model file not found: {candidate}; expected the official {name} for the {side} "
            f"hand in {folder} (download it from https://mano.is.tue.mpg.de)"
        )
    return candidate
