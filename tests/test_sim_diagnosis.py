"""The force pipeline's failure diagnosis tells wrist lag, slip, lost contact and knocks apart."""

import numpy as np
import pytest

from dexcanvas_core.sim.diagnosis import failure_diagnosis

FPS = 120.0
T = 120


def _case(kind: str):
    t = np.arange(T) / FPS
    ref_wrist = np.stack([t * 2.0, 0 * t, 0.2 + 0 * t], axis=1)  # carried at 2 m/s
    ref_obj = ref_wrist + np.array([0.0, 0.0, -0.1])
    wrist = ref_wrist.copy()
    obj = ref_obj.copy()
    touching = np.ones(T, bool)
    R = np.repeat(np.eye(3)[None], T, axis=0)
    if kind == "wrist lag":  # hand 6 cm behind, object firmly in it
        wrist[:, 0] -= 0.06 * t / t[-1]
        obj[:, 0] -= 0.06 * t / t[-1]
    elif kind == "slip":  # hand on track, object sliding out of it while touched
        obj[:, 0] -= 0.06 * t / t[-1]
    elif kind == "lost contact":
        obj[:, 2] -= 0.3 * np.clip(t - 0.5, 0, None) ** 2 * 9.81
        touching[50:] = False
    elif kind == "knocked":  # the reference object stays on the table
        ref_obj[:] = ref_obj[0]
        obj[:, 0] += 0.06 * t / t[-1]
    return failure_diagnosis(T - 1, FPS, wrist, ref_wrist, R, obj, ref_obj, touching)


@pytest.mark.parametrize("kind", ["wrist lag", "slip", "lost contact", "knocked"])
def test_failure_reasons(kind):
    d = _case(kind)
    assert d["reason"] == kind, d
    assert d["frame"] == T - 1 and d["time_s"] == pytest.approx((T - 1) / FPS, abs=1e-3)


def test_no_failure_no_diagnosis():
    z = np.zeros((T, 3))
    assert failure_diagnosis(None, FPS, z, z, np.eye(3)[None], z, z, np.ones(T, bool)) is None
