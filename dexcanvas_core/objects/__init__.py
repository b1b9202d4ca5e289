"""Objects beyond the built-in catalogue: meshes, their collision shapes, objects manifests.

* :mod:`.mesh` — reading and checking a mesh, convex parts (``coacd`` for non-convex meshes),
  a signed-distance grid, all cached on disk by the mesh's content hash;
* :mod:`.manifest` — the TOML objects manifest (``--objects``) and objects directories
  (``--objects-dir``);
* :mod:`.options` — the command-line options every scene-building command shares.

Lookups by id (``dexcanvas_core.taxonomy.object_spec``) and geometry
(``dexcanvas_core.demos.object_geometry``) see these objects once they are in use
(``dexcanvas_core.taxonomy.use_objects``).
"""
