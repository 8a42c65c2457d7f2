"""Convex polygon geometry for scene building: standard shapes, validation, mass properties.

Not on the hot path: these run once per body when a scene is loaded or a world is built. All
lengths are in metres in the polygon's own frame (the frame its vertices are given in); nothing
here knows about world positions or angles.

Tolerances are relative to the polygon's size ``L`` (the diagonal of its bounding box), so a
polygon is accepted or refused the same way at any scale and anywhere relative to the origin:

* two vertices closer than ``1e-9 * L`` are duplicates;
* the area must exceed ``1e-9 * L**2`` (a sliver thinner than about a billionth of its length is
  refused as "zero area");
* at every vertex the turn from the incoming to the outgoing edge must not go clockwise by more
  than ``sin(turn) = -1e-9`` (after orienting counter-clockwise). Exactly or nearly collinear
  vertices therefore pass (stability suites use them); a real dent does not.
"""

from __future__ import annotations

import math

import numpy as np

from isaac.scene.limits import MAX_VERTICES

DUPLICATE_TOLERANCE = 1e-9  # x L: vertices this close are the same vertex
AREA_TOLERANCE = 1e-9  # x L^2: smallest accepted area
TURN_TOLERANCE = 1e-9  # sine of the largest clockwise turn accepted at a vertex


def box_vertices(width: float, height: float) -> np.ndarray:
    """(4, 2) vertices (m) of a width x height box centred at the origin, counter-clockwise,
    starting at the bottom-left corner."""
    hw, hh = 0.5 * width, 0.5 * height
    return np.array([[-hw, -hh], [hw, -hh], [hw, hh], [-hw, hh]], dtype=np.float64)


def regular_vertices(sides: int, radius: float, phase: float = 0.0) -> np.ndarray:
    """(sides, 2) vertices (m) of a regular polygon of circumradius `radius` (m) centred at the
    origin, counter-clockwise; vertex k is at angle ``phase + 2*pi*k/sides`` (rad, CCW from +x)."""
    # determinism: math.cos/sin (not a vectorised call) so the bits do not depend on SIMD paths.
    out = np.empty((sides, 2), dtype=np.float64)
    for k in range(sides):
        a = phase + 2.0 * math.pi * k / sides
        out[k, 0] = radius * math.cos(a)
        out[k, 1] = radius * math.sin(a)
    return out


def _signed_area(v: np.ndarray) -> float:
    # shoelace about vertex 0: accurate even when the polygon is far from the origin.
    e = v[1:] - v[0]
    return 0.5 * float(np.sum(e[:-1, 0] * e[1:, 1] - e[:-1, 1] * e[1:, 0]))


def _segments_cross(p: np.ndarray, q: np.ndarray, r: np.ndarray, s: np.ndarray) -> bool:
    """Whether segments pq and rs intersect (touching counts)."""

    def orient(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    d1, d2 = orient(r, s, p), orient(r, s, q)
    d3, d4 = orient(p, q, r), orient(p, q, s)
    if ((d1 > 0) != (d2 > 0) and d1 != 0 and d2 != 0) and (
        (d3 > 0) != (d4 > 0) and d3 != 0 and d4 != 0
    ):
        return True

    def on_segment(a, b, c):  # c collinear with ab: is it within ab's box?
        return min(a[0], b[0]) <= c[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= c[1] <= max(
            a[1], b[1]
        )

    return (
        (d1 == 0 and on_segment(r, s, p))
        or (d2 == 0 and on_segment(r, s, q))
        or (d3 == 0 and on_segment(p, q, r))
        or (d4 == 0 and on_segment(p, q, s))
    )


def _self_intersects(v: np.ndarray) -> bool:
    k = len(v)
    for i in range(k):
        for j in range(i + 1, k):
            if j == i + 1 or (i == 0 and j == k - 1):
                continue  # neighbouring edges share a vertex by construction
            if _segments_cross(v[i], v[(i + 1) % k], v[j], v[(j + 1) % k]):
                return True
    return False


def validate_polygon(vertices) -> np.ndarray:
    """Check a convex polygon and return its vertices (m) as a (k, 2) float64 CCW array.

    `vertices` is a sequence of k (x, y) pairs in either winding; a clockwise polygon is returned
    reversed (same vertices, opposite order), a counter-clockwise one unchanged, bit for bit.
    Raises ValueError with a one-line reason for: fewer than 3 or more than MAX_VERTICES vertices,
    non-finite coordinates, duplicate vertices, all vertices collinear, a self-intersecting
    outline (a "bow tie", a star), a non-convex outline, or an area too small for its size
    (tolerances in the module docstring).
    """
    try:
        v = np.array(vertices, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("vertices must be a list of [x, y] pairs of numbers") from None
    if v.ndim != 2 or v.shape[1] != 2:
        raise ValueError("vertices must be a list of [x, y] pairs of numbers")
    k = v.shape[0]
    if k < 3:
        raise ValueError(f"a polygon needs at least 3 vertices, got {k}")
    if k > MAX_VERTICES:
        raise ValueError(f"a polygon has at most {MAX_VERTICES} vertices, got {k}")
    if not np.all(np.isfinite(v)):
        raise ValueError("vertex coordinates must be finite numbers")

    size = float(np.hypot(*(v.max(axis=0) - v.min(axis=0))))
    if size == 0.0:
        raise ValueError("all vertices are the same point")
    gaps = np.hypot(v[:, None, 0] - v[None, :, 0], v[:, None, 1] - v[None, :, 1])
    gaps[np.arange(k), np.arange(k)] = np.inf
    if np.min(gaps) <= DUPLICATE_TOLERANCE * size:
        i, j = np.unravel_index(int(np.argmin(gaps)), gaps.shape)
        i, j = min(i, j), max(i, j)
        raise ValueError(f"vertices {i} and {j} are duplicates ({v[i].tolist()})")

    # collinear-only: every vertex within tolerance of the line through the two farthest apart.
    i, j = np.unravel_index(int(np.argmax(np.where(np.isinf(gaps), -1.0, gaps))), gaps.shape)
    axis = (v[j] - v[i]) / gaps[i, j]
    offsets = (v[:, 0] - v[i, 0]) * axis[1] - (v[:, 1] - v[i, 1]) * axis[0]
    if np.max(np.abs(offsets)) <= DUPLICATE_TOLERANCE * size:
        raise ValueError("all vertices are collinear (zero area)")

    if _signed_area(v) < 0.0:
        v = v[::-1].copy()

    # turn at each vertex: cross(incoming edge, outgoing edge) / (|in| |out|) = sin(turn).
    incoming = v - np.roll(v, 1, axis=0)
    outgoing = np.roll(v, -1, axis=0) - v
    cross = incoming[:, 0] * outgoing[:, 1] - incoming[:, 1] * outgoing[:, 0]
    dot = incoming[:, 0] * outgoing[:, 0] + incoming[:, 1] * outgoing[:, 1]
    lengths = np.hypot(incoming[:, 0], incoming[:, 1]) * np.hypot(outgoing[:, 0], outgoing[:, 1])
    convex_turns = bool(np.all(cross >= -TURN_TOLERANCE * lengths))
    # a simple convex outline turns once around in total; a star turns twice or more.
    winding = float(np.sum(np.arctan2(cross, dot))) / (2.0 * math.pi)
    if not convex_turns or abs(winding - 1.0) > 1e-6:
        if _self_intersects(v):
            raise ValueError("the outline crosses itself (self-intersecting polygon)")
        bad = int(np.argmin(cross / lengths))
        raise ValueError(f"the polygon is not convex (it turns inwards at vertex {bad})")

    area = _signed_area(v)
    if area <= AREA_TOLERANCE * size * size:
        raise ValueError(f"the polygon's area {area!r} m^2 is too small for its size {size!r} m")
    return v


def mass_properties(vertices) -> tuple[float, np.ndarray, float]:
    """Area (m^2), centroid (m, (2,) in the vertices' frame) and polar second moment of area about
    the centroid (m^4) of a CCW convex polygon (as returned by `validate_polygon`).

    Mass is density * area and the moment of inertia about the centre of mass is
    density * second_moment.

    Triangle fan from vertex 0 (as Box2D's b2ComputePolygonMass): for the triangle
    (v0, v0 + e1, v0 + e2), D = e1 x e2, area D/2, centroid offset (e1 + e2)/3 and polar moment
    about v0 D/12 (|e1|^2 + e1.e2 + |e2|^2). Working relative to v0 keeps the sums small for a
    polygon far from the origin; the parallel axis theorem then moves the moment to the centroid.
    """
    v = np.asarray(vertices, dtype=np.float64)
    origin = v[0]
    area = 0.0
    cx = cy = 0.0
    moment = 0.0
    for i in range(1, len(v) - 1):
        e1x, e1y = v[i, 0] - origin[0], v[i, 1] - origin[1]
        e2x, e2y = v[i + 1, 0] - origin[0], v[i + 1, 1] - origin[1]
        d = e1x * e2y - e1y * e2x
        tri_area = 0.5 * d
        area += tri_area
        cx += tri_area * (e1x + e2x) / 3.0
        cy += tri_area * (e1y + e2y) / 3.0
        moment += (d / 12.0) * (
            e1x * e1x + e1x * e2x + e2x * e2x + e1y * e1y + e1y * e2y + e2y * e2y
        )
    cx /= area
    cy /= area
    second_moment = moment - area * (cx * cx + cy * cy)
    centroid = np.array([origin[0] + cx, origin[1] + cy], dtype=np.float64)
    return float(area), centroid, float(second_moment)
