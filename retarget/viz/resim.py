"""Replaying a run's re-simulation and recording what ``retarget run`` does not store.

:func:`record_resimulation` re-simulates the run's commands (deterministic: the same object
trajectory as the run) and records the simulated hand joints and every robot contact point with
its force and hand part.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from dexcanvas_core.sim.forces import object_contacts
from dexcanvas_core.table import table_of
from dexcanvas_core.trajectory import Trajectory
from retarget.validate import FORCE_CONTACT_TIMECONST, Resimulator, ValidateConfig
from retarget.viz.contacts import ContactFrames, robot_body_parts


class _RecordingResimulator(Resimulator):
    """The run's :class:`~retarget.validate.Resimulator`, keeping the data of its last step."""

    last_data: mujoco.MjData | None = None

    def _contact_forces(self, d):  # after every physics step: keep the data to read later
        self.last_data = d
        return super()._contact_forces(d)


@dataclass
class RobotSimRecord:
    """What :func:`record_resimulation` recorded, per data frame."""

    result: object
    """The ``retarget.validation_result.ValidationResult`` (the run's metrics come from the
    same)."""
    qpos: np.ndarray
    """(T, hand_nq) simulated hand joint positions at the end of each frame."""
    contacts: ContactFrames
    """Robot contact points at the last physics step of each frame."""


def record_resimulation(
    hand,
    geometry,
    q_command: np.ndarray,
    human: Trajectory,
    progress: Callable[[int, int], None] | None = None,
    metrics: dict | None = None,
) -> RobotSimRecord:
    """Re-simulate ``q_command`` like ``retarget run`` does and record the robot's state.

    ``metrics``: the run's ``metrics.json``; a force-matching run (``"forces": true``) was
    re-simulated with stiff contacts, and is replayed the same way.

    The simulation is the one of ``retarget.validate.Resimulator`` (same model, same settings,
    deterministic); after each data frame the simulated hand joints and every hand–object
    contact (point, force of the hand on the object, hand part) are read from its state.
    """
    stiff = bool(metrics and metrics.get("forces"))
    sim = _RecordingResimulator(
        hand,
        geometry,
        ValidateConfig(contact_timeconst=FORCE_CONTACT_TIMECONST if stiff else None),
        table=table_of(human),
    )
    m = sim.model
    group_of_body, part_of_body = robot_body_parts(hand, m)
    T = human.num_frames
    qpos = np.zeros((T, sim.hand_nq))
    records: list[list] = [[] for _ in range(T)]

    def on_frame(done: int, total: int) -> None:  # called once each frame's steps are done
        t = done - 1
        d = sim.last_data
        qpos[t] = d.qpos[: sim.hand_nq]
        for c in object_contacts(m, d, sim.object_body):
            if group_of_body[c.other_body] < 0:
                continue  # the table
            records[t].append(
                (c.pos, c.force, int(group_of_body[c.other_body]), int(part_of_body[c.other_body]))
            )
        if progress is not None:
            progress(done, total)

    result = sim.run(q_command, human, progress=on_frame)
    return RobotSimRecord(
        result=result,
        qpos=qpos,
        contacts=ContactFrames.from_records(records, source="re-simulation"),
    )
