"""Helpers shared by the benchmarks: the demonstration suite and atomic JSON output.

The suite is the built-in generator's (``dexcanvas_core.demos``): ``pick_pairs`` takes feasible
(object, manipulation type) pairs round-robin over the 21 types (shuffled within a type by the
seed), ``generate_one`` generates the demonstration of the ``i``-th pair with operator
``i mod 5`` and seed ``seed + i`` (retrying an infeasible seed), so every benchmark that uses
them sees the same demonstrations for the same ``--seed``.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import numpy as np

GENERATION_ATTEMPTS = 3
"""Seeds tried per pair (``seed + i + 1000·attempt``) before a pair is given up."""


def pick_pairs(n: int, seed: int) -> list:
    """``n`` feasible pairs, round-robin over the manipulation types (shuffled within a type)."""
    from dexcanvas_core.demos import feasible_pairs

    rng = np.random.default_rng(seed)
    by_type: dict[str, list] = {}
    for p in feasible_pairs():
        by_type.setdefault(p.manipulation_type.name, []).append(p)
    for v in by_type.values():
        rng.shuffle(v)
    types = sorted(by_type)
    out = []
    k = 0
    while len(out) < n:
        t = types[k % len(types)]
        out.append(by_type[t][(k // len(types)) % len(by_type[t])])
        k += 1
    return out


def operator_for(i: int) -> str:
    """The operator of the ``i``-th demonstration of a suite (cycled over the five)."""
    from dexcanvas_core.demos import OPERATORS

    ops = sorted(OPERATORS)
    return ops[i % len(ops)]


def generate_one(pair, i: int, seed: int) -> tuple:
    """``(demo, seed_used)``: the ``i``-th demonstration of a suite (module docstring).

    Raises the last generation error when every attempt failed.
    """
    from dexcanvas_core.demos import generate_demo

    for attempt in range(GENERATION_ATTEMPTS):
        s = seed + i + 1000 * attempt
        try:
            return generate_demo(pair, operator_for(i), s), s
        except Exception as e:  # a rare infeasible seed: try another
            if attempt == GENERATION_ATTEMPTS - 1:
                raise
            logging.warning("demo %s failed (%s); retrying with another seed", pair, e)
    raise AssertionError("unreachable")


def generate(n: int, seed: int) -> list:
    """The trajectories of the first ``n`` pairs (a pair whose every attempt fails is skipped)."""
    trajs = []
    for i, pair in enumerate(pick_pairs(n, seed)):
        try:
            demo, _ = generate_one(pair, i, seed)
        except Exception as e:
            logging.warning("demo %s skipped (%s)", pair, e)
            continue
        trajs.append(demo.trajectory if hasattr(demo, "trajectory") else demo)
    return trajs


def json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def atomic_write_json(path: Path, obj) -> None:
    """Write ``obj`` as indented JSON through a temporary file and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(obj, indent=2, default=json_default))
    os.replace(tmp, path)
