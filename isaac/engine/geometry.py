"""World-frame geometry of every body at the current pose (the seed's FillEnvSpaceList)."""

from __future__ import annotations

import numba
import numpy as np

from isaac import trig
from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)

# determinism: the step's own sin/cos (isaac/trig.py: IEEE basic operations only), compiled; the
# same bits as the pure-Python function the scene layer calls, on any machine (libm's last bit
# differs between implementations).
sin_cos = numba.njit(cache=True, nogil=True)(trig.sin_cos)


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def transform(
    position, angle, exists, vertices_local, normals_local, vertex_count, radius, vertices,
    normals, aabb,
):  # fmt: skip
    """Fill world vertices (n, V, 2), world edge normals (n, V, 2) and AABBs (n, 4) in place.

    Counter-clockwise rotation: x_world = x + cos(a) lx - sin(a) ly, y_world = y + sin(a) lx +
    cos(a) ly (the seed's code). aabb rows are (min x, min y, max x, max y) in m; a circle's
    (vertex_count 1: its centre) is its centre +- radius (m). Bodies that do not exist are
    skipped (their rows keep stale values and are never read).
    """
    n = position.shape[0]
    for i in range(n):
        if not exists[i]:
            continue
        s, c = sin_cos(angle[i])
        px = position[i, 0]
        py = position[i, 1]
        lo_x = np.inf
        lo_y = np.inf
        hi_x = -np.inf
        hi_y = -np.inf
        for k in range(vertex_count[i]):
            lx = vertices_local[i, k, 0]
            ly = vertices_local[i, k, 1]
            x = px + (c * lx - s * ly)
            y = py + (s * lx + c * ly)
            vertices[i, k, 0] = x
            vertices[i, k, 1] = y
            nx = normals_local[i, k, 0]
            ny = normals_local[i, k, 1]
            normals[i, k, 0] = c * nx - s * ny
            normals[i, k, 1] = s * nx + c * ny
            lo_x = min(lo_x, x)
            lo_y = min(lo_y, y)
            hi_x = max(hi_x, x)
            hi_y = max(hi_y, y)
        if vertex_count[i] == 1:
            r = radius[i]
            lo_x -= r
            lo_y -= r
            hi_x += r
            hi_y += r
        aabb[i, 0] = lo_x
        aabb[i, 1] = lo_y
        aabb[i, 2] = hi_x
        aabb[i, 3] = hi_y
