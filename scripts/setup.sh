#!/usr/bin/env bash
# Set up the project in ./.venv (idempotent). Needs Python >= 3.10 and the package registries.
# torch is pinned first: torch==2.13.0 is a CPU wheel available offline on the reference
# machines; any other spec would pull a multi-GB CUDA build.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q "torch==2.13.0"
.venv/bin/python -m pip install -q -e ".[dev,bench]"
