"""Seeing the results: meshcat scenes, headless stills, plots and an offline HTML report.

One module per concept:

* ``data`` — what a picture shows per frame (:class:`~retarget.viz.data.SceneData`): a run
  directory, its human demonstration, the recorded re-simulation, contacts;
* ``view`` — layout and camera (:class:`~retarget.viz.view.SceneOptions`);
* ``meshcat_scene`` — the meshcat scene, a server bound to 127.0.0.1, :func:`view_run`;
* ``chromium`` / ``mujoco_render`` — the two still renderers;
* ``snapshot`` — ``retarget snapshot`` (:func:`run_snapshot`);
* ``plots`` — force, object-error and contact-heatmap plots (matplotlib, Agg);
* ``report`` — ``retarget report`` (:func:`run_report`).

Heavy imports (meshcat, matplotlib, MuJoCo rendering) happen on first use.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "ReportConfig": "retarget.viz.report",
    "RendererUnavailableError": "retarget.viz.errors",
    "SceneData": "retarget.viz.data",
    "SceneOptions": "retarget.viz.view",
    "SnapshotConfig": "retarget.viz.snapshot",
    "VizError": "retarget.viz.errors",
    "load_run": "retarget.viz.data",
    "run_report": "retarget.viz.report",
    "run_snapshot": "retarget.viz.snapshot",
    "scene_data": "retarget.viz.data",
    "view_run": "retarget.viz.meshcat_scene",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'retarget.viz' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
