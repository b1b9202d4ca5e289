"""Retargeting a human demonstration onto a robot hand: a QP per frame, warm-started in time.

Per frame the human targets are

* the wrist: MANO's wrist frame (``R = exp(global_rot_aa)``, origin at keypoint 0) is the robot's
  ``wrist`` body frame by construction of the hand models (``retarget.hands.base``);
* keypoints: every MANO21 keypoint the robot can match (``hand.keypoint_map``);

positions (wrist and keypoints) are scaled by the hand's size ratio ``hand.scale`` about the
object's centre (about the wrist when there is no object): the robot hand is the human hand
enlarged around the object, so its fingertips land just outside the surface and the contact
terms below close them onto it, instead of the wrist pinning a larger hand into the object;
* fingertip-to-fingertip vectors from the thumb (scaled), which keep pinches closed;
* contacts: where the human fingertip touches the object (a fingertip within
  ``contact_threshold`` of the object surface, or a phalanx, by default; the force pipeline's
  contact records with ``contacts_from="records"``), the robot fingertip site goes to the same
  surface point (unscaled, in the object's frame);

and the limits are the joint ranges, velocity bounds, the model's couplings, non-penetration
of the hand's collision geoms and the object, and no self-collision between the collision geoms
of different fingers (and of fingers and palm; ``HandModel.self_collision_pairs``). The same
objectives run on the Pinocchio backend (default; our QP through ``qpsolvers``) or the mink
backend (``mink.solve_ik`` with the objectives as mink tasks, mink's configuration limit and
self-collision limit, and our hand–object, coupling and wrist-speed rows: mink's collision limit
has one minimum distance for all pairs, no table clearance or per-link clearance). The
warm-start prediction and the end-of-step penetration re-steps are the Pinocchio backend's.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import mujoco
import numpy as np

from dexcanvas_core.keypoints import MANO21
from dexcanvas_core.rotations import aa_to_matrix, aa_to_quat_wxyz
from dexcanvas_core.table import DEFAULT_TABLE, Table
from dexcanvas_core.trajectory import Trajectory
from retarget._kernels import predicted_start
from retarget.errors import RetargetError
from retarget.hands.base import WRIST_SITE, wrist_qpos_from_mano
from retarget.kinematics import MujocoKinematics, PinocchioKinematics
from retarget.limits import (
    CollisionLimit,
    ContactSweep,
    CouplingLimit,
    FrameSpeedLimit,
    JointLimit,
    VelocityLimit,
)
from retarget.limits.coupling import servo_follower_map
from retarget.objectives import (
    KeypointObjective,
    PostureObjective,
    SmoothnessObjective,
    SurfaceContactObjective,
    VectorObjective,
    WristPoseObjective,
)
from retarget.qp import QPSolveError, build_qp, solve_qp
from retarget.scene import Scene, build_retarget_scene, check_table
from retarget.state import RobotState

log = logging.getLogger(__name__)

Backend = Literal["pinocchio", "mink"]


@dataclass(frozen=True)
class RetargetConfig:
    """Weights and switches of the per-frame QP."""

    backend: Backend = "pinocchio"
    """``pinocchio`` (our QP on Pinocchio kinematics) or ``mink`` (mink on MuJoCo)."""
    iterations: int = 3
    """Most Gauss–Newton iterations per frame (warm-started from the previous frame)."""
    first_frame_iterations: int = 30
    """Most iterations on the first frame (starting from the open posture)."""
    step_tolerance: float = 5e-3
    """A frame's iterations stop once the largest joint step falls below this [rad or m]
    (the next step would be smaller still); 0 always runs the full count. Measured on the
    built-in cube2/tripod (shadow, allegro, leap, svh) against 0: keypoint and penetration
    errors within 0.01 mm, contact error within 0.05 mm; 1.4–2.3 QP solves per frame instead
    of 3."""
    warm_start_extrapolate: bool = True
    """Start each frame's iterations from a prediction instead of the previous solution: the
    wrist moved by the human wrist's motion since the last frame, the finger joints at their
    last velocity unless a contact switched on or off in the last two frames (clipped to the
    joint ranges). Measured on 15 built-in runs (Shadow, Allegro, LEAP × 5 pairs): 1.57 → 1.16
    QP solves per frame, keypoint error 19.50 → 19.37 mm, contact error 2.00 → 2.03 mm, deepest
    penetration 1.08 → 1.41 mm (within the end-of-frame check's margin + 0.5 mm).
    Extrapolating the robot wrist's own velocity instead doubles the jump a contact onset makes
    (the contacts leave the wrist nearly free to move): Shadow on a generated cube2/tripod, the
    wrist went 4.5 cm down in 2 frames instead of 2 cm."""
    max_feasibility_iterations: int = 3
    """Extra iterations a frame may take while its solution penetrates the object (or one
    finger another) by more than the margin + 0.5 mm (see ``_solve_frame``). Measured with
    closest-point rows only, LEAP on generated cylinder1h/adducted_thumb: deepest penetration
    4.78 mm without the check, 1.46 mm with it; with every contact's rows, LEAP on the built-in
    cylinder2/extension_type: 2.27 mm with full-speed re-steps, 1.41 mm with the shrinking
    trust regions."""
    solver: str = "daqp"
    # Contacts dominate: where the human touches the object, the robot finger goes to the same
    # surface point even if the (scaled) keypoints and the wrist must give way. Measured on
    # generated demonstrations (4 pairs × 4 hands): contact error 5–12 mm → 1–2 mm and re-sim
    # success 0/16 → 3/16 against the keypoint-dominant weights (w_tips 10, w_wrist_pos 20,
    # w_contacts 50, squeeze 4 mm), for ~4 mm more keypoint error.
    # Every keypoint weighs the same and the wrist gives way more easily (the keypoint error
    # counts all keypoints alike, the wrist not at all). benchmarks/retarget_speed_quality.py
    # (3 hands × 20 pairs) against w_wrist 2/2, w_joints 0.3, w_vectors 5: keypoint error
    # 21.8 → 19.2 mm, contact error 2.5 → 1.8 mm, strict re-sim success 28 → 33 %.
    # The wrist and posture terms pull on the keypoints too: 0.3 / 1e-3 → 0.15 / 1e-4 (the
    # posture term then mostly regularises joints no keypoint moves). Same benchmark, seed 0 /
    # seed 1 (`--seed`), against dex-retargeting's 16.44 / 15.99 mm: keypoint error 17.74 /
    # 17.69 → 16.21 / 16.15 mm, strict re-sim success 53 / 38 → 53 / 35 %, loose 85 / 75 →
    # 82 / 77 %; force matching (variant (d) of benchmarks/force_preservation.py on its cached
    # human simulations, five-finger hands and LEAP, 135 runs) 49 → 50 % strict. Weaker still
    # trades re-sim success or force matching for keypoints. Seed 0: wrist 0.1 16.12 mm, 52 %
    # (seed 1 16.03 mm, 37 %), but the heavy cube of `retarget run --hand allegro --pair
    # cube2H/tripod --forces` slips out at frame 390, 0.7 s after lift-off (the thumb tip joint's
    # command drifts 0.36 rad/s with the human's); + w_smooth 0.03 16.06 mm, 43 %; wrist 0.03,
    # w_smooth 0.01 15.51 mm, 42 %; no wrist, posture or smoothness 14.96 mm, 38 % (1.5× the
    # time per frame).
    w_wrist_pos: float = 0.15
    w_wrist_rot: float = 0.15
    """Weight of the wrist's rotation error [per rad²]; the keypoint error's main lever (a
    radian weighed like a metre holds every fingertip off by the human wrist's orientation).
    Both wrist weights are multiplied by the hand's ``HandModel.wrist_weight`` (0 on Panda and
    SVH, 1/3 on Ability and Inspire, 1 on the others).
    benchmarks/retarget_speed_quality.py, all 7 hands × 20 pairs (2026-12-03), 0.15 → 0.05:
    keypoint error 19.54 → 18.21 mm, contact-point error 11.05 → 9.76 mm, strict re-sim
    success 40 → 40 %, force matching's five-finger strict success (variant (d) of
    benchmarks/force_preservation.py on its 27 reproduced human simulations) 46.3 → 46.3 %;
    but the heavy cube of ``retarget run --hand allegro --pair cube2H/tripod --forces`` drops
    (9.5 cm). With ``joint_limit_margin`` 0.1 as well: 18.82 mm, 10.17 mm, 39 %, force matching
    48.1 % (LEAP 66.7 → 74.1 %), the heavy cube held (0.97 cm); the wrist offset
    (``use_wrist_offset``) was taken instead (18.61 mm, 10.47 mm, 39 %; with it 0.05 drops the
    heavy cube again, 11.1 cm, even with a 0.1 rad joint limit margin)."""
    w_tips: float = 1.0
    w_joints: float = 1.0
    w_vectors: float = 1.0
    w_contacts: float = 200.0
    contact_tangent_weight: float = 0.01
    """Weight factor of a contact's error *along* the object's surface (at the human's contact
    point) relative to its error across it: the robot link must touch the surface (full
    ``w_contacts``) and is pulled towards the human's point with ``w_contacts`` × this
    factor, so a hand that cannot put its links exactly where the human's were still grips
    the object near them instead of hovering or pressing in between (1: isotropic). The
    human's contact normal sets the split. Measured with benchmarks/retarget_speed_quality.py
    (3 hands × 20 pairs), 1 → 0.05: strict / loose re-sim success 47 / 73 → 53 / 85 %,
    keypoint error 18.7 → 17.7 mm, penetration 1.19 → 1.06 mm; the contact-point error (distance
    to the human's point) grows 1.7 → 5.4 mm. Force matching (variant (d) of
    benchmarks/force_preservation.py on its cached human simulations, five-finger hands and
    LEAP, 135 runs), strict / loose: 1 → 42 / 81 %, 0.2 → 44 / 84 %, 0.1 → 45 / 88 %,
    0.05 → 49 / 89 %, 0.03 → 44 / 88 %, 0 → 42 / 87 %; so force matching keeps 0.05
    (``force_contact_tangent_weight``).
    Without force matching, benchmarks/retarget_speed_quality.py, all 7 hands × 20 pairs
    (2026-12-06; ``--set contact_tangent_weight=X``), 0.05 / 0.01 / 0: keypoint error 15.94 /
    15.42 / 15.34 mm (dex-retargeting 15.55), strict re-sim success 48.9 / 48.1 / 44.4 %, loose
    77.8 / 81.5 / 83.7 %, contact-point error 8.2 / 10.9 / 13.0 mm, penetration 1.51 / 1.47 /
    1.66 mm. On contact frames the tangential pull was what kept the keypoints off dex-
    retargeting's (Ability: 16.5 against 11.8 mm there, 11.1 against 11.9 on the other frames);
    so 0.01."""
    force_contact_tangent_weight: float = 0.05
    """``contact_tangent_weight`` when ``force_matching`` is on. The force QP places the human's
    forces at the human's contact points, so the robot's contacts are held nearer to them.
    Measured 2026-12-06, variant (d) of benchmarks/force_preservation.py on its cached human
    simulations (all 7 hands, 180 runs), 0.05 → 0.01: 100 → 95 runs lifted (Allegro 16 → 13,
    LEAP 17 → 15, Panda 7 → 5; the five-finger hands 60 → 62 of 108), and the heavy cube of
    ``retarget run --hand allegro --pair cube2H/tripod --forces`` drops (9.5 cm)."""
    contact_hover_m: float | None = 0.005
    """How a contact's error across the surface follows its robot link's signed distance to
    the object where the link hovers off it (``SurfaceContactObjective.hover``, ``h`` [m]):
    the error is the link point's offset ``o`` along the human contact's normal plus
    ``φ(d − o)``, ``d`` the link–object distance, ``φ(x) = x²/h`` below ``h`` and ``x`` beyond
    (``o + φ ≈ d`` once the link is more than ``h`` farther from the object than from the
    tangent plane); None: always the offset. The offset alone is zero anywhere in the tangent
    plane at the human's point, which a link can be in far off a curved object; on flat faces
    the two agree. Default 5 mm; the measurements behind it: CHANGELOG.md."""
    w_closing: float = 50.0
    """Weight [per m²] of the closing terms: where the human touches the object with more than
    one phalanx of a finger (a power grasp's distal and middle phalanges), the robot links
    standing for the others than the contact's are pulled to within ``closing_slack_m`` of
    the surface too (their signed distance to the object beyond it, from 5 cm in; weight
    ramped in over ``closing_ramp_s``), so that the finger wraps the object as the human's
    does. 0: only the contact's link."""
    closing_slack_m: float = 0.004
    """A closing link within this [m] of the object is left where it is: its term pulls it no
    nearer, and never pushes it out (the non-penetration rows do)."""
    closing_ramp_s: float = 0.5
    """A closing term's weight rises from 0 to ``w_closing`` over this long [s] after its human
    phalanx began to touch (pulled in at the contact's onset, a link can turn the finger about
    its contact as it lands)."""
    grip_surface_normals: bool = True
    """The grip (``grip="wrench"``; not force matching, whose forces are the human's own
    vectors) presses each contacting robot link along the object's normal where that link
    touches (the direction in which the link–object distance grows at its nearest point) when
    that is within 45° of the human contact's normal, and its friction cone is about that
    normal (``Retargeter._surface_normals``); False: the human contact's normal. Where the
    robot's link meets the object elsewhere than the human's phalanx (a larger hand on a
    ball), a push along the human's normal slides the link over the surface."""
    w_posture: float = 1e-4
    w_smooth: float = 0.05
    damping: float = 1e-5
    """Levenberg–Marquardt damping of the step."""
    joint_limit_margin: float | None = None
    """How far [rad or m] the kinematic solution keeps each finger joint inside its range (at
    most a quarter of the range; 0: the whole range; None: the hand's own,
    ``HandModel.joint_limit_margin``, 0 but on Allegro). The servo commands keep the whole
    range. A joint resting on its limit cannot press: Allegro's middle distal joint on its
    extension limit (−0.227 rad) on the built-in cube2/tripod, its pad on the cube's top edge,
    squeezed sideways by the abduction joint (2.7–3.3 N along the cube's face against 1.4 N
    planned) while the index pressed 0.5–1.4 N instead of 4.2: the cube turned in the grasp,
    and the heavy cube of ``--forces`` stayed held only with the human wrist's own pose (with
    the calibrated wrist offset it dropped, 12.1 cm; with the offset and 0.05 rad, Allegro's
    default, it is held: 1.06 cm). Not a margin for every hand: with
    benchmarks/retarget_speed_quality.py (7 hands × 20 pairs, the wrist offset on) 0.05 for
    every hand costs Shadow 10.31 → 10.68 mm keypoint error and Inspire 25 → 15 % strict
    success (0.1: Inspire 35 → 20 % without the offset)."""
    use_wrist_offset: bool = True
    """Aim the wrist at the human wrist pose composed with the hand's calibrated
    ``HandModel.wrist_offset`` (``retarget calibrate-wrist``), where its fingers match the
    human's, instead of at the human wrist pose itself (hands without an offset, the Panda
    gripper: the pose itself). benchmarks/retarget_speed_quality.py, 7 hands × 20 pairs
    (2026-12-03), off → on (Allegro with its joint limit margin): keypoint error 19.54 → 18.61
    mm (Inspire 20.15 → 17.76, Ability 15.62 → 14.19, SVH 16.49 → 15.05, Allegro 19.31 →
    18.64; seed 1, all 7: 19.07 → 18.15), strict re-sim success 40 → 39 % (seed 1: 35 → 36 %)
    (Allegro 25 → 35 %, LEAP 65 → 50 %, Inspire 35 → 25 %, Ability 30 → 40 %); force matching
    (variant (d) of benchmarks/force_preservation.py on its 27 reproduced human simulations)
    five-finger 46.3 → 46.3 %. Allegro's hold of the heavy cube with ``--forces`` needs its
    joint limit margin with it (see ``joint_limit_margin``). See ``retarget.calibration``."""
    use_contacts: bool = True
    use_collision: bool = True
    penetration_margin: float = 0.001
    """Penetration [m] the non-penetration rows allow (soft contacts need a little)."""
    table_clearance: float = 0.003
    """Height [m] the hand's collision geoms keep above the table. With the object's 1 mm
    penetration margin a finger may rest on the table in the kinematic solution; re-simulated,
    the grip squeeze then presses it into the table instead of the object (Shadow's thumb on
    a lateral pinch of cube2)."""
    noncontact_clearance: float = 0.002
    """Distance [m] a robot finger link keeps from the object on frames where the human's
    corresponding phalanx does not touch it (0: only non-penetration). Contact preservation
    both ways: keypoint targets near the surface can press a robot link the human kept clear
    onto the object (Shadow on generated cube2/tripod, operator2: the ring finger's middle
    link 1 mm into the cube, and in re-simulation the grasp was thumb–middle–ring instead of
    the human's thumb–index–middle). Both backends. Measured with
    benchmarks/retarget_speed_quality.py (3 hands × 20 pairs, surface keypoint scaling),
    0 → 2 mm: strict re-sim success 42 → 47 %, finger–finger penetration 1.37 → 1.01 mm."""
    collision_distmax: float = 0.03
    """Hand–object pairs farther than this [m] are left out of an iterate."""
    use_self_collision: bool = True
    """Keep the collision geoms of different fingers (and fingers and palm) apart
    (``HandModel.self_collision_pairs``)."""
    self_collision_margin: float = 0.001
    """Finger–finger penetration [m] the self-collision rows allow."""
    self_collision_distmax: float = 0.01
    """Hand–hand pairs farther than this [m] are left out of an iterate."""
    contact_ramp_s: float = 0.0
    """A contact's weight ramps up over its first and down over its last this many seconds
    (0: off). Switched on and off at full weight, a contact snaps the wrist to and from the
    surface (Shadow, built-in cylinder1/lateral_tripod: 4.1 m/s wrist peak against the
    human's 0.7 m/s, 99th percentile wrist acceleration 94 m/s²; with a 0.1 s ramp 1.7 m/s and
    65 m/s²). Off by default: with 0.1 s, benchmarks/retarget_speed_quality.py (3 hands × 20
    pairs) measured strict re-sim success 27 % against 33 % without (the grasp forms later)."""
    use_link_contacts: bool = True
    """A finger whose tip keypoint does not touch the object but whose distal pad, middle or
    proximal phalanx does (a lateral pinch's thumb pad, a power grasp's fingers) gets the
    contact on the corresponding robot link (``_contact_links``) instead of none."""
    link_contact_threshold: float = 0.011
    """Distance [m] from a human phalanx's bone axis (MANO keypoint to keypoint) to the
    surface below which that phalanx touches (inferred contacts): a finger's radius, about
    8–10 mm, plus a little."""
    contact_threshold: float = 0.012
    """Human fingertip keypoint–surface distance [m] below which a fingertip is in contact
    (inferred when the trajectory has no contact records). MANO's tip keypoint sits at the end
    of the finger, about one pad radius (7–9 mm) from a surface the pad touches."""
    keypoint_scaling: str = "surface"
    """How the human keypoints are scaled to the robot hand's size (``_scaled_keypoints``):
    ``uniform`` — about the object's centre by the hand scale; ``surface`` — the same, but a
    keypoint's distance to the object's surface is a robot-sized finger radius plus the
    human's gap near the object (touching keypoints stay touching), scaled fully from
    ``scale_blend_m`` out. Measured with benchmarks/retarget_speed_quality.py (Shadow,
    Allegro, LEAP × 20 pairs; strict re-sim success, keypoint / contact error): uniform 47 %,
    19.1 / 1.76 mm; surface 42 %, 18.7 / 1.34 mm (robot links pressed onto the object where
    the human's kept a gap); surface with ``noncontact_clearance`` (the default) 47 %,
    18.7 / 1.72 mm, deepest penetration 1.50 → 1.19 mm. dex-retargeting fed the same targets:
    5 % with uniform, 15 % with surface."""
    finger_radius_m: float = 0.008
    """``keypoint_scaling="surface"``: the human finger's radius [m] about its keypoints: a
    keypoint this close to the surface touches it (MANO's fingertip keypoint sits about one
    pad radius, 7–9 mm, from a surface the pad touches; ``contact_threshold``)."""
    scale_blend_m: float = 0.05
    """``keypoint_scaling="surface"``: gap [m] between a human finger and the object's surface
    from which the gap gets the full hand scale."""
    max_joint_speed: float = 20.0
    """Velocity bound [rad/s or m/s] per joint and QP iterate."""
    max_wrist_speed: float = 1.5
    """Bound [m/s] on the wrist's translation from one frame's solution to the next, over all
    of the frame's iterations (``inf``: none). The contact terms outweigh the wrist's, so a
    contact switching on can pull the wrist several centimetres in one frame, and back the
    next (Shadow on generated cube2/tripod, operator2: 5.1 cm down and 3.4 cm up at 120 fps,
    6.5 m/s, while the human wrist moved 0.01 m/s); the robot's wrist servo cannot follow
    that and the re-simulated hand lags up to 4.9 cm. The human wrist stays well below the
    bound (under 1 m/s on the built-in cylinder1/lateral_tripod, asserted in
    ``test_onsets_do_not_snap_the_wrist``). The bound is per axis. Measured with
    benchmarks/retarget_speed_quality.py (3 hands × 20 pairs, uniform keypoint scaling),
    none → 1.5 m/s: strict re-sim success
    47 → 47 %, keypoint error 19.17 → 19.12 mm; 0.75 m/s: 43 %."""
    squeeze_depth: float = 0.01
    """``grip="depth"``: where the human touches the object, the robot's position *command*
    (``q_command``) presses each contacting finger this far [m] into the surface (along the
    surface normal, finger joints only), so that position servos produce a grip force. The
    kinematic solution ``q`` itself stays outside the object. 0 disables it."""
    grip: str = "wrench"
    """How the position command (``q_command``) presses the object where the human touches it:

    * ``wrench`` — contact forces from the object's weight and motion: where the hand alone
      carries the object (off the table, or within ``grip_lead_s`` of leaving it), the force
      distribution QP (``retarget.force_matching.distribute``: friction cones, torque limits)
      finds the contact forces producing ``m (a + g ẑ)``, plus ``grip_force_n`` between fingers
      that push against each other, applied through the servo gains (``Δq = K⁻¹ Jᵀ f``, after
      closing any gap to the surface). An unopposed finger is not pressed.
    * ``depth`` — every contacting finger pressed ``squeeze_depth`` into the surface.

    ``force_matching`` (the human's measured forces) replaces both. Measured with
    benchmarks/retarget_speed_quality.py (3 hands × 20 pairs), strict / loose re-sim success:
    ``depth`` 28 / 62 %; ``wrench`` with ``grip_force_n`` 1 N 28 / 80 %, 3 N 40 / 80 %, 6 N
    42 / 70 %. Pressing every contact by a fixed depth shoves the object with the first finger
    to arrive or one resting on top (Allegro on generated cylinder6/rotation: the index alone on
    the top face at 11 N, 7× the weight; 52 N when the next finger's squeeze switched on) and
    presses along the human's contact normals whether that grips or not (Shadow on generated
    cube1/tripod: the thumb on the top edge at 8 N and a finger on the top face at 3.6 N pushed
    the cube down, net −2.75 m·g, while the finger opposite the thumb pressed 0 N; at lift-off
    every contact force fell to zero and the cube stayed on the table)."""
    grip_force_n: float = 3.0
    """``grip="wrench"``: normal force [N] each opposed contact presses with on top of what
    the object's weight and motion need (a margin against slip)."""
    grip_lead_s: float = 0.15
    """``grip="wrench"``: the weight is carried from this long [s] before the object leaves
    the table (the grip must be there when the table stops helping), ramped in as the force
    pipeline's grip does (``dexcanvas_core.sim.grip.carried_load``)."""
    force_matching: bool = False
    """Replace the depth squeeze by force matching (``retarget.force_matching``): the human's
    per-finger contact forces (force pipeline output) distributed over the robot's contacts
    by the force QP and applied through the servo gains, ``Δq = K⁻¹ Jᵀ f``, after closing any
    gap between finger and surface. Needs a trajectory with contact records carrying forces."""
    idle_contact_clearance: float | None = 0.001
    """Force matching: a finger the captured hand touches the object with (its contact flag)
    while the human's simulated finger does not press (no force) is commanded this far [m] off
    the surface where the kinematic solution leaves it nearer (or inside, up to the
    penetration margin), so its servo does not press where the human did not; None: its
    command is the kinematic solution. Measured 2026-12-06, variant (d) of
    benchmarks/force_preservation.py on its cached human simulations (all 7 hands, 180 runs;
    ``--set idle_contact_clearance=X``), None / 0 / 1 / 2 / 4 mm: runs lifted 100 / 101 / 101 /
    99 / 101, five-finger force correlation on successful runs (whole clip) 0.730 / 0.723 /
    0.739 / 0.744 / 0.742, over contact frames 0.454 / 0.447 / 0.471 / 0.488 / 0.485; the fingers
    the human loads lightly (under 10 % of the hand's force) 0.296 / 0.292 / 0.349 / 0.327 /
    0.321, the others 0.816 / 0.815 / 0.825 / 0.828 / 0.826; paired heavy / light 36 / 61 →
    44 / 61 % at 1 mm."""
    force_mu: float = 0.8
    """Friction coefficient of the force QP's (linearised, inner) cones."""
    force_scale: float = 1.0
    """Force matching asks the force QP for this multiple of the human's per-finger forces (the
    object's wrench stays the required one, so the extra is squeeze between the fingers): a
    grip margin, at the cost of pressing harder than the human. The metrics still compare
    with the human's own forces. Measured 2026-12-05 on the force-preservation benchmark's
    cached human simulations (``--hands shadow ability inspire svh leap --variants d --set
    force_scale=X``, 150 s each), five-finger (d) runs lifted of 108 at 0.7 / 1 / 1.25 / 1.5 /
    2: 56 / 60 / 63 / 63 / 61 (LEAP, of 27: 15 / 17 / 17 / 16 / 19), force profile correlation
    on successful runs 0.71 / 0.73 / 0.74 / 0.75 / 0.77, paired heavy / light 36 / 53, 36 / 61,
    39 / 64, 44 / 58, 42 / 61 %, the fingers' median relative magnitude error 0.42 / 0.43 /
    0.46 / 0.55 / 0.81 (the object force error 5–6 % of the weight at every scale). The
    default stays the human's forces: the gains are a few runs, with 2–10 flipping each way."""
    contacts_from: str = "geometry"
    """Which human fingers and phalanges touch, frame by frame:

    * ``geometry`` — inferred from the captured hand keypoints and the object's surface
      (``contact_threshold``, ``link_contact_threshold``), also for trajectories that carry
      the force pipeline's contact records (their forces are still what force matching uses);
    * ``records`` — the force pipeline's contact records.

    The records are where the *simulated* hand touched, which tracks the captured one only
    approximately, while the keypoint targets and the contact points come from the captured
    hand; flags from the records pulled robot links onto surface points the captured hand
    did not touch and left out fingers it did (Inspire, generated cube1/large_diameter: index
    in contact on 445 frames by geometry, 108 by the records). On the eight force-preservation
    runs where force matching failed and the weight-aware grip did not (Inspire, Ability,
    SVH), force matching re-simulated with stiff contacts lifted 0 of 8 with the records'
    flags and 6 of 8 with the geometric ones."""

    def validate(self) -> RetargetConfig:
        if self.backend not in ("pinocchio", "mink"):
            raise RetargetError(f"unknown backend {self.backend!r}; use pinocchio or mink")
        if self.iterations < 1 or self.first_frame_iterations < 1:
            raise RetargetError("iterations must be >= 1")
        if self.max_feasibility_iterations < 0:
            raise RetargetError("max_feasibility_iterations must be >= 0")
        if not (np.isfinite(self.step_tolerance) and self.step_tolerance >= 0):
            raise RetargetError(
                f"step_tolerance must be finite and >= 0, got {self.step_tolerance}"
            )
        for k, v in self.__dict__.items():
            if k.startswith("w_") and not (np.isfinite(v) and v >= 0):
                raise RetargetError(f"weight {k} must be finite and >= 0, got {v}")
        for k in (
            "penetration_margin",
            "noncontact_clearance",
            "self_collision_margin",
            "table_clearance",
            "contact_ramp_s",
            "closing_ramp_s",
            "closing_slack_m",
        ):
            v = getattr(self, k)
            if not (np.isfinite(v) and v >= 0):
                raise RetargetError(f"{k} must be finite and >= 0 [m], got {v}")
        h = self.contact_hover_m
        if h is not None and not (np.isfinite(h) and h >= 0):
            raise RetargetError(f"contact_hover_m must be None or finite and >= 0 [m], got {h}")
        jlm = self.joint_limit_margin
        if jlm is not None and not (np.isfinite(jlm) and jlm >= 0):
            raise RetargetError(f"joint_limit_margin must be None or finite and >= 0, got {jlm}")
        if self.contacts_from not in ("geometry", "records"):
            raise RetargetError(
                f"unknown contacts_from {self.contacts_from!r}; use geometry or records"
            )
        if self.keypoint_scaling not in ("surface", "uniform"):
            raise RetargetError(
                f"unknown keypoint_scaling {self.keypoint_scaling!r}; use surface or uniform"
            )
        if not (np.isfinite(self.scale_blend_m) and self.scale_blend_m > 0):
            raise RetargetError(
                f"scale_blend_m must be finite and > 0 [m], got {self.scale_blend_m}"
            )
        if self.grip not in ("wrench", "depth"):
            raise RetargetError(f"unknown grip {self.grip!r}; use wrench or depth")
        for k in ("grip_force_n", "grip_lead_s"):
            v = getattr(self, k)
            if not (np.isfinite(v) and v >= 0):
                raise RetargetError(f"{k} must be finite and >= 0, got {v}")
        c = self.idle_contact_clearance
        if c is not None and not (np.isfinite(c) and 0 <= c <= 0.02):
            raise RetargetError(f"idle_contact_clearance must be None or 0–0.02 [m], got {c}")
        for k in ("contact_tangent_weight", "force_contact_tangent_weight"):
            v = getattr(self, k)
            if not (np.isfinite(v) and v >= 0):
                raise RetargetError(f"{k} must be finite and >= 0 (1: isotropic), got {v}")
        if not (np.isfinite(self.force_scale) and self.force_scale > 0):
            raise RetargetError(
                f"force_scale must be finite and > 0 (1: the human's forces), got "
                f"{self.force_scale}"
            )
        if not (self.max_wrist_speed > 0):  # inf allowed: no bound
            raise RetargetError(
                f"max_wrist_speed must be > 0 [m/s] (inf: none), got {self.max_wrist_speed}"
            )
        for k in ("collision_distmax", "self_collision_distmax"):
            v = getattr(self, k)
            if not (np.isfinite(v) and v > 0):
                raise RetargetError(f"{k} must be finite and > 0 [m], got {v}")
        return self


@dataclass
class RobotTrajectory:
    """A retargeted trajectory and what the solver measured along it."""

    hand: str
    joint_names: list[str]
    q: np.ndarray
    """(T, nq) joint positions in MuJoCo ``qpos`` order; the first 6 are the floating wrist."""
    q_command: np.ndarray
    """(T, nq) position-servo targets: ``q`` plus the grip's offsets on contact frames."""
    timestamp: np.ndarray
    """(T,) [s]."""
    tip_sites: list[str]
    tip_pos_world: np.ndarray
    """(T, F, 3) robot fingertip sites [m]."""
    keypoint_err: np.ndarray
    """(T,) mean distance [m] between robot sites and their (scaled) human keypoint targets."""
    min_distance: np.ndarray
    """(T,) smallest signed hand–object distance [m] (negative: penetration); inf without object."""
    self_min_distance: np.ndarray
    """(T,) smallest signed distance [m] between collision geoms of different hand parts (the
    self-collision pairs; negative: penetration); inf when none is within the query distance."""
    contact_active: np.ndarray
    """(T, F) bool: the human fingertip mapped to this robot finger touches the object."""
    contact_err: np.ndarray
    """(T, F) [m] where active: distance from the robot finger's surface point nearest the object
    to the human's contact point; NaN elsewhere."""
    solve_time_s: float
    robot_force: np.ndarray | None = None
    """(T, F, 3) [N] the commanded contact force per robot finger (on the object): force
    matching's, or the weight-aware grip's (``grip="wrench"``); ``None`` with ``grip="depth"``."""
    human_force: np.ndarray | None = None
    """(T, F, 3) [N] the human force of the finger each robot finger stands for (force
    matching only)."""
    wrench_shortfall: np.ndarray | None = None
    """(T,) [N] how far the commanded forces fall short of the object force asked for (the
    human's with force matching; the weight and motion's with the weight-aware grip)."""
    meta: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return self.q.shape[0]

    @property
    def ms_per_frame(self) -> float:
        return 1e3 * self.solve_time_s / max(self.num_frames, 1)

    @property
    def self_penetration_max_m(self) -> float:
        """Deepest penetration [m] between different hand parts over the trajectory (0: none)."""
        d = self.self_min_distance
        return float(max(0.0, -d.min())) if d.size else 0.0

    def save_npz(self, path, extra: dict[str, np.ndarray] | None = None) -> None:
        """Write every array (plus ``extra`` ones) to one ``.npz``, atomically (temp + rename)."""
        import json
        import os
        from pathlib import Path

        path = Path(path)
        tmp = path.with_name(f".{path.name}.tmp")
        with open(tmp, "wb") as f:
            np.savez_compressed(
                f,
                q=self.q,
                q_command=self.q_command,
                wrist_pose=self.q[:, :6],
                timestamp=self.timestamp,
                joint_names=np.array(self.joint_names),
                tip_sites=np.array(self.tip_sites),
                tip_pos_world=self.tip_pos_world,
                keypoint_err=self.keypoint_err,
                min_distance=self.min_distance,
                self_min_distance=self.self_min_distance,
                contact_active=self.contact_active,
                contact_err=self.contact_err,
                meta=np.array(json.dumps({"hand": self.hand, **self.meta}, default=str)),
                **{
                    k: v
                    for k in ("robot_force", "human_force", "wrench_shortfall")
                    if (v := getattr(self, k)) is not None
                },
                **(extra or {}),
            )
        os.replace(tmp, path)


class Retargeter:
    """Retarget human trajectories onto one robot hand (and optionally one object).

    Args:
        hand: a ``retarget.hands.HandModel`` (see ``retarget.hands.get_hand``).
        geometry: the object's ``ObjectGeometry`` (``dexcanvas_core.demos.object_geometry``);
            ``None`` retargets the hand alone (keypoint-only use).
        config: weights and switches.
        table: the table of the trajectories it will retarget (``table_of(trajectory)``;
            default the default table): the hand keeps ``table_clearance`` above its top, and
            only there. :meth:`retarget` refuses a trajectory on another table.
    """

    def __init__(
        self,
        hand,
        geometry=None,
        config: RetargetConfig | None = None,
        table: Table | None = None,
    ):
        self.hand = hand
        self.geometry = geometry
        self.cfg = (config or RetargetConfig()).validate()
        # The hand's self-collision variant, whatever use_self_collision says: its contact
        # filters are those of the self-collision pairs, which the metrics always measure (the
        # scene is kinematic: contact settings change nothing else).
        self.scene: Scene = build_retarget_scene(
            hand, geometry, DEFAULT_TABLE if table is None else table, self_collision=True
        )
        self.table = self.scene.table
        m = self.scene.model
        self.nq = self.scene.hand_nq
        if self.cfg.backend == "pinocchio":
            self.kin = PinocchioKinematics(m)
        else:
            self.kin = MujocoKinematics(m, self.scene.data, nq=self.nq)
        self.keypoint_map = dict(hand.keypoint_map)
        self.keypoint_map.pop("wrist", None)
        self.kp_names = list(self.keypoint_map)
        self.kp_index = np.array([MANO21.index(k) for k in self.kp_names])
        self.kp_sites = [self.keypoint_map[k] for k in self.kp_names]
        tip_human = list(hand.mapped_human_fingers)
        self.tip_human = tip_human
        self.tip_index = np.array([MANO21.index(f"{f}_tip") for f in tip_human])
        self.tip_sites = [f"{hand.fingers[f]}_tip_site" for f in tip_human]
        self.scale = float(hand.scale)
        c = self.cfg
        is_tip = np.array([k.endswith("_tip") for k in self.kp_names])
        self.keypoints = KeypointObjective(self.kp_sites, np.where(is_tip, c.w_tips, c.w_joints))
        ww = hand.wrist_weight  # the hand's factor on the wrist weights
        self.wrist = WristPoseObjective(WRIST_SITE, (ww * c.w_wrist_pos, ww * c.w_wrist_rot))
        thumb_site = self.tip_sites[0] if tip_human and tip_human[0] == "thumb" else None
        pairs = [(s, thumb_site) for s in self.tip_sites[1:]] if thumb_site else []
        # A gripper's two "fingers" both take several human fingers: no vectors among them.
        pairs = [(a, b) for a, b in pairs if a != b]
        self.vec_human = (
            [(self.tip_index[i + 1], self.tip_index[0]) for i, (a, _) in enumerate(pairs)]
            if pairs
            else []
        )
        self.vectors = VectorObjective(pairs, c.w_vectors)
        self.contacts = None
        if geometry is not None:
            part_geoms = self._contact_links(hand, m)
            if not c.use_link_contacts:
                part_geoms = [p[:1] for p in part_geoms]
            self.contacts = SurfaceContactObjective(
                m,
                self.scene.data,
                [p[0] for p in part_geoms],
                self.scene.object_geoms,
                self.nq,
                c.w_contacts,
                part_geoms=part_geoms,
                tangent_weight=(
                    c.force_contact_tangent_weight if c.force_matching else c.contact_tangent_weight
                ),
                hover=c.contact_hover_m,
                closing_weight=c.w_closing,
                closing_slack=c.closing_slack_m,
            )
        q0 = hand.default_qpos(m)[: self.nq]
        self.q_default = q0
        finger_mask = np.ones(self.nq, bool)
        finger_mask[:6] = False
        self.posture = PostureObjective(q0, c.w_posture, mask=finger_mask)
        self.smooth = SmoothnessObjective(c.w_smooth)
        lower = np.where(m.jnt_limited[: self.nq], m.jnt_range[: self.nq, 0], -np.inf)
        upper = np.where(m.jnt_limited[: self.nq], m.jnt_range[: self.nq, 1], np.inf)
        self.lower, self.upper = lower, upper
        # The kinematic solution keeps the finger joints joint_limit_margin inside their ranges
        # (at most a quarter of a range); the servo commands (the grip's squeeze) keep the whole
        # range, so a finger resting near a limit can still press.
        margin = hand.joint_limit_margin if c.joint_limit_margin is None else c.joint_limit_margin
        inner = np.minimum(margin, 0.25 * (upper - lower))
        inner[:6] = 0.0  # the wrist's coordinates
        self._solve_lower, self._solve_upper = lower + inner, upper - inner
        limited = m.jnt_limited[: self.nq].astype(bool)
        self.limits = [JointLimit(self._solve_lower, self._solve_upper, limited)]
        coupling = CouplingLimit.from_mjmodel(m)
        if coupling:
            self.limits.append(coupling)
        self._coupling = coupling
        self._servo_map = None  # (nq, nq) servoed joints → all (``_servo_follower_map``)
        # One mj_collision sweep per iterate finds the hand–object and hand–hand pairs within
        # their query distances, for both limits and the metrics (ContactSweep).
        # Hand–hand pairs are reported as far as the self pairs need, hand–object and
        # hand–table pairs as far as the collision limit needs (ContactSweep.set_margins).
        self.sweep = ContactSweep(m, self.scene.data, self.nq)
        self.sweep.set_margins(
            self.scene.hand_geoms,
            c.self_collision_distmax,
            self.scene.object_geoms + self.scene.table_geoms,
            c.collision_distmax,
        )
        self.collision = None  # the non-penetration limit (when use_collision)
        self.distance_query = None  # the same query, for metrics, whatever use_collision says
        if geometry is not None and self.scene.object_geoms:
            obstacles = self.scene.object_geoms + self.scene.table_geoms
            pairs_geom = [(a, b) for a in self.scene.hand_geoms for b in obstacles]
            table = set(self.scene.table_geoms)
            self.distance_query = CollisionLimit(
                m,
                self.scene.data,
                pairs_geom,
                hand_nq=self.nq,
                margin=c.penetration_margin,
                distmax=c.collision_distmax,
                sweep=self.sweep,
                pair_margins=[
                    -c.table_clearance if b in table else c.penetration_margin
                    for _, b in pairs_geom
                ],
            )
            if self.cfg.use_collision:
                self.collision = self.distance_query
                self.limits.append(self.collision)
        if self.contacts is not None:
            # The iterate's contact points read the sweep's configuration (no second
            # mj_kinematics on the scene), other configurations a posed copy.
            self.contacts.kinematics = self.sweep.kinematics
        self._pair_parts = None  # (pairs, F·3): which finger part each hand-object pair's geom is
        if self.distance_query is not None and self.contacts is not None:
            F = len(self.contacts.part_geoms)
            part_of = {}
            for f, parts in enumerate(self.contacts.part_geoms):
                for k, geoms in enumerate(parts):
                    for g in geoms:
                        part_of.setdefault(g, []).append(f * 3 + k)
            obj = set(self.scene.object_geoms)
            mask = np.zeros((len(self.distance_query.pairs), F * 3), bool)
            for i, (a, b) in enumerate(self.distance_query.pairs):
                if b in obj:
                    mask[i, part_of.get(a, [])] = True
            self._pair_parts = mask
            self._base_margins = self.distance_query.pair_margins.copy()
        self._wrist_speed = np.full(self.nq, np.inf)  # FrameSpeedLimit's v_max [m/s or rad/s]
        self._wrist_speed[:3] = c.max_wrist_speed
        # Self-collision: the same query for metrics, the limit when use_self_collision.
        self.self_pairs = _geom_pairs(m, hand.self_collision_pairs())
        self.self_collision = None
        self.self_distance_query = None
        if self.self_pairs:
            self.self_distance_query = CollisionLimit(
                m,
                self.scene.data,
                self.self_pairs,
                hand_nq=self.nq,
                margin=c.self_collision_margin,
                distmax=c.self_collision_distmax,
                self_collision=True,
                max_recovery=c.self_collision_margin,
                sweep=self.sweep,
            )
            if self.cfg.use_self_collision:
                self.self_collision = self.self_distance_query
                self.limits.append(self.self_collision)
        # The iterates' velocity limit (_solve_frame; one object, which memoises its box).
        self._velocity = VelocityLimit(c.max_joint_speed)
        self._mink = None
        if self.cfg.backend == "mink":
            self._mink = _MinkSolver(self)

    def _contact_links(self, hand, m) -> list[list[list[int]]]:
        """Per robot finger, the collision geoms of the links that stand for the human's
        distal, middle and proximal phalanx (thumb: distal, proximal, metacarpal): the tip
        site's link, then the links towards the palm that have geoms (at most three; a
        two-link finger's proximal link takes both the middle and the proximal phalanx).

        A link is a rigid group of bodies (MuJoCo's ``body_weldid``): a jointless body welded
        to its parent belongs to the parent's link. Allegro's fingertips are such bodies
        (``link_3.0_tip`` on ``link_3.0``); counted as links of their own, the distal
        phalanx stood for the human's middle one, and on a fingertip contact the
        non-contact clearance held it 2 mm off the object, the tip short of the surface
        (built-in cube2/tripod: the middle finger 4 mm off the cube, 10 mm from its contact
        point)."""
        chains = hand.hand_parts(m)
        weld = m.body_weldid
        geoms_of = lambda w: [g for g in self.scene.hand_geoms if weld[m.geom_bodyid[g]] == w]  # noqa: E731
        out = []
        for f, site in zip(self.tip_human, self.tip_sites, strict=True):
            link = weld[m.site_bodyid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, site)]]
            geoms = geoms_of(link)
            if not geoms:
                raise RetargetError(f"hand {hand.name!r}: no collision geom on {site}'s link")
            parts = [geoms]
            robot_finger = hand.fingers[f]
            # A robot finger several human fingers drive (a gripper's) keeps its tip only.
            shared = sum(v == robot_finger for v in hand.fingers.values()) > 1
            links: list[int] = []  # the finger's links, palm to tip
            for b in chains.get(robot_finger, []):
                w = int(weld[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b)])
                if w not in links:
                    links.append(w)
            if not shared and link in links:
                for w in reversed(links[: links.index(link)]):
                    g = geoms_of(w)
                    if g:
                        parts.append(g)
                    if len(parts) == 3:
                        break
            if len(parts) == 2:  # two links: the proximal one takes both phalanges
                parts.append(parts[1])
            out.append(parts)
        return out

    # ------------------------------------------------------------------ targets
    def human_targets(self, traj: Trajectory) -> dict[str, np.ndarray]:
        """Per-frame targets in world coordinates (see the module docstring)."""
        h = traj.hand
        if h.joint_pos is None:
            from dexcanvas_core.mano import ManoLayer

            layer = ManoLayer(h.name)
            h_kp = layer.forward_numpy(
                betas=h.betas[None], global_orient=h.global_rot_aa, hand_pose=h.finger_pose,
                transl=h.global_pos,
            ).keypoints  # fmt: skip
        else:
            h_kp = h.joint_pos.astype(np.float64)
        if not np.all(np.isfinite(h_kp)):
            raise RetargetError(f"trajectory {traj.uuid}: human keypoints contain NaN")
        R_wrist = aa_to_matrix(h.global_rot_aa.astype(np.float64))
        scaled = self._scaled_keypoints(traj, h_kp)  # (T, 21, 3)
        wrist_p = scaled[:, 0]
        if self.cfg.use_wrist_offset and self.hand.wrist_offset is not None:
            R_wrist, wrist_p = self.hand.wrist_offset.apply(R_wrist, wrist_p)
        kp = scaled[:, self.kp_index]
        vec = (
            np.stack([scaled[:, a] - scaled[:, b] for a, b in self.vec_human], axis=1)
            if self.vec_human
            else np.zeros((traj.num_frames, 0, 3))
        )
        out = {"wrist_p": wrist_p, "wrist_R": R_wrist, "keypoints": kp, "vectors": vec}
        T, F = traj.num_frames, len(self.tip_sites)
        active = np.zeros((T, F), bool)
        parts = np.zeros((T, F), int)
        by_part = np.zeros((T, F, 3), bool)
        points = np.zeros((T, F, 3))
        normals = np.zeros((T, F, 3))
        if self.geometry is not None and traj.objects:
            R_obj = aa_to_matrix(traj.object.rot_aa.astype(np.float64))
            p_obj = traj.object.pos.astype(np.float64)
            tips_world = h_kp[:, self.tip_index]  # (T, F, 3)
            tips_obj = np.einsum("tji,tfj->tfi", R_obj, tips_world - p_obj[:, None])
            sdf, n_obj = self.geometry.sdf_and_normal(tips_obj.reshape(-1, 3))
            sdf = sdf.reshape(T, F)
            n_obj = n_obj.reshape(T, F, 3)
            surf_obj = tips_obj - sdf[..., None] * n_obj  # surface point under the fingertip
            records = traj.contacts is not None and self.cfg.contacts_from == "records"
            if records:
                by_part = self._parts_from_records(traj)
            else:
                by_part = np.zeros((T, F, 3), bool)
                by_part[..., 0] = sdf < self.cfg.contact_threshold
            # A finger whose tip keypoint does not touch may touch with its distal pad, else its
            # middle, else its proximal phalanx: that link's contact replaces the tip's
            # (lateral pinch, power grasps).
            n_parts = np.array([len(p) for p in self.contacts.part_geoms])[None]
            active = by_part[..., 0].copy()
            for k in (0, 1, 2) if self.cfg.use_link_contacts else ():
                seg = self._segment_rows(k)
                a, b = h_kp[:, seg[:, 0]], h_kp[:, seg[:, 1]]  # (T, F, 3) segment ends
                u = np.linspace(0.0, 1.0, 5)[:, None, None, None]
                pts = (1 - u) * a[None] + u * b[None]  # (5, T, F, 3)
                pts_obj = np.einsum("tji,stfj->stfi", R_obj, pts - p_obj[None, :, None])
                d, n = self.geometry.sdf_and_normal(pts_obj.reshape(-1, 3))
                d, n = d.reshape(5, T, F), n.reshape(5, T, F, 3)
                j = d.argmin(axis=0)  # (T, F) the sample nearest the surface
                dk = np.take_along_axis(d, j[None], 0)[0]
                nk = np.take_along_axis(n, j[None, ..., None], 0)[0]
                pk = np.take_along_axis(pts_obj, j[None, ..., None], 0)[0]
                if not records:
                    by_part[..., k] = dk < self.cfg.link_contact_threshold
                # (k = 0: the distal phalanx's pad touches while the tip keypoint, at the end
                # of the finger, is farther than contact_threshold: a lateral pinch's thumb)
                use = by_part[..., k] & ~active & (n_parts > k)
                surf_obj[use] = (pk - dk[..., None] * nk)[use]
                n_obj[use] = nk[use]
                parts[use] = k
                active |= use
            points = np.einsum("tij,tfj->tfi", R_obj, surf_obj) + p_obj[:, None]
            normals = np.einsum("tij,tfj->tfi", R_obj, n_obj)
        out.update(
            contact_active=active, contact_points=points, contact_normals=normals,
            contact_part=parts, contact_by_part=by_part,
        )  # fmt: skip
        return out

    def _scaled_keypoints(self, traj: Trajectory, h_kp: np.ndarray) -> np.ndarray:
        """The human keypoints ``h_kp`` (T, 21, 3) [m, world] scaled to the robot hand's size.

        Without an object: about the wrist by ``scale``. With one, ``keypoint_scaling``:

        * ``uniform`` — about the object's centre by ``scale``;
        * ``surface`` — the same, then each keypoint moved along the surface normal until its
          distance to the surface is that of a robot-sized finger with the human's gap: with
          ``ρ = finger_radius_m`` and the human keypoint's distance ``d``, ``scale·d`` within
          ``ρ`` (touching), ``scale·ρ + (d − ρ)·g(d)`` beyond, the gap's scale ``g`` going
          from 1 to ``scale`` over ``scale_blend_m`` (smoothstep; ``scale·d`` far away). Across
          the surface the keypoints keep the robot hand's spread (its fingers are wider
          apart); towards it, a keypoint that touches stays touching and one that keeps a gap
          keeps it.

        Scaled uniformly, a fingertip on the object is pushed ``(scale − 1)·r`` off the surface
        (``r`` its distance from the centre: ~9 mm on a 5 cm cube for Shadow's 1.37), so the
        keypoint and contact targets disagree on every contact frame and a contact switching on
        pulls the finger, and the wrist with it, across the gap (Shadow on generated
        cube2/tripod, operator2: the thumb 21.8 mm from its contact target after the onset
        frame's solve, the wrist dived 6.8 cm and came back while the human's stood still;
        with ``surface`` 2.6 mm and one 1.3 cm wrist step, no return)."""
        s = self.scale
        if self.geometry is None or not traj.objects:
            c = h_kp[:, :1]
            return c + s * (h_kp - c)
        c = traj.object.pos.astype(np.float64)[:, None]  # (T, 1, 3)
        u = c + s * (h_kp - c)
        if self.cfg.keypoint_scaling == "uniform":
            return u
        R_obj = aa_to_matrix(traj.object.rot_aa.astype(np.float64))  # (T, 3, 3) object → world
        d, _ = self.geometry.sdf_and_normal(np.einsum("tji,tkj->tki", R_obj, h_kp - c))
        d_u, n_u = self.geometry.sdf_and_normal(np.einsum("tji,tkj->tki", R_obj, u - c))
        rho = self.cfg.finger_radius_m
        x = np.clip((d - rho) / self.cfg.scale_blend_m, 0.0, 1.0)
        gap_scale = 1.0 + (s - 1.0) * x * x * (3.0 - 2.0 * x)
        d_target = np.where(d < rho, s * d, s * rho + (d - rho) * gap_scale)  # (T, 21) [m]
        n_world = np.einsum("tij,tkj->tki", R_obj, n_u)
        return u - (d_u - d_target)[..., None] * n_world

    def _frame_margins(self, by_part: np.ndarray) -> np.ndarray:
        """Per frame and hand–object pair, the margin [m] of its non-penetration row: the
        penetration margin where the pair's hand geom stands for a phalanx the human touches
        the object with (``by_part`` (..., F, 3)), or that is no finger part (palm), else the
        clearance ``−noncontact_clearance``; the table pairs keep theirs. Returns
        (..., pairs)."""
        lead = by_part.shape[:-2]
        margins = np.broadcast_to(self._base_margins, (*lead, self._base_margins.size)).copy()
        if self.cfg.noncontact_clearance <= 0:
            return margins
        mask = self._pair_parts  # (pairs, F·3)
        flags = by_part.reshape(*lead, -1).astype(np.int64)
        allowed = flags @ mask.T.astype(np.int64) > 0  # (..., pairs)
        margins[mask.any(axis=1) & ~allowed] = -self.cfg.noncontact_clearance
        return margins

    def _closing_parts(self, tg: dict, fps: float) -> np.ndarray | None:
        """(T, F, 3) factors in [0, 1] on ``w_closing`` of the finger parts the human touches
        the object with besides each finger's contact part (the closing terms' links): 0 where
        not, rising from 0 to 1 over the ``closing_ramp_s`` after the part's touch began;
        ``None`` without closing terms."""
        if self.contacts is None or not (self.cfg.use_contacts and self.cfg.w_closing > 0):
            return None
        on = np.asarray(tg["contact_by_part"], bool).copy()
        part = np.asarray(tg["contact_part"], int)
        np.put_along_axis(on, part[..., None], False, axis=-1)
        on &= np.asarray(tg["contact_active"], bool)[..., None]
        since = np.zeros(on.shape)  # frames each part has been touching, this one included
        run = np.zeros(on.shape[1:])
        for t in range(on.shape[0]):
            run = np.where(on[t], run + 1, 0)
            since[t] = run
        n = max(self.cfg.closing_ramp_s * fps, 1.0)
        return np.clip(since / n, 0.0, 1.0)

    def _segment_rows(self, k: int) -> np.ndarray:
        """(F, 2) MANO21 rows of each finger's phalanx ``k`` (0: distal, 1: middle,
        2: proximal; the thumb's 1: proximal, 2: metacarpal)."""
        end = lambda f: f"{f}_tip" if k == 0 else f"{f}{4 - k}"  # noqa: E731
        return np.array([[MANO21.index(f"{f}{3 - k}"), MANO21.index(end(f))]
                         for f in self.tip_human])  # fmt: skip

    def _parts_from_records(self, traj: Trajectory) -> np.ndarray:
        """(T, F, 3) bool: the force pipeline's contact records on each finger's distal,
        middle and proximal part (thumb: ip, mcp, cmc)."""
        T, F = traj.num_frames, len(self.tip_sites)
        out = np.zeros((T, F, 3), bool)
        names = {}
        for i, f in enumerate(self.tip_human):
            joints = ("ip", "mcp", "cmc") if f == "thumb" else ("dip", "pip", "mcp")
            for k, j in enumerate(joints):
                names[f"{f}_{j}"] = (i, k)
        c = traj.contacts
        for frame, part in zip(c.frame, c.joint_name, strict=True):
            hit = names.get(part)
            if hit is not None:
                out[frame, hit[0], hit[1]] = True
        return out

    # ------------------------------------------------------------------ solving
    def retarget(
        self, traj: Trajectory, progress: Callable[[int, int], None] | None = None
    ) -> RobotTrajectory:
        """Retarget every frame of ``traj``; ``progress(done, total)`` is called per frame."""
        traj.validate()
        check_table(self.table, traj, "Retargeter")
        tg = self.human_targets(traj)
        T = traj.num_frames
        q = self.q_default.copy()
        q[:6] = wrist_qpos_from_mano(tg["wrist_R"][0], tg["wrist_p"][0])
        Q = np.zeros((T, self.nq))
        Qc = np.zeros((T, self.nq))
        has_obj = self.geometry is not None and bool(traj.objects)
        solve_s = 0.0
        self.smooth.set_previous(None)
        fm = None
        if self.cfg.force_matching and has_obj:
            fm = self._force_targets(traj)
        elif (
            self.cfg.grip == "wrench"
            and has_obj
            and self.cfg.use_contacts
            and self.contacts is not None
        ):
            fm = self._grip_targets(traj)
        ramp = contact_ramp(tg["contact_active"], self.cfg.contact_ramp_s * traj.fps)
        wq = wrist_qpos_from_mano(tg["wrist_R"], tg["wrist_p"])  # (T, 6)
        obj_quat = aa_to_quat_wxyz(traj.object.rot_aa) if has_obj else None
        clearance = self.collision is not None and self._pair_parts is not None
        margins = self._frame_margins(tg["contact_by_part"]) if clearance else None  # (T, pairs)
        closing = self._closing_parts(tg, traj.fps)
        try:
            for t in range(T):
                if has_obj:
                    self.scene.set_object_pose(traj.object.pos[t], quat_wxyz=obj_quat[t])
                self.wrist.set_target(tg["wrist_p"][t], tg["wrist_R"][t])
                self.keypoints.set_targets(tg["keypoints"][t])
                if self.vec_human:
                    self.vectors.set_targets(tg["vectors"][t])
                if self.contacts is not None:
                    active = tg["contact_active"][t] & self.cfg.use_contacts
                    self.contacts.set_contacts(
                        active,
                        tg["contact_points"][t],
                        tg["contact_part"][t],
                        ramp[t],
                        normals=tg["contact_normals"][t],
                        closing=None if closing is None else closing[t],
                    )
                if margins is not None:
                    self.collision.pair_margins = margins[t]
                n_it = self.cfg.first_frame_iterations if t == 0 else self.cfg.iterations
                t0 = time.perf_counter()
                q0 = q
                if t >= 2 and self.cfg.warm_start_extrapolate:
                    q0 = self._warm_start(Q[t - 2 : t], wq[t - 1 : t + 1], tg["contact_active"], t)
                q = self._solve_frame(q0, n_it, traj.timestamp, t, q_prev=q if t > 0 else None)
                if fm is not None:
                    Qc[t] = q + self._force_squeeze(q, t, tg, fm)
                else:
                    Qc[t] = q + self._squeeze(q, tg["contact_active"][t], tg["contact_normals"][t])
                solve_s += time.perf_counter() - t0
                self.smooth.set_previous(q)
                Q[t] = q
                if progress is not None:
                    progress(t + 1, T)
        finally:  # the limit is shared with the metrics: leave it as it was, also on errors
            if clearance:
                self.collision.pair_margins = self._base_margins.copy()
        m = self.measure(traj, Q, tg)
        return RobotTrajectory(
            hand=self.hand.name,
            joint_names=[
                mujoco.mj_id2name(self.scene.model, mujoco.mjtObj.mjOBJ_JOINT, j)
                for j in range(self.nq)
            ],
            q=Q,
            q_command=Qc,
            timestamp=traj.timestamp.copy(),
            tip_sites=list(self.tip_sites),
            tip_pos_world=m["tip_pos_world"],
            keypoint_err=m["keypoint_err"],
            min_distance=m["min_distance"],
            self_min_distance=m["self_min_distance"],
            contact_active=m["contact_active"],
            contact_err=m["contact_err"],
            solve_time_s=solve_s,
            robot_force=None if fm is None else fm["robot_force"],
            human_force=None if fm is None else fm["human_force"],
            wrench_shortfall=None if fm is None else fm["shortfall"],
            meta={
                "backend": self.cfg.backend,
                "uuid": traj.uuid,
                "scale": self.scale,
                "config": {k: v for k, v in self.cfg.__dict__.items()},
            },
        )

    def measure(self, traj: Trajectory, Q: np.ndarray, targets: dict | None = None) -> dict:
        """Kinematic metrics of any joint trajectory ``Q`` (T, nq) against ``traj``'s targets.

        Returns ``tip_pos_world (T, F, 3)``, ``keypoint_err (T,)`` (mean robot-site distance to
        the scaled human keypoints [m]), ``min_distance (T,)`` (smallest hand–object signed
        distance [m], inf without object), ``self_min_distance (T,)`` (smallest signed distance
        between different hand parts [m], inf when none is near), ``contact_active (T, F)`` and
        ``contact_err (T, F)`` (distance from the finger surface nearest the object to the human
        contact point [m], NaN where inactive). The retargeter's own output and baselines are
        measured alike.
        """
        tg = self.human_targets(traj) if targets is None else targets
        T, F = traj.num_frames, len(self.tip_sites)
        Q = np.asarray(Q, dtype=np.float64)
        if Q.shape != (T, self.nq):
            raise RetargetError(f"joint trajectory has shape {Q.shape}, expected ({T}, {self.nq})")
        tips = np.zeros((T, F, 3))
        kp_err = np.zeros(T)
        min_d = np.full(T, np.inf)
        self_d = np.full(T, np.inf)
        c_err = np.full((T, F), np.nan)
        active_all = np.asarray(tg["contact_active"], bool)
        has_obj = self.geometry is not None and bool(traj.objects)
        obj_geoms = set(self.scene.object_geoms)
        obj_quat = aa_to_quat_wxyz(traj.object.rot_aa) if has_obj else None
        tip_sites, kp_sites = tuple(self.tip_sites), tuple(self.kp_sites)
        for t in range(T):
            q = Q[t]
            if has_obj:
                self.scene.set_object_pose(traj.object.pos[t], quat_wxyz=obj_quat[t])
            self.kin.forward(q)
            tips[t] = self.kin.site_positions(tip_sites)
            robot_kp = self.kin.site_positions(kp_sites)
            kp_err[t] = float(np.mean(np.linalg.norm(robot_kp - tg["keypoints"][t], axis=1)))
            if self.distance_query is not None:
                d = self.distance_query.distances(q)
                min_d[t] = min((x[2] for x in d if x[1] in obj_geoms), default=np.inf)
            if self.self_distance_query is not None:
                self_d[t] = self.self_distance_query.min_distance(q)
            if self.contacts is not None and active_all[t].any():
                self.contacts.set_contacts(
                    active_all[t], tg["contact_points"][t], tg["contact_part"][t]
                )
                d_c = self.contacts.distances_to_targets(q)
                c_err[t, active_all[t]] = d_c[active_all[t]]
        return {
            "tip_pos_world": tips,
            "keypoint_err": kp_err,
            "min_distance": min_d,
            "self_min_distance": self_d,
            "contact_active": active_all.copy(),
            "contact_err": c_err,
        }

    def _servo_gains(self) -> tuple[np.ndarray, np.ndarray]:
        """``(kp, tau_max)`` per hand joint (:func:`retarget.force_matching.servo_gains`)."""
        from retarget.force_matching import servo_gains

        return servo_gains(self.scene.model, self.nq)

    def _object_com(self) -> np.ndarray:
        return self.geometry.com

    def _grip_targets(self, traj: Trajectory) -> dict:
        """Per-frame object wrench the hand must supply: ``λ m (a + g ẑ)`` and no torque about
        the centre of mass, with ``a`` the object's captured acceleration (50 ms smoothing) and
        ``λ`` the share of the weight the hand carries (the force pipeline's
        ``sim.grip.carried_load``: 0 while the object rests on the table, 1 off it, built up
        over the ``grip_lead_s`` before lift-off: the grip must be there when the table stops
        helping)."""
        from dexcanvas_core.rotations import aa_to_quat_wxyz
        from dexcanvas_core.sim.physics import capture_acceleration, carried_load

        T, F = traj.num_frames, len(self.tip_sites)
        kp, tau_max = self._servo_gains()
        R = aa_to_matrix(traj.object.rot_aa.astype(np.float64))
        p = traj.object.pos.astype(np.float64)
        load = carried_load(
            self.geometry, p, aa_to_quat_wxyz(traj.object.rot_aa), traj.fps,
            lead_s=self.cfg.grip_lead_s, table=self.table or DEFAULT_TABLE,
        )  # fmt: skip
        acc = capture_acceleration(p, traj.fps)
        W = np.zeros((T, 6))
        W[:, :3] = (load * self.geometry.mass_kg)[:, None] * (acc + np.array([0.0, 0.0, 9.81]))
        return {
            "mode": "grip",
            "kp": kp,
            "tau_max": tau_max,
            "human_force": None,
            "wrench": W,
            "com_local": self._object_com(),
            "robot_force": np.zeros((T, F, 3)),
            "shortfall": np.zeros(T),
            "R_obj": R,
            "p_obj": p,
        }

    def human_finger_forces(self, traj: Trajectory) -> np.ndarray:
        """(T, F, 3) [N, world]: the human's summed contact force on the object of the human
        finger each robot fingertip stands for (``tip_human`` order; a gripper's merged finger
        repeats), from the force pipeline's contact records."""
        from dexcanvas_core.trajectory import FORCE_GROUPS

        c = traj.contacts
        if c is None or c.num_records == 0 or traj.object_wrench_world is None:
            raise RetargetError(
                f"force matching needs the human's contact forces, and trajectory {traj.uuid} "
                "has none: run it through the force pipeline first (dexcanvas simulate), or use "
                "retarget run --forces, which does"
            )
        groups = c.finger_totals().astype(np.float64)  # (T, 6, 3) on the object, world
        return np.stack([groups[:, FORCE_GROUPS.index(f)] for f in self.tip_human], axis=1)

    def _force_targets(self, traj: Trajectory) -> dict:
        """Per-frame human forces of the robot's fingers and the object wrench to reproduce."""
        human = self.human_finger_forces(traj)
        kp, tau_max = self._servo_gains()
        T, F = traj.num_frames, len(self.tip_sites)
        return {
            "mode": "human",
            "kp": kp,
            "tau_max": tau_max,
            "human_force": human,
            "wrench": traj.object_wrench_world.astype(np.float64),
            "com_local": self._object_com(),
            "robot_force": np.zeros((T, F, 3)),
            "shortfall": np.zeros(T),
            "R_obj": aa_to_matrix(traj.object.rot_aa.astype(np.float64)),
            "p_obj": traj.object.pos.astype(np.float64),
        }

    def _force_squeeze(self, q: np.ndarray, t: int, tg: dict, fm: dict) -> np.ndarray:
        """Joint offsets that make the servos press with the force QP's contact forces."""
        from retarget.force_matching import distribute, squeeze_offsets

        W = fm["wrench"][t]
        normals = tg["contact_normals"][t]
        if fm["mode"] == "human":
            f_des = self.cfg.force_scale * fm["human_force"][t]
            active = tg["contact_active"][t] & (np.linalg.norm(f_des, axis=1) > 1e-3)
        else:
            # No human forces: the wrench the object needs, plus a light squeeze between
            # fingers that push against each other (an unopposed finger is not pressed).
            active = tg["contact_active"][t]
            opp = opposed_contacts(active, normals)
            f_des = -self.cfg.grip_force_n * normals * opp[:, None]
            if not W.any():
                active = opp
        # A finger the captured hand touches with while the human's presses nothing is backed
        # off the surface (``idle_contact_clearance``) instead of pressed by the servo.
        idle = np.zeros_like(active)
        if fm["mode"] == "human" and self.cfg.idle_contact_clearance is not None:
            idle = tg["contact_active"][t] & ~active
        if not active.any():
            fm["shortfall"][t] = float(np.linalg.norm(W[:3]))
            if not idle.any():
                return np.zeros(self.nq)
        self.kin.forward(q)
        idx = np.flatnonzero(active | idle)
        pressed = active[idx]
        fingers = np.isfinite(fm["kp"])
        bodies, P, gap = self.contacts.nearest_of(q, idx)
        Jall = self.kin.point_jacobians(bodies, P)[:, :, : self.nq]
        # Over the servoed joints, each carrying the joints its linkage drives (a coupled
        # distal joint moves with its servo, and its share of the load is the servo's: τ =
        # (J C)ᵀ f); the wrist has no column (it does not squeeze).
        C = self._servo_follower_map(q)
        Jall = Jall @ C
        dq = np.zeros(self.nq)
        # The robot link presses where it touches, along the object's normal there
        # (``grip_surface_normals``), which is not the human's where the robot's link meets
        # the object elsewhere (a larger hand's fingertip on an apple's upper side, the
        # human's on its equator). Force matching keeps the human's normals: its forces are
        # the human's own vectors, their cones the human's.
        normals = normals.copy()
        if self.cfg.grip_surface_normals and fm["mode"] != "human":
            normals[idx] = self._surface_normals(q, idx, normals[idx])
            f_des = -self.cfg.grip_force_n * normals * opp[:, None]
        if pressed.any():
            ia = idx[pressed]
            J = list(Jall[pressed])
            com = fm["p_obj"][t] + fm["R_obj"][t] @ fm["com_local"]
            dist = distribute(
                P[pressed],
                normals[ia],
                f_des[ia],
                W,
                com,
                mu=self.cfg.force_mu,
                jacobians=[Ji[:, fingers] for Ji in J],
                tau_max=np.minimum(fm["tau_max"][fingers], 1e3),
            )
            fm["robot_force"][t, ia] = dist.forces
            fm["shortfall"][t] = dist.force_shortfall_n
            dq = squeeze_offsets(J, dist.forces, np.where(fingers, fm["kp"], np.inf))
        # K⁻¹Jᵀf presses from the surface: a finger the kinematic solution leaves short of it
        # (non-penetration margin, contact error) first closes that gap, else a light force
        # is spent in the air (Allegro on cube2h/tripod: 3.6 mm mean contact error, 0.2 N
        # reached instead of the human's ~2 N, the cube dropped); one the solution leaves
        # inside it (up to the 2 mm penetration margin) backs out to it, else it presses that
        # depth's servo force on top of the plan's (k·d with k = kp/L², e.g. 1.5 N for
        # Allegro's 10 N·m/rad at a 0.1 m lever and 1.5 mm). An idle finger goes out to its
        # clearance where it is nearer. The two groups take a damped step each: one step for
        # both solves them jointly through the joints they share (Shadow's WRJ0/1, SVH's
        # spread), which the force benchmark's (d) measured worse (five-finger correlation on
        # the same 61 successful runs 0.739 → 0.732, SVH cube2/sliding 0.83 → 0.63).
        # The idle fingers' clearance is a distance: it grows along the surface normal at the
        # finger's nearest point (the distance's gradient), which is not the human contact's
        # where the robot finger sits on an edge the human touched beside.
        target = np.where(pressed, 0.0, self.cfg.idle_contact_clearance or 0.0)
        # A finger point inside the object (the solution's penetration margin) has no such
        # gradient to trust near an edge (the nearest face from inside may not be the one it
        # went through): it keeps the human contact's normal (a pressed one: the normal where
        # it touches with ``grip_surface_normals``).
        step_normals = normals[idx].copy()
        if (~pressed).any() and self.geometry is not None:
            R_o, p_o = fm["R_obj"][t], fm["p_obj"][t]
            d_loc, n_loc = self.geometry.sdf_and_normal((P[~pressed] - p_o) @ R_o)
            idle = np.flatnonzero(~pressed)[d_loc > 0.0]
            step_normals[idle] = n_loc[d_loc > 0.0] @ R_o.T
        for group in (pressed, ~pressed & (gap < target)):
            err = (gap - target)[group]
            if err.any():
                delta = -(err[:, None] * step_normals[group]).reshape(-1)
                dq = dq + _damped_step(Jall[group].reshape(-1, self.nq), delta)
        return self._within_limits(q + C @ dq) - q

    def _surface_normals(self, q: np.ndarray, idx: np.ndarray, human: np.ndarray) -> np.ndarray:
        """(k, 3) for the contacting fingers ``idx`` at ``q``: the object's outward normal
        [world] where each finger's contact link is nearest it (the direction in which the
        link–object distance grows, from the contact term's distance query: the gradient of
        the object's signed distance at that point), where the link is outside the surface or
        within the penetration margin + 0.5 mm of it and that normal is within 45° of the
        human contact's (``human`` (k, 3)): the link touches the face the human's phalanx
        does. Elsewhere the human's normal: deeper, the nearest face from inside need not be
        the one the link touches; beyond 45°, the link's nearest point is on an edge or
        another face (a fingertip over a cube's edge), where pressing along that normal does
        not squeeze the object as the human does."""
        out = np.array(human, dtype=np.float64, copy=True)
        _, _, gap = self.contacts.nearest_of(q, idx)
        n = self.contacts.nearest_directions(q, idx)
        use = (gap > -(self.cfg.penetration_margin + 5e-4)) & (
            np.einsum("ki,ki->k", n, out) > np.cos(np.radians(45.0))
        )
        out[use] = n[use]
        return out

    def _servo_follower_map(self, q: np.ndarray) -> np.ndarray:
        """``(nq, nq)`` map from a displacement of the servoed finger joints to every joint's,
        the unservoed finger joints following through the model's couplings
        (``CouplingLimit.follower_map``; Ability's and Inspire's distal joints, SVH's 11 mimic
        joints, Shadow's distal J0): zero columns for the wrist and the followers. Cached when
        the couplings are linear (every hand here)."""
        if self._servo_map is not None:
            return self._servo_map
        C = servo_follower_map(self.scene.model, q, self.nq, self._coupling)
        C[:, :6] = 0.0  # the wrist's servos do not squeeze
        if self._coupling.linear:
            self._servo_map = C
        return C

    def _squeeze(self, q: np.ndarray, active: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """``grip="depth"``: joint offset pressing each contacting finger ``squeeze_depth``
        into the surface.

        ``Δq = C (J C)ᵀ (J C (J C)ᵀ + λ I)⁻¹ δ`` with ``δ = −depth · n`` per active contact,
        ``J`` the contact points' Jacobians and ``C`` the servoed finger joints' follower map
        (the wrist does not move; coupled joints follow their servo).
        """
        dq = np.zeros(self.nq)
        if self.contacts is None or self.cfg.squeeze_depth <= 0 or not active.any():
            return dq
        self.kin.forward(q)
        idx = np.flatnonzero(active)
        bodies, P, _ = self.contacts.nearest_of(q, idx)
        J = self.kin.point_jacobians(bodies, P)[:, :, : self.nq]
        J = J.reshape(-1, self.nq)
        C = self._servo_follower_map(q)  # the servos move; coupled joints follow them
        delta = np.concatenate([-self.cfg.squeeze_depth * normals[i] for i in idx])
        dq = C @ _damped_step(J @ C, delta)
        return self._within_limits(q + dq) - q

    def _objectives(self):
        objs = [self.keypoints, self.posture, self.smooth]
        if any(self.wrist.weight):  # (a hand with wrist_weight 0: no wrist term to build)
            objs.insert(0, self.wrist)
        if self.vec_human:
            objs.append(self.vectors)
        if self.cfg.use_contacts and self.contacts is not None:
            objs.append(self.contacts)
        return objs

    def _solve_frame(
        self,
        q: np.ndarray,
        iterations: int,
        timestamp: np.ndarray,
        t: int,
        q_prev: np.ndarray | None = None,
    ) -> np.ndarray:
        dt = float(timestamp[t] - timestamp[t - 1]) if t > 0 else 1.0 / 30.0
        frame = []
        if q_prev is not None and np.isfinite(self.cfg.max_wrist_speed):
            frame = [FrameSpeedLimit(q_prev, self._wrist_speed)]
        if self._mink is not None:
            return self._mink.solve(q, iterations, frame, dt)
        limits = [*self.limits, self._velocity, *frame] if t > 0 else self.limits
        objectives = self._objectives()
        extra = self.cfg.max_feasibility_iterations
        i = fixes = 0
        while True:
            self.kin.forward(q)
            state = RobotState(q=q, kin=self.kin, dt=dt)
            try:
                dq = self._solve_step(state, objectives, limits)
            except QPSolveError:
                if not fixes:
                    raise
                # The trust region is too small to back out as far as the rows ask: keep the
                # last solution (deeper than the margin, shallower than without the re-steps).
                return q
            q = q + dq
            i += 1
            if not fixes and i < iterations and np.abs(dq).max() >= self.cfg.step_tolerance:
                continue
            # The rows are linear in the step; a finger sliding or turning on a curved surface
            # (or a box fingertip rolling onto its edge) can end the step deeper than the
            # margin, or inside a clearance (Shadow's middle proximal swinging round the
            # example cube2's edge from 24 mm off, outside every row: 0.2 mm from the cube
            # instead of 2). Check the end point and take more steps while it violates a
            # margin, each in a trust region 4× smaller than the last: at full speed the
            # linearisation can flip between two rows every step (LEAP's index finger on the
            # built-in cylinder2/extension_type: 0.17 rad steps, 2.2 mm deep after 10 of them).
            if fixes >= extra or not self._violates_margins(q):
                return q
            fixes += 1
            limits = [*self.limits, self._trust_region(fixes), *frame]

    def _trust_region(self, fixes: int) -> VelocityLimit:
        """The velocity bound of an end-of-step re-step (both backends): ``fixes`` (≥ 1)
        times 4× smaller than the per-iterate bound."""
        return VelocityLimit(self.cfg.max_joint_speed * 0.25**fixes)

    def _solve_step(self, state: RobotState, objectives, limits) -> np.ndarray:
        """One QP step. If it is infeasible because a penetrating pair cannot back out as
        far as its row asks (joint limits in the way; a random Allegro pose in the round-trip
        test), solve again with the collision rows only forbidding deeper penetration."""
        try:
            return solve_qp(build_qp(state, objectives, limits, self.cfg.damping), self.cfg.solver)
        except QPSolveError:
            lims = [x for x in (self.collision, self.self_collision) if x is not None]
            if not lims:
                raise
            for x in lims:
                x.hold_only = True
            try:
                return solve_qp(
                    build_qp(state, objectives, limits, self.cfg.damping), self.cfg.solver
                )
            finally:
                for x in lims:
                    x.hold_only = False

    def _warm_start(
        self, Q_last: np.ndarray, wq: np.ndarray, active: np.ndarray, t: int
    ) -> np.ndarray:
        """Frame ``t``'s starting point from the last two solutions ``Q_last`` (2, nq), the
        human wrist's joint coordinates at ``t − 1`` and ``t`` and the contact flags: the
        wrist moves as the human's did, the fingers at their last velocity unless a contact
        switched in the last two frames (its jump is no velocity to go on with). A prediction
        deeper in the object than the margins falls back to the last solution (more than one
        step may be needed to undo it: the example cube2/tripod, Shadow, 17 mm deep). The
        prediction is clipped to the solver's joint ranges (inside the servos' by
        ``joint_limit_margin``)."""
        q0 = predicted_start(Q_last, wq, active, t, self._solve_lower, self._solve_upper)
        return Q_last[1] if self._too_deep(q0) or self._breaks_couplings(q0) else q0

    COUPLING_TOLERANCE = 5e-3
    """A warm-start prediction whose joint couplings are off by more than this [rad or m] falls
    back to the last solution (``_warm_start``)."""

    def _breaks_couplings(self, q: np.ndarray) -> bool:
        """Whether ``q`` breaks one of the model's joint couplings by more than
        :attr:`COUPLING_TOLERANCE`. The prediction is clipped to the joint ranges joint by
        joint, so a driving joint stopped at its limit while the joint it drives went on
        breaks their coupling; the QP's equality rows then ask more than one iterate's
        velocity bound allows to undo it, and the frame's QP is infeasible."""
        c = self._coupling
        if not c or not c.rows:
            return False
        _, b = c.equalities(RobotState(q=q, kin=self.kin))
        return bool(b.size) and float(np.abs(b).max()) > self.COUPLING_TOLERANCE

    def _within_limits(self, q: np.ndarray) -> np.ndarray:
        """``q`` clipped to the servo commands' joint ranges (``np.clip`` costs 2.3× as much on
        30 dofs: 3.2 against 1.4 µs)."""
        return np.minimum(np.maximum(q, self.lower), self.upper)

    def _too_deep(self, q: np.ndarray) -> bool:
        """Whether ``q`` is deeper than a collision limit's margin + 0.5 mm anywhere (one
        sweep, which the frame's first iterate then reuses)."""
        for lim in (self.collision, self.self_collision):
            if lim is not None and lim.min_distance(q) < -(lim.margin + 5e-4):
                return True
        return False

    def _violates_margins(self, q: np.ndarray) -> bool:
        """Whether some pair at ``q`` is closer than its margin allows, by more than 0.5 mm:
        deeper than the penetration margin, or inside a clearance (a link the human keeps
        clear of the object, the table).

        Only the pairs near at the last linearisation are checked
        (``CollisionLimit.near_violation``: a step from farther away would need a joint speed
        the velocity rows rarely allow)."""
        for lim in (self.collision, self.self_collision):
            if lim is not None and lim.near_violation(q) < -5e-4:
                return True
        return False


def contact_ramp(active: np.ndarray, frames: float) -> np.ndarray:
    """(T, F) weight factors in (0, 1] of contacts ``active`` (T, F): a contact's weight rises
    over its first ``frames`` frames and falls over its last ones (1 where inactive, unused)."""
    T, F = active.shape
    since = np.zeros((T, F))
    until = np.zeros((T, F))
    run = np.zeros(F)
    for t in range(T):
        run = np.where(active[t], run + 1, 0)
        since[t] = run
    run = np.zeros(F)
    for t in range(T - 1, -1, -1):
        run = np.where(active[t], run + 1, 0)
        until[t] = run
    n = max(float(frames), 1.0)
    return np.where(active, np.minimum(1.0, np.minimum(since, until) / n), 1.0)


def opposed_contacts(active: np.ndarray, normals: np.ndarray, cos_max: float = -0.3) -> np.ndarray:
    """(F,) which active contacts have another active contact pushing back against them.

    A contact is opposed when some other active contact's surface normal points at least
    ~107° away from its own (``nᵢ·nⱼ < cos_max``): pressing both squeezes the object between
    them. An unopposed finger (the first finger to arrive, one resting on the top face while
    others grip the sides) pressed into the surface only pushes the object (Allegro on
    generated cylinder6/rotation: the index alone on the top face at 11 N, 7× the
    cylinder's weight, before the grasp closes)."""
    a = np.asarray(active, bool)
    n = np.asarray(normals, dtype=np.float64)
    dots = n @ n.T
    ok = (dots < cos_max) & a[None, :] & a[:, None]
    return a & ok.any(axis=1)


def _geom_pairs(m: mujoco.MjModel, names: list[tuple[str, str]]) -> list[tuple[int, int]]:
    """Geom ids of named pairs in ``m`` (the retargeting scene shares the hand's geom names)."""
    out = []
    for a, b in names:
        ia = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, a)
        ib = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, b)
        if ia < 0 or ib < 0:
            raise RetargetError(f"self-collision pair ({a!r}, {b!r}) is not in the scene")
        out.append((ia, ib))
    return out


def _damped_step(J: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Least-norm joint step moving the points of Jacobian ``J`` by ``delta``:
    ``Jᵀ (J Jᵀ + λ I)⁻¹ δ`` with a small damping λ = 1e-6."""
    return J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(J.shape[0]), delta)


class _MinkSolver:
    """The mink backend: our objectives as mink tasks, mink's limits, ``mink.solve_ik``."""

    def __init__(self, rt: Retargeter):
        import mink

        self.rt = rt
        m = rt.scene.model
        self.configuration = mink.Configuration(m)
        # One MjData for mink, our kinematics and the collision queries: the object pose set
        # on the scene is the one mink's collision limit sees.
        self.configuration.data = rt.scene.data
        self.kin = rt.kin
        cl = mink.ConfigurationLimit(m, gain=1.0)
        # The kinematic solution's ranges (inside by the joint limit margin), as on the
        # Pinocchio backend: the hand's joints are the scene's first qpos entries.
        lim = m.jnt_limited[: rt.nq].astype(bool)
        cl.lower[: rt.nq][lim] = rt._solve_lower[lim]
        cl.upper[: rt.nq][lim] = rt._solve_upper[lim]
        self.limits = [cl]
        if rt.collision is not None:
            # Our hand–object rows, as on the Pinocchio backend: per-pair margins (the table's
            # clearance, the clearance of links the human keeps off the object) and the further
            # contacts mj_collision reports, which mink's CollisionAvoidanceLimit (one minimum
            # distance, closest points only) cannot express.
            self.limits.append(self._rows(rt.collision))
        if rt.self_collision is not None:
            # One mink pair per self-collision pair: grouping all hand geoms would also pair
            # links of one finger and the resting contacts the hand excludes.
            name = lambda g: m.geom(g).name  # noqa: E731
            self.limits.append(
                mink.CollisionAvoidanceLimit(
                    m,
                    geom_pairs=[([name(a)], [name(b)]) for a, b in rt.self_pairs],
                    gain=1.0,
                    minimum_distance_from_collisions=-rt.cfg.self_collision_margin,
                    collision_detection_distance=rt.cfg.self_collision_distmax,
                )
            )
        self.constraints = [mink.EqualityConstraintTask(m, cost=1.0)] if m.neq else []
        coupling = next((c for c in rt.limits if isinstance(c, CouplingLimit)), None)
        if coupling is not None and coupling.ranges:
            # Limited fixed tendons (Shadow's distal coupling): mink has no tendon limit.
            self.limits.append(self._rows(coupling))
        self.frame_dt = 1.0 / 30.0  # the frame's time step (FrameSpeedLimit's band)

    def _rows(self, limit):
        """One of our limits as a mink limit: its rows ``G Δq ≤ h`` and its finite box
        bounds, at the configuration mink solves at (``Δq = v·dt``)."""
        import mink

        kin, nq, solver = self.kin, self.rt.nq, self

        class _Rows(mink.Limit):
            def compute_qp_inequalities(self, configuration, dt):
                state = RobotState(q=configuration.q[:nq].copy(), kin=kin, dt=solver.frame_dt)
                G, h = limit.inequalities(state)
                box = limit.bounds(state)
                if box is not None:
                    eye = np.eye(nq)
                    lo, hi = box
                    up, dn = np.isfinite(hi), np.isfinite(lo)
                    G = np.concatenate([G, eye[up], -eye[dn]])
                    h = np.concatenate([h, hi[up], -lo[dn]])
                if not G.shape[0]:
                    return mink.Constraint()
                return mink.Constraint(G=G * dt, h=h)

        return _Rows()

    def _task(self, objective):
        import mink

        kin = self.kin

        class _Task(mink.Task):
            def __init__(self):
                super().__init__(cost=np.ones(1))

            def _state(self, configuration):
                return RobotState(q=configuration.q.copy(), kin=kin)

            def compute_error(self, configuration):
                return objective.error(self._state(configuration))

            def compute_jacobian(self, configuration):
                return objective.jacobian(self._state(configuration))

            def compute_qp_residual(self, configuration):
                # mink stacks (√W J, −√W e) of all tasks: H = JᵀWJ, c = JᵀWe, as ours.
                s = self._state(configuration)
                e = objective.error(s)
                if e.size == 0:
                    return np.zeros((0, s.nv)), np.zeros(0), 0.0
                sw = np.sqrt(objective.weights(e.shape[0]))
                return sw[:, None] * objective.jacobian(s), -sw * e, 0.0

            def compute_qp_objective(self, configuration):
                H, c = objective.qp_terms(self._state(configuration))
                return mink.Objective(H, c)

        return _Task()

    def solve(self, q: np.ndarray, iterations: int, frame=(), dt: float = 1.0 / 30.0):
        """``iterations`` mink steps from ``q``; ``frame``: per-frame limits of ours (the
        wrist's speed bound), ``dt`` the frame's time step."""
        import mink

        conf = self.configuration
        conf.update(q)
        self.frame_dt = dt
        tasks = [self._task(o) for o in self.rt._objectives()]
        limits = [*self.limits, *(self._rows(x) for x in frame)]
        cfg = self.rt.cfg

        def step(limits):
            v = mink.solve_ik(
                conf, tasks, dt=1.0, solver=cfg.solver, damping=cfg.damping,
                limits=limits, constraints=self.constraints or None,
            )  # fmt: skip
            conf.integrate_inplace(v, 1.0)
            return v

        for _ in range(iterations):
            if np.abs(step(limits)).max() < cfg.step_tolerance:
                break
        # The Pinocchio backend's end-of-step check (``_solve_frame``): while the solution is
        # deeper than the margins, more steps in trust regions 4× smaller each time (Allegro's
        # proximal box on the cube's face flipped between two rows: 3–4 mm deep every other
        # frame without them).
        for fixes in range(1, cfg.max_feasibility_iterations + 1):
            if not self.rt._violates_margins(conf.q[: self.rt.nq]):
                break
            step([*limits, self._rows(self.rt._trust_region(fixes))])
        return conf.q.copy()
