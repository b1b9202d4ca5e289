"""Wrist offset calibration: where a robot hand's wrist sits, relative to the scaled human wrist,
when its fingers match the human's.

The hand models put MANO's wrist frame on each robot by its kinematics
(:class:`~retarget.hands.base.WristAlignment`): fingers along MANO's distal axis, thumb on its
radial side, the wrist point on the mount. A grasp asks for more: a hand whose fingers curl
differently from a human's (Inspire's and Ability's one motor per finger, SVH's coupled
phalanges) reaches the human's fingertips only with its wrist flexed and moved, and the wrist
pose objective, pulling towards the human's wrist pose, then holds every keypoint off.

Measured here by retargeting demonstrations with the wrist free (both wrist weights 0, no
object terms, posture and smoothness off: keypoints and vectors alone, so nothing but the
fingers places the wrist) and averaging the robot wrist site's pose in the human wrist frame
over every frame: the rotation by its chordal L2 mean (``scipy``'s ``Rotation.mean``), the
translation by its mean. Joints proximal to every keypoint (Shadow's WRJ1 and WRJ0,
:func:`proximal_joints`) are held at their default: with the floating wrist free they would
take up any wrist rotation (on a synthetic motion with a known offset, Shadow's came out 11°
wrong with them free, within 0.5° with them held: ``tests/test_calibration.py``). The
demonstrations are generated ones by another operator and seed than the benchmarks use
(``operator2``, seed 1) of pairs past the benchmarks' suites (from the 41st pair of their
order), so the benchmarks judge the offset on motions and pairs it was not measured on. The
result goes in the hand module as ``HandModel.wrist_offset``; with
``RetargetConfig.wrist.use_offset`` on, ``Retargeter.human_targets`` aims the wrist at the
human wrist pose composed with it.

Measured with ``python -m benchmarks.retarget_speed_quality --hands shadow allegro leap inspire
ability svh --n-pairs 20`` (operator1, seed 0; without and with the offsets of 12 calibration
pairs), keypoint error and strict re-simulation success without → with: Shadow 10.41 → 10.31 mm
(65 → 65 %), Allegro 19.09 → 18.53 mm (30 → 25 %), LEAP 19.13 → 18.91 mm (65 → 50 %), Inspire
20.15 → 17.76 mm (35 → 25 %), Ability 15.62 → 14.19 mm (30 → 40 %), SVH 16.49 → 15.05 mm (45 →
45 %); all six 16.8 → 15.8 mm (dex-retargeting 14.9), 45 → 42 % strict (dex-retargeting 13 %).
The wrist rotation weight 0 instead (Inspire, Ability, SVH): 17.87 / 14.02 / 13.90 mm, Inspire's
strict success 35 → 25 %. On by default (``wrist.use_offset``): all 7 hands 19.54 → 18.61 mm
keypoint error, 40 → 39 % strict; Allegro's hold of the heavy built-in cube with force matching
(``retarget run --hand allegro --pair cube2H/tripod --forces``) needs Allegro's joint limit
margin with it (``HandModel.joint_limit_margin``; without it the cube drops, 12.1 cm).

Run ``retarget calibrate-wrist --hand NAME``; it prints the ``WristOffset(...)`` to paste.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn
from scipy.spatial.transform import Rotation

from dexcanvas_core.demos import feasible_pairs, generate_demo, spread_pairs
from dexcanvas_core.demos import operator as operator_by_name
from dexcanvas_core.objects.geometry import object_geometry
from retarget.config import RetargetConfig
from retarget.errors import RetargetError
from retarget.hands import get_hand
from retarget.hands.base import WRIST_JOINTS, WRIST_SITE
from retarget.pipeline import check_pair
from retarget.retargeter import Retargeter

log = logging.getLogger(__name__)

#: Operator and seed of the calibration's demonstrations (the benchmarks use operator1, seed 0).
CALIBRATION_OPERATOR = "operator2"
CALIBRATION_SEED = 1
#: Pairs of the benchmarks' order skipped (their 20-pair suites take the first ~20).
CALIBRATION_SKIP = 40


@dataclass(frozen=True)
class WristCalibration:
    """The measured offset and how well one constant offset describes the frames."""

    hand: str
    rotvec: np.ndarray
    """(3,) [rad] mean robot wrist rotation in the human wrist frame (rotation vector)."""
    translation: np.ndarray
    """(3,) [m] mean robot wrist position in the human wrist frame (robot size)."""
    rotation_spread_deg: tuple[float, float]
    """Median and 90th percentile of the frames' angle [deg] from the mean rotation."""
    translation_sd_m: np.ndarray
    """(3,) [m] standard deviation of the frames' positions about the mean."""
    keypoint_err_free_m: float
    """Mean keypoint error [m] of the wrist-free solve the offset was measured on."""
    pairs: tuple[str, ...]
    frames: int
    source: str
    locked_joints: tuple[str, ...] = ()
    """The hand's joints held at their default posture (:func:`proximal_joints`)."""

    def as_python(self) -> str:
        """The ``HandModel`` field to paste into the hand's module."""
        r = ", ".join(f"{x:.4f}" for x in self.rotvec)
        t = ", ".join(f"{x:.4f}" for x in self.translation)
        return (
            "wrist_offset=WristOffset(\n"
            f"    rotvec=({r}),  # rad, |{np.degrees(np.linalg.norm(self.rotvec)):.1f}°|\n"
            f"    translation=({t}),  # m\n"
            f'    source="{self.source}",\n'
            ")"
        )

    def summary(self) -> dict:
        return {
            "hand": self.hand,
            "rotvec_rad": [float(x) for x in self.rotvec],
            "angle_deg": float(np.degrees(np.linalg.norm(self.rotvec))),
            "translation_m": [float(x) for x in self.translation],
            "rotation_spread_deg": {
                "median": self.rotation_spread_deg[0],
                "p90": self.rotation_spread_deg[1],
            },
            "translation_sd_m": [float(x) for x in self.translation_sd_m],
            "keypoint_err_free_m": self.keypoint_err_free_m,
            "pairs": list(self.pairs),
            "frames": self.frames,
            "source": self.source,
            "locked_joints": list(self.locked_joints),
        }


def calibration_demos(
    hand,
    n_pairs: int = 8,
    *,
    operator: str = CALIBRATION_OPERATOR,
    seed: int = CALIBRATION_SEED,
    max_frames: int | None = 300,
    skip: int = CALIBRATION_SKIP,
    on_demo: Callable[[str], None] | None = None,
) -> list[tuple[object, object]]:
    """``n_pairs`` generated demonstrations ``[(pair, trajectory)]`` the hand can perform: the
    benchmarks' group-spread order of the feasible pairs (``spread_pairs``) from its ``skip``-th
    pair on, each cropped to ``max_frames`` (``Trajectory.crop``, as the benchmarks do)."""
    if n_pairs < 1:
        raise RetargetError("calibration needs at least one demonstration pair")
    operator_by_name(operator)  # an unknown name fails here, naming the known ones
    order = []
    for p in spread_pairs(feasible_pairs())[skip:]:
        try:
            check_pair(hand, p.manipulation_type)
        except RetargetError:
            continue
        order.append(p)
    out = []
    for p in order:
        try:
            traj = generate_demo(p, operator=operator, seed=seed).trajectory
        except Exception as e:  # a pair the generator cannot script: take the next one
            log.info("calibration: %s skipped (%s)", p, e)
            continue
        out.append((p, traj.crop(max_frames)))
        if on_demo is not None:
            on_demo(str(p))
        if len(out) == n_pairs:
            break
    if not out:
        raise RetargetError(f"hand {hand.name!r}: no demonstration could be generated")
    return out


def wrist_in_target_frame(retargeter, traj, Q: np.ndarray, targets: dict | None = None):
    """Per frame, the robot wrist site's pose in the frame of ``retargeter``'s wrist targets
    (the human wrist pose when ``wrist.use_offset`` is off or the hand has no offset):
    ``(rotations (T, 3, 3), positions (T, 3) [m])``."""
    tg = retargeter.human_targets(traj) if targets is None else targets
    R_h, p_h = tg["wrist_R"], tg["wrist_p"]
    Q = np.asarray(Q, dtype=np.float64)
    T = traj.num_frames
    if Q.shape != (T, retargeter.nq):
        raise RetargetError(
            f"joint trajectory has shape {Q.shape}, expected ({T}, {retargeter.nq})"
        )
    R_rel, p_rel = np.zeros((T, 3, 3)), np.zeros((T, 3))
    for t in range(T):
        retargeter.kin.forward(Q[t])
        R_rel[t] = R_h[t].T @ retargeter.kin.site_rotation(WRIST_SITE)
        p_rel[t] = R_h[t].T @ (retargeter.kin.site_position(WRIST_SITE) - p_h[t])
    return R_rel, p_rel


def proximal_joints(retargeter) -> list[str]:
    """The hand's own joints proximal to every keypoint site (Shadow's WRJ1 and WRJ0): with the
    floating wrist free they are redundant for the keypoints, so a wrist-free solve could turn
    them instead of the wrist."""
    m = retargeter.scene.model

    def chain(body: int) -> set[int]:
        joints = set()
        while body > 0:
            joints.update(range(m.body_jntadr[body], m.body_jntadr[body] + m.body_jntnum[body]))
            body = m.body_parentid[body]
        return joints

    sites = [m.site(s).id for s in retargeter.kp_sites]
    common = set.intersection(*(chain(m.site_bodyid[s]) for s in sites))
    return [m.joint(j).name for j in sorted(common) if m.joint(j).name not in WRIST_JOINTS]


def calibrate_wrist(
    hand,
    demos: Sequence[tuple[object, object]],
    *,
    on_pair: Callable[[str], None] | None = None,
    seed: int | None = None,
) -> WristCalibration:
    """Measure ``hand``'s wrist offset on ``demos`` (``[(pair, trajectory)]``; see the module
    docstring). ``on_pair`` is called with each pair's name once it is solved; ``seed``, the
    demonstrations' seed, only goes into the ``source`` note."""
    cfg = RetargetConfig.from_overrides({
        "wrist.position_weight": 0.0, "wrist.rotation_weight": 0.0, "wrist.use_offset": False,
        "posture.weight": 0.0, "smoothness.weight": 0.0, "contacts.enabled": False,
        "collision.enabled": False, "self_collision.enabled": False,
    })  # fmt: skip
    probe = Retargeter(hand, None, cfg)
    locked = proximal_joints(probe)
    if locked:  # held at their default posture (a narrow range: the QP keeps its bounds)
        m = probe.scene.model
        q0 = {j: float(probe.q_default[m.jnt_qposadr[m.joint(j).id]]) for j in locked}
        ranges = {j: (q0[j] - 1e-6, q0[j] + 1e-6) for j in locked}
        hand = dataclasses.replace(hand, joint_ranges={**hand.joint_ranges, **ranges})
    rots, poss, kp_err, names = [], [], [], []
    for pair, traj in demos:
        geom = object_geometry(pair.object.id) if traj.objects else None
        rt = Retargeter(hand, geom, cfg)
        robot = rt.retarget(traj)
        R_rel, p_rel = wrist_in_target_frame(rt, traj, robot.q)
        rots.append(R_rel)
        poss.append(p_rel)
        kp_err.append(robot.keypoint_err)
        names.append(str(pair))
        if on_pair is not None:
            on_pair(str(pair))
    R = Rotation.from_matrix(np.concatenate(rots))
    P = np.concatenate(poss)
    mean = R.mean()
    dev = np.degrees((mean.inv() * R).magnitude())
    ops = sorted({t.operator or "an unnamed operator" for _, t in demos})
    seed_note = f" (seed {seed})" if seed is not None else ""
    frames = int(P.shape[0])
    return WristCalibration(
        hand=hand.name,
        rotvec=mean.as_rotvec(),
        translation=P.mean(axis=0),
        rotation_spread_deg=(float(np.median(dev)), float(np.quantile(dev, 0.9))),
        translation_sd_m=P.std(axis=0),
        keypoint_err_free_m=float(np.concatenate(kp_err).mean()),
        pairs=tuple(names),
        frames=frames,
        source=(
            f"retarget calibrate-wrist: {len(names)} generated pair{'s' * (len(names) != 1)}"
            f" of {', '.join(ops)}"
            f"{seed_note}, {frames} frames"
        ),
        locked_joints=tuple(locked),
    )


# ------------------------------------------------------------------------------------- CLI
@dataclass(frozen=True)
class CalibrateConfig:
    """``retarget calibrate-wrist``."""

    hand: str
    n_pairs: int = 8
    operator: str = CALIBRATION_OPERATOR
    seed: int = CALIBRATION_SEED
    max_frames: int | None = 300
    as_json: bool = False


def run_calibrate(cfg: CalibrateConfig) -> WristCalibration:
    """Generate the demonstrations, measure the offset, print it (a table and the field to paste,
    or JSON)."""
    hand = get_hand(cfg.hand)
    console = Console(stderr=cfg.as_json)
    cols = ("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
            TimeElapsedColumn())  # fmt: skip
    with Progress(*cols, console=console, transient=True) as prog:
        gen = prog.add_task(f"generating {cfg.operator}'s demonstrations", total=cfg.n_pairs)
        demos = calibration_demos(
            hand, cfg.n_pairs, operator=cfg.operator, seed=cfg.seed, max_frames=cfg.max_frames,
            on_demo=lambda _: prog.advance(gen),
        )  # fmt: skip
        solve = prog.add_task(f"{hand.name}: retargeting with the wrist free", total=len(demos))
        cal = calibrate_wrist(hand, demos, on_pair=lambda _: prog.advance(solve), seed=cfg.seed)
    if cfg.as_json:
        print(json.dumps(cal.summary(), indent=2))
        return cal
    cur = hand.wrist_offset
    console.print(
        f"[bold]{hand.name}[/bold]: {cal.frames} frames of {len(cal.pairs)} pairs "
        f"({', '.join(cal.pairs)})\n"
        f"  mean wrist rotation {np.degrees(np.linalg.norm(cal.rotvec)):.1f}° "
        f"(frames from it: median {cal.rotation_spread_deg[0]:.1f}°, "
        f"90th percentile {cal.rotation_spread_deg[1]:.1f}°)\n"
        f"  mean wrist position {np.round(1e3 * cal.translation, 1)} mm "
        f"(sd {np.round(1e3 * cal.translation_sd_m, 1)} mm), MANO wrist frame\n"
        f"  keypoint error with the wrist free: {1e3 * cal.keypoint_err_free_m:.2f} mm"
        + (f" ({', '.join(cal.locked_joints)} held at rest)" if cal.locked_joints else "")
        + "\n"
        "  current offset: "
        + (
            "none"
            if cur is None
            else f"{np.degrees(np.linalg.norm(cur.rotvec)):.1f}°, "
            f"{np.round(1e3 * np.asarray(cur.translation), 1)} mm"
        )
    )
    console.print("\nfor the HandModel in the hand's module:\n", style="bold")
    console.print(cal.as_python(), highlight=False, markup=False, soft_wrap=True)  # paste-able
    return cal
