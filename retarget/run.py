"""``retarget run``: retarget one demonstration onto one robot hand, re-simulate, write results.

``run_retarget(RunConfig(hand="shadow", pair="cube2/tripod"))`` is what the CLI calls; library
users can call it too (or :func:`retarget.pipeline.run_pipeline` for the results in memory,
without files). It writes into ``out``:

* ``robot_trajectory.npz`` — joint positions and servo commands (MuJoCo ``qpos`` order, names
  included), timestamps, fingertip positions, per-frame keypoint/contact errors and hand–object
  distances, simulated object pose, per-finger contact forces;
* ``metrics.json`` — the numbers (success, object errors, keypoint error, hand–object and
  finger–finger penetration, speed).

Both files are written atomically (a unique temporary file, then rename), by one process at a
time (a second run on the same ``out`` is refused while the first holds its lock); an ``out``
holding a run is refused without ``overwrite``, checked before any work.
"""

from __future__ import annotations

from retarget.metrics import run_metrics
from retarget.outputs import open_run_dir, write_run
from retarget.pipeline import RunConfig, check_options, run_pipeline
from retarget.summary import print_summary

__all__ = ["RunConfig", "run_retarget"]


def run_retarget(cfg: RunConfig) -> dict:
    """Run the pipeline (:func:`retarget.pipeline.run_pipeline`), write its files into
    ``cfg.output_dir()`` and, with ``cfg.progress``, print the summary; return the metrics.

    Raises:
        RetargetError: bad options, an unknown hand or pair, a missing demonstration, human
            forces the force pipeline could not produce.
        dexcanvas_core.safe_io.OutputError: ``cfg.out`` holds a run and ``cfg.overwrite`` is
            false, cannot be written, is a file, or another process is writing it (checked
            before any work).

    >>> import os, tempfile
    >>> out = tempfile.mkdtemp()
    >>> m = run_retarget(RunConfig(hand="panda", pair="cube2/tripod", out=out, progress=False))
    >>> m["hand"], m["pair"], sorted(os.listdir(out))
    ('panda', 'cube2/tripod', ['metrics.json', 'robot_trajectory.npz'])
    """
    check_options(cfg)  # bad options before the output directory is made
    with open_run_dir(cfg.output_dir(), overwrite=cfg.overwrite) as out_dir:
        result = run_pipeline(cfg)
        metrics = run_metrics(result, cfg)
        write_run(out_dir, result, metrics)
    if cfg.progress:
        print_summary(metrics, out_dir)
    return metrics
