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

import itertools
import math
from typing import NamedTuple

import numpy as np

from isaac import trig
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
    # determinism: isaac.trig (IEEE basic operations only), not libm or a vectorised call, so the
    # vertices have the same bits on every machine; the log embeds them expanded all the same.
    out = np.empty((sides, 2), dtype=np.float64)
    for k in range(sides):
        a = phase + 2.0 * math.pi * k / sides
        s, c = trig.sin_cos(a)
        out[k, 0] = radius * c
        out[k, 1] = radius * s
    return out


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


def _sequential_sum(terms: np.ndarray) -> np.ndarray:
    """Sum of (n, m) `terms` along axis 1, strictly left to right.

    determinism: numpy's own sum may pair terms differently for different array shapes; a
    polygon's sums (so its acceptance) must not depend on which other polygons share its batch.
    """
    total = np.zeros(terms.shape[0])
    for j in range(terms.shape[1]):
        total = total + terms[:, j]
    return total


def _signed_areas(v: np.ndarray) -> np.ndarray:
    """(n,) signed areas (m^2, > 0 counter-clockwise) of (n, k, 2) polygons."""
    # shoelace about vertex 0: accurate even when the polygon is far from the origin.
    e = v[:, 1:] - v[:, :1]
    return 0.5 * _sequential_sum(e[:, :-1, 0] * e[:, 1:, 1] - e[:, :-1, 1] * e[:, 1:, 0])


# Problem codes of `_shape_codes`, in the order the checks run; 0 is a valid polygon.
_NONFINITE, _ONE_POINT, _DUPLICATE, _COLLINEAR, _NOT_CONVEX, _TOO_SMALL = range(1, 7)


def _shape_codes(v: np.ndarray):
    """Check (n, k, 2) polygons of one vertex count k at once.

    Returns (codes, oriented, flipped, extents): codes (n,) int, the first failed check or 0;
    oriented (n, k, 2), each polygon counter-clockwise (a clockwise one reversed, flipped (n,)
    True); extents (n,) the bounding-box diagonals (m). Every check runs on the oriented
    vertices, so checking the oriented result again gives the same answer: a polygon stored as
    `validate_polygon` returns it loads back.
    """
    n, k = v.shape[0], v.shape[1]
    codes = np.zeros(n, dtype=np.int64)
    with np.errstate(all="ignore"):  # non-finite or degenerate polygons are refused below
        finite = np.isfinite(v).all(axis=(1, 2))
        flip = _signed_areas(v) < 0.0
        oriented = np.where(flip[:, None, None], v[:, ::-1, :], v)
        span = oriented.max(axis=1) - oriented.min(axis=1)
        size = np.hypot(span[:, 0], span[:, 1])

        # duplicates: the closest two vertices (every pair: the outline may not be convex yet).
        gaps = np.hypot(
            oriented[:, :, None, 0] - oriented[:, None, :, 0],
            oriented[:, :, None, 1] - oriented[:, None, :, 1],
        )
        gaps[:, np.arange(k), np.arange(k)] = np.inf
        duplicate = gaps.min(axis=(1, 2)) <= DUPLICATE_TOLERANCE * size

        # collinear-only: every vertex within tolerance of the line through the two farthest
        # apart.
        far = np.argmax(np.where(np.isinf(gaps), -1.0, gaps).reshape(n, k * k), axis=1)
        rows = np.arange(n)
        a, b = oriented[rows, far // k], oriented[rows, far % k]
        axis = (b - a) / gaps[rows, far // k, far % k][:, None]
        offsets = (oriented[:, :, 0] - a[:, None, 0]) * axis[:, None, 1] - (
            oriented[:, :, 1] - a[:, None, 1]
        ) * axis[:, None, 0]
        collinear = np.abs(offsets).max(axis=1) <= DUPLICATE_TOLERANCE * size

        # turn at each vertex: cross(incoming edge, outgoing edge) / (|in| |out|) = sin(turn).
        incoming = oriented - np.roll(oriented, 1, axis=1)
        outgoing = np.roll(oriented, -1, axis=1) - oriented
        cross = incoming[..., 0] * outgoing[..., 1] - incoming[..., 1] * outgoing[..., 0]
        dot = incoming[..., 0] * outgoing[..., 0] + incoming[..., 1] * outgoing[..., 1]
        lengths = np.hypot(incoming[..., 0], incoming[..., 1]) * np.hypot(
            outgoing[..., 0], outgoing[..., 1]
        )
        convex_turns = np.all(cross >= -TURN_TOLERANCE * lengths, axis=1)
        # a simple convex outline turns once around in total; a star turns twice or more. (The
        # total is an integer in exact arithmetic, so rounding never decides this test.)
        winding = _sequential_sum(np.arctan2(cross, dot)) / (2.0 * math.pi)
        convex = convex_turns & (np.abs(winding - 1.0) <= 1e-6)

        small = _signed_areas(oriented) <= AREA_TOLERANCE * size * size
    # the first failed check wins: fill codes from the last check to the first.
    for code, failed in (
        (_TOO_SMALL, small),
        (_NOT_CONVEX, ~convex),
        (_COLLINEAR, collinear),
        (_DUPLICATE, duplicate),
        (_ONE_POINT, size == 0.0),
        (_NONFINITE, ~finite),
    ):
        codes[failed] = code
    return codes, oriented, flip, size


def _reason(code: int, given: np.ndarray, oriented: np.ndarray, flipped: bool) -> str:
    """The one-line reason for problem `code` of one polygon (vertex indices as given)."""
    k = len(given)

    def as_given(i: int) -> int:
        return k - 1 - i if flipped else i

    if code == _NONFINITE:
        return "vertex coordinates must be finite numbers"
    if code == _ONE_POINT:
        return "all vertices are the same point"
    if code == _DUPLICATE:
        gaps = np.hypot(
            given[:, None, 0] - given[None, :, 0], given[:, None, 1] - given[None, :, 1]
        )
        gaps[np.arange(k), np.arange(k)] = np.inf
        i, j = sorted(np.unravel_index(int(np.argmin(gaps)), gaps.shape))
        return f"vertices {i} and {j} are duplicates ({given[i].tolist()})"
    if code == _COLLINEAR:
        return "all vertices are collinear (zero area)"
    if code == _NOT_CONVEX:
        if _self_intersects(oriented):
            return "the outline crosses itself (self-intersecting polygon)"
        incoming = oriented - np.roll(oriented, 1, axis=0)
        outgoing = np.roll(oriented, -1, axis=0) - oriented
        cross = incoming[:, 0] * outgoing[:, 1] - incoming[:, 1] * outgoing[:, 0]
        lengths = np.hypot(incoming[:, 0], incoming[:, 1]) * np.hypot(
            outgoing[:, 0], outgoing[:, 1]
        )
        bad = as_given(int(np.argmin(cross / lengths)))
        return (
            f"the polygon is not convex (it turns inwards at vertex {bad}, {given[bad].tolist()};"
            f" vertices count from 0)"
        )
    area = float(_signed_areas(oriented[None])[0])
    span = oriented.max(axis=0) - oriented.min(axis=0)
    size = float(np.hypot(span[0], span[1]))
    return f"the polygon's area {area!r} m^2 is too small for its size {size!r} m"


def _as_vertices(vertices) -> np.ndarray:
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
    return v


def validate_polygon(vertices) -> np.ndarray:
    """Check a convex polygon and return its vertices (m) as a (k, 2) float64 CCW array.

    `vertices` is a sequence of k (x, y) pairs in either winding; a clockwise polygon is returned
    reversed (same vertices, opposite order), a counter-clockwise one unchanged, bit for bit.
    Raises ValueError with a one-line reason for: fewer than 3 or more than MAX_VERTICES vertices,
    non-finite coordinates, duplicate vertices, all vertices collinear, a self-intersecting
    outline (a "bow tie", a star), a non-convex outline, or an area too small for its size
    (tolerances in the module docstring). The checks run on the counter-clockwise result, so
    the result passes them again unchanged.
    """
    v = _as_vertices(vertices)
    codes, oriented, flipped, _ = _shape_codes(v[None])
    if codes[0]:
        raise ValueError(_reason(int(codes[0]), v, oriented[0], bool(flipped[0])))
    return oriented[0].copy()


class PolygonFacts(NamedTuple):
    """What `survey` finds about n polygons, in their order.

    problems: None, or the one-line reason the polygon is not one `validate_polygon` accepts
        and returns unchanged (counter-clockwise, 3..MAX_VERTICES vertices, convex, ...).
    extents: (n,) bounding-box diagonals (m).
    largest_coordinates: (n,) the largest |x| or |y| of each polygon's vertices (m).
    areas, second_moments: (n,) as `mass_properties` gives them, bit for bit (m^2, m^4);
        meaningless where a problem is given.
    """

    problems: list
    extents: np.ndarray
    largest_coordinates: np.ndarray
    areas: np.ndarray
    second_moments: np.ndarray


def survey(polygons) -> PolygonFacts:
    """Check and measure `polygons` (each a sequence of (x, y) pairs, m, as a scene stores them).

    Polygons of one vertex count are handled together, so 100,000 polygons take a fraction of a
    second; each polygon's results depend on its own vertices only (not on its batch).
    """
    n = len(polygons)
    problems: list[str | None] = [None] * n
    extents = np.full(n, np.nan)
    largest = np.full(n, np.nan)
    areas = np.full(n, np.nan)
    second_moments = np.full(n, np.nan)
    groups: dict[int, list[int]] = {}
    for index, vertices in enumerate(polygons):
        known = _SURVEYED.get(id(vertices))
        if known is not None and known[0] is vertices:
            problems[index], extents[index], largest[index], areas[index], second_moments[index] = (
                known[1]
            )
            continue
        k = len(vertices)
        if k < 3:
            problems[index] = f"a polygon needs at least 3 vertices, got {k}"
        elif k > MAX_VERTICES:
            problems[index] = f"a polygon has at most {MAX_VERTICES} vertices, got {k}"
        else:
            groups.setdefault(k, []).append(index)
    for k, members in groups.items():
        chunk = max(1, 1_000_000 // (k * k))  # about 8 MB per (n, k, k) array of gaps
        for start in range(0, len(members), chunk):
            part = members[start : start + chunk]
            try:
                flat = itertools.chain.from_iterable(
                    itertools.chain.from_iterable(polygons[i] for i in part)
                )
                v = np.fromiter(flat, dtype=np.float64, count=len(part) * k * 2)
            except (TypeError, ValueError):  # not all of them pairs of numbers: find which
                for i in part:
                    problems[i] = _pairs_problem(polygons[i])
                part = [i for i in part if problems[i] is None]
                v = np.array([polygons[i] for i in part], dtype=np.float64)
            v = v.reshape(len(part), k, 2)
            codes, oriented, flipped, size = _shape_codes(v)
            index = np.array(part)
            extents[index] = size
            largest[index] = np.abs(v).max(axis=(1, 2))
            with np.errstate(all="ignore"):
                area, second_moment = _mass_properties(v)
            areas[index] = area
            second_moments[index] = second_moment
            for j in np.flatnonzero(codes):
                problems[part[j]] = _reason(int(codes[j]), v[j], oriented[j], bool(flipped[j]))
            for j in np.flatnonzero((codes == 0) & flipped):
                problems[part[j]] = (
                    "the vertices are clockwise (a scene stores them counter-clockwise)"
                )
    if n <= _REMEMBER_MOST:
        for index, vertices in enumerate(polygons):
            if _immutable(vertices) and id(vertices) not in _SURVEYED:
                if len(_SURVEYED) >= _SURVEYED_MOST:
                    _SURVEYED.clear()
                _SURVEYED[id(vertices)] = (
                    vertices,
                    (
                        problems[index],
                        float(extents[index]),
                        float(largest[index]),
                        float(areas[index]),
                        float(second_moments[index]),
                    ),
                )
    return PolygonFacts(problems, extents, largest, areas, second_moments)


# `survey`'s results for the vertex tuples it saw last, by the tuple itself (kept here, so its id is
# not reused): the scene loader gives every box of one size the same tuple (bodies.box_tuple), so a
# sweep that reads one scene many times surveys its boxes once. A polygon's results depend on its
# own vertices alone, and a tuple of tuples of floats cannot change: the same bits. Only the
# polygons of small calls are remembered (a pile's 100 polygons are new each time: looking them over
# would cost about 1% of its load, for nothing).
_SURVEYED: dict[int, tuple] = {}
_SURVEYED_MOST = 256
_REMEMBER_MOST = 32  # polygons in a call whose results are remembered


def _immutable(vertices) -> bool:
    return type(vertices) is tuple and all(
        type(p) is tuple and all(type(c) is float for c in p) for p in vertices
    )


def _pairs_problem(vertices) -> str | None:
    """Why `vertices` is not a list of (x, y) pairs of numbers, or None (then it is one)."""
    try:
        _as_vertices(vertices)
    except ValueError as exc:
        return str(exc)
    return None


def _mass_properties(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(areas, second moments) of (n, k, 2) CCW polygons: `mass_properties`, every polygon at
    once, with the same operations in the same order (so the same bits)."""
    n, k = v.shape[0], v.shape[1]
    ox, oy = v[:, 0, 0], v[:, 0, 1]
    area = np.zeros(n)
    cx = np.zeros(n)
    cy = np.zeros(n)
    moment = np.zeros(n)
    for i in range(1, k - 1):
        e1x, e1y = v[:, i, 0] - ox, v[:, i, 1] - oy
        e2x, e2y = v[:, i + 1, 0] - ox, v[:, i + 1, 1] - oy
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
    return area, moment - area * (cx * cx + cy * cy)


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
