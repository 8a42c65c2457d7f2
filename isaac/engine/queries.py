"""World queries: what a ray hits first, what lies in a box, what overlaps a shape, and which
body lies closest to a point. Each reads one pose of the world (a `State`, or a `StepRecord`
of a recorded step) and changes nothing.

Units and frames: metres, world frame (x right, y up), angles counter-clockwise in radians.
A ray is the segment origin + t * direction for t in [0, max_fraction] (direction is not
normalised: it is Box2D v3's `translation`), so a fraction of 0.5 with max_fraction 1 is half
way along `direction`.

What each query reports:
- `ray_cast_many` / `ray_cast`: the first shape the ray enters: fraction t, point
  origin + t * direction, the unit outward normal of the shape there and the body. A ray that
  starts inside a shape, or on its boundary, does not hit that shape ("initial overlap is
  treated as a miss", Box2D v3's b2RayCastPolygon and b2RayCastCircle); it reports the next
  shape it enters. Shapes are closed: a ray grazing a vertex or running along an edge hits it.
  Ties (equal fractions) go to the lowest body index.
- `query_box`: bodies whose tight world AABB overlaps the box [lo, hi] (closed: touching
  counts). AABB only, as Box2D's b2World_OverlapAABB: a body whose box meets the query box
  but whose shape does not is reported; `overlaps` gives the exact answer.
- `overlaps`: bodies whose shape overlaps a given circle or convex polygon at a pose
  (touching counts), by the engine's own narrow-phase tests for one pair: SAT over both
  polygons' face normals (`narrow_phase.max_separation`) and the circle contacts
  (`circles.round_contact`, margin 0).
- `closest`: the body whose shape is nearest to a point (distance 0 when the point is inside,
  then the point itself is the closest point), ties to the lowest index.

Only bodies that exist in the pose are considered, and with a `QueryFilter` only those the
collision filter's rule (`isaac.collision_filter.collides`, Box2D's b2ShouldCollide) lets meet
the filter: with group 0 that is Box2D v3's b2QueryFilter (the body's category has a bit of the
filter's mask and the body's mask a bit of the filter's category).

Ray broad phase: a uniform grid built at each call from the current boxes (cell side the
median box side; at most 4 cells and 16 list entries a body, coarser cells else), bodies listed
in each cell in index order; each ray walks its cells in order along the ray (Amanatides and
Woo, 1987), tests each body once (a per-ray stamp) and stops once its best hit lies before the
cell it would enter next. The grid only prunes: every body a ray could hit before its best is
tested, so the result is the one a test of every body gives (tests/test_queries.py checks that
against brute force).

Shapes dispatch on a kind code (`shape_kinds`): POLYGON, CIRCLE. A new shape kind is one more
code and one more branch in `_ray_shape`, `_overlaps_shape` and `_distance_shape`.

Input is checked here, in Python, before anything reaches compiled code (TypeError or
ValueError naming the argument); the kernels trust it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from isaac import collision_filter
from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.circles import round_contact
from isaac.engine.geometry import transform
from isaac.engine.integrate import DIVERGED_POSITION
from isaac.engine.narrow_phase import max_separation
from isaac.scene.limits import FILTER_BITS, MAX_GROUP, MAX_SIZE, MIN_SIZE
from isaac.scene.polygon import validate_polygon
from isaac.scene.spec import DEFAULT_CATEGORY, DEFAULT_MASK

POLYGON = 0
CIRCLE = 1

# m: every query coordinate (origins, ray ends, points, box corners, a shape's pose) is within
# this of the origin, the bound the engine keeps every body within (the divergence check)
MAX_QUERY_COORDINATE = DIVERGED_POSITION
MAX_QUERY_ANGLE = 1e6  # rad, the scene's own bound on angles (isaac.trig's accurate range)
# cells of the ray grid: at most this many per body considered (plus GRID_SPARE_CELLS)
GRID_CELLS_PER_BODY = 4
GRID_SPARE_CELLS = 16
GRID_ENTRIES_PER_BODY = 16  # cell list entries a body, at most (bodies far above the median)
# bodies are binned into every cell their box comes within this share of the world's largest
# coordinate (at least 1 m) of: far more than the few roundings in the walk's cell boundaries,
# so a hit point always lies in a cell the walk visits and its body is binned in
GRID_MARGIN = 2.0**-30


def shape_kinds(model) -> np.ndarray:
    """(n,) int64 shape kind code of every body: CIRCLE for a circle (one vertex, a radius:
    `isaac.engine.world.Model`), POLYGON for a convex polygon."""
    return np.where(model.vertex_count == 1, CIRCLE, POLYGON).astype(np.int64)


@dataclass(frozen=True)
class QueryFilter:
    """Which bodies a query may report, by the collision filter's rule
    (`isaac.collision_filter.collides`): the bodies a body of this filter could collide with.
    category, mask: whole numbers of FILTER_BITS (32) bits; group: in [-MAX_GROUP, MAX_GROUP]
    (a negative group leaves out the bodies of that group, a positive one takes them whatever
    the bits). The default is the default body's filter: category 1, every mask bit, no group.
    Without a filter (None) a query considers every existing body."""

    category: int = DEFAULT_CATEGORY
    mask: int = DEFAULT_MASK
    group: int = 0

    def __post_init__(self) -> None:
        hi = 2**FILTER_BITS - 1
        for field, lo, top in (
            ("category", 0, hi),
            ("mask", 0, hi),
            ("group", -MAX_GROUP, MAX_GROUP),
        ):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise TypeError(f"QueryFilter {field} must be an int, got {type(value).__name__}")
            if not lo <= value <= top:
                raise ValueError(f"QueryFilter {field} {value} must be in {lo}..{top}")


@dataclass(frozen=True)
class RayHit:
    """The first hit of one ray. hit: whether it hit; body: its index (-1 for none); name: its
    name (None); point: (x, y) m, world, origin + fraction * direction; normal: unit, world,
    pointing out of the hit shape; fraction: t in [0, max_fraction] (NaN for no hit, as are the
    point and the normal)."""

    hit: bool
    body: int
    name: str | None
    point: tuple[float, float]
    normal: tuple[float, float]
    fraction: float


@dataclass(frozen=True)
class RayHits:
    """The first hits of m rays, row k for ray k (read-only arrays). hit: (m,) bool; body: (m,)
    int64 body index, -1 for none; point: (m, 2) m, world; normal: (m, 2) unit, world, out of
    the hit shape; fraction: (m,) in [0, max_fraction]. NaN in point, normal and fraction where
    a ray hits nothing."""

    hit: np.ndarray
    body: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    fraction: np.ndarray

    def __len__(self) -> int:
        return self.hit.shape[0]


@dataclass(frozen=True)
class Closest:
    """The body nearest to a point. found: False when no body is considered (then body -1,
    name None, point and distance NaN); point: (x, y) m, world, the point of the body's shape
    nearest to the query point (the query point itself when inside); distance: m, >= 0, 0
    inside or on the boundary."""

    found: bool
    body: int
    name: str | None
    point: tuple[float, float]
    distance: float


# ---- input checks (Python, before any compiled code) -------------------------------------------


def _numbers(value, name: str) -> np.ndarray:
    """`value` as a float64 array, TypeError unless it is numbers (bools and strings are not)."""
    try:
        a = np.asarray(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be numbers, got {type(value).__name__}") from None
    if a.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be numbers, got {type(value).__name__} of {a.dtype}")
    return np.array(a, dtype=np.float64)


def _within(a: np.ndarray, name: str, bound: float, unit: str = "m") -> None:
    bad = ~np.isfinite(a)
    if bad.any():
        where = f" (row {np.argwhere(bad)[0][0]})" if a.ndim == 2 else ""
        raise ValueError(f"{name} must be finite{where}, got {a[bad][0]}")
    if a.size and np.abs(a).max() > bound:
        raise ValueError(f"{name} must be within {bound:g} {unit} of 0, got {np.abs(a).max():g}")


def _point(value, name: str) -> np.ndarray:
    """(2,) float64: an (x, y) point (m, world)."""
    a = _numbers(value, name)
    if a.shape != (2,):
        raise ValueError(f"{name} must be one (x, y) pair, got shape {a.shape}")
    _within(a, name, MAX_QUERY_COORDINATE)
    return a


def _points(value, name: str) -> np.ndarray:
    """(m, 2) float64, C-contiguous: m (x, y) rows (m, world)."""
    a = _numbers(value, name)
    if a.ndim != 2 or a.shape[1] != 2:
        raise ValueError(f"{name} must be an (m, 2) array of (x, y) rows, got shape {a.shape}")
    _within(a, name, MAX_QUERY_COORDINATE)
    return np.ascontiguousarray(a)


def _fractions(value, m: int) -> np.ndarray:
    """(m,) float64 max fractions, each finite and >= 0 (a number or one per ray)."""
    if isinstance(value, bool):
        raise TypeError("max_fraction must be a number, got bool")
    a = _numbers(value, "max_fraction")
    if a.ndim == 0:
        a = np.full(m, float(a))
    elif a.shape != (m,):
        raise ValueError(f"max_fraction must be a number or one per ray ({m},), got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError("max_fraction must be finite")
    if (a < 0.0).any():
        raise ValueError(f"max_fraction must be >= 0, got {a[a < 0.0][0]}")
    return a


def _eligible(model, state, filter) -> np.ndarray:
    """(n,) bool: the bodies a query considers: existing ones the filter lets meet it."""
    exists = np.asarray(state.exists, dtype=bool)
    if exists.shape != (model.n_bodies,):
        raise ValueError(f"the state's exists is {exists.shape}, the model has {model.n_bodies}")
    if filter is None:
        return exists.copy()
    if not isinstance(filter, QueryFilter):
        raise TypeError(
            f"filter must be an isaac.engine.queries.QueryFilter or None, "
            f"got {type(filter).__name__}"
        )
    meets = collision_filter.collides(
        int(filter.category), int(filter.mask), int(filter.group),
        model.category, model.mask, model.group,
    )  # fmt: skip
    return exists & meets


@dataclass(frozen=True)
class _World:
    """World geometry of one pose: vertices, normals (n + extra, W, 2), boxes (n + extra, 4),
    as the step computes them (`geometry.transform`); rows past n are for a query shape."""

    kind: np.ndarray
    vertices: np.ndarray
    normals: np.ndarray
    vertex_count: np.ndarray
    radius: np.ndarray
    aabb: np.ndarray


def _world(model, state, extra: int = 0, width: int = 0) -> _World:
    n = model.n_bodies
    position = np.array(state.position, dtype=np.float64)
    angle = np.array(state.angle, dtype=np.float64)
    exists = np.array(state.exists, dtype=bool)
    if position.shape != (n, 2) or angle.shape != (n,) or exists.shape != (n,):
        raise ValueError(
            f"the state's position, angle and exists must be ({n}, 2), ({n},), ({n},) for "
            f"this model's {n} bodies, got {position.shape}, {angle.shape}, {exists.shape}"
        )
    if not (np.isfinite(position).all() and np.isfinite(angle).all()):
        raise ValueError("the state's positions and angles must be finite")
    w = max(model.vertices_local.shape[1], width)
    vertices = np.zeros((n + extra, w, 2))
    normals = np.zeros((n + extra, w, 2))
    aabb = np.zeros((n + extra, 4))
    transform(
        position, angle, exists, model.vertices_local, model.normals_local, model.vertex_count,
        model.radius, vertices, normals, aabb,
    )  # fmt: skip
    count = np.zeros(n + extra, dtype=np.int64)
    count[:n] = model.vertex_count
    radius = np.zeros(n + extra)
    radius[:n] = model.radius
    kind = np.zeros(n + extra, dtype=np.int64)
    kind[:n] = shape_kinds(model)
    return _World(kind, vertices, normals, count, radius, aabb)


# ---- ray casts ---------------------------------------------------------------------------------


@numba.njit(cache=True, nogil=True, inline="always")
def _ray_polygon(vertices, normals, count, i, ox, oy, dx, dy, max_fraction):
    """(hit, fraction, face) of ray o + t d, t in [0, max_fraction], against convex polygon i:
    Box2D v3's b2RayCastPolygon, clipping t against each edge's half-plane. For edge k with
    outward normal n_k through vertex v_k the ray is inside while
        n_k . (o + t d - v_k) <= 0,  i.e.  t * (n_k . d) <= n_k . (v_k - o) = numerator,
    so a face with n_k . d < 0 (entering) raises the lower bound, one with n_k . d > 0
    (leaving) lowers the upper bound, and a parallel face outside (numerator < 0) is a miss.
    The entry face is the one that raised the lower bound last; none (lower stays 0 from the
    start) means the origin was inside or on the boundary: a miss (initial overlap).
    The comparisons are written without division (numerator < lower * denominator when the
    denominator is negative), as Box2D does."""
    lower = 0.0
    upper = max_fraction
    face = -1
    for k in range(count[i]):
        nx = normals[i, k, 0]
        ny = normals[i, k, 1]
        numerator = nx * (vertices[i, k, 0] - ox) + ny * (vertices[i, k, 1] - oy)
        denominator = nx * dx + ny * dy
        if denominator == 0.0:
            if numerator < 0.0:
                return False, 0.0, -1
        elif denominator < 0.0 and numerator < lower * denominator:
            lower = numerator / denominator
            face = k
        elif denominator > 0.0 and numerator < upper * denominator:
            upper = numerator / denominator
        if upper < lower:
            return False, 0.0, -1
    if face < 0:
        return False, 0.0, -1
    return True, lower, face


@numba.njit(cache=True, nogil=True, inline="always")
def _ray_circle(cx, cy, r, ox, oy, dx, dy, max_fraction):
    """(hit, fraction) of ray o + t d against the circle of centre c and radius r: the smaller
    root of |s + t d|^2 = r^2 (s = o - c), i.e. a t^2 + 2 b t + c0 = 0 with a = d.d, b = s.d,
    c0 = s.s - r^2. Written in the stable form:
    - the discriminant b^2 - a c0 equals a (r^2 - |q|^2) with q = s - (b/a) d the ray line's
      point nearest the centre (Box2D v3's b2RayCastCircle), which does not cancel for a ray
      that grazes the circle as b^2 - a c0 does;
    - the near root is c0 / (sqrt(disc) - b) (Vieta: t_near t_far = c0 / a), whose
      denominator is a sum of two positive terms, where (-b - sqrt(disc)) / a cancels for an
      origin near the surface.
    A miss when the origin is inside or on the circle (c0 <= 0: initial overlap), when the
    ray points away (b >= 0) or passes by (r^2 < |q|^2), or beyond max_fraction."""
    sx = ox - cx
    sy = oy - cy
    a = dx * dx + dy * dy
    rr = r * r
    c0 = (sx * sx + sy * sy) - rr
    b = sx * dx + sy * dy
    if a == 0.0 or c0 <= 0.0 or b >= 0.0:
        return False, 0.0
    t_mid = -b / a
    qx = sx + t_mid * dx
    qy = sy + t_mid * dy
    h2 = rr - (qx * qx + qy * qy)
    if h2 < 0.0:
        return False, 0.0
    t = c0 / (np.sqrt(a * h2) - b)
    if t > max_fraction:
        return False, 0.0
    return True, t


@numba.njit(cache=True, nogil=True, inline="always")
def _ray_shape(kind, vertices, normals, count, radius, i, ox, oy, dx, dy, max_fraction):
    """(hit, fraction, nx, ny) of a ray against body i's shape, by its kind code."""
    if kind[i] == CIRCLE:
        cx = vertices[i, 0, 0]
        cy = vertices[i, 0, 1]
        hit, t = _ray_circle(cx, cy, radius[i], ox, oy, dx, dy, max_fraction)
        if not hit:
            return False, 0.0, 0.0, 0.0
        # the outward normal: from the centre to the hit point, made unit
        hx = (ox + t * dx) - cx
        hy = (oy + t * dy) - cy
        length = np.sqrt(hx * hx + hy * hy)
        return True, t, hx / length, hy / length
    hit, t, face = _ray_polygon(vertices, normals, count, i, ox, oy, dx, dy, max_fraction)
    if not hit:
        return False, 0.0, 0.0, 0.0
    return True, t, normals[i, face, 0], normals[i, face, 1]


@numba.njit(cache=True, nogil=True)
def build_grid(aabb, eligible):
    """A uniform grid over the eligible bodies' boxes (aabb (n, 4): lo x, lo y, hi x, hi y, m).
    Returns (origin_x, origin_y, cell, nx, ny, start, bodies): cell side (m), nx * ny cells,
    row-major (cell iy * nx + ix), the bodies of cell c in bodies[start[c]:start[c + 1]] in
    increasing index (determinism: the walk then meets ties in index order). A body is binned
    into every cell its box, widened by the margin (GRID_MARGIN), overlaps; cells are made
    coarser until that is at most GRID_ENTRIES_PER_BODY entries a body. nx = 0: no body."""
    n = aabb.shape[0]
    m = 0
    lo_x = np.inf
    lo_y = np.inf
    hi_x = -np.inf
    hi_y = -np.inf
    for i in range(n):
        if eligible[i]:
            m += 1
            lo_x = min(lo_x, aabb[i, 0])
            lo_y = min(lo_y, aabb[i, 1])
            hi_x = max(hi_x, aabb[i, 2])
            hi_y = max(hi_y, aabb[i, 3])
    empty = np.zeros(1, dtype=np.int64)
    if m == 0:
        return 0.0, 0.0, 1.0, 0, 0, empty, empty
    scale = max(1.0, max(max(abs(lo_x), abs(hi_x)), max(abs(lo_y), abs(hi_y))))
    margin = GRID_MARGIN * scale
    lo_x -= 2.0 * margin
    lo_y -= 2.0 * margin
    hi_x += 2.0 * margin
    hi_y += 2.0 * margin
    # cell side: the median of the bodies' larger box sides (most bodies then span 1-4 cells)
    sides = np.empty(m)
    k = 0
    for i in range(n):
        if eligible[i]:
            sides[k] = max(aabb[i, 2] - aabb[i, 0], aabb[i, 3] - aabb[i, 1])
            k += 1
    sides.sort()
    cell = max(sides[m // 2], margin)
    width = hi_x - lo_x
    height = hi_y - lo_y
    most = GRID_CELLS_PER_BODY * m + GRID_SPARE_CELLS
    cell = max(cell, max(width, height) / most)
    while (math.floor(width / cell) + 1.0) * (math.floor(height / cell) + 1.0) > most:
        cell *= 1.25
    nx = int(math.floor(width / cell)) + 1
    ny = int(math.floor(height / cell)) + 1
    # many bodies much larger than the median would each fill many cells: coarser cells until
    # the lists hold at most GRID_ENTRIES_PER_BODY entries a body (one cell holds m)
    while nx * ny > 1:
        entries = 0
        for i in range(n):
            if eligible[i]:
                x0, y0, x1, y1 = _cell_span(aabb, i, margin, lo_x, lo_y, cell, nx, ny)
                entries += (x1 - x0 + 1) * (y1 - y0 + 1)
        if entries <= GRID_ENTRIES_PER_BODY * m + GRID_SPARE_CELLS:
            break
        cell *= 2.0
        nx = int(math.floor(width / cell)) + 1
        ny = int(math.floor(height / cell)) + 1
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    # two passes over the bodies in index order: count each cell's bodies, then place them
    for i in range(n):
        if eligible[i]:
            x0, y0, x1, y1 = _cell_span(aabb, i, margin, lo_x, lo_y, cell, nx, ny)
            for iy in range(y0, y1 + 1):
                for ix in range(x0, x1 + 1):
                    start[iy * nx + ix + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    bodies = np.empty(start[nx * ny], dtype=np.int64)
    for i in range(n):
        if eligible[i]:
            x0, y0, x1, y1 = _cell_span(aabb, i, margin, lo_x, lo_y, cell, nx, ny)
            for iy in range(y0, y1 + 1):
                for ix in range(x0, x1 + 1):
                    c = iy * nx + ix
                    bodies[fill[c]] = i
                    fill[c] += 1
    return lo_x, lo_y, cell, nx, ny, start, bodies


@numba.njit(cache=True, nogil=True, inline="always")
def _clip_slab(o, d, lo, hi, t0, t1):
    """[t0, t1] clipped to where o + t * d lies in [lo, hi] (one axis of a box, m); an empty
    interval (t0 > t1) when a ray parallel to the axis lies outside it."""
    if d == 0.0:
        if o < lo or o > hi:
            return 1.0, 0.0
        return t0, t1
    ta = (lo - o) / d
    tb = (hi - o) / d
    return max(t0, min(ta, tb)), min(t1, max(ta, tb))


@numba.njit(cache=True, nogil=True, inline="always")
def _cell_index(x, lo, cell, count):
    """The cell along one axis holding coordinate x, clamped to 0 .. count - 1."""
    k = int(math.floor((x - lo) / cell))
    return min(max(k, 0), count - 1)


@numba.njit(cache=True, nogil=True, inline="always")
def _cell_span(aabb, i, margin, lo_x, lo_y, cell, nx, ny):
    """(x0, y0, x1, y1): the cells body i's box widened by `margin` overlaps (inclusive)."""
    x0 = _cell_index(aabb[i, 0] - margin, lo_x, cell, nx)
    y0 = _cell_index(aabb[i, 1] - margin, lo_y, cell, ny)
    x1 = _cell_index(aabb[i, 2] + margin, lo_x, cell, nx)
    y1 = _cell_index(aabb[i, 3] + margin, lo_y, cell, ny)
    return x0, y0, x1, y1


@numba.njit(cache=True, nogil=True)
def cast_rays(
    origins, directions, max_fraction, kind, vertices, normals, count, radius, grid, hit_body,
    hit_fraction, hit_point, hit_normal,
):  # fmt: skip
    """The first hit of each ray k: origins (m, 2) m, directions (m, 2) m (the ray is
    origin + t * direction, t in [0, max_fraction[k]]), against the bodies of `grid`
    (`build_grid`). Fills hit_body (m,) (-1: none), hit_fraction (m,), hit_point (m, 2) and
    hit_normal (m, 2) (NaN where none).

    Each ray clips [0, max_fraction] to the grid's box, then walks the cells it crosses in
    order (Amanatides and Woo): in each, every body not yet tested by this ray is tested; the
    best hit is the smallest fraction, ties to the lowest index; the walk stops when the best
    hit lies strictly before the boundary into the next cell (a body hit there or later cannot
    be better: its hit point lies in a later cell, which it is binned in). Each boundary's t is
    computed afresh from the cell index, never accumulated, so its error stays a few roundings
    of the coordinates (the binning margin covers it)."""
    lo_x, lo_y, cell, nx, ny, start, bodies = grid
    n = kind.shape[0]
    tested = np.full(n, -1, dtype=np.int64)
    hi_x = lo_x + nx * cell
    hi_y = lo_y + ny * cell
    for r in range(origins.shape[0]):
        hit_body[r] = -1
        hit_fraction[r] = np.nan
        hit_point[r, 0] = np.nan
        hit_point[r, 1] = np.nan
        hit_normal[r, 0] = np.nan
        hit_normal[r, 1] = np.nan
        ox = origins[r, 0]
        oy = origins[r, 1]
        dx = directions[r, 0]
        dy = directions[r, 1]
        t_end = max_fraction[r]
        if nx == 0 or (dx == 0.0 and dy == 0.0):
            continue
        # the ray's part inside the grid's box (slabs), within [0, max_fraction]
        t0, t1 = _clip_slab(ox, dx, lo_x, hi_x, 0.0, t_end)
        t0, t1 = _clip_slab(oy, dy, lo_y, hi_y, t0, t1)
        if t0 > t1:
            continue
        ix = _cell_index(ox + t0 * dx, lo_x, cell, nx)
        iy = _cell_index(oy + t0 * dy, lo_y, cell, ny)
        step_x = 1 if dx > 0.0 else -1
        step_y = 1 if dy > 0.0 else -1
        best_t = np.inf
        best = -1
        best_nx = 0.0
        best_ny = 0.0
        while True:
            c = iy * nx + ix
            for q in range(start[c], start[c + 1]):
                i = bodies[q]
                if tested[i] == r:
                    continue
                tested[i] = r
                hit, t, mx, my = _ray_shape(
                    kind, vertices, normals, count, radius, i, ox, oy, dx, dy, t_end
                )
                # determinism: strict '<', and bodies met in index order within a cell; a tie
                # met in a later cell goes to the lower index explicitly
                if hit and (t < best_t or (t == best_t and i < best)):
                    best_t = t
                    best = i
                    best_nx = mx
                    best_ny = my
            tx = np.inf
            if dx != 0.0:
                tx = (lo_x + (ix + 1 if dx > 0.0 else ix) * cell - ox) / dx
            ty = np.inf
            if dy != 0.0:
                ty = (lo_y + (iy + 1 if dy > 0.0 else iy) * cell - oy) / dy
            t_next = min(tx, ty)
            if best_t < t_next or t_next > t1:
                break
            # on a tie (a corner) step x first: the cell beside the corner is visited too
            if tx <= ty:
                ix += step_x
            else:
                iy += step_y
            if ix < 0 or ix >= nx or iy < 0 or iy >= ny:
                break
        if best >= 0:
            hit_body[r] = best
            hit_fraction[r] = best_t
            hit_point[r, 0] = ox + best_t * dx
            hit_point[r, 1] = oy + best_t * dy
            hit_normal[r, 0] = best_nx
            hit_normal[r, 1] = best_ny


def ray_cast_many(model, state, origins, directions, max_fraction=1.0, filter=None) -> RayHits:
    """The first hit of each of m rays origins[k] + t * directions[k], t in [0, max_fraction]
    (origins, directions: (m, 2) m, world; max_fraction: a number >= 0 or (m,)), in the pose
    `state` (a `State` or `StepRecord` of `model`), among the bodies `filter` lets through.
    A zero direction hits nothing. See the module docstring for what counts as a hit."""
    origins = _points(origins, "origins")
    directions = _points(directions, "directions")
    if directions.shape != origins.shape:
        raise ValueError(
            f"directions must have one row per origin ({origins.shape[0]}), "
            f"got {directions.shape[0]}"
        )
    fractions = _fractions(max_fraction, origins.shape[0])
    _within(origins + fractions[:, None] * directions, "the rays' ends", MAX_QUERY_COORDINATE)
    eligible = _eligible(model, state, filter)
    world = _world(model, state)
    m = origins.shape[0]
    body = np.empty(m, dtype=np.int64)
    fraction = np.empty(m)
    point = np.empty((m, 2))
    normal = np.empty((m, 2))
    grid = build_grid(world.aabb, eligible)
    cast_rays(
        origins, directions, fractions, world.kind, world.vertices, world.normals,
        world.vertex_count, world.radius, grid, body, fraction, point, normal,
    )  # fmt: skip
    hits = RayHits(body >= 0, body, point, normal, fraction)
    for a in (hits.hit, body, point, normal, fraction):
        a.flags.writeable = False
    return hits


def ray_cast(model, state, origin, direction, max_fraction=1.0, filter=None) -> RayHit:
    """The first hit of the ray origin + t * direction, t in [0, max_fraction] (origin,
    direction: (x, y) m, world; max_fraction >= 0): `ray_cast_many` of one ray."""
    origin = _point(origin, "origin")
    direction = _point(direction, "direction")
    if isinstance(max_fraction, bool) or np.ndim(max_fraction) != 0:
        raise TypeError(f"max_fraction must be one number, got {type(max_fraction).__name__}")
    hits = ray_cast_many(model, state, origin[None], direction[None], max_fraction, filter)
    b = int(hits.body[0])
    return RayHit(
        hit=b >= 0,
        body=b,
        name=model.names[b] if b >= 0 else None,
        point=(float(hits.point[0, 0]), float(hits.point[0, 1])),
        normal=(float(hits.normal[0, 0]), float(hits.normal[0, 1])),
        fraction=float(hits.fraction[0]),
    )


# ---- box, shape and point queries --------------------------------------------------------------


def query_box(model, state, lo, hi, filter=None) -> np.ndarray:
    """(k,) int64 sorted indices of the bodies whose world AABB (tight: the box of a polygon's
    vertices, a circle's centre +- radius) overlaps the box [lo, hi] (lo, hi: (x, y) m, world,
    lo <= hi; closed, so touching counts). AABB only (Box2D's b2World_OverlapAABB); for the
    exact shapes use `overlaps` with a box polygon."""
    lo = _point(lo, "lo")
    hi = _point(hi, "hi")
    if (lo > hi).any():
        raise ValueError(f"lo must be <= hi in x and y, got lo {lo.tolist()}, hi {hi.tolist()}")
    eligible = _eligible(model, state, filter)
    box = _world(model, state).aabb
    inside = (box[:, 0] <= hi[0]) & (box[:, 2] >= lo[0]) & (box[:, 1] <= hi[1])
    inside &= box[:, 3] >= lo[1]
    return np.flatnonzero(eligible & inside).astype(np.int64)


def _query_shape(shape, pose):
    """(vertices_local (1, k, 2), normals_local (1, k, 2), count (1,), radius (1,), position
    (1, 2), angle (1,)) of a query shape: a circle (radius, m) or a convex polygon (vertices,
    m, in the shape's frame), placed at pose (x, y[, angle]) (m, m, rad; world)."""
    if isinstance(shape, bool):
        raise TypeError("shape must be a radius (m) or a list of (x, y) vertices (m), got bool")
    p = _numbers(pose, "pose")
    if p.shape not in ((2,), (3,)):
        raise ValueError(f"pose must be (x, y) or (x, y, angle), got shape {p.shape}")
    _within(p[:2], "pose position", MAX_QUERY_COORDINATE)
    angle = float(p[2]) if p.shape == (3,) else 0.0
    _within(np.array([angle]), "pose angle", MAX_QUERY_ANGLE, "rad")
    s = _numbers(shape, "shape")
    if s.ndim == 0:
        r = float(s)
        if not (MIN_SIZE <= 2.0 * r <= MAX_SIZE):
            raise ValueError(
                f"shape: a circle's radius must be {MIN_SIZE / 2:g} .. {MAX_SIZE / 2:g} m, got {r}"
            )
        local = np.zeros((1, 1, 2))
        local_normals = np.array([[[1.0, 0.0]]])
        count = np.array([1], dtype=np.int64)
        radius = np.array([r])
    else:
        try:
            v = validate_polygon(s)
        except ValueError as exc:
            raise ValueError(f"shape: {exc}") from None
        _within(v, "shape vertices", MAX_QUERY_COORDINATE)
        k = v.shape[0]
        # outward normal of a counter-clockwise edge (dx, dy) is (dy, -dx) / |edge|, as
        # isaac.engine.world.build_model gives the bodies'
        edge = np.roll(v, -1, axis=0) - v
        length = np.sqrt(edge[:, 0] ** 2 + edge[:, 1] ** 2)
        local = v[None].copy()
        local_normals = np.stack([edge[:, 1] / length, -edge[:, 0] / length], axis=1)[None]
        count = np.array([k], dtype=np.int64)
        radius = np.array([np.sqrt(np.max(v[:, 0] ** 2 + v[:, 1] ** 2))])
    return local, np.ascontiguousarray(local_normals), count, radius, p[None, :2].copy(), angle


@numba.njit(cache=True, nogil=True, inline="always")
def _overlaps_shape(kind, vertices, normals, count, radius, i, q):
    """Whether body i's shape and the query shape (row q) overlap or touch, by their kinds:
    SAT for two polygons (no face of either separates them: the largest face separation is
    <= 0), the circle contact test otherwise (a gap of at most 0)."""
    if kind[i] == POLYGON and kind[q] == POLYGON:
        s_i = max_separation(vertices, normals, i, count[i], q, count[q])[0]
        s_q = max_separation(vertices, normals, q, count[q], i, count[i])[0]
        return max(s_i, s_q) <= 0.0
    return round_contact(vertices, normals, count, radius, i, q, 0.0)[0]


@numba.njit(cache=True, nogil=True)
def overlapping(kind, vertices, normals, count, radius, aabb, eligible, q, out):
    """Write into `out` the eligible bodies (indices below q, increasing) whose box meets the
    query shape's (row q) and whose shape overlaps it; returns how many."""
    k = 0
    for i in range(q):
        if not eligible[i]:
            continue
        if (
            aabb[i, 0] > aabb[q, 2]
            or aabb[i, 2] < aabb[q, 0]
            or aabb[i, 1] > aabb[q, 3]
            or aabb[i, 3] < aabb[q, 1]
        ):
            continue
        if _overlaps_shape(kind, vertices, normals, count, radius, i, q):
            out[k] = i
            k += 1
    return k


def overlaps(model, state, shape, pose, filter=None) -> np.ndarray:
    """(k,) int64 sorted indices of the bodies whose shape overlaps (or touches) the query
    shape: `shape` a circle's radius (m) or a convex polygon's (x, y) vertices (m, in the
    shape's own frame, either winding, as a scene's `polygon:`), placed at `pose`
    (x, y) or (x, y, angle) (m, world; rad, counter-clockwise): a shape vertex v is at
    (x, y) + R(angle) v in the world."""
    local, local_normals, count, radius, position, angle = _query_shape(shape, pose)
    eligible = _eligible(model, state, filter)
    n = model.n_bodies
    world = _world(model, state, extra=1, width=local.shape[1])
    # the query shape placed as the step places a body (the same transform), row n
    mine = np.zeros((1, local.shape[1], 2))
    mine_normals = np.zeros((1, local.shape[1], 2))
    mine_box = np.zeros((1, 4))
    transform(
        position, np.array([angle]), np.ones(1, dtype=bool), local, local_normals, count, radius,
        mine, mine_normals, mine_box,
    )  # fmt: skip
    world.vertices[n, : local.shape[1]] = mine[0]
    world.normals[n, : local.shape[1]] = mine_normals[0]
    world.aabb[n] = mine_box[0]
    world.vertex_count[n] = count[0]
    world.radius[n] = radius[0]
    world.kind[n] = CIRCLE if count[0] == 1 else POLYGON
    out = np.empty(n, dtype=np.int64)
    k = overlapping(
        world.kind, world.vertices, world.normals, world.vertex_count, world.radius, world.aabb,
        eligible, n, out,
    )  # fmt: skip
    return out[:k].copy()


@numba.njit(cache=True, nogil=True, inline="always")
def _distance_shape(kind, vertices, normals, count, radius, i, px, py):
    """(squared distance, qx, qy): from point p to body i's shape and its nearest point q
    (p itself, distance 0, inside or on the boundary)."""
    if kind[i] == CIRCLE:
        cx = vertices[i, 0, 0]
        cy = vertices[i, 0, 1]
        ex = px - cx
        ey = py - cy
        dist = np.sqrt(ex * ex + ey * ey)
        r = radius[i]
        if dist <= r:
            return 0.0, px, py
        qx = cx + ex * (r / dist)
        qy = cy + ey * (r / dist)
        gap = dist - r
        return gap * gap, qx, qy
    # convex polygon: inside when behind every face; else the nearest point lies on an edge
    # the point is in front of (only those are measured)
    best = np.inf
    bx = px
    by = py
    k_count = count[i]
    for k in range(k_count):
        v1x = vertices[i, k, 0]
        v1y = vertices[i, k, 1]
        if normals[i, k, 0] * (px - v1x) + normals[i, k, 1] * (py - v1y) <= 0.0:
            continue
        k2 = k + 1 if k + 1 < k_count else 0
        ex = vertices[i, k2, 0] - v1x
        ey = vertices[i, k2, 1] - v1y
        u = ((px - v1x) * ex + (py - v1y) * ey) / (ex * ex + ey * ey)
        u = min(max(u, 0.0), 1.0)
        qx = v1x + u * ex
        qy = v1y + u * ey
        d2 = (px - qx) * (px - qx) + (py - qy) * (py - qy)
        if d2 < best:
            best = d2
            bx = qx
            by = qy
    if best == np.inf:
        return 0.0, px, py
    return best, bx, by


@numba.njit(cache=True, nogil=True)
def nearest(kind, vertices, normals, count, radius, eligible, px, py):
    """(body, squared distance, qx, qy): the eligible body nearest to p (ties: lowest index;
    -1 when none)."""
    best = np.inf
    body = -1
    bx = np.nan
    by = np.nan
    for i in range(kind.shape[0]):
        if not eligible[i]:
            continue
        d2, qx, qy = _distance_shape(kind, vertices, normals, count, radius, i, px, py)
        if d2 < best:
            best = d2
            body = i
            bx = qx
            by = qy
    return body, best, bx, by


def closest(model, state, point, filter=None) -> Closest:
    """The body whose shape is nearest to `point` ((x, y) m, world) and the nearest point of
    it (m, world), with the distance (m; 0 inside or on the boundary)."""
    p = _point(point, "point")
    eligible = _eligible(model, state, filter)
    world = _world(model, state)
    body, d2, qx, qy = nearest(
        world.kind, world.vertices, world.normals, world.vertex_count, world.radius, eligible,
        float(p[0]), float(p[1]),
    )  # fmt: skip
    if body < 0:
        return Closest(False, -1, None, (math.nan, math.nan), math.nan)
    return Closest(True, int(body), model.names[body], (float(qx), float(qy)), math.sqrt(d2))
