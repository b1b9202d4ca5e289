"""The README's Python example runs as written, on a short window of the demonstration (the
grasp and the lift of the built-in ``cube2/tripod``, so force matching has forces to match)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(), re.S)


def test_readme_python_example_runs_and_gives_what_it_says():
    blocks = python_blocks()
    assert len(blocks) == 1, "the README has one Python example"
    code = blocks[0]
    load = 'dc.load_demonstration("cube2/tripod")'
    assert load in code
    ns: dict = {}
    exec(compile(code.replace(load, f"{load}.slice(230, 330)"), str(README), "exec"), ns)
    result, metrics, tips, obs, done = (ns[k] for k in ("result", "metrics", "tips", "obs", "done"))
    T = result.trajectory.num_frames
    assert T == 100 and result.robot.q_command.shape == (T, result.robot.q.shape[1])
    assert result.human_sim is not None, "the force pipeline simulated the human's forces"
    assert result.calibration is not None, "the commands were force-calibrated"
    assert metrics["forces"] and metrics["frames"] == T
    assert tips.shape[0] == T and tips.shape[2] == 3 and np.isfinite(tips.numpy()).all()
    assert done.shape == (1024,) and all(v.shape[0] == 1024 for v in obs.values())
