"""MuJoCo's warnings as data: how often each type fired in a simulation, and from which frame.

MuJoCo counts warnings per ``MjData`` (``d.warning[i].number``, ``i`` a ``mujoco.mjtWarning``)
and prints only the first of each type. :class:`WarningCounter` reads those counters after every
data frame of a simulation and keeps, per type, the total count and the first frame it appeared
in. ``BADQPOS``, ``BADQVEL`` and ``BADQACC`` mean the solver blew up (NaN, inf or huge values
in the state or its acceleration): MuJoCo then resets the data to the model's initial state and
carries on, so the rest of the simulation is meaningless and the run is a failure.

This only reads the counters; where MuJoCo's log text goes is set elsewhere.
"""

from __future__ import annotations

import mujoco
import numpy as np

BLOW_UP = ("BADQPOS", "BADQVEL", "BADQACC")
"""Warning types that mean the solver blew up (the run fails)."""

_NAMES = tuple(
    name.removeprefix("mjWARN_")
    for name, value in sorted(mujoco.mjtWarning.__members__.items(), key=lambda kv: int(kv[1]))
    if name != "mjNWARNING"
)


class WarningCounter:
    """Counts one ``MjData``'s MuJoCo warnings per frame of a simulation.

    Call :meth:`update` after each frame's physics steps with the frame index. Simulation time
    or a counter going down means the data was reset (``mj_resetData``, or MuJoCo's own reset
    after a blow-up, which leaves only the blow-up's count, 1): the counters then count anew.
    """

    def __init__(self) -> None:
        self._seen = np.zeros(len(_NAMES), dtype=np.int64)
        self._time = -np.inf
        self.counts: dict[str, int] = {}
        self.first_frame: dict[str, int] = {}

    def update(self, d: mujoco.MjData, frame: int) -> None:
        """Add the warnings ``d`` counted since the previous call, as of ``frame``."""
        reset = d.time < self._time  # the data was reset since: its counters restarted
        self._time = float(d.time)
        for i, name in enumerate(_NAMES):
            n = int(d.warning[i].number)
            new = n if reset or n < self._seen[i] else n - self._seen[i]
            self._seen[i] = n
            if new > 0:
                self.counts[name] = self.counts.get(name, 0) + int(new)
                self.first_frame.setdefault(name, int(frame))

    def resumed(self, d: mujoco.MjData) -> WarningCounter:
        """A copy of this counter that continues from ``d``'s current counters (for a
        simulation restored to an earlier state: the warnings since then are not counted)."""
        out = WarningCounter()
        out.counts, out.first_frame = dict(self.counts), dict(self.first_frame)
        out._seen = np.array([int(d.warning[i].number) for i in range(len(_NAMES))])
        out._time = float(d.time)
        return out

    def to_dict(self) -> dict[str, dict[str, int]]:
        """``{type: {"count": n, "first_frame": f}}`` in MuJoCo's type order; ``{}``: none."""
        return {
            name: {"count": self.counts[name], "first_frame": self.first_frame[name]}
            for name in _NAMES
            if name in self.counts
        }

    @property
    def blew_up(self) -> bool:
        """Whether a blow-up warning (:data:`BLOW_UP`) fired."""
        return any(name in self.counts for name in BLOW_UP)


def blew_up(warnings: dict) -> bool:
    """Whether a ``mujoco_warnings`` record (:meth:`WarningCounter.to_dict`) holds a blow-up."""
    return any(name in warnings for name in BLOW_UP)


def describe(warnings: dict) -> str:
    """One line for a summary: ``BADQACC ×3 (from frame 57), CONTACTFULL ×1 (from frame 2)``."""
    return ", ".join(
        f"{name} ×{w['count']} (from frame {w['first_frame']})" for name, w in warnings.items()
    )
