#!/usr/bin/env bash
# Set up the project in ./.venv (idempotent). Needs Python >= 3.10 and the package registries.
# torch is pinned first: torch==2.13.0 is a CPU wheel available offline on the reference
# machines; any other spec would pull a multi-GB CUDA build.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}

# System packages of the renderers (retarget snapshot / report): headless Chromium for the
# meshcat pages, EGL or OSMesa for MuJoCo's offscreen renderer. Installed only when missing,
# as root, with apt; otherwise a note (the renderers' tests then fail, naming the package:
# tests/system_packages.py).
RENDER_PKGS="chromium libosmesa6 libegl1 libegl-mesa0 libgl1-mesa-dri"
if command -v dpkg-query >/dev/null 2>&1; then
  missing=""
  for pkg in $RENDER_PKGS; do
    if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
      missing="$missing $pkg"
    fi
  done
  if [ -n "$missing" ]; then
    if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
      echo "setup: installing renderer packages:$missing"
      export DEBIAN_FRONTEND=noninteractive
      # shellcheck disable=SC2086  # one word per package
      if ! apt-get install -y -q --no-install-recommends $missing >/dev/null; then
        apt-get update -q >/dev/null
        apt-get install -y -q --no-install-recommends $missing >/dev/null \
          || echo "setup: note: could not install$missing; stills need them (see README)"
      fi
    else
      echo "setup: note: stills need the Debian packages$missing; as root run:"
      echo "  apt-get install -y --no-install-recommends$missing"
    fi
  fi
else
  echo "setup: note: not a Debian system; for stills install Chromium and Mesa's EGL or OSMesa"
fi

if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q "torch==2.13.0"
.venv/bin/python -m pip install -q -e ".[dev,bench]"
