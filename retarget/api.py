"""The in-memory API: one demonstration onto one robot hand, the results and the metrics,
without files (``retarget run`` adds the files and the summary; ``retarget batch`` runs it in
workers and collects the rows).

>>> import retarget
>>> from dexcanvas_core import load_demonstration
>>> human = load_demonstration("cube2/tripod").slice(0, 30)  # the first quarter second
>>> out = retarget.retarget(human, "allegro")
>>> out.robot.q_command.shape, out.sim.success, out.metrics["hand"]
((30, 22), True, 'allegro')
"""

from __future__ import annotations

from dataclasses import dataclass

from dexcanvas_core.loaders.selection import subject_of
from dexcanvas_core.trajectory import Trajectory
from retarget.errors import RetargetError
from retarget.hands import HandModel, get_hand
from retarget.metrics import run_metrics
from retarget.pipeline import (
    PipelineResult,
    RunConfig,
    check_pair,
    check_run,
    refine_config,
    retarget_config,
    retarget_demonstration,
)
from retarget.progress import Progress
from retarget.robot_trajectory import RobotTrajectory
from retarget.time_scale import time_scaled
from retarget.validation_result import ValidationResult

RUN_SETTINGS = ("backend", "force_scale", "calibrate_iterations", "refine_retries", "time_scale")
"""``retarget(**settings)`` names that are the run's options (``RunConfig`` fields); every other
name is a ``RetargetConfig`` field (``--set NAME=VALUE``)."""


@dataclass
class Retargeted:
    """A demonstration retargeted onto a hand: the pipeline's results and the run's metrics
    (what :func:`retarget` returns).

    >>> from dexcanvas_core import load_demonstration
    >>> out = retarget(load_demonstration("cube2/tripod").slice(0, 20), "panda")
    >>> out.sim.q_sim.shape, out.metrics["frames"], out.config.hand
    ((20, 8), 20, 'panda')
    """

    result: PipelineResult
    """Everything the pipeline computed (:class:`~retarget.pipeline.PipelineResult`)."""
    metrics: dict
    """What ``retarget run`` writes to ``metrics.json`` (:func:`retarget.metrics.run_metrics`)."""
    config: RunConfig
    """The run's options as a ``RunConfig`` (no pair or output: nothing is loaded or written)."""

    @property
    def robot(self) -> RobotTrajectory:
        """The robot trajectory (``q``, ``q_command``, fingertips, per-frame errors)."""
        return self.result.robot

    @property
    def sim(self) -> ValidationResult:
        """The re-simulation of ``robot.q_command`` (``q_sim``, object track, forces)."""
        return self.result.sim

    @property
    def success(self) -> bool:
        """Whether the re-simulated robot kept the object on its track."""
        return bool(self.result.sim.success)


def run_config(
    hand: str, forces: bool = False, refine: bool = False, dataset=None, **settings
) -> RunConfig:
    """The ``RunConfig`` of :func:`retarget`'s arguments (``settings``: :data:`RUN_SETTINGS`
    and ``RetargetConfig`` overrides); raises ``RetargetError`` for a bad value."""
    run = {k: settings.pop(k) for k in RUN_SETTINGS if k in settings}
    cfg = RunConfig(
        hand=hand,
        dataset=dataset,
        forces=forces,
        refine=refine,
        overrides=settings,
        progress=False,
        **run,
    )
    check_run(cfg)
    retarget_config(cfg)  # unknown or refused --set fields before any work
    return cfg


def retarget_with(
    trajectory: Trajectory,
    cfg: RunConfig,
    subject=None,
    hand=None,
    progress: Progress | None = None,
) -> Retargeted:
    """:func:`retarget` with its options as a ``RunConfig`` (``cfg.pair``, ``cfg.index`` and
    ``cfg.out`` are not used); ``subject``: what the trajectory shows (default its own
    ``scene``/``gesture``); ``hand``: ``cfg.hand``'s model when already looked up."""
    if not isinstance(trajectory, Trajectory):
        raise RetargetError(
            f"trajectory must be a dexcanvas_core Trajectory, got {type(trajectory).__name__} "
            "(load one with dexcanvas_core.load_demonstration)"
        )
    hand = get_hand(cfg.hand) if hand is None else hand
    subject = subject_of(trajectory) if subject is None else subject
    check_pair(hand, subject.manipulation_type)
    traj = time_scaled(trajectory, cfg.time_scale)
    refine_cfg = refine_config(cfg.forces, retries=cfg.refine_retries) if cfg.refine else None
    result = retarget_demonstration(
        traj,
        subject,
        hand,
        retarget_config(cfg),
        calibrate_iterations=cfg.calibrate_iterations,
        refine=refine_cfg,
        progress=progress,
    )
    return Retargeted(result, run_metrics(result, cfg), cfg)


def retarget(
    trajectory: Trajectory,
    hand: str | HandModel,
    forces: bool = False,
    refine: bool = False,
    **settings,
) -> Retargeted:
    """Retarget ``trajectory`` onto ``hand``, re-simulate it and score it, in memory: what
    ``retarget run`` computes, without files or terminal output.

    Args:
        trajectory: a human demonstration (``dexcanvas_core.load_demonstration``, a dataset
            row, or a slice of one); what it shows is read from its ``scene`` and ``gesture``.
        hand: a registered hand name (``retarget hands``) or a ``HandModel``.
        forces: force matching (``retarget run --forces``): the robot presses like the human
            did; a demonstration without contact forces is first run through the force
            pipeline.
        refine: when the re-simulation loses the object, run the physics refinement.
        settings: the run's options :data:`RUN_SETTINGS` (``backend``, ``force_scale``,
            ``calibrate_iterations`` (default 10), ``refine_retries`` (default 4),
            ``time_scale``), and any ``RetargetConfig`` field, e.g. ``w_contacts=100.0``.

    Returns:
        A :class:`Retargeted`: ``.robot``, ``.sim``, ``.metrics``, ``.result``.

    Raises:
        RetargetError: an unknown hand or setting, a pair the hand cannot perform, human forces
            the force pipeline could not produce.

    >>> from dexcanvas_core import load_demonstration
    >>> human = load_demonstration("cube2/tripod").slice(0, 30)
    >>> out = retarget(human, "panda", w_contacts=150.0)
    >>> out.robot.q_command.shape, out.success, out.metrics["retarget_overrides"]
    ((30, 8), True, {'w_contacts': 150.0})
    """
    model = hand if isinstance(hand, HandModel) else get_hand(hand)
    cfg = run_config(model.name, forces, refine, **settings)
    return retarget_with(trajectory, cfg, hand=model)
