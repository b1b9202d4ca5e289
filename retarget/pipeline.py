"""The retargeting pipeline: one demonstration onto one robot hand, with its results in memory.

load → (human forces: the force pipeline, when force matching needs them) → QP retargeting →
re-simulation → (force calibration) → (physics refinement, when the re-simulation lost the
object) → :class:`PipelineResult`. ``retarget run`` is this plus the run metrics
(:mod:`retarget.metrics`), the files (:mod:`retarget.outputs`) and the terminal summary
(:mod:`retarget.summary`); the benchmarks and ``retarget snapshot`` call the same functions.

:func:`run_pipeline` starts from a :class:`RunConfig` (what to load, which hand, which steps);
:func:`retarget_demonstration` from a demonstration already in memory.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from dexcanvas_core.checks import (
    check_bool,
    check_float,
    check_int,
    check_path,
    check_str,
    check_type,
)
from dexcanvas_core.objects.geometry import ObjectGeometry, object_geometry
from dexcanvas_core.table import table_of
from dexcanvas_core.trajectory import Trajectory
from retarget.config import RetargetConfig
from retarget.errors import RetargetError
from retarget.force_calibration import (
    ForceCalibrationConfig,
    ForceCalibrationResult,
    calibrate_forces,
)
from retarget.hands import HandModel, get_hand
from retarget.human_forces import (
    HUMAN_REPLAY_SEED,
    HumanReplay,
    human_forces,
    simulate_human,
)
from retarget.loading import load_subject, parse_pair
from retarget.overrides import build_config
from retarget.progress import Progress
from retarget.refine import RefineConfig, RefineResult, calibrate_refined, refine
from retarget.retargeter import Retargeter
from retarget.robot_trajectory import RobotTrajectory
from retarget.time_scale import check_time_scale, time_scaled
from retarget.validate import (
    FORCE_CONTACT_TIMECONST,
    Resimulator,
    ValidateConfig,
    ValidationResult,
)


@dataclass(frozen=True)
class RunConfig:
    """One retargeting run: what to load, onto which hand, which steps, where to write.

    >>> over = {"w_contacts": 150}
    >>> cfg = RunConfig(hand="shadow", pair="cube2/tripod", forces=True, overrides=over)
    >>> cfg.output_dir()
    PosixPath('runs/shadow_cube2_tripod_0')
    >>> retarget_config(cfg).contacts.weight, retarget_config(cfg).force_matching.enabled
    (150, True)
    """

    hand: str
    """Registered hand name (``retarget hands``)."""
    pair: str | None = None
    """``object/manipulation_type``, e.g. ``cube2/tripod``; ``None`` with a ``dataset``: its row
    ``index`` whatever it shows (the row names its object and type)."""
    dataset: Path | None = None
    """DexCanvas-layout Lance dataset; ``None``: the built-in demonstrations."""
    index: int = 0
    """Which of the dataset's demonstrations of this pair (0-based); without a pair, which row."""
    out: Path | None = None
    """Output directory; default ``runs/<hand>_<object>_<type>_<index>``."""
    overwrite: bool = False
    """Replace the run in ``out`` (its ``metrics.json``, ``robot_trajectory.npz``); without it
    a directory holding either is refused before any work."""
    backend: Literal["pinocchio", "mink"] = "pinocchio"
    forces: bool = False
    """Force matching: the robot presses like the human did (``retarget.force_matching``). A
    demonstration without contact forces is first run through the force pipeline
    (``dexcanvas_core.sim``, sampling MPC)."""
    refine: bool = False
    """When the re-simulation fails, run the physics refinement (``retarget.refine``: the
    force pipeline's sampling MPC on the robot hand) and report it next to the open-loop
    result."""
    refine_retries: int = 4
    """How often the refinement backtracks when it loses the object (``RefineConfig.retries``)."""
    calibrate_iterations: int = 10
    """``forces``: corrected re-simulations of the force calibration
    (``retarget.force_calibration``: the servo commands corrected in re-simulation until the
    fingers press like the human's; the written commands and the reported result are the
    chosen iterate's, ``calibration`` in ``metrics.json`` says what it changed). 0: the
    force-matched commands as planned."""
    force_scale: float = 1.0
    """Force matching presses with this multiple of the human's forces
    (``RetargetConfig.force_matching.scale``: a grip margin); needs ``forces``."""
    human_replay: bool = False
    """Also run the force pipeline again at another seed of its sampling MPC
    (``HUMAN_REPLAY_SEED``) and score its per-finger forces against the matched ones as the
    robot's are (:func:`human_replay_metrics`): how well the human's own forces reproduce, the
    ceiling of the robot's force correlation; needs ``forces``."""
    overrides: dict = field(default_factory=dict)
    """``RetargetConfig`` fields changed from their defaults (``--set NAME=VALUE``), e.g.
    ``{"w_contacts": 100.0}``; the run's own options (``backend``, ``forces``, ``force_scale``)
    are set by their fields, not here."""
    time_scale: float = 1.0
    """Execute the demonstration this many times slower (1 to ``MAX_TIME_SCALE``): its
    timestamps are stretched about the first before anything else (force pipeline,
    retargeting, re-simulation) sees it; frames, poses and contact records are unchanged, the
    frame rate is divided by it. For arms that cannot follow a human's wrist at full speed;
    recorded in ``metrics.json`` (``time_scale``) and shown in the summary when not 1."""
    progress: bool = True
    """Show progress bars and the summary on the terminal."""

    def __post_init__(self) -> None:
        err = RetargetError
        check_str("hand", self.hand, error=err)
        check_str("pair", self.pair, optional=True, error=err)
        check_path("dataset", self.dataset, optional=True, error=err)
        check_int("index", self.index, min=0, error=err)
        check_path("out", self.out, optional=True, error=err)
        check_str("backend", self.backend, choices=("pinocchio", "mink"), error=err)
        for name in ("forces", "refine", "human_replay", "progress"):
            check_bool(name, getattr(self, name), error=err)
        check_int("refine_retries", self.refine_retries, min=0, error=err)
        check_int("calibrate_iterations", self.calibrate_iterations, min=0, error=err)
        check_float("force_scale", self.force_scale, positive=True, error=err)
        if not isinstance(self.overrides, dict):
            raise RetargetError(
                f"overrides must be a dict of RetargetConfig fields, got {self.overrides!r} "
                f"({type(self.overrides).__name__})"
            )
        object.__setattr__(self, "time_scale", check_time_scale(self.time_scale))

    def output_dir(self) -> Path:
        if self.out is not None:
            return Path(self.out)
        if self.pair is None:
            stem = Path(self.dataset).name.removesuffix(".lance") if self.dataset else "builtin"
            return Path("runs") / f"{self.hand}_{stem}_{self.index}"
        obj, typ = self.pair.split("/", 1)
        return Path("runs") / f"{self.hand}_{obj}_{typ}_{self.index}"


def check_pair(hand, manipulation_type) -> None:
    """Raise if the hand cannot perform this manipulation type at all.

    In-hand manipulation (rolling, sliding, finger transfer, rotation) needs independently driven
    fingers: a parallel gripper (one actuated DoF) cannot do it. Four-finger hands drop the pinky
    (it is not needed by any type's object motion); the gripper merges index and middle.
    """
    model = hand.compile()
    finger_actuators = model.nu - 6
    if manipulation_type is None:  # an imported row of unknown type: nothing to rule out
        return
    if manipulation_type.group == "in_hand" and finger_actuators < 3:
        raise RetargetError(
            f"hand {hand.name!r} cannot perform {manipulation_type.name!r}: in-hand manipulation "
            f"needs independently driven fingers and {hand.name} has {finger_actuators} finger "
            "actuator(s); pick a dexterous hand (retarget hands)"
        )


@dataclass
class PipelineResult:
    """What the pipeline computed for one demonstration and one hand, in memory.

    >>> from dexcanvas_core import load_demonstration
    >>> human = load_demonstration("cube2/tripod").slice(0, 30)
    >>> result = retarget_demonstration(human, "cube2/tripod", "allegro")
    >>> result.hand.name, result.success, result.calibration is None, result.refined is None
    ('allegro', True, True, True)
    """

    trajectory: Trajectory
    """The human demonstration as retargeted: time-scaled, and force-annotated when force
    matching ran the force pipeline."""
    subject: Any
    """What it shows: a ``Pair``, or a dataset row's ``RowSubject``."""
    geometry: ObjectGeometry
    retargeter: Retargeter
    robot: RobotTrajectory
    """The retargeted trajectory; after force calibration its ``q_command`` is the calibrated
    commands (``planned_commands`` the plan's)."""
    sim: ValidationResult
    """The re-simulation of ``robot.q_command``."""
    resimulator: Resimulator
    """The re-simulation's scene (run other commands in it: ``resimulator.run(q, trajectory)``)."""
    setup_s: float
    """Seconds spent before retargeting (human forces, retargeter construction)."""
    human_sim: dict | None = None
    """The force pipeline's metrics when this run simulated the human's forces."""
    replay: HumanReplay | None = None
    calibration: ForceCalibrationResult | None = None
    planned_commands: np.ndarray | None = None
    """The force-matched commands before force calibration (``None`` without it)."""
    planned_sim: ValidationResult | None = None
    """Their re-simulation (``None`` without force calibration)."""
    refined: RefineResult | None = None
    """The physics refinement, when it ran (the re-simulation lost the object)."""
    substituted: str | None = None
    """The pair whose demonstration stands in (a heavy object's light twin); ``None``: its own."""

    @property
    def hand(self):
        return self.retargeter.hand

    @property
    def success(self) -> bool:
        """The re-simulation kept the object (strict rule), or the refinement did."""
        return bool(self.sim.success or (self.refined is not None and self.refined.success))


def refine_config(forces: bool, **settings) -> RefineConfig:
    """The refinement's configuration in a run: force-matching runs refine through the force
    pipeline's contacts (``FORCE_CONTACT_TIMECONST``); ``settings`` override ``RefineConfig``
    fields."""
    return RefineConfig(
        **{"contact_timeconst": FORCE_CONTACT_TIMECONST if forces else None, **settings}
    )


def retarget_demonstration(
    traj: Trajectory,
    subject,
    hand,
    config: RetargetConfig | None = None,
    *,
    calibrate_iterations: int = 10,
    refine: RefineConfig | None = None,
    human_replay: bool = False,
    progress: Progress | None = None,
) -> PipelineResult:
    """Retarget ``traj`` (showing ``subject``: a ``Pair``, a ``RowSubject`` or
    ``"OBJECT/TYPE"``) onto ``hand`` (a hand model or its name, ``retarget hands``) and
    re-simulate it.

    With ``config.force_matching``: the human's forces first (the force pipeline, when ``traj``
    has none), re-simulation through the force pipeline's contacts, then
    ``calibrate_iterations`` force-calibration re-simulations (0: the plan as it is).
    ``refine``: when the re-simulation loses the object, the physics refinement with this
    configuration (:func:`refine_config`), force-calibrated too when force matching;
    ``None``: no refinement. ``human_replay`` (force matching): the force pipeline again at
    ``HUMAN_REPLAY_SEED``. ``progress``: a :class:`Progress` showing each step's bar.

    >>> from dexcanvas_core import load_demonstration
    >>> human = load_demonstration("cube2/tripod").slice(230, 330)   # the grasp and the lift
    >>> forces = RetargetConfig.from_overrides({"force_matching": True})
    >>> result = retarget_demonstration(human, "cube2/tripod", "shadow", forces,
    ...                                 calibrate_iterations=1)
    >>> result.human_sim["success"], len(result.calibration.iterates)
    (True, 2)
    """
    check_type(
        "traj",
        traj,
        Trajectory,
        hint="; load one with load_demonstration(PAIR)",
        error=RetargetError,
    )
    check_type("hand", hand, (str, HandModel), error=RetargetError)
    check_type("config", config, RetargetConfig, optional=True, error=RetargetError)
    check_int("calibrate_iterations", calibrate_iterations, min=0, error=RetargetError)
    check_type("refine", refine, RefineConfig, optional=True, error=RetargetError)
    check_bool("human_replay", human_replay, error=RetargetError)
    config = RetargetConfig() if config is None else config
    subject = parse_pair(subject) if isinstance(subject, str) else subject
    hand = get_hand(hand) if isinstance(hand, str) else hand
    forces = config.force_matching.enabled
    if human_replay and not forces:
        raise RetargetError("a human replay scores force matching: set force_matching")
    geometry = object_geometry(subject.object.id)
    t0 = time.perf_counter()
    human_sim = None
    if forces and (traj.contacts is None or traj.object_wrench_world is None):
        traj, human_sim = human_forces(traj, subject.object.id, progress)
    table = table_of(traj)
    retargeter = Retargeter(hand, geometry, config, table=table)
    setup_s = time.perf_counter() - t0
    replay = None
    if human_replay:
        res, m = simulate_human(
            traj, subject.object.id, progress,
            f"human replay (force pipeline, seed {HUMAN_REPLAY_SEED})", HUMAN_REPLAY_SEED,
        )  # fmt: skip
        replay = HumanReplay(res.trajectory if res.success else None, m)
    robot = retargeter.retarget(traj, progress=_task(progress, "retargeting", traj.num_frames))
    vcfg = ValidateConfig(contact_timeconst=FORCE_CONTACT_TIMECONST if forces else None)
    resim = Resimulator(hand, geometry, vcfg, table=table)
    sim = resim.run(
        robot.q_command, traj, progress=_task(progress, "re-simulating", traj.num_frames)
    )
    calibrated = planned = planned_sim = None
    if forces and calibrate_iterations > 0:
        n = calibrate_iterations
        calibrated = calibrate_forces(
            retargeter, resim, robot, traj, sim, ForceCalibrationConfig(iterations=n),
            progress=_task(progress, f"calibrating forces ({n} re-simulations)", n + 1),
        )  # fmt: skip
        planned_sim, planned = sim, robot.q_command
        sim, robot.q_command = calibrated.sim, calibrated.commands
    robot.meta["simulation"] = sim.meta
    result = PipelineResult(
        trajectory=traj, subject=subject, geometry=geometry, retargeter=retargeter, robot=robot,
        sim=sim, resimulator=resim, setup_s=setup_s, human_sim=human_sim, replay=replay,
        calibration=calibrated, planned_commands=planned, planned_sim=planned_sim,
    )  # fmt: skip
    if refine is not None and not sim.success:
        result.refined = refine_lost(result, refine, calibrate_iterations, progress)
    return result


def refine_lost(
    result: PipelineResult,
    config: RefineConfig,
    calibrate_iterations: int = 10,
    progress: Progress | None = None,
) -> RefineResult:
    """The physics refinement (:func:`retarget.refine.refine`) of a run whose re-simulation
    lost the object, with ``config`` (:func:`refine_config`); force-calibrated
    (``calibrate_iterations`` replays, 0: none) when the run force-matches and the refinement
    kept the object.

    >>> from dexcanvas_core import load_demonstration
    >>> human = load_demonstration("cube2/tripod").slice(0, 20)
    >>> result = retarget_demonstration(human, "cube2/tripod", "shadow")
    >>> replayed = refine_lost(result, refine_config(False, tracker="open_loop"))
    >>> replayed.success, replayed.ctrl.shape[0]
    (True, 20)
    """
    check_type("result", result, PipelineResult, error=RetargetError)
    check_type(
        "config",
        config,
        RefineConfig,
        hint="; make one with refine_config(...)",
        error=RetargetError,
    )
    check_int("calibrate_iterations", calibrate_iterations, min=0, error=RetargetError)
    hand, rt, traj, robot = result.hand, result.retargeter, result.trajectory, result.robot
    task = _task(progress, "refining (MPC on the robot)", 1)
    refined = refine(hand, result.geometry, traj, robot, rt.tip_sites, config)
    if task is not None:
        task(1, 1)
    if refined.success and rt.cfg.force_matching.enabled and calibrate_iterations > 0:
        n = calibrate_iterations
        task = _task(progress, f"calibrating the refined forces ({n} replays)", 1)
        refined = calibrate_refined(
            hand, result.geometry, traj, robot, rt.tip_sites, refined, config,
            ForceCalibrationConfig(iterations=n), rt.cfg.force_matching.scale,
        )  # fmt: skip
        if task is not None:
            task(1, 1)
    return refined


def _task(progress: Progress | None, name: str, total: int):
    return None if progress is None else progress.task(name, total)


# RetargetConfig fields a run sets through its own options, not ``--set``
RUN_OPTIONS = {
    "backend": "--backend",
    "force_matching": "--forces",
    "force_scale": "--force-scale",
}


def retarget_config(cfg: RunConfig) -> RetargetConfig:
    """The run's ``RetargetConfig``: the defaults, ``cfg.overrides``, then the run's own
    options; an unknown field, one of the run's options or a value the config refuses is a
    ``RetargetError`` naming it."""
    return build_config(
        RetargetConfig, cfg.overrides, "--set", RUN_OPTIONS,
        backend=cfg.backend, force_matching=cfg.forces, force_scale=cfg.force_scale,
    )  # fmt: skip


def check_run(cfg: RunConfig) -> None:
    """Refuse option combinations that make no sense, before any work."""
    check_type(
        "cfg",
        cfg,
        RunConfig,
        hint="; make one with RunConfig(hand=..., pair=...)",
        error=RetargetError,
    )
    if cfg.force_scale != 1.0 and not cfg.forces:
        raise RetargetError(
            "--force-scale scales the human forces that force matching presses with: add "
            "--forces (or leave --force-scale out)"
        )
    if cfg.human_replay and not cfg.forces:
        raise RetargetError(
            "--human-replay scores the human's forces against a second simulation of them, "
            "for force matching: add --forces (or leave --human-replay out)"
        )


def check_options(cfg: RunConfig) -> HandModel:
    """The checks of ``cfg`` that need no data (:func:`check_run`, the hand, the pair's form and
    whether the hand can perform it); return the hand. Raises ``RetargetError``."""
    check_run(cfg)
    hand = get_hand(cfg.hand)
    if cfg.pair is not None:  # a pair the hand cannot perform fails before any loading
        check_pair(hand, parse_pair(cfg.pair, cfg.dataset).manipulation_type)
    return hand


def run_pipeline(cfg: RunConfig) -> PipelineResult:
    """Load the demonstration ``cfg`` names and run :func:`retarget_demonstration` on it with
    ``cfg``'s hand and steps (progress bars on the terminal when ``cfg.progress``).

    Raises:
        RetargetError: a bad option, an unknown hand or pair, a pair the hand cannot perform, a
            missing demonstration, or human forces the force pipeline could not produce.

    >>> result = run_pipeline(RunConfig(hand="panda", pair="cube2/tripod", progress=False))
    >>> result.robot.q_command.shape[1], result.trajectory.num_frames
    (8, 736)
    """
    hand = check_options(cfg)
    # The demonstration first: on first use it is built, and the terminal says so at once.
    traj, subject, substituted = load_subject(cfg.pair, cfg.dataset, cfg.index, cfg.progress)
    if cfg.pair is None:  # a row's own type, known only now
        check_pair(hand, subject.manipulation_type)
    traj = time_scaled(traj, cfg.time_scale)
    rcfg = retarget_config(cfg)
    refine_cfg = refine_config(cfg.forces, retries=cfg.refine_retries) if cfg.refine else None
    with Progress(cfg.progress) as prog:
        result = retarget_demonstration(
            traj, subject, hand, rcfg, calibrate_iterations=cfg.calibrate_iterations,
            refine=refine_cfg, human_replay=cfg.human_replay, progress=prog,
        )  # fmt: skip
    result.substituted = substituted
    return result
