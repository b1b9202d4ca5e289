"""Seeing the results: meshcat scenes, headless stills, plots and an offline HTML report.

One module per concept:

* ``data`` — what a picture shows per frame (:class:`~retarget.viz.data.SceneData`): a run
  directory, its human demonstration;
* ``contacts`` — human and robot contact points per frame
  (:class:`~retarget.viz.contacts.ContactFrames`);
* ``resim`` — the run's re-simulation replayed and recorded;
* ``view`` — layout and camera (:class:`~retarget.viz.view.SceneOptions`);
* ``meshcat_scene`` — the meshcat scene, :func:`view_run`; ``meshcat_connection``: its server,
  bound to 127.0.0.1; ``meshcat_geoms``: drawing primitives, meshes and MuJoCo geoms;
* ``chromium`` / ``mujoco_render`` — the two still renderers (``mujoco_child``: the MuJoCo
  renderer's child process);
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
