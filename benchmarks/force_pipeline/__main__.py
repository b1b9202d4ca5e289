"""``python -m benchmarks.force_pipeline``: the benchmark's command line."""

from benchmarks.force_pipeline.cli import main

raise SystemExit(main())
