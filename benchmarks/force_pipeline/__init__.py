"""Force pipeline: tracking success, physical consistency and force signatures on a fixed suite.

The suite: ``--n-pairs`` (default 32) feasible pairs of the built-in generator
(``dexcanvas_core.demos``), taken round-robin over the 21 manipulation types (shuffled within a
type by ``--seed``, operators cycled: ``benchmarks._common``, the same demonstrations as
``benchmarks.mocap_fit``), one generated demonstration per pair. Every demonstration is
tracked in MuJoCo by the simulated MANO hand (``dexcanvas_core.sim.pipeline.simulate``,
``--tracker`` ``mpc`` or ``open_loop``, default settings otherwise) in up to three conditions
(``--conditions``):

* ``clean`` — the generated demonstration as it is;
* ``mocap`` — the same demonstration through the mocap stage: the marker stream
  (``mocap.render_markers``: 1 mm per-axis noise, 10 % single-sample dropouts, the renderer's
  default occlusion gaps and label swaps) fitted back (``mocap.fit_markers``, default options);
  the fitted MANO hand and object tracks are simulated, with the demonstration's object id;
* ``mocap_size`` — the mocap-fitted demonstration with the object's size changed by +20 % on
  even-numbered pairs and −20 % on odd ones (``SimConfig(object_scale=…)``; the hand reference
  follows the resized surface, ``sim.resize``, as in synthesis).

Heavy vs light: for every pair whose object has a weighted ``H`` variant in the catalogue
(``taxonomy.heavy_variant``: cube2 → cube2h), the clean demonstration is also simulated with
``SimConfig(object_id=<heavy id>)`` (same geometry, the heavy mass) unless ``--no-heavy``.

Reported per condition (one table; errors count as failures, the other columns are over the
runs that did not raise):

* strict success (DexCanvas: no frame with object position error > 5 cm, whole clip tracked)
  and loose success (mean error < 10 cm and < 0.5 rad), as rates over the pairs;
* object translation error [cm] and rotation error [deg]: mean over runs of each run's mean
  (a failed run's over the frames tracked until it failed);
* compute [s per demo-second]: median over runs of the tracking's process CPU time divided by
  the demonstration's duration; workers run one thread each, so this is one core's cost;
* Newton–Euler residual [% of m·g]: median over runs of each run's median of
  ‖F_hand + F_table + m·g − m·a‖ / (m·g), with ``a`` the simulated object's acceleration (sim)
  and the captured one (capture; both sides smoothed over 50 ms);
* static-hold weight ratio: median over runs with static-hold frames (object off the table,
  captured acceleration < 0.5 m/s²) of |mean vertical hand force / (m·g) − 1| [%];
* "target met?": the paper's targets — strict success ≥ 90 % nominal (``clean``, ``mocap``;
  the paper states it for its mocap-fitted suite) and ≥ 80 % with size perturbation
  (``mocap_size``), ≤ 5 s compute per demo-second, Newton–Euler ≤ 5 % (sim and capture), hold
  weight within 3 %.

Also printed: the force signature per manipulation type (first condition run): the mean over
that type's runs with a static hold of each part's share of the summed mean contact-force
magnitudes (thumb, index, middle, ring, pinky, palm); and heavy vs light per pair: masses and
their ratio, hold weight ratios, summed mean hold force [N] and its ratio.

Writes JSON (default ``benchmarks/results/force_pipeline/<date>-<commit>.json``, atomically):
every run's metrics, the demonstrations (with the mocap fit's errors), the aggregates and target
checks; and per-finger force plots (``sim.plots.plot_finger_forces``) of every run of the first
``--plots`` pairs into ``force_plots/`` next to the JSON. Runs are parallel over ``--workers``
processes (spawned; one OMP/MKL/torch thread each)::

    python -m benchmarks.force_pipeline                     # 32 pairs, 3 conditions, MPC
    python -m benchmarks.force_pipeline --n-pairs 2 --conditions clean mocap \\
        --tracker open_loop --workers 1 --plots 1 --out /tmp/fp.json   # smoke run
    python -m benchmarks.force_pipeline --conditions mocap --no-heavy \\
        --set grip_force_floor_n=None --out /tmp/fp_ablation.json       # an ablation

Modules: ``config`` (``BenchConfig``, conditions, targets, the runs of a pair), ``jobs`` (the
work per pair and the worker pool), ``aggregate`` (aggregates and target checks), ``tables``
(output), ``cli`` (``run_benchmark`` and ``main``).
"""
