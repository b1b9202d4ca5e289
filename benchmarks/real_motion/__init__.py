"""Real motion: robot hands and the MANO force pipeline on real captures and fast real-like motions.

The built-in demonstrations move slowly (wrist ≤ 0.55 m/s); real wrists carry objects at
2.5–3 m/s. This benchmark runs the toolkit on two kinds of cases:

* **real captures** under ``--captures DIR`` (nothing is downloaded; a missing set is named, with
  where to get it): ``DIR/mano-npz/*.npz`` (format ``mano-npz``), ``DIR/dexycb/`` (DexYCB as
  HO-3D-style meta pickles, format ``ho3d``: the sequences whose object is one of the DexCanvas
  YCB items, ``--per-object N`` each, chosen deterministically; the YCB models from
  ``--models DIR``) and ``DIR/taco/`` (format ``taco``). Left hands are mirrored to right ones
  (``mirror_left``). A format whose reader this checkout lacks
  (``dexcanvas_core.capture.formats.READERS``) is skipped, and said so. Each capture is imported
  (``dexcanvas import``) into its own dataset; an object that neither the capture nor the
  catalogue gives a mass (e.g. the mustard bottle) gets ``--density`` (500 kg/m³) × its mesh's
  volume;
* **stress cases**: built-in pick-and-place demonstrations whose hand holds the object
  (``--pairs``), each turned into fast rigid motions of the held object inserted into its hold
  (``dexcanvas_core.capture.stress``: carry 0.3 m at 1.5 m/s; transport 0.45 m at 2 m/s, 0.7 m
  at 2.5 m/s, 1.0 m at 3 m/s; tool use 60° at 4 rad/s; the lift 3× faster), exported as
  ``mano-npz`` and imported into one dataset. Each case's peak wrist speed and acceleration are
  recorded.

Runs, per hand (``--hands``, default every five-finger hand) × case × mode: ``keypoints``
(``retarget run``), ``forces`` (``--forces``), ``forces_refine`` (``--forces --refine``); and per
case the MANO force pipeline (``dexcanvas simulate``, mode ``mano``). The force modes take the
human's forces from that simulation (the same one ``retarget run --forces`` would make, at the
same seed); where it lost the object they fail without running ("no human forces"), as
``retarget run --forces`` does.

Measured per run:

* **strict success in the contact window**: no frame between the row's ``object_move`` start and
  end frames with an object position error above 5 cm (the re-simulation's per-frame error in
  ``robot_trajectory.npz``; ``forces_refine`` where the open loop failed there: the physics
  refinement's, which succeeds when it never lost the object or lost it after the window's end).
  The DexCanvas rule over the whole clip is kept beside it (``success``);
* **wrist tracking error**: mean over the clip of the re-simulated wrist's distance [mm] and
  largest hinge error [deg] from its command (the open-loop re-simulation's);
* **object error max** in the window [cm] (runs the refinement kept: its max over the frames it
  tracked), **kinematic penetration max** [mm], **ms/frame** (the retargeting loop) and the
  run's **wall time** [s];
* the MANO pipeline: strict success in the window, and for a failure its frame, phase (before,
  in or after the window) and the force pipeline's own diagnosis (``failure`` of its metrics,
  ``dexcanvas_core.sim.diagnosis``: wrist lag, lost contact, slip or knocked, with the wrist lag
  and slip behind the call).

Jobs run on ``--workers`` spawned processes and are resumable: each finished job's record is
written atomically to ``--work DIR`` (default ``benchmarks/results/real_motion_work/``), and a
rerun skips it (``--retry-errors`` reruns those that raised); the imported datasets are kept
there too. Prints a table per mode (cases × hands and MANO) and a summary (per hand × mode), and
writes JSON (default ``benchmarks/results/real_motion/<date>-<commit>.json``) and the page
``docs/benchmarks/real_motion.md`` (``python -m benchmarks.pages`` regenerates it from the newest
JSON)::

    python -m benchmarks.real_motion --captures DIR --models DIR --workers 2
    python -m benchmarks.real_motion --hands shadow --modes keypoints --cases carry --limit 1
    python -m benchmarks.pages

Modules: ``config`` (``BenchConfig``, modes, capture sets, targets), ``cases`` (stress and real
captures, imported once), ``jobs`` (the job store, the work per job, the scheduler),
``aggregate`` (a job's record, aggregates, target checks), ``tables`` (terminal tables and the
page), ``cli`` (``run_benchmark`` and ``main``).
"""
