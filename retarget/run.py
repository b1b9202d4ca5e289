"""``retarget run``: retarget one demonstration onto one robot hand, re-simulate, write results.

``run_retarget(RunConfig(hand="shadow", pair="cube2/tripod"))`` is what the CLI calls; library
users can call it too. It writes into ``out``:

* ``robot_trajectory.npz`` — joint positions and servo commands (MuJoCo ``qpos`` order, names
  included), timestamps, fingertip positions, per-frame keypoint/contact errors and hand–object
  distances, simulated object pose, per-finger contact forces;
* ``metrics.json`` — the numbers (success, object errors, keypoint error, hand–object and
  finger–finger penetration, speed).

Both files are written atomically (temporary file, then rename).
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from dexcanvas_core.sim.signal import CAPTURE_SMOOTH_S, moving_average
from dexcanvas_core.table import table_of
from retarget.errors import RetargetError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunConfig:
    """One retargeting run."""

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
    (``RetargetConfig.force_scale``: a grip margin); needs ``forces``."""
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
        object.__setattr__(self, "time_scale", check_time_scale(self.time_scale))

    def output_dir(self) -> Path:
        if self.out is not None:
            return Path(self.out)
        if self.pair is None:
            stem = Path(self.dataset).name.removesuffix(".lance") if self.dataset else "builtin"
            return Path("runs") / f"{self.hand}_{stem}_{self.index}"
        obj, typ = self.pair.split("/", 1)
        return Path("runs") / f"{self.hand}_{obj}_{typ}_{self.index}"


MAX_TIME_SCALE = 10.0
"""The slowest execution ``RunConfig.time_scale`` allows (a 6 s demonstration in a minute)."""


def check_time_scale(scale) -> float:
    """``scale`` (a number or its text) as a float if it is a finite number from 1 to
    ``MAX_TIME_SCALE``; else a one-line :class:`RetargetError` saying so."""
    try:
        s = float(scale)
    except (TypeError, ValueError):
        s = float("nan")
    if not (np.isfinite(s) and 1.0 <= s <= MAX_TIME_SCALE):
        raise RetargetError(
            f"--time-scale must be a finite number from 1 to {MAX_TIME_SCALE:g} (the "
            f"demonstration is executed that many times slower), got {str(scale)!r}"
        )
    return s


def time_scaled(traj, scale: float):
    """``traj`` executed ``scale`` (≥ 1) times slower: timestamps stretched about the first,
    frame rate divided by ``scale``, everything else (frames, poses, contact records, uuid)
    unchanged. ``scale`` 1: ``traj`` itself."""
    import dataclasses

    scale = check_time_scale(scale)
    if scale == 1.0:
        return traj
    t0 = traj.timestamp[0]
    return dataclasses.replace(
        traj, timestamp=t0 + scale * (traj.timestamp - t0), fps=traj.fps / scale
    )


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


def load_subject(cfg: RunConfig):
    """``(trajectory, subject, substituted)`` of a run: the demonstration ``cfg`` names, what it
    shows (a ``Pair``, or for a row taken without ``pair`` a ``RowSubject``), and the pair whose
    demonstration stands in for it (``None``: its own).

    Raises:
        RetargetError: neither ``pair`` nor ``dataset``, or no such demonstration.
    """
    from dexcanvas_core.errors import DexCanvasError
    from dexcanvas_core.loaders.selection import load_row, subject_of

    if cfg.pair is None:
        if cfg.dataset is None:
            raise RetargetError(
                "say which demonstration: --pair OBJECT/TYPE (built-in data), or --dataset D "
                "--index I"
            )
        try:
            traj = load_row(cfg.dataset, cfg.index)  # puts the dataset's objects in use
            return traj, subject_of(traj), None
        except DexCanvasError as e:
            raise RetargetError(str(e)) from e
    pair = _parse_pair(cfg)
    traj, substituted = _load_demonstration(cfg, pair)
    return traj, pair, substituted


def _parse_pair(cfg: RunConfig):
    """``cfg.pair`` as a ``Pair`` (an imported dataset's objects in use first)."""
    from dexcanvas_core.capture import use_dataset_objects
    from dexcanvas_core.errors import DexCanvasError
    from dexcanvas_core.taxonomy import Pair

    try:
        if cfg.dataset is not None:
            use_dataset_objects(cfg.dataset)
        return Pair.parse(cfg.pair)
    except DexCanvasError as e:
        raise RetargetError(str(e)) from e


def _load_demonstration(cfg: RunConfig, pair):
    """The demonstration of ``pair``; for a heavy object without one of its own (the built-in
    data has light objects only), the light object's demonstration, to be simulated with the
    heavy object (same shape, its mass) — said on the terminal and in ``metrics.json``."""
    from dexcanvas_core.errors import DatasetError
    from dexcanvas_core.loaders.selection import load_demonstration
    from dexcanvas_core.taxonomy import Pair

    def load(p):
        if cfg.dataset is None:
            _ensure_builtin(p, cfg.progress)
        return load_demonstration(p, cfg.index, cfg.dataset)

    try:
        return load(pair), None
    except DatasetError as e:
        base = pair.object.base_id
        if not pair.object.heavy or base is None:
            raise RetargetError(str(e)) from e
        light = Pair.parse(f"{base}/{pair.manipulation_type.name}")
        try:
            traj = load(light)
        except DatasetError:
            raise RetargetError(str(e)) from e
        log.warning(
            "no %s demonstration: using %s's with the %s object", pair, light, pair.object.id
        )
        return traj, str(light)


def _ensure_builtin(pair, progress: bool) -> None:
    """Build the built-in demonstration of ``pair`` if it is not cached yet, saying so on the
    terminal first (``progress``; else in the log) with where it is cached, then showing the
    build's progress bar (``builtin.builtin_demonstration_path``).

    Raises:
        DatasetError: ``pair`` is not in the built-in set, or its demonstration fails the
            checks.
    """
    from dexcanvas_core.builtin import (
        builtin_demonstration_cached,
        builtin_demonstration_path,
        builtin_pair_path,
    )
    from dexcanvas_core.demos import builtin_pairs

    if builtin_demonstration_cached(pair) is not None:
        return
    if pair not in builtin_pairs():
        builtin_demonstration_path(pair)  # raises the DatasetError that says so
    line = (
        f"building the built-in demonstration {pair} (first use; cached in "
        f"{builtin_pair_path(pair)})"
    )
    if progress:
        from rich.console import Console

        Console(stderr=True, highlight=False).print(line, markup=False)
    else:
        log.info("%s", line)
    builtin_demonstration_path(pair, progress=progress)


FORCE_CONTACT_TIMECONST = 0.02
"""Contact solref time constant [s] of force-matching re-simulations: the force pipeline's own
(``dexcanvas_core.sim.scene.PhysicsSettings.solref``), so the robot presses the object through
the contact model the human's forces were measured with. Soft contacts give a little: a
finger pressing ``K⁻¹Jᵀf`` into them presses 60–90 % of ``f`` (``tests/test_force_matching.py``),
and the force calibration (``retarget.force_calibration``) makes up the rest. Measured on the
force-preservation benchmark (five-finger hands and LEAP, ``--variants d``, 2026-12-07), 5 /
10 / 20 ms: five-finger (d) strict success 62 / 64 / 68 %, paired heavy / light 50 / 64,
58 / 61, 64 / 69 %, force profile correlation on successful runs 0.792 / 0.789 / 0.793 (on the
66 runs all three lift 0.802 / 0.801 / 0.811), object force error 6 / 7 / 8 % of the weight.
Every hand's and object's collision geoms already carry this ``solref`` (and MuJoCo's default
``solimp``), so the override's one remaining effect is zero contact margin (some of Shadow's
geoms have 0.5 mm). A literal, pinned to the pipeline's by a test: importing
``dexcanvas_core.sim.scene`` here would cost the CLI ~2 s."""


HUMAN_REPLAY_SEED = 1
"""MPC seed of the human replay (``RunConfig.human_replay``, the force-preservation benchmark's
``--human-replay``); the force pipeline's first simulation runs at ``MPCConfig``'s default, 0."""


def human_sim_config(object_id: str, tracker: str = "mpc", mpc_seed: int | None = None):
    """The force pipeline's ``SimConfig`` for one human simulation with ``object_id``: the
    defaults, or the sampling MPC at ``mpc_seed`` (the human replay)."""
    from dexcanvas_core.sim.mpc import MPCConfig
    from dexcanvas_core.sim.pipeline import SimConfig

    if mpc_seed is None:
        return SimConfig(tracker=tracker, object_id=object_id)
    return SimConfig(tracker=tracker, object_id=object_id, mpc=MPCConfig(seed=mpc_seed))


def _simulate_human(traj, pair, prog, label: str, mpc_seed: int | None = None):
    """The force pipeline on ``traj`` with ``pair``'s object (at ``mpc_seed``, else the
    defaults): ``(result, metrics)``."""
    from dexcanvas_core.sim.pipeline import simulate

    task = prog.task(label, traj.num_frames)
    done = [0]

    def step(n):
        done[0] += n
        if task is not None:
            task(done[0], traj.num_frames)

    res = simulate(traj, human_sim_config(pair.object.id, mpc_seed=mpc_seed), progress=step)
    return res, {k: v for k, v in res.metrics.items() if k != "config"}


def _human_forces(traj, pair, prog):
    """Run the force pipeline on ``traj`` (with ``pair``'s object) for the human's forces."""
    res, m = _simulate_human(traj, pair, prog, "human forces (force pipeline)")
    if not res.success:
        raise RetargetError(
            f"the force pipeline could not reproduce this demonstration with {pair.object.id} "
            f"(object error > 5 cm at frame {m['failed_at_frame']}"
            + (f": {m['failure']['reason']}" if m.get("failure") else "")
            + "), so there are no human forces to match; try another --index, or run without "
            "--forces (dexcanvas simulate shows why it failed)"
        )
    return res.trajectory, m


def _human_replay(traj, pair, prog, fingers) -> dict:
    """``RunConfig.human_replay``: the force pipeline again at ``HUMAN_REPLAY_SEED`` on the
    force-annotated ``traj``, scored against its forces on ``fingers``; the replay's outcome
    only when it did not reproduce the demonstration."""
    res, m = _simulate_human(
        traj, pair, prog, f"human replay (force pipeline, seed {HUMAN_REPLAY_SEED})",
        HUMAN_REPLAY_SEED,
    )  # fmt: skip
    return human_replay_outcome(traj, res.trajectory if res.success else None, m, fingers)


def human_replay_outcome(first, second, sim_metrics: dict, fingers=None) -> dict:
    """The human replay's entry (``metrics.json``'s and the benchmark's ``human_replay``): its
    outcome (``sim_metrics``, the force pipeline's) and, when it reproduced the demonstration
    (``second``, its force-annotated trajectory; ``None`` when it did not), its forces scored
    against ``first``'s by :func:`human_replay_metrics`."""
    out = {
        "mpc_seed": HUMAN_REPLAY_SEED,
        "success": second is not None,
        "failed_at_frame": sim_metrics.get("failed_at_frame"),
        "object_pos_err_max_m": sim_metrics.get("object_pos_err_max_m"),
    }
    if second is not None:
        out.update(human_replay_metrics(first, second, fingers))
    return out


def _corr(a: np.ndarray, b: np.ndarray) -> float | None:
    """Pearson correlation; 0 when one side is constant and the other is not (a robot finger
    that never presses where the human's does reproduces none of its profile: leaving it out
    would flatter the mean), ``None`` when both are constant."""
    sa, sb = a.std() > 0, b.std() > 0
    if not (sa and sb):
        return 0.0 if sa or sb else None
    return float(np.corrcoef(a, b)[0, 1])


REACH_M = 0.005
"""A force-matched finger *reaches* the human's contact when the kinematic plan keeps it within
this distance [m] of the human's contact point (median over the frames the human finger
loads; ``finger_force_profiles``' ``contact_reach_m``). Measured 2026-12-06 on the
force-preservation benchmark's five-finger (d) runs that kept the object (222 scored
fingers; the same at 7e2995d and in the full run at bbcfe31): fingers within 3 mm
correlate with the human's profile at 0.83 (72 fingers; the human replay on the same
fingers 0.84), 3–5 mm 0.83 (40; 0.83), 5–10 mm 0.70 (62; 0.78), 10–20 mm 0.83 (35; 0.91),
beyond 0.58 (9; 0.96): past 5 mm the robot's correlation falls behind the replay's (README,
force preservation)."""

LOAD_BEARING_SHARE = 0.1
"""A human finger is *load-bearing* when its mean force over the demonstration is at least this
share of the summed mean force of the fingers the robot maps (``force_metrics``'s
``*_load_bearing`` means). Measured on the force-preservation benchmark (five-finger hands,
successful (d) runs, 2026-12-05): the 154 load-bearing finger profiles correlate with the
human's at 0.82, the 42 lighter touches (mean 0.02–0.53 N) at 0.30: the plan asks for them
(plan vs human 0.92 on Shadow and Ability), but the servos replayed open loop lose the contact
when the object drifts from its planned pose (Shadow on cylinder1h/ring: the ring finger 0.1–4.5
mm off the simulated cylinder, the cylinder 1–2 cm from the human's; README, force
preservation). The force pipeline run again with another MPC seed (``human_replay_metrics``, the
same runs and fingers, 2026-12-06) reproduces its own load-bearing profiles at 0.89 and its light
touches at 0.47."""


def profile_band_frames(fps: float) -> int:
    """Frames of the moving average that band-limits force profiles to the demonstration's
    bandwidth (``profile_correlation_smoothed``): the force pipeline's capture smoothing
    (``dexcanvas_core.sim.signal.CAPTURE_SMOOTH_S``, 50 ms; the captured motion the human's
    forces are simulated from says nothing faster). Measured 2026-12-06 on the
    force-preservation benchmark's five-finger (d) runs that kept the object (68; power above a
    75 ms moving average, median over loaded fingers): the human's profiles carry 0.2 % of it,
    the re-simulated robots' 1.6 % (Inspire, 0.05 N·m·s/rad servo damping) to 8.5 % (Ability,
    none in PSYONIC's model). That is contact chatter: Ability's ring finger on the heavy
    cylinder of cylinder1/finger_transfer swings between 0 and 13 N every 10 ms (2 ms physics
    steps; the same at 1 ms), and its frame means look like noise. The whole-clip correlation
    0.797 read 0.845 band-limited (5 ms contacts then; with the force pipeline's 20 ms,
    2026-12-07 on a slower machine, 0.793 and 0.820: README, force preservation)."""
    if not (np.isfinite(fps) and fps > 0):
        raise RetargetError(f"force profiles: fps must be > 0, got {fps}")
    return max(1, round(CAPTURE_SMOOTH_S * fps))


def finger_force_profiles(
    H: np.ndarray,
    R: np.ndarray,
    fingers,
    reach: np.ndarray | None = None,
    band_frames: int | None = None,
) -> dict:
    """Per finger, how the contact-force magnitudes ``R`` (T, F) [N] reproduce the reference
    ``H`` (T, F) [N] (columns named by ``fingers``): ``correlation`` over the frames where
    either exceeds 0.05 N, ``profile_correlation`` over every frame, ``relative_magnitude_error``
    (Σ|r − h| / Σh over the frames the reference carries force), both mean forces and the
    finger's ``load_share`` of the reference's summed mean force. A finger the reference never
    loads (0.05 N on at most 2 frames) has no profile to match: its three scores are ``None``;
    a reproduction that never presses where it does scores 0 (``_corr``).

    ``reach`` (T, F) [m], optional: the kinematic plan's distance from each robot finger to the
    human's contact point (``RobotTrajectory.contact_err``, NaN where inactive); each scored
    finger then also gets ``contact_reach_m``, its median over the frames the reference loads
    (``None`` when the plan has no contact target there). A finger the plan cannot bring onto
    the human's contact presses elsewhere or nowhere: ``REACH_M``.

    ``band_frames`` (:func:`profile_band_frames`), optional: each scored finger then also gets
    ``profile_correlation_smoothed``, the whole-clip correlation of both profiles
    moving-averaged over that many frames (the demonstration's bandwidth)."""
    H = np.asarray(H, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    if H.ndim != 2 or H.shape != R.shape or H.shape[1] != len(fingers):
        raise RetargetError(
            f"force profiles: reference {H.shape} and reproduction {R.shape} must both be "
            f"(frames, {len(fingers)} fingers)"
        )
    if reach is not None and np.shape(reach) != H.shape:
        raise RetargetError(f"force profiles: reach {np.shape(reach)} must be {H.shape}")
    if band_frames is not None and not (
        isinstance(band_frames, int | np.integer) and band_frames >= 1
    ):
        raise RetargetError(f"force profiles: band_frames must be an int >= 1, got {band_frames}")
    if band_frames is not None:
        Hs, Rs = moving_average(H, band_frames), moving_average(R, band_frames)
    per = {}
    total = float(H.mean(axis=0).sum())
    for i, f in enumerate(fingers):
        h, r = H[:, i], R[:, i]
        hm = float(h.mean())
        on = (h > 0.05) | (r > 0.05)
        held = h > 0.05  # where the reference finger carries force
        used = held.sum() > 2
        rel = float(np.abs(r[held] - h[held]).sum() / h[held].sum()) if used else None
        per[f] = {
            "correlation": _corr(h[on], r[on]) if used else None,
            "profile_correlation": _corr(h, r) if used else None,
            "relative_magnitude_error": rel,
            "human_force_mean_n": hm,
            "robot_force_mean_n": float(r.mean()),
            "load_share": hm / total if total > 0 else None,
        }
        if band_frames is not None:
            per[f]["profile_correlation_smoothed"] = _corr(Hs[:, i], Rs[:, i]) if used else None
        if reach is not None and used:
            d = np.asarray(reach, dtype=np.float64)[held, i]
            d = d[np.isfinite(d)]
            per[f]["contact_reach_m"] = float(np.median(d)) if d.size else None
    return per


def correlation_means(per: dict) -> dict:
    """The means of :func:`finger_force_profiles`' correlations over the scored fingers
    (all, and the load-bearing ones: ``LOAD_BEARING_SHARE``); ``None`` where none is scored.
    When the fingers carry ``profile_correlation_smoothed``, also its mean
    (``force_profile_correlation_mean_smoothed``).
    When the fingers carry ``contact_reach_m``, also the whole-clip mean over those whose plan
    reaches the human's contact (``REACH_M``; ``force_profile_correlation_mean_reached``) and
    how many of the scored fingers do (``fingers_reached``, of ``fingers_scored``)."""

    def mean_of(key: str, keep=lambda v: True) -> float | None:
        vals = [v[key] for v in per.values() if v.get(key) is not None and keep(v)]
        return float(np.mean(vals)) if vals else None

    def load_bearing(v: dict) -> bool:
        return v["load_share"] >= LOAD_BEARING_SHARE

    out = {
        "force_correlation_mean": mean_of("correlation"),
        "force_profile_correlation_mean": mean_of("profile_correlation"),
        "force_correlation_mean_load_bearing": mean_of("correlation", load_bearing),
        "force_profile_correlation_mean_load_bearing": mean_of("profile_correlation", load_bearing),
    }
    scored = [v for v in per.values() if v["profile_correlation"] is not None]
    if any("profile_correlation_smoothed" in v for v in scored):
        out["force_profile_correlation_mean_smoothed"] = mean_of("profile_correlation_smoothed")
    if any("contact_reach_m" in v for v in scored):
        reached = [v for v in scored if reaches(v)]
        out["force_profile_correlation_mean_reached"] = mean_of("profile_correlation", reaches)
        out["fingers_reached"] = len(reached)
        out["fingers_scored"] = len(scored)
    return out


def reaches(finger: dict) -> bool:
    """Whether a scored finger's plan reaches the human's contact (``contact_reach_m`` ≤
    ``REACH_M``; a finger without one does not)."""
    d = finger.get("contact_reach_m")
    return d is not None and d <= REACH_M


def human_replay_metrics(first, second, fingers=None) -> dict:
    """How well a second force-pipeline simulation of the same demonstration (another random
    seed of its sampling MPC) reproduces the first's per-finger forces, scored exactly as
    :func:`force_metrics` scores a robot against the first: the ceiling a robot matched to one
    simulation can be expected to reach, since the human's forces are themselves one sample.

    ``first``, ``second``: force-annotated trajectories (``Trajectory.contacts``) of the same
    demonstration; compared over their common frames (a simulation that lost the object stops
    early). ``fingers``: human fingers to score (default the five). Returns
    ``force_per_finger`` and the correlation means (the keys of :func:`force_metrics`).
    """
    from dexcanvas_core.trajectory import FORCE_GROUPS

    fingers = tuple(FORCE_GROUPS[:5] if fingers is None else fingers)
    bad = [f for f in fingers if f not in FORCE_GROUPS[:5]]
    if bad:
        raise RetargetError(f"unknown finger(s) {bad}; choose from {FORCE_GROUPS[:5]}")
    for name, tr in (("first", first), ("second", second)):
        if tr is None or tr.contacts is None:
            raise RetargetError(
                f"human replay: the {name} trajectory has no contact forces (run it through "
                "the force pipeline first)"
            )
    T = min(first.num_frames, second.num_frames)
    if T < 3:
        raise RetargetError(f"human replay: {T} common frames, need at least 3")
    cols = [FORCE_GROUPS.index(f) for f in fingers]
    H = np.linalg.norm(first.contacts.finger_totals()[:T, cols], axis=2)
    R = np.linalg.norm(second.contacts.finger_totals()[:T, cols], axis=2)
    per = finger_force_profiles(H, R, fingers, band_frames=profile_band_frames(first.fps))
    return {"force_per_finger": per, "frames": T, **correlation_means(per)}


def force_metrics(robot, sim, human, retargeter) -> dict:
    """Force preservation of a force-matched run: per corresponding finger, the correlation of
    the human's and the re-simulated robot's contact-force magnitudes — over the frames where
    either touches (``correlation``: does the force vary alike while in contact) and over the
    whole demonstration (``profile_correlation``: the force profile, on/off timing included) —
    and their relative magnitude error; the object force error (robot fingers' summed force vs
    the human hand's) over frames where the human holds the object off the table (and, for
    reference, over all contact frames); contact precision/recall (robot finger in contact vs
    human finger in contact); the share of frames whose required force the QP could produce
    (shortfall below 10 % of it or 0.05 N).

    The correlations and the magnitude error cover the fingers the human loaded (above 0.05 N
    on more than 2 frames); a robot finger that never presses there scores 0. A finger the
    human never loaded has no profile to match (``None``): the robot pressing with it counts
    against ``contact_precision`` instead. ``*_load_bearing`` repeat the two correlation means
    over the loaded fingers carrying at least ``LOAD_BEARING_SHARE`` of the hand's force
    (``load_share`` per finger: its mean human force over the sum of the mapped fingers')."""
    from dexcanvas_core.trajectory import FORCE_GROUPS

    H = np.linalg.norm(robot.human_force, axis=2)  # (T, F) per human finger the robot maps
    # the robot finger each human finger drives (a gripper merges index and middle)
    col = [sim.fingers.index(retargeter.hand.fingers[f]) for f in retargeter.tip_human]
    R = np.linalg.norm(sim.finger_force_world[:, col], axis=2)
    # a robot without a contact plan (a baseline's replay scored by the benchmark) has no reach
    per = finger_force_profiles(
        H, R, retargeter.tip_human, getattr(robot, "contact_err", None),
        profile_band_frames(human.fps),
    )  # fmt: skip
    human_total = human.contacts.finger_totals()[:, : len(FORCE_GROUPS)].sum(axis=1)
    robot_total = sim.finger_force_world.sum(axis=1)
    touch = np.linalg.norm(human_total, axis=1) > 0.05
    # the hand's net force on the object is only the human's to match while the hand alone
    # carries it: off the table (the table's share differs between the two simulations)
    from dexcanvas_core.rotations import aa_to_matrix

    R_o = aa_to_matrix(human.object.rot_aa.astype(np.float64))
    p_o = human.object.pos.astype(np.float64)
    low = retargeter.geometry.lowest_z(R_o, p_o)
    lifted = table_of(human).height_above(np.c_[p_o[:, :2], low]) > 0.01
    werr_all = np.linalg.norm(robot_total - human_total, axis=1)[touch]
    werr = np.linalg.norm(robot_total - human_total, axis=1)[touch & lifted]
    hc, rc = H > 0.05, R > 0.05
    need = np.linalg.norm(robot.human_force.sum(axis=1), axis=1)
    ok = robot.wrench_shortfall <= np.maximum(0.1 * need, 0.05)

    return {
        "force_per_finger": per,
        **correlation_means(per),
        "object_force_error_mean_n": float(werr.mean()) if werr.size else None,
        "object_force_error_contact_frames_mean_n": float(werr_all.mean())
        if werr_all.size
        else None,
        "contact_precision": float((hc & rc).sum() / max(rc.sum(), 1)),
        "contact_recall": float((hc & rc).sum() / max(hc.sum(), 1)),
        "wrench_feasible_fraction": float(ok[touch].mean()) if touch.any() else None,
    }


def refined_force_metrics(robot, refined, human, retargeter) -> dict | None:
    """:func:`force_metrics` of the physics refinement's simulation (``RefineResult``) over the
    frames it tracked (all of them unless it lost the object), against the same human forces
    and force plan as the re-simulation's; ``wrench_feasible_fraction`` is the force QP's, not
    the refinement's, and is left out. ``None`` when it lost the object within 3 frames."""
    from types import SimpleNamespace

    Tt = refined.finger_force_world.shape[0]
    if Tt < 3:
        return None
    part = SimpleNamespace(
        human_force=robot.human_force[:Tt],
        wrench_shortfall=robot.wrench_shortfall[:Tt],
        contact_err=robot.contact_err[:Tt],
    )
    sim = SimpleNamespace(finger_force_world=refined.finger_force_world, fingers=refined.fingers)
    human_t = human if Tt == human.num_frames else human.slice(0, Tt)
    m = force_metrics(part, sim, human_t, retargeter)
    m.pop("wrench_feasible_fraction")
    return m


def _num(x: float | None) -> str:
    return "–" if x is None else f"{x:.2f}"


def _atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


# RetargetConfig fields a run sets through its own options, not ``--set``
_RUN_OPTIONS = {
    "backend": "--backend",
    "force_matching": "--forces",
    "force_scale": "--force-scale",
}


def retarget_config(cfg: RunConfig):
    """The run's ``RetargetConfig``: the defaults, ``cfg.overrides``, then the run's own
    options; an unknown field, one of the run's options or a value the config refuses is a
    ``RetargetError`` naming it."""
    from retarget.overrides import build_config
    from retarget.retargeter import RetargetConfig

    return build_config(
        RetargetConfig, cfg.overrides, "--set", _RUN_OPTIONS,
        backend=cfg.backend, force_matching=cfg.forces, force_scale=cfg.force_scale,
    )  # fmt: skip


def run_retarget(cfg: RunConfig) -> dict:
    """Retarget, re-simulate and write the outputs; return the metrics dict."""
    from retarget.hands import get_hand

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
    hand = get_hand(cfg.hand)
    if cfg.pair is not None:  # a pair the hand cannot perform fails before any loading
        check_pair(hand, _parse_pair(cfg).manipulation_type)
    # The demonstration first: on first use it is built, and the terminal says so at once;
    # the solver's modules compile their numba kernels on a machine's first import (seconds).
    traj, pair, substituted = load_subject(cfg)
    if cfg.pair is None:  # a row's own type, known only now
        check_pair(hand, pair.manipulation_type)
    traj = time_scaled(traj, cfg.time_scale)
    from dexcanvas_core.objects.geometry import object_geometry, object_record
    from retarget.retargeter import Retargeter
    from retarget.validate import Resimulator, ValidateConfig

    rcfg = retarget_config(cfg)
    geometry = object_geometry(pair.object.id)
    out_dir = cfg.output_dir()
    out_dir.mkdir(parents=True, exist_ok=True)

    progress_ctx = _Progress(cfg.progress)
    with progress_ctx as prog:
        t0 = time.perf_counter()
        human_sim = None
        if cfg.forces and (traj.contacts is None or traj.object_wrench_world is None):
            traj, human_sim = _human_forces(traj, pair, prog)
        table = table_of(traj)
        retargeter = Retargeter(hand, geometry, rcfg, table=table)
        setup_s = time.perf_counter() - t0
        replay = None
        if cfg.human_replay:
            replay = _human_replay(traj, pair, prog, retargeter.tip_human)
        robot = retargeter.retarget(traj, progress=prog.task("retargeting", traj.num_frames))
        vcfg = ValidateConfig(contact_timeconst=FORCE_CONTACT_TIMECONST if cfg.forces else None)
        resim = Resimulator(hand, geometry, vcfg, table=table)
        sim = resim.run(robot.q_command, traj, progress=prog.task("re-simulating", traj.num_frames))
        calibrated = planned = None
        if cfg.forces and cfg.calibrate_iterations > 0:
            from retarget.force_calibration import ForceCalibrationConfig, calibrate_forces

            n = cfg.calibrate_iterations
            calibrated = calibrate_forces(
                retargeter, resim, robot, traj, sim, ForceCalibrationConfig(iterations=n),
                progress=prog.task(f"calibrating forces ({n} re-simulations)", n + 1),
            )  # fmt: skip
            sim, planned = calibrated.sim, robot.q_command
            robot.q_command = calibrated.commands

    kin_pen = (
        float(max(0.0, -np.min(robot.min_distance)))
        if np.isfinite(robot.min_distance).any()
        else 0.0
    )
    contact_err = robot.contact_err[np.isfinite(robot.contact_err)]
    per_finger = contact_error_per_finger(robot.contact_err, retargeter.tip_human)
    metrics = {
        "hand": hand.name,
        "pair": str(pair),
        "uuid": traj.uuid,
        "dataset": str(cfg.dataset) if cfg.dataset else "built-in",
        "backend": cfg.backend,
        "frames": traj.num_frames,
        "fps": traj.fps,
        "time_scale": float(cfg.time_scale),
        **sim.metrics(),
        "keypoint_err_mean_m": float(robot.keypoint_err.mean()),
        "penetration_max_m": kin_pen,
        "self_penetration_max_m": robot.self_penetration_max_m,
        "sim_penetration_max_m": float(sim.penetration_max_m),
        "contact_err_mean_m": float(contact_err.mean()) if contact_err.size else None,
        "contact_frames": int(robot.contact_active.any(axis=1).sum()),
        "contact_err_per_finger_m": per_finger,
        "contacts_off_target": [f for f, e in per_finger.items() if e > CONTACT_OFF_TARGET_M],
        "ms_per_frame": robot.ms_per_frame,
        "setup_s": setup_s,
        "retarget_config": asdict(retargeter.cfg),
        "retarget_overrides": dict(cfg.overrides),
        "demonstration_of": substituted or str(pair),
        "object": object_record(pair.object.id),
        "approximate_object": bool(geometry.approximate),
        "table": table.to_dict(),
        "forces": cfg.forces,
        "force_scale": cfg.force_scale if cfg.forces else None,
    }
    if cfg.forces:
        metrics.update(force_metrics(robot, sim, traj, retargeter))
        metrics["human_force_pipeline"] = human_sim
        if replay is not None:
            metrics["human_replay"] = replay
    if calibrated is not None:
        metrics["calibration"] = calibrated.metrics()
    refined = None
    if cfg.refine and not sim.success:
        from retarget.refine import RefineConfig, refine

        rcfg = RefineConfig(
            contact_timeconst=FORCE_CONTACT_TIMECONST if cfg.forces else None,
            retries=cfg.refine_retries,
        )
        with _Progress(cfg.progress) as prog:
            task = prog.task("refining (MPC on the robot)", 1)
            refined = refine(hand, geometry, traj, robot, retargeter.tip_sites, rcfg)
            if task is not None:
                task(1, 1)
            if refined.success and cfg.forces and cfg.calibrate_iterations > 0:
                from retarget.force_calibration import ForceCalibrationConfig
                from retarget.refine import calibrate_refined

                n = cfg.calibrate_iterations
                task = prog.task(f"calibrating the refined forces ({n} replays)", 1)
                refined = calibrate_refined(
                    hand, geometry, traj, robot, retargeter.tip_sites, refined, rcfg,
                    ForceCalibrationConfig(iterations=n), retargeter.cfg.force_scale,
                )  # fmt: skip
                if task is not None:
                    task(1, 1)
        metrics["refine"] = refined.metrics()
        metrics["success_refined"] = refined.success
        if cfg.forces:
            metrics["refine"]["forces"] = refined_force_metrics(robot, refined, traj, retargeter)
    robot.meta["simulation"] = sim.meta
    _save(out_dir, robot, sim, refined, planned)
    _atomic_write_text(out_dir / "metrics.json", json.dumps(metrics, indent=2, sort_keys=True))
    if cfg.progress:
        _print_summary(metrics, out_dir)
    return metrics


def _save(out_dir: Path, robot, sim, refined=None, planned=None) -> None:
    """``planned``: the force-matched commands before force calibration (``q_command`` is the
    calibrated ones)."""
    extra = {} if refined is None else {"ctrl_refined": refined.ctrl}
    if planned is not None:
        extra["q_command_planned"] = planned
    robot.save_npz(
        out_dir / "robot_trajectory.npz",
        extra=extra
        | {
            "object_pos_sim": sim.object_pos_sim,
            "object_rot_sim": sim.object_rot_sim,
            "object_pos_err": sim.object_pos_err,
            "object_rot_err": sim.object_rot_err,
            "finger_force_world": sim.finger_force_world,
            "force_parts": np.array([*sim.fingers, "palm"]),
            "q_sim": sim.q_sim,
            "finger_servo_err": sim.finger_servo_err,
            "wrist_pos_tracking_err": sim.wrist_pos_err,
            "wrist_rot_tracking_err": sim.wrist_rot_err,
        },
    )


class _Progress:
    """rich progress bars (or nothing when ``enabled`` is False)."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self._p = None

    def __enter__(self):
        if self.enabled:
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

            self._p = Progress(
                "[progress.description]{task.description}",
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                transient=False,
            )
            self._p.__enter__()
        return self

    def __exit__(self, *exc):
        if self._p is not None:
            self._p.__exit__(*exc)
        return False

    def task(self, name: str, total: int):
        if self._p is None:
            return None
        tid = self._p.add_task(name, total=total)
        return lambda done, _total: self._p.update(tid, completed=done)


CONTACT_OFF_TARGET_M = 0.01
"""A finger whose contacting link stays farther than this [m] from the human's contact point
(mean over its contact frames) is reported off target: the hand does not make the human's
grasp. The contact targets give way along the surface (``contact_tangent_weight``), so links a
few millimetres from the human's points still grip; beyond a centimetre they mostly do not.
benchmarks/force_preservation.py (2026-12-02, five-finger hands, force matching): strict
re-simulation success 55 % for runs with a mean contact error of 2–5 mm, 71 % for 5–10 mm and
26 % beyond."""


def contact_error_per_finger(contact_err: np.ndarray, fingers: list[str]) -> dict[str, float]:
    """``{human finger: mean contact error [m] over its contact frames}`` from the (T, F)
    per-frame errors (NaN where the finger has no contact); fingers never in contact are left
    out."""
    err = np.asarray(contact_err, dtype=np.float64)
    if err.ndim != 2 or err.shape[1] != len(fingers):
        raise RetargetError(
            f"contact errors must be (frames, {len(fingers)}) for fingers {fingers}, "
            f"got {err.shape}"
        )
    out = {}
    for k, f in enumerate(fingers):
        e = err[:, k][np.isfinite(err[:, k])]
        if e.size:
            out[f] = float(e.mean())
    return out


def _object_cell(rec: dict | None) -> str:
    """The summary's object row: id, mass, size and where the shape came from."""
    if not rec:
        return "—"
    size = " × ".join(f"{100 * v:.1f}" for v in rec["size_m"])
    text = f"{rec['id']}: {1000 * rec['mass_kg']:.0f} g, {size} cm, {rec['shape_source']}"
    if rec.get("mesh"):
        text += f" ({Path(rec['mesh']).name})"
    if rec.get("approximate"):
        text += (
            " [yellow](approximate: a stand-in for the real object; give its model with "
            "--objects-dir)[/yellow]"
        )
    return text


def _print_summary(m: dict, out_dir: Path) -> None:
    from rich.console import Console
    from rich.table import Table

    from retarget.validate import servo_summary

    ok = "[green]SUCCESS[/green]" if m["success"] else "[red]FAILED[/red]"
    t = Table(title=f"{m['hand']} · {m['pair']} · {ok}", show_header=False)
    if m.get("time_scale", 1.0) != 1.0:
        t.add_row(
            "time scale",
            f"[yellow]executed {m['time_scale']:g}× slower than demonstrated[/yellow] "
            f"({m['frames']} frames at {m['fps']:.4g} Hz)",
        )
    t.add_row(
        "object error max / mean",
        f"{100 * m['object_pos_err_max_m']:.1f} / "
        f"{100 * m['object_pos_err_mean_m']:.1f} cm  (success: every frame ≤ 5 cm)",
    )
    t.add_row("object rotation error mean", f"{np.degrees(m['object_rot_err_mean_rad']):.1f}°")
    t.add_row("object", _object_cell(m.get("object")))
    t.add_row("loose rule (mean < 10 cm, < 0.5 rad)", "yes" if m["success_loose"] else "no")
    t.add_row("keypoint error mean", f"{1000 * m['keypoint_err_mean_m']:.1f} mm")
    if m["contact_err_mean_m"] is not None:
        t.add_row(
            "contact error mean",
            f"{1000 * m['contact_err_mean_m']:.1f} mm ({m['contact_frames']} contact frames)",
        )
    if m.get("contacts_off_target"):
        t.add_row(
            f"contacts off target (mean > {1000 * CONTACT_OFF_TARGET_M:.0f} mm)",
            ", ".join(
                f"{f} {1000 * m['contact_err_per_finger_m'][f]:.1f} mm"
                for f in m["contacts_off_target"]
            ),
        )
    t.add_row(
        "penetration max (kinematic / sim)",
        f"{1000 * m['penetration_max_m']:.1f} / {1000 * m['sim_penetration_max_m']:.1f} mm",
    )
    t.add_row("finger–finger penetration max", f"{1000 * m['self_penetration_max_m']:.1f} mm")
    if (servo := servo_summary(m)) is not None:
        t.add_row("servo tracking error mean (sim − command)", servo)
    forces = ", ".join(f"{k} {v:.2f}" for k, v in m["finger_force_mean_n"].items())
    t.add_row("mean contact force [N]", forces)
    band_ms = 1e3 * CAPTURE_SMOOTH_S  # profile_band_frames' window
    if m.get("force_correlation_mean") is not None:
        t.add_row(
            "force matching",
            f"correlation {_num(m['force_profile_correlation_mean'])} (whole clip) / "
            f"{_num(m['force_correlation_mean'])} (contact frames) / "
            f"{_num(m.get('force_profile_correlation_mean_smoothed'))} (whole clip over "
            f"{band_ms:.0f} ms); load-bearing fingers "
            f"{_num(m['force_profile_correlation_mean_load_bearing'])}; object force error "
            f"{_num(m['object_force_error_mean_n'])} N, wrench feasible "
            f"{100 * m['wrench_feasible_fraction']:.0f} % of contact frames"
            + (
                f"; {m['fingers_reached']} of {m['fingers_scored']} fingers reach the human's "
                f"contacts (≤ {1000 * REACH_M:.0f} mm), correlation "
                f"{_num(m['force_profile_correlation_mean_reached'])}"
                if "fingers_reached" in m
                else ""
            ),
        )
    if (hr := m.get("human_replay")) is not None:
        if hr["success"]:
            text = (
                f"correlation {_num(hr['force_profile_correlation_mean'])} (whole clip) / "
                f"{_num(hr['force_correlation_mean'])} (contact frames) / "
                f"{_num(hr.get('force_profile_correlation_mean_smoothed'))} (whole clip over "
                f"{band_ms:.0f} ms): the human's forces against themselves, the robot's ceiling"
            )
        else:
            text = f"[red]lost the object at frame {hr['failed_at_frame']}[/red]: no ceiling"
        t.add_row(f"human replay (MPC seed {hr['mpc_seed']})", text)
    if "calibration" in m:
        c = m["calibration"]
        first = c["iterates"][0]
        planned = "kept" if first["success"] else "lost"
        t.add_row(
            "force calibration",
            f"iterate {c['chosen_iterate']} of {len(c['iterates']) - 1} (the plan {planned} the "
            f"object); force error {_num(c['force_error_before'])} → "
            f"{_num(c['force_error_after'])}, correlation "
            f"{_num(c.get('profile_correlation_before'))} → "
            f"{_num(c.get('profile_correlation_after'))}; commands moved "
            f"{np.degrees(c['finger_cmd_deviation_mean_rad']):.2f}° (fingers); "
            f"{c['compute_s']:.1f} s",
        )
    if "refine" in m:
        r = m["refine"]
        ok = "[green]SUCCESS[/green]" if r["success"] else "[red]FAILED[/red]"
        t.add_row(
            "physics refinement",
            f"{ok}: object error max {100 * r['object_pos_err_max_m']:.1f} cm; commands moved "
            f"{np.degrees(r['finger_ctrl_deviation_mean_rad']):.1f}° (fingers), "
            f"{1000 * r['wrist_pos_deviation_mean_m']:.1f} mm (wrist); "
            f"{r['attempts']} attempt{'s' if r['attempts'] > 1 else ''}, {r['compute_s']:.1f} s"
            + (
                f"; force calibration: iterate {c['chosen_iterate']}, force error "
                f"{_num(c['force_error_before'])} → {_num(c['force_error_after'])}"
                if (c := r.get("calibration"))
                else ""
            ),
        )
        if r.get("forces"):
            rf = r["forces"]
            t.add_row(
                "refined force matching",
                f"correlation {_num(rf['force_profile_correlation_mean'])} (whole clip) / "
                f"{_num(rf['force_correlation_mean'])} (contact frames), object force error "
                f"{_num(rf['object_force_error_mean_n'])} N",
            )
    if m.get("retarget_overrides"):
        t.add_row(
            "settings (--set)", ", ".join(f"{k}={v!r}" for k, v in m["retarget_overrides"].items())
        )
    t.add_row("speed", f"{m['ms_per_frame']:.2f} ms/frame ({m['backend']})")
    t.add_row("written", f"{out_dir}/robot_trajectory.npz, metrics.json")
    Console().print(t)
