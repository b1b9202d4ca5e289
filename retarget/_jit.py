"""numba for the solver's inner loops: compiled at import to fixed signatures, cached on disk.

The retargeting iterate spends its time in many small array passes (collision rows, Jacobians,
Gauss–Newton sums) whose NumPy form is mostly per-call overhead; the modules ``_kernels`` do
each pass in one compiled loop. Every kernel is declared with its argument types, so it is
compiled (or loaded from the cache) when its module is imported, never inside a timed solve:
arrays it only reads are typed read-only (writable ones are accepted too), of any layout where
the solver passes views (a one-contact sweep's arrays are C-contiguous, a larger one's
strided) and C-contiguous where it owns them (a differently laid out array is a TypeError,
not a silent recompilation). ``cache=True`` keeps the machine code in
``__pycache__`` beside the source (or numba's user-wide cache where that is read-only): the
first import on a machine compiles for a few seconds, later ones load in a fraction of a
second. ``NUMBA_DISABLE_JIT=1`` runs the kernels as plain Python (for debugging).
"""

from __future__ import annotations

from numba import njit
from numba import types as nt


def _array(dtype, ndim: int, writable: bool = False, layout: str = "A"):
    return nt.Array(dtype, ndim, layout, readonly=not writable)


F1, F2, F3 = (_array(nt.float64, n) for n in (1, 2, 3))
"""Read-only float64 arrays of 1, 2 and 3 dimensions, any layout (views the solver slices)."""
F2W = _array(nt.float64, 2, writable=True)
"""A writable float64 array filled in place."""
F2C, F3C = (_array(nt.float64, n, layout="C") for n in (2, 3))
"""Read-only C-contiguous float64 arrays: the solver's own Jacobians and masks, whose inner
loops run twice as fast with the layout known (a keypoint term's sum: 8.2 → 4.4 µs)."""
F1CW, F2CW, F3CW = (_array(nt.float64, n, writable=True, layout="C") for n in (1, 2, 3))
"""Writable C-contiguous float64 arrays (the QP's ``P`` and ``c``, Jacobian buffers)."""
I1 = _array(nt.int64, 1)
I2_32 = _array(nt.int32, 2)
B1 = _array(nt.boolean, 1)
B2 = _array(nt.boolean, 2)
INT, FLOAT, BOOL = nt.int64, nt.float64, nt.boolean


def kernel(*argtypes):
    """``@kernel(F2, I1, ...)``: an eagerly compiled, disk-cached numba function with these
    argument types (the return type is inferred)."""
    return njit(tuple(argtypes), cache=True)
