"""Signed distance between a robot link and the object (the contact terms' geometry query)."""

from __future__ import annotations

import mujoco
import numpy as np


def link_distance(model, d, geoms, object_geoms, bodies, reach: float, fallback: np.ndarray):
    """``(body, p, dist, g)`` of the link with collision ``geoms`` against ``object_geoms`` in
    ``d`` (``mj_geomDistance`` over the pairs): the body name (``bodies`` by body id) of its geom
    nearest the object, that geom's point nearest the object [m], the signed distance [m]
    (``reach`` when farther) and the unit direction ``g`` in which the distance grows when
    ``p`` moves (away from the object; ``fallback`` where the two nearest points coincide)."""
    m = model
    fromto = np.zeros(6)
    best, best_g = np.inf, -1
    p = np.zeros(3)
    q = np.zeros(3)
    for g in geoms:
        for o in object_geoms:
            dist = mujoco.mj_geomDistance(m, d, g, o, reach, fromto)
            if dist < best:
                best, best_g = dist, g
                p, q = fromto[:3].copy(), fromto[3:].copy()
    v = p - q
    norm = float(np.sqrt(v @ v))
    gdir = v / (norm if best >= 0 else -norm) if norm > 1e-9 else np.asarray(fallback)
    body = bodies[m.geom_bodyid[best_g]] if best_g >= 0 else ""
    return body, p, best, gdir
