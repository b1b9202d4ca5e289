"""The benchmarks: each one a command, ``python -m benchmarks.<name>``, that prints its tables
and writes its numbers with the commit, machine and command that produced them to
``benchmarks/results/<name>/<date>-<commit>.json``; ``python -m benchmarks.pages`` writes the
pages in ``docs/benchmarks/`` from the newest file of each folder.

Packages (one module per step: ``config``, ``jobs``, ``aggregate``, ``tables``, ``cli``, ...):
``force_preservation``, ``force_pipeline``, ``real_motion``. Modules: ``retarget_speed_quality``,
``wrist_tracking``, ``ycb_models``, ``mocap_fit``, ``rl_buffer``, ``capture_conventions``,
``scale`` (its arithmetic and page in ``scale_report``).
Shared helpers (demonstration suites, re-simulation, worker pools, table cells, result paths):
``_common``. How each benchmark measures: its docstring.
"""
