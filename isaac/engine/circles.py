"""Contacts of pairs with a circle: circle-circle and polygon-circle.

A circle is a body of one vertex (its centre) and a radius (isaac.engine.world.Model). Each pair
gives one contact, as the polygon pairs of isaac.engine.narrow_phase do: a unit normal from a
to b, a depth (the exact MTD: the sum of the radii less the centres' distance, or the radius
less the distance from the centre to the polygon), and a point on the circle's surface (the
incident body's, as for polygons; for two circles b's).

Polygon-circle follows Box2D's polygon-circle manifold (b2CollidePolygonAndCircle, Box2D 2.3):
the polygon face whose line the centre is farthest outside; if the centre is inside every face
line, that face's normal; else, if the centre projects beyond one end of the face, the axis
from that vertex to the centre (the vertex's Voronoi region), otherwise the face normal.

The feature code has the polygon-pair layout ((side * 64 + face) * 64 + region), side 0 when
the reference (the polygon, or a for two circles) is body a: the push-out reads it to move the
point with the incident body, and warm starting to match contacts from step to step. region:
0 the face, 1 its first vertex, 2 its second.
"""

from __future__ import annotations

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)


@numba.njit(cache=True, nogil=True, inline="always")
def round_contact(vertices, normals, vertex_count, radius, a, b, margin):
    """The contact of pair (a, b), one of them a circle (vertex_count 1):
    (touching, px, py, nx, ny, depth, feature); touching is False when the gap exceeds `margin`
    (m). depth < 0 is a speculative contact's gap."""
    if vertex_count[a] == 1 and vertex_count[b] == 1:
        dx = vertices[b, 0, 0] - vertices[a, 0, 0]
        dy = vertices[b, 0, 1] - vertices[a, 0, 1]
        dist = np.sqrt(dx * dx + dy * dy)
        depth = radius[a] + radius[b] - dist
        if -depth > margin:
            return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0
        if dist > 0.0:
            nx = dx / dist
            ny = dy / dist
        else:  # concentric: any axis is an MTD; up, so the choice is fixed
            nx = 0.0
            ny = 1.0
        rb = radius[b]
        return True, vertices[b, 0, 0] - rb * nx, vertices[b, 0, 1] - rb * ny, nx, ny, depth, 0
    if vertex_count[a] == 1:
        side = 1
        p = b
        c = a
    else:
        side = 0
        p = a
        c = b
    cx = vertices[c, 0, 0]
    cy = vertices[c, 0, 1]
    r = radius[c]
    count = vertex_count[p]
    # the face whose line the centre is farthest outside (strict '>': lowest index on ties)
    best = -np.inf
    face = 0
    for k in range(count):
        s = normals[p, k, 0] * (cx - vertices[p, k, 0]) + normals[p, k, 1] * (
            cy - vertices[p, k, 1]
        )
        if s > best:
            best = s
            face = k
    if best - r > margin:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0
    k2 = face + 1
    if k2 == count:
        k2 = 0
    v1x = vertices[p, face, 0]
    v1y = vertices[p, face, 1]
    v2x = vertices[p, k2, 0]
    v2y = vertices[p, k2, 1]
    nx = normals[p, face, 0]
    ny = normals[p, face, 1]
    depth = r - best
    region = 0
    if best > 0.0:
        ex = v2x - v1x
        ey = v2y - v1y
        vx = 0.0
        vy = 0.0
        if (cx - v1x) * ex + (cy - v1y) * ey <= 0.0:
            region = 1
            vx = v1x
            vy = v1y
        elif (cx - v2x) * ex + (cy - v2y) * ey >= 0.0:
            region = 2
            vx = v2x
            vy = v2y
        if region != 0:
            # outside the face line (best > 0), so the centre is not on the vertex: dist > 0
            dx = cx - vx
            dy = cy - vy
            dist = np.sqrt(dx * dx + dy * dy)
            depth = r - dist
            if -depth > margin:
                return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0
            nx = dx / dist
            ny = dy / dist
    # n points from the polygon to the circle; the point is on the circle's surface
    px = cx - r * nx
    py = cy - r * ny
    if side == 1:
        nx = -nx
        ny = -ny
    return True, px, py, nx, ny, depth, (side * 64 + face) * 64 + region
