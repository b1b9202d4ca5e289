"""``python -m benchmarks.real_motion``: the benchmark's command line."""

from benchmarks.real_motion.cli import main

raise SystemExit(main())
