"""Robot joint configurations for tests: the model's joint couplings applied by hand."""

from __future__ import annotations

import mujoco
import numpy as np


def coupled(m: mujoco.MjModel, q: np.ndarray) -> np.ndarray:
    """``q`` with every joint-coupling equality of ``m`` (``mjEQ_JOINT``, polynomial in the
    driving joint) made exact: the driven joints take the value their driver gives them."""
    q = q.copy()
    for e in range(m.neq):
        if m.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT and m.eq_obj2id[e] >= 0:
            c = m.eq_data[e]
            x = q[m.jnt_qposadr[m.eq_obj2id[e]]]
            q[m.jnt_qposadr[m.eq_obj1id[e]]] = c[0] + c[1] * x + c[2] * x**2 + c[3] * x**3
    return q
