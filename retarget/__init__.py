"""retarget: the robot side of dexcanvas-retarget.

QP retargeting of human demonstrations onto robot hands, re-simulation validation, force
matching and calibration, physics refinement, metrics and visualisation. Builds on
``dexcanvas_core`` (data flows one way: this package imports it, never the reverse).

The names a user needs are importable from here (loaded on first use, so ``import retarget``
stays cheap):

>>> import retarget
>>> hand = retarget.get_hand("allegro")
>>> hand.name, hand.mapped_human_fingers
('allegro', ('thumb', 'index', 'middle', 'ring'))

One demonstration end to end, in memory (``retarget run`` adds the files and the summary):

>>> from dexcanvas_core import load_demonstration
>>> human = load_demonstration("cube2/tripod").slice(0, 30)  # the first quarter second
>>> result = retarget.retarget_demonstration(human, "cube2/tripod", "shadow")
>>> result.robot.q_command.shape[0], result.sim.success
(30, True)

The same with the run's metrics (what ``retarget run`` writes to ``metrics.json``):

>>> out = retarget.retarget(human, "allegro")
>>> out.robot.q_command.shape, out.sim.success, out.metrics["keypoint_err_mean_m"] < 0.05
((30, 22), True, True)
"""

from __future__ import annotations

import importlib

from retarget.errors import RetargetError

__version__ = "0.1.0"

_EXPORTS = {
    # hands
    "get_hand": "retarget.hands",
    "available_hands": "retarget.hands",
    "register": "retarget.hands",
    "HandModel": "retarget.hands",
    # retargeting
    "Retargeter": "retarget.retargeter",
    "RetargetConfig": "retarget.config",
    "RobotTrajectory": "retarget.robot_trajectory",
    "retarget_keypoints": "retarget.keypoint_input",
    # re-simulation, force calibration, refinement
    "Resimulator": "retarget.validate",
    "ValidateConfig": "retarget.validate",
    "ForceCalibrationConfig": "retarget.force_calibration",
    "calibrate_forces": "retarget.force_calibration",
    "RefineConfig": "retarget.refine",
    "refine_lost": "retarget.pipeline",
    # the pipeline and its outputs
    "RunConfig": "retarget.pipeline",
    "PipelineResult": "retarget.pipeline",
    "retarget_demonstration": "retarget.pipeline",
    "run_pipeline": "retarget.pipeline",
    "retarget": "retarget.api",
    "Retargeted": "retarget.api",
    "run_batch": "retarget.batch",
    "BatchConfig": "retarget.batch",
    "read_robot_rows": "retarget.robot_dataset",
    "run_retarget": "retarget.run",
    "run_metrics": "retarget.metrics",
    "force_metrics": "retarget.metrics",
    "write_run": "retarget.outputs",
    # batched FK for learning
    "TorchHandFK": "retarget.torch_fk",
}

__all__ = ["RetargetError", *_EXPORTS]


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'retarget' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
