"""Force preservation: do retargeted robot hands move the object like the human, pressing alike?

Demonstrations: ``--n-pairs`` (default 20) generated pairs of the built-in demonstrations, spread
evenly over the four groups (power, intermediate, precision, in-hand) exactly as
``benchmarks.retarget_speed_quality`` picks them (``_common.load_demonstrations``), cropped to
``--max-frames`` if given. Light and heavy: a pair whose object has a weighted ``H`` variant in
the catalogue (``taxonomy.heavy_variant``: cube2 → cube2h) is also run as a heavy version of the
same demonstration: the human is simulated with ``SimConfig(object_id=<heavy id>)`` and every
robot variant retargeted and re-simulated with the heavy object's geometry (same shape, its
mass). ``--no-heavy`` leaves them out.

Human forces: every (pair, object) goes once through the force pipeline
(``dexcanvas_core.sim.pipeline.simulate``; sampling MPC, or ``--human-tracker open_loop`` for
speed). Where it does not reproduce the demonstration (DexCanvas rule) there are no human forces
to match: variant (d) is skipped for it (counted and listed) and the force columns of the other
variants stay empty.

Human replay (``--no-human-replay`` to skip; ``mpc`` only): every (pair, object) the force
pipeline reproduced is simulated a second time with another seed of its sampling MPC
(``HUMAN_REPLAY_SEED``), and the replay's per-finger forces are scored against the first
simulation's exactly as a robot's are (``retarget.metrics.human_replay_metrics``). The human's
forces are one sample of a stochastic tracker: a robot matched to that sample cannot be
expected to correlate with it better than another equally valid sample does, so the replay
is the force correlation's ceiling, reported on the same runs and fingers as each variant's
(``replay_ceiling``), and the replay's success on light and heavy objects is the heavy/light
parity the human hand model itself reaches (``human_heavy_vs_light``). It doubles the force
pipeline's CPU time (cached with ``--human-cache`` like the first simulations).

Per hand (``--hands``, default every registered hand; a hand skips pairs it cannot perform,
``retarget.pipeline.check_pair``) and per (pair, object), five variants side by side:

* **(a) dex-retargeting** — its position retargeting (``retarget.baselines``, free wrist unless
  ``--dex-wrist fixed``) on the same scaled keypoint targets, re-simulated on its ``q``;
* **(b) keypoints** — ``Retargeter`` with ``use_contacts=False, squeeze_depth=0``;
* **(c) + contacts** — default ``RetargetConfig`` (contact preservation, the 10 mm grip squeeze),
  re-simulated on ``q_command``; contacts inferred from the demonstration's geometry, as the
  kinematic product does without the force pipeline;
* **(d) + forces** — ``force_matching=True`` on the force-annotated demonstration (contacts
  inferred from its geometry as in (c), the human's per-finger forces from its records →
  force-distribution QP → ``K⁻¹Jᵀf`` offsets),
  re-simulated on ``q_command`` with the force pipeline's contacts
  (``retarget.validate.FORCE_CONTACT_TIMECONST``, 20 ms: the default contacts (a)–(c) have too),
  then force-calibrated as ``retarget run --forces`` does (``retarget.force_calibration``,
  ``--calibrate-iterations``, default 10; 0: the planned commands): the row is the chosen
  iterate's, with the planned commands' success in ``planned_success``;
* **(e) + refinement** — (d), and where (d)'s replay fails, ``retarget.refine.refine``: the
  force pipeline's sampling MPC on the robot hand (its contacts as (d)'s), starting from (d)'s
  commands; success and object errors are the refined rollout's (no force columns: the
  refinement reports no per-finger forces), plus how far the commands moved.

Measured per run (``Resimulator``: the hand's own position servos, object free on a table):

* strict success (no frame with object position error > 5 cm) and mean-error success (mean
  < 10 cm and < 0.5 rad); mean object position [cm] and rotation [°] errors;
* force correlation — ``retarget.metrics.force_metrics``: per corresponding finger, the correlation
  of the human's and the re-simulated robot's contact-force magnitudes, averaged over fingers
  (runs with human forces only; the human side is (d)'s ``human_force``), two ways: over the
  whole demonstration (the force *profile*, on/off timing included) and over only the frames
  where either finger touches (how the force varies while in contact); over the fingers the
  human loaded (> 0.05 N on more than 2 frames), a robot finger that never presses there
  scoring 0; and the whole-demonstration one over the load-bearing fingers only (those
  carrying at least ``retarget.force_scores.LOAD_BEARING_SHARE`` of the hand's mean force: the
  breakdown that separates the grip from light touches; the target is checked on all);
* object force error — mean over frames where the human touches of ‖Σ robot contact forces −
  Σ human contact forces‖ [N] (the force part of the hand's wrench on the object; the
  re-simulation reports no contact points, so no torque), also as % of the object's weight m·g;
* contact precision / recall, and for (d) the share of frames whose required force the force QP
  could produce (``wrench_feasible_fraction``);
* penetration — deepest kinematic hand–object penetration of the solution ``q`` [mm] and the
  deepest one seen in the re-simulation;
* ms/frame — the per-frame retargeting loop (ours: QP solve + squeeze or force QP; dex-
  retargeting: its per-frame call), divided by the frame count. The force pipeline's time is
  reported per simulation, apart.

Aggregates (errors count as failures; skipped (d) runs are not runs): per hand and over the
five-finger hands (five distinct robot fingers), per variant; heavy vs light per variant (all
runs, and the same (hand, pair) with both objects). The "target met?" table checks the issue's
targets on the five-finger hands (on every hand run when none was): (d) strict success ≥ 85 %
(and (e)'s: the issue asks for it "with (d) or (e)") and ≥ 2× (a)'s on the same runs; mean
force correlation ≥ 0.8 (both ways) and object force error ≤ 15 % of the weight on (d)'s
successful runs; heavy variants succeed as often as their light ones ((d), and (e)).

Writes JSON (default ``benchmarks/results/force_preservation/<date>-<commit>.json``,
atomically) and a PNG of strict success by variant and hand (grouped bars, next to the JSON
unless ``--plot``). Work runs on ``--workers`` spawned processes, one thread each::

    python -m benchmarks.force_preservation                      # 20 pairs, every hand, MPC
    python -m benchmarks.force_preservation --hands allegro --n-pairs 2 \\
        --human-tracker open_loop --workers 1 --out /tmp/fp7.json   # smoke run

Ablations of the retargeting: ``--variants`` runs a subset (the others' rows are marked
skipped; (e) brings (d)), ``--set NAME=VALUE`` changes a ``RetargetConfig`` field of our
variants (each variant's defining fields win), and ``--human-cache DIR`` stores each human
simulation (its record as JSON and the force-annotated demonstration as a Lance dataset,
:mod:`benchmarks.force_preservation.cache`) keyed by the demonstration's data, the object, the
tracker's ``SimConfig`` and the force pipeline's source (``dexcanvas_core.sim``, ``.mano``), so
a second run reads them back instead of running the force pipeline again::

    python -m benchmarks.force_preservation --hands shadow ability inspire svh leap \\
        --variants d --human-cache ~/.cache/dexcanvas-retarget/human-sims \\
        --set contact_tangent_weight=0.2 --out /tmp/ablation.json

Modules: ``config`` (``BenchConfig``, variants, targets), ``jobs`` (the work per case and the
worker pool), ``cache`` (the human-simulation cache), ``aggregate`` (aggregates and target
checks), ``tables`` and ``plots`` (output), ``cli`` (``run_benchmark`` and ``main``).
"""
