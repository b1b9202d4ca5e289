"""``python -m benchmarks.force_preservation``: the benchmark's command line."""

from benchmarks.force_preservation.cli import main

raise SystemExit(main())
