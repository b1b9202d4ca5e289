"""Compiled inner loops of the collision limits (numba).

A retargeting iterate turns ``mj_collision``'s contacts into non-penetration rows. Written as
NumPy array operations this took some 60 small operations per iterate, each costing one to
two microseconds of interpreter and dispatch overhead on arrays of a few dozen rows: the
collision limits were half of a frame's solve time (Shadow, the speed benchmark's 20 pairs:
0.70 ms per frame with both, 0.30 without). Each function here is one pass in a single loop;
:mod:`retarget.limits.collision` documents what the rows mean.

Row sets travel packed, one ``(k, 10)`` array per set (a call's cost grows with the number of
arrays passed and returned, ~0.1–0.4 µs each): columns ``D`` the signed distance [m], ``PA``
and ``PB`` the nearest points on the pair's first (hand) and second geom [m, world], ``N`` the
unit normal first → second (NaN where the points coincide), with a separate ``(k,)`` array of
pair indices.

Compiled at import, cached on disk: :mod:`retarget._jit`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from retarget._jit import B1, BOOL, F1, F2, F2C, F2W, FLOAT, I1, I2_32, INT, kernel

D, PA, PB, N = 0, 1, 4, 7
"""Columns of a packed row: distance, point on geom a (3), point on geom b (3), normal (3)."""
WIDTH = 10


@kernel(I2_32, F1, F2, F2, I1, INT, I1)
def sweep_select(geom, dist, pos, frame, lut, ngeom, ga):
    """The contacts of registered pairs, sorted by (pair, distance), stable.

    Args:
        geom (n, 2), dist (n,), pos (n, 3), frame (n, 9): ``mj_collision``'s contacts.
        lut (ngeom², ): ``geom₁·ngeom + geom₂`` → registered pair index (−1: none).
        ga (P,): the hand geom of each registered pair.

    Returns ``(pair, closest, rows)``: per kept contact its pair, whether it is the pair's
    closest contact, and its packed row (the surface points are the contact position ∓ d/2
    along its normal; the normal turned to point from the pair's first geom to its second).
    """
    n = dist.shape[0]
    sel = np.empty(n, np.int64)
    ps = np.empty(n, np.int64)
    k = 0
    for i in range(n):
        p = lut[geom[i, 0] * ngeom + geom[i, 1]]
        if p >= 0:
            sel[k] = i
            ps[k] = p
            k += 1
    for a in range(1, k):  # insertion sort (a few dozen contacts), stable like np.lexsort
        si, pi = sel[a], ps[a]
        di = dist[si]
        b = a - 1
        while b >= 0 and (ps[b] > pi or (ps[b] == pi and dist[sel[b]] > di)):
            sel[b + 1] = sel[b]
            ps[b + 1] = ps[b]
            b -= 1
        sel[b + 1] = si
        ps[b + 1] = pi
    rows = np.empty((k, WIDTH))
    closest = np.empty(k, np.bool_)
    for j in range(k):
        i = sel[j]
        d = dist[i]
        # The contact lists the pair's geoms in either order: the sign makes a → b.
        sign = 0.5 if geom[i, 0] == ga[ps[j]] else -0.5
        rows[j, D] = d
        for c in range(3):
            nc = frame[i, c]
            half = (sign * d) * nc
            rows[j, PA + c] = pos[i, c] - half
            rows[j, PB + c] = pos[i, c] + half
            rows[j, N + c] = (2.0 * sign) * nc
        closest[j] = j == 0 or ps[j] != ps[j - 1]
    return ps[:k].copy(), closest, rows


@njit(cache=True, inline="always")
def far_from(i, pair_margins, far):
    """The distance [m] from which pair ``i``'s closest contact in the sweep stands for its
    distance: ``far`` beyond its allowed distance (0, or its clearance where its margin is
    negative); ``inf`` for ``i < 0``."""
    if i < 0:
        return np.inf
    return max(-pair_margins[i], 0.0) + far


@kernel(I1, B1, F2, I1, I1, I1, F1, FLOAT, FLOAT)
def limit_select(pair, closest, rows, swept_map, every_map, far_map, pair_margins, far, distmax):
    """One limit's rows from a sweep (:func:`sweep_select`'s output), in sweep order:
    ``(index, rows, n_first)``, first the closest contacts within ``distmax`` of its swept
    pairs and of its ``far_map`` pairs whose closest contact is at least ``far`` beyond their
    allowed distance (:func:`far_from`; ``n_first`` of them), then every other contact within
    ``distmax`` of its pairs (further contacts of those, all contacts of its other per-pair
    ones).

    ``swept_map`` / ``every_map`` / ``far_map``: per registered pair, the limit's pair index
    (−1: not the limit's) among its swept pairs / among its swept and per-pair ones / among
    the per-pair ones whose closest contact may stand for their distance when far.
    """
    n = pair.shape[0]
    order = np.empty(n, np.int64)
    index = np.empty(n, np.int64)
    first = np.zeros(n, np.bool_)
    m = 0
    for j in range(n):  # the closest contacts first
        p = pair[j]
        d = rows[j, D]
        if closest[j] and d < distmax and every_map[p] >= 0:
            if swept_map[p] >= 0 or d >= far_from(far_map[p], pair_margins, far):
                order[m] = j
                index[m] = every_map[p]
                first[j] = True
                m += 1
    n_first = m
    for j in range(n):
        e = every_map[pair[j]]
        if e >= 0 and not first[j] and rows[j, D] < distmax:
            order[m] = j
            index[m] = e
            m += 1
    out = np.empty((m, WIDTH))
    for r in range(m):
        out[r] = rows[order[r]]
    return index[:m].copy(), out, n_first


@kernel(I1, F2, INT, F2, I1, F1, FLOAT, BOOL, FLOAT)
def row_setup(index, rows, n_first, geom_xpos, ga, pair_margins, max_recovery, hold_only, near):
    """The non-penetration rows' directions and right-hand sides: ``(index, out, near_pairs)``
    with ``out`` packed rows whose ``D`` column holds ``h`` instead of the distance.

    Where the nearest points coincide (normal NaN: touching exactly) the direction is the one
    from the hand geom's centre (``geom_xpos[ga[index]]``) to the contact point, exact for
    spheres and capsules; a row without any direction is dropped. ``h = d + margin``, at least
    ``−max_recovery`` (NaN: no cap), at least 0 with ``hold_only``. ``near_pairs``: the pairs
    among the first ``n_first`` rows (each pair's closest points) within ``near`` [m] of their
    allowed distance (0, or the clearance where the margin is negative); ``near_rows``: each
    one's row in ``out`` (−1: dropped), ``near_slack``: its ``d + margin`` [m] (uncapped).
    """
    k = index.shape[0]
    keep = np.empty(k, np.int64)
    out = np.empty((k, WIDTH))
    near_pairs = np.empty(n_first, np.int64)
    near_rows = np.empty(n_first, np.int64)
    near_slack = np.empty(n_first)
    nn = m = 0
    for r in range(k):
        i = index[r]
        pm = pair_margins[i]
        d = rows[r, D]
        if r < n_first and d + min(pm, 0.0) < near:
            near_pairs[nn] = i
            near_rows[nn] = m
            near_slack[nn] = d + pm
            nn += 1
        out[m] = rows[r]
        if not np.isfinite(rows[r, N]):
            c0 = rows[r, PB] - geom_xpos[ga[i], 0]
            c1 = rows[r, PB + 1] - geom_xpos[ga[i], 1]
            c2 = rows[r, PB + 2] - geom_xpos[ga[i], 2]
            cn = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
            if cn < 1e-12:
                if r < n_first and nn > 0 and near_pairs[nn - 1] == i:
                    near_rows[nn - 1] = -1
                continue
            out[m, N] = c0 / cn
            out[m, N + 1] = c1 / cn
            out[m, N + 2] = c2 / cn
        h = d + pm
        if max_recovery == max_recovery:  # (not NaN)
            h = max(h, -max_recovery)
        if hold_only:
            h = max(h, 0.0)
        out[m, D] = h
        keep[m] = i
        m += 1
    return (
        keep[:m].copy(), out[:m].copy(), near_pairs[:nn].copy(), near_rows[:nn].copy(),
        near_slack[:nn].copy(),
    )  # fmt: skip


@njit(cache=True)
def _add_normal_jacobians(J, masks, index, out_rows, col, sign, G):
    """``G[r] += sign · nᵀ J_p``: the Jacobian of the point ``out_rows[r, col:col+3]`` fixed
    to the body whose dof mask is ``masks[index[r]]``, from the world-frame joint Jacobian
    ``J`` (6, nv) (per dof the twist ``(v₀, ω)`` at the world origin, so ``J_p = v₀ + ω × p``),
    projected on the row's normal ``n``: ``nᵀ(ω × p) = ωᵀ(p × n)``."""
    k, nv = G.shape
    for r in range(k):
        nx, ny, nz = out_rows[r, N], out_rows[r, N + 1], out_rows[r, N + 2]
        px, py, pz = out_rows[r, col], out_rows[r, col + 1], out_rows[r, col + 2]
        cx = py * nz - pz * ny
        cy = pz * nx - px * nz
        cz = px * ny - py * nx
        mask = masks[index[r]]
        for j in range(nv):
            if mask[j] != 0.0:
                v = nx * J[0, j] + ny * J[1, j] + nz * J[2, j]
                v += cx * J[3, j] + cy * J[4, j] + cz * J[5, j]
                G[r, j] += sign * v


@kernel(I1, F2, INT, F2, I1, F1, FLOAT, BOOL, FLOAT, F2C, F2C, F2C, BOOL)
def rows_and_jacobians(
    index, rows, n_first, geom_xpos, ga, pair_margins, max_recovery, hold_only, near,
    J, masks_a, masks_b, self_collision,
):  # fmt: skip
    """:func:`row_setup` and the rows ``G = nᵀ (J_a − J_b)`` (``J_b`` only for
    ``self_collision``) from a world-frame joint Jacobian and per-pair body dof masks:
    ``(G, h, near_pairs, near_rows, near_slack)``."""
    keep, out, near_pairs, near_rows, near_slack = row_setup(
        index, rows, n_first, geom_xpos, ga, pair_margins, max_recovery, hold_only, near
    )
    G = np.zeros((keep.shape[0], J.shape[1]))
    _add_normal_jacobians(J, masks_a, keep, out, PA, 1.0, G)
    if self_collision:
        _add_normal_jacobians(J, masks_b, keep, out, PB, -1.0, G)
    return G, out[:, D].copy(), near_pairs, near_rows, near_slack


@kernel(F2, I1, F1, I1, F1, F1, FLOAT)
def check_after_step(G, near_rows, near_slack, near_pairs, q, q_lin, after):
    """The near pairs (``near_pairs``) the end-of-step check measures at ``q``: those the
    linear rows predict within ``after`` [m] of their allowed distance after the step from
    ``q_lin`` (``near_slack − G_r·(q − q_lin)``, ``G_r`` the pair's row ``near_rows`` in
    ``G``), and those without a row (−1)."""
    k = near_rows.shape[0]
    out = np.empty(k, np.int64)
    n = 0
    for j in range(k):
        r = near_rows[j]
        if r >= 0:
            s = near_slack[j]
            for a in range(q.shape[0]):
                s -= G[r, a] * (q[a] - q_lin[a])
            if s >= after:
                continue
        out[n] = near_pairs[j]
        n += 1
    return out[:n].copy()


@kernel(F1, F1, F1)
def joint_box(q, lower, upper):
    """``JointLimit``'s step bounds ``(−max(q − lower, 0), max(upper − q, 0))`` (∓inf
    ranges: unbounded; a start outside the range may step back, not further out)."""
    n = q.shape[0]
    lo, hi = np.empty(n), np.empty(n)
    for i in range(n):
        lo[i] = -max(q[i] - lower[i], 0.0)
        hi[i] = max(upper[i] - q[i], 0.0)
    return lo, hi


@kernel(F1, F1, F1, FLOAT)
def band_box(q, q_prev, v_max, dt):
    """``FrameSpeedLimit``'s step bounds: ``q + Δq`` within ``v_max · dt`` of ``q_prev`` and
    ``Δq = 0`` always admitted; at ``dt = 0`` the finite bands are 0 (``inf · 0`` would be
    NaN)."""
    n = q.shape[0]
    lo, hi = np.empty(n), np.empty(n)
    for i in range(n):
        if dt > 0:
            band = v_max[i] * dt
        else:
            band = 0.0 if np.isfinite(v_max[i]) else np.inf
        off = q_prev[i] - q[i]
        lo[i] = min(off - band, 0.0)
        hi[i] = max(off + band, 0.0)
    return lo, hi


@njit(cache=True)
def _boxes_apart(xpos, xmat, a, b, ea, eb):
    """Whether boxes ``a`` and ``b`` (half sizes ``ea``, ``eb``; poses from ``xpos`` and the
    row-major ``xmat``, whose columns are a box's axes) are separated: one of the 15 axes of
    the separating axis test (the boxes' face normals and the cross products of their edges)
    has their projections apart. Exact for boxes; a small tolerance keeps touching boxes and
    parallel edges (a zero cross product) on the overlapping side."""
    R = np.empty((3, 3))  # Ra^T Rb: b's axes in a's frame
    absR = np.empty((3, 3))
    t = np.empty(3)  # b's centre in a's frame
    for i in range(3):
        t[i] = 0.0
        for k in range(3):
            t[i] += xmat[a, 3 * k + i] * (xpos[b, k] - xpos[a, k])
        for j in range(3):
            r = 0.0
            for k in range(3):
                r += xmat[a, 3 * k + i] * xmat[b, 3 * k + j]
            R[i, j] = r
            absR[i, j] = abs(r) + 1e-9
    for i in range(3):  # a's face normals
        if abs(t[i]) > ea[i] + eb[0] * absR[i, 0] + eb[1] * absR[i, 1] + eb[2] * absR[i, 2]:
            return True
    for j in range(3):  # b's face normals
        tj = t[0] * R[0, j] + t[1] * R[1, j] + t[2] * R[2, j]
        if abs(tj) > ea[0] * absR[0, j] + ea[1] * absR[1, j] + ea[2] * absR[2, j] + eb[j]:
            return True
    for i in range(3):  # edge × edge
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            ra = ea[i1] * absR[i2, j] + ea[i2] * absR[i1, j]
            rb = eb[j1] * absR[i, j2] + eb[j2] * absR[i, j1]
            if abs(t[i2] * R[i1, j] - t[i1] * R[i2, j]) > ra + rb:
                return True
    return False


@njit(cache=True)
def _sphere_box_apart(xpos, xmat, a, b, radius, eb):
    """Whether the sphere of ``radius`` about geom ``a``'s centre misses box ``b`` (half sizes
    ``eb``; pose from ``xpos`` and the row-major ``xmat``): the centre's distance from the
    box (0 inside) is at least the radius."""
    d2 = 0.0
    for i in range(3):
        t = 0.0
        for k in range(3):
            t += xmat[b, 3 * k + i] * (xpos[a, k] - xpos[b, k])
        out = abs(t) - eb[i]
        if out > 0.0:
            d2 += out * out
    return d2 >= radius * radius


@kernel(F2, F2, I1, I1, I1, F1, B1, F2, F2, B1, F1, I1, I1, I1, F1)
def broad_phase(
    xpos, xmat, sph, sph_a, sph_b, reach2, boxes, box_a, box_b, obb, obb_reach,
    pln, pln_a, pln_b, pln_reach,
):  # fmt: skip
    """The per-pair path's candidates (``CollisionLimit.candidates``): the pairs ``sph``
    whose geoms' centres ``xpos`` are closer than ``√reach2`` (and, for box–box pairs,
    ``boxes``, whose first box grown by the query distance (half sizes ``box_a``) meets the
    second (``box_b``): a box within that distance of another lies in it grown so; for the
    other pairs whose second geom is a box, ``obb``, whose first geom's bounding sphere grown
    by the query distance (radius ``obb_reach``) meets that box: a large box such as the table
    has a bounding sphere that reaches everything), then the plane pairs ``pln`` whose hand
    geom's centre is less than ``pln_reach`` above the plane (its frame's z axis from
    ``xmat``)."""
    out = np.empty(sph.shape[0] + pln.shape[0], np.int64)
    m = 0
    for i in range(sph.shape[0]):
        a, b = sph_a[i], sph_b[i]
        dx = xpos[a, 0] - xpos[b, 0]
        dy = xpos[a, 1] - xpos[b, 1]
        dz = xpos[a, 2] - xpos[b, 2]
        if dx * dx + dy * dy + dz * dz >= reach2[i]:
            continue
        if boxes[i] and _boxes_apart(xpos, xmat, a, b, box_a[i], box_b[i]):
            continue
        if obb[i] and _sphere_box_apart(xpos, xmat, a, b, obb_reach[i], box_b[i]):
            continue
        out[m] = sph[i]
        m += 1
    for i in range(pln.shape[0]):
        a, b = pln_a[i], pln_b[i]
        h = (xpos[a, 0] - xpos[b, 0]) * xmat[b, 2]
        h += (xpos[a, 1] - xpos[b, 1]) * xmat[b, 5]
        h += (xpos[a, 2] - xpos[b, 2]) * xmat[b, 8]
        if h < pln_reach[i]:
            out[m] = pln[i]
            m += 1
    return out[:m].copy()


@kernel(I1, B1, F2, I1, F1, FLOAT, I1)
def seen_candidates(pair, closest, rows, seen_map, pair_margins, far, extra):
    """The per-pair path's candidates, ascending: the pairs ``seen_map`` maps a reported
    contact's registered pair to (``pair``, ``closest``, ``rows``: :func:`sweep_select`'s
    output; −1: not one of them) whose closest contact is nearer than :func:`far_from`
    (:func:`limit_select` takes the others from the sweep), and the pairs ``extra`` (the
    broad phase's)."""
    n = 0
    for j in range(pair.shape[0]):
        n = max(n, seen_map[pair[j]] + 1)
    for i in range(extra.shape[0]):
        n = max(n, extra[i] + 1)
    mark = np.zeros(n, np.bool_)
    for j in range(pair.shape[0]):
        s = seen_map[pair[j]]
        if s >= 0 and closest[j] and rows[j, D] < far_from(s, pair_margins, far):
            mark[s] = True
    for i in range(extra.shape[0]):
        mark[extra[i]] = True
    out = np.empty(n, np.int64)
    m = 0
    for i in range(n):
        if mark[i]:
            out[m] = i
            m += 1
    return out[:m].copy()


@kernel(F2, F2, F2, F1)
def coupling_rows(A1, A2, C, q):
    """The coupling equalities' rows at ``q`` (``CouplingLimit.equalities``): with
    ``sᵢ = Aᵢ q`` and the polynomial ``p`` of coefficients ``C`` (k, 5), ``(A₁ − p'(s₂) A₂,
    p(s₂) − s₁)``."""
    k, nv = A1.shape
    A = np.empty((k, nv))
    b = np.empty(k)
    for r in range(k):
        s1 = 0.0
        s2 = 0.0
        for j in range(nv):
            s1 += A1[r, j] * q[j]
            s2 += A2[r, j] * q[j]
        p = C[r, 4]
        dp = 4.0 * C[r, 4]
        for i in range(3, -1, -1):  # Horner
            p = p * s2 + C[r, i]
            if i > 0:
                dp = dp * s2 + i * C[r, i]
        for j in range(nv):
            A[r, j] = A1[r, j] - dp * A2[r, j]
        b[r] = p - s1
    return A, b


@kernel(F2W)
def set_normals(rows):
    """Fill the ``N`` columns of packed rows from their points: ``(p_b − p_a) / ±|p_b − p_a|``
    (− where penetrating: the normal points the way the distance grows; NaN where the points
    coincide)."""
    for r in range(rows.shape[0]):
        v0 = rows[r, PB] - rows[r, PA]
        v1 = rows[r, PB + 1] - rows[r, PA + 1]
        v2 = rows[r, PB + 2] - rows[r, PA + 2]
        norm = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        if norm > 1e-9:
            s = norm if rows[r, D] >= 0 else -norm
            rows[r, N], rows[r, N + 1], rows[r, N + 2] = v0 / s, v1 / s, v2 / s
        else:
            rows[r, N] = rows[r, N + 1] = rows[r, N + 2] = np.nan
