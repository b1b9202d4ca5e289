"""Object shapes: the catalogue's primitive compositions and given meshes, their collision shapes,
objects manifests.

* :mod:`.geometry` — an object's solid shape and its signed distance
  (:func:`~.geometry.object_geometry`);
* :mod:`.primitives` — boxes, cylinders, spheres, capsules and convex parts with exact distances;
* :mod:`.ycb_shapes` — YCB-style items as primitive compositions;
* :mod:`.mesh` — reading and checking a mesh, convex parts (``coacd`` for non-convex meshes),
  a signed-distance grid, all cached on disk by the mesh's content hash;
* :mod:`.manifest` — the TOML objects manifest (``--objects``) and objects directories
  (``--objects-dir``);
* :mod:`.options` — the command-line options every scene-building command shares.

Lookups by id (``dexcanvas_core.taxonomy.object_spec``) and geometry
(:func:`.geometry.object_geometry`) see these objects once they are in use
(``dexcanvas_core.taxonomy.use_objects``).
"""
