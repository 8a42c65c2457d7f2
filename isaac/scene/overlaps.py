"""Bodies that overlap where a scene places them: bounding boxes on a grid, then SAT on pairs.

For the warnings of `isaac check` and `isaac run` (isaac.scene.warnings), which must not load
compiled code: pure numpy, every stage vectorised over bodies or pairs, in chunks so a scene of
100,000 bodies piled on one spot stays within a bounded memory.

Outline:
    place every body: world vertices (R(angle) (v - centroid) + position, the engine's model
        re-centres each polygon on its area centroid), outward edge normals, bounding boxes,
        thickness (the smallest width, as the engine's model computes it);
    bounding-box pairs from a uniform grid (box_pairs says why not a one-axis sweep): boxes
        sharing a cell are candidates, those whose boxes meet are the pairs;
    SAT on those pairs over both polygons' edge normals: depth = over all axes, the smallest
        distance one projection must move along the axis, either way, to clear the other (the
        minimum translation distance, m; <= 0 separated). Not the length the two projections
        share: when one holds the other (a marble in a box) that is the inner one's width.
        A circle is its centre (one vertex) with a radius that widens its projections; with
        circles, the axes from each body's vertices to the other's circle centre are tested
        too (the axis a circle and a polygon's vertex region need), which for convex shapes
        keeps the minimum the exact MTD (every axis's overlap is an upper bound of it).

Not the engine's narrow phase (isaac.engine.narrow_phase: numba, hysteresis, contact points):
these figures describe the scene as written, before its first step.
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import numpy as np

# elements of the largest temporary array one chunk of pairs builds (8 bytes each)
_CHUNK_ELEMENTS = 2_000_000
# a box covering more grid cells than this is tested against every box instead (box_pairs)
_MANY_CELLS = 64


class Placement(NamedTuple):
    """Every body of a scene where the scene places it, world frame, (n, ...) arrays.

    vertices: (n, width, 2) m, counter-clockwise, padded by repeating the last vertex.
    normals: (n, width, 2) outward unit normal of edge k (vertex k to k + 1), padded by
        repeating the last one (a repeated axis changes no minimum).
    centre: (n, 2) m, the centre of mass (the scene's `position`).
    lo, hi: (n, 2) m, the bounding box.
    thickness: (n,) m, the smallest width: over the edges, the largest depth of a vertex behind
        the edge, minimised (isaac.engine.world.build_model computes the same); a circle's
        diameter.
    radius: (n,) m, a circle's radius (its one vertex is its centre), 0 for a polygon.
    """

    vertices: np.ndarray
    normals: np.ndarray
    centre: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    thickness: np.ndarray
    radius: np.ndarray


def place(bodies) -> Placement:
    """The Placement of `bodies` (validated BodySpecs), grouped by vertex count so each group is
    one set of array operations."""
    n = len(bodies)
    # at least one column: a circle is its centre, one vertex (a scene of circles alone has no
    # polygon to set the width)
    width = max(max((len(b.vertices) for b in bodies), default=3), 1)
    vertices = np.zeros((n, width, 2))
    normals = np.zeros((n, width, 2))
    thickness = np.zeros(n)
    positions = itertools.chain.from_iterable(b.position for b in bodies)
    centre = np.fromiter(positions, np.float64, count=2 * n).reshape(n, 2)
    angle = np.fromiter((b.angle for b in bodies), dtype=np.float64, count=n)
    radius = np.zeros(n)
    groups: dict[int, list[int]] = {}
    for i, b in enumerate(bodies):
        if b.circle is not None:
            radius[i] = b.circle
        else:
            groups.setdefault(len(b.vertices), []).append(i)
    circles = np.flatnonzero(radius > 0.0)
    vertices[circles] = centre[circles, None, :]
    normals[circles] = (1.0, 0.0)  # any unit axis: an extra axis changes no minimum
    thickness[circles] = 2.0 * radius[circles]
    for k in sorted(groups):  # determinism: groups in a fixed order
        index = np.array(groups[k])
        # one flat pass over the coordinates: np.array on nested tuples costs ~3x as much
        flat = itertools.chain.from_iterable(
            itertools.chain.from_iterable(bodies[i].vertices for i in groups[k])
        )
        raw = np.fromiter(flat, np.float64, count=len(index) * k * 2).reshape(-1, k, 2)
        nxt = np.roll(raw, -1, axis=1)
        cross = raw[..., 0] * nxt[..., 1] - nxt[..., 0] * raw[..., 1]
        area = cross.sum(axis=1) / 2.0
        # area centroid: sum (v_i + v_i+1) cross_i / (6 A)
        centroid = ((raw + nxt) * cross[..., None]).sum(axis=1) / (6.0 * area[:, None])
        local = raw - centroid[:, None, :]
        c, s = np.cos(angle[index]), np.sin(angle[index])
        # R = [[cos, -sin], [sin, cos]], counter-clockwise
        world_x = c[:, None] * local[..., 0] - s[:, None] * local[..., 1]
        world_y = s[:, None] * local[..., 0] + c[:, None] * local[..., 1]
        v = np.stack([world_x, world_y], axis=-1) + centre[index, None, :]
        edge = np.roll(v, -1, axis=1) - v
        length = np.hypot(edge[..., 0], edge[..., 1])
        # outward normal of a counter-clockwise edge (dx, dy) is (dy, -dx) / |edge|
        normal = np.stack([edge[..., 1] / length, -edge[..., 0] / length], axis=-1)
        vertices[index, :k] = v
        vertices[index, k:] = v[:, k - 1 : k]
        normals[index, :k] = normal
        normals[index, k:] = normal[:, k - 1 : k]
        # depth of vertex j behind edge i: -n_i . (v_j - v_i), shape (m, edges, vertices)
        behind = -(
            normal[:, :, None, 0] * (v[:, None, :, 0] - v[:, :, None, 0])
            + normal[:, :, None, 1] * (v[:, None, :, 1] - v[:, :, None, 1])
        )
        thickness[index] = behind.max(axis=2).min(axis=1)
    return Placement(
        vertices,
        normals,
        centre,
        vertices.min(axis=1) - radius[:, None],
        vertices.max(axis=1) + radius[:, None],
        thickness,
        radius,
    )


def _quantile_90(x: np.ndarray) -> float:
    """np.quantile(x, 0.9) (its default linear method, the same value bit for bit) without
    np.quantile, which imports numpy.ma (through np.unique) on every start-up that checks a
    scene."""
    s = np.sort(x)
    at = (len(s) - 1) * 0.9
    i = int(at)
    gamma = at - i
    a, b = s[i], s[min(i + 1, len(s) - 1)]
    # numpy's _lerp: from the nearer end
    return float(b - (b - a) * (1.0 - gamma)) if gamma >= 0.5 else float(a + (b - a) * gamma)


def box_pairs(lo: np.ndarray, hi: np.ndarray, limit: int) -> tuple[np.ndarray, np.ndarray, bool]:
    """(a, b, complete): the pairs a < b whose bounding boxes overlap (touching counts), sorted
    by (a, b); at most `limit` of them, complete False if more were left out.

    A uniform grid, not a one-axis sweep: bodies spread over a plane (a pile's starting grid)
    overlap in x with a whole column and in y with a whole row, so a sweep makes n * sqrt(n)
    candidates (1e6 for a 10,000-body pile, 1e8 for 100,000). Cells are as wide as the 90th
    percentile of the boxes' sizes; each box goes into every cell it covers, boxes sharing a
    cell are candidates, and the candidates whose boxes meet are the pairs. A box covering more
    than _MANY_CELLS cells (a floor, a wall) is instead tested against every box."""
    n = len(lo)
    empty = np.zeros(0, dtype=np.int64)
    if n < 2:
        return empty, empty, True
    extent = (hi - lo).max(axis=1)
    cell = max(_quantile_90(extent), 1e-300)
    first = np.floor(lo / cell)
    last = np.floor(hi / cell)
    span = last - first + 1.0  # (n, 2) cells covered along x and y
    covered = span[:, 0] * span[:, 1]
    large = covered > _MANY_CELLS
    found_a, found_b = [], []
    kept = 0
    # large boxes: against every box, a few at a time
    for chunk in np.array_split(np.flatnonzero(large), max(1, int(large.sum()) * n // 10**7)):
        if len(chunk) == 0:
            continue
        meet = (
            (lo[None, :, 0] <= hi[chunk, None, 0])
            & (lo[chunk, None, 0] <= hi[None, :, 0])
            & (lo[None, :, 1] <= hi[chunk, None, 1])
            & (lo[chunk, None, 1] <= hi[None, :, 1])
        )
        rows, others = np.nonzero(meet)
        big = chunk[rows]
        # a pair of two large boxes once; a box never with itself
        keep = (big != others) & (~large[others] | (big < others))
        found_a.append(np.minimum(big, others)[keep])
        found_b.append(np.maximum(big, others)[keep])
        kept += int(keep.sum())
    # small boxes: into every cell they cover (at most _MANY_CELLS each)
    small = np.flatnonzero(~large)
    count = covered[small].astype(np.int64)
    body = np.repeat(small, count)
    k = np.arange(len(body)) - np.repeat(np.cumsum(count) - count, count)  # cell within body
    width = span[body, 0].astype(np.int64)
    cx = first[body, 0] + k % width
    cy = first[body, 1] + k // width
    order = np.lexsort((body, cy, cx))  # determinism: by cell, then by body
    body, cx, cy = body[order], cx[order], cy[order]
    new_cell = np.ones(len(body), dtype=bool)
    new_cell[1:] = (cx[1:] != cx[:-1]) | (cy[1:] != cy[:-1])
    starts = np.flatnonzero(new_cell)
    ends = np.append(starts[1:], len(body))
    end_of = np.repeat(ends, ends - starts)  # per entry: the end of its cell's run
    partners = end_of - np.arange(len(body)) - 1
    cumulative = np.cumsum(partners)
    start = 0
    while start < len(body) and kept <= limit:
        budget = (cumulative[start - 1] if start else 0) + _CHUNK_ELEMENTS
        stop = min(len(body), max(start + 1, int(np.searchsorted(cumulative, budget, "right"))))
        c = partners[start:stop]
        total = int(c.sum())
        if total:
            at = np.repeat(np.arange(start, stop), c)
            run_start = np.repeat(np.cumsum(c) - c, c)
            other = at + 1 + (np.arange(total) - run_start)
            a, b = body[at], body[other]
            meet = (lo[a, 0] <= hi[b, 0]) & (lo[b, 0] <= hi[a, 0])
            meet &= (lo[a, 1] <= hi[b, 1]) & (lo[b, 1] <= hi[a, 1])
            found_a.append(np.minimum(a, b)[meet])
            found_b.append(np.maximum(a, b)[meet])
            kept += int(meet.sum())
        start = stop
    complete = start >= len(body) or kept <= limit
    if not found_a:
        return empty, empty, True
    # a pair sharing several cells was found once per cell (sort and drop repeats: faster here
    # than np.unique's hashing)
    key = np.sort(np.concatenate(found_a) * n + np.concatenate(found_b))
    key = key[np.append(key[:1] == key[:1], key[1:] != key[:-1])]
    complete = complete and len(key) <= limit
    key = key[:limit]
    return key // n, key % n, complete


def _chunks(count: int, width: int):
    size = max(1, _CHUNK_ELEMENTS // (2 * width * width))
    for start in range(0, count, size):
        yield slice(start, min(start + size, count))


def depths(placed: Placement, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(p,) SAT depth (m) of each pair (a[k], b[k]): over both polygons' edge normals (and,
    with circles, the vertex-to-centre axes), the smallest min(max_a - min_b, max_b - min_a)
    of the two projections, which is the minimum translation distance when positive, also when
    one body holds the other (a circle of radius r centred in a box of half-width h: h + r);
    zero or negative (the gap along the best axis) when they do not overlap."""
    out = np.empty(len(a))
    width = placed.vertices.shape[1]
    rounded = bool(placed.radius.any())
    for part in _chunks(len(a), 2 * width if rounded else width):
        va, vb = placed.vertices[a[part]], placed.vertices[b[part]]  # (p, width, 2)
        axes = [placed.normals[a[part]], placed.normals[b[part]]]
        if rounded:
            axes += [_towards(va, placed.centre[b[part]]), _towards(vb, placed.centre[a[part]])]
        axes = np.concatenate(axes, axis=1)
        # projections of every vertex on every axis: (p, axes, vertices)
        pa = axes[:, :, None, 0] * va[:, None, :, 0] + axes[:, :, None, 1] * va[:, None, :, 1]
        pb = axes[:, :, None, 0] * vb[:, None, :, 0] + axes[:, :, None, 1] * vb[:, None, :, 1]
        ra = placed.radius[a[part], None]
        rb = placed.radius[b[part], None]
        # how far b must move along +axis (a's top past b's bottom) or -axis (b's top past a's
        # bottom) to clear a: the smaller of the two, not the overlap of the two intervals,
        # which under containment (a circle in a box) is the inner body's width, less than the
        # MTD. For intervals that only partly overlap, or not at all, the two are the same.
        lo_a, hi_a = pa.min(axis=2) - ra, pa.max(axis=2) + ra
        lo_b, hi_b = pb.min(axis=2) - rb, pb.max(axis=2) + rb
        overlap = np.minimum(hi_a - lo_b, hi_b - lo_a)
        out[part] = overlap.min(axis=1)
    return out


def _towards(v: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(p, width, 2) unit axes from each vertex v[k, j] to centre[k]; (1, 0) where they meet."""
    d = centre[:, None, :] - v
    length = np.hypot(d[..., 0], d[..., 1])[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(length > 0.0, d / length, np.array([1.0, 0.0]))


def centre_depths(placed: Placement, container: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """(p,) how deep (m) the centre of body inner[k] lies inside polygon container[k]: the
    smallest distance behind its edges, positive inside, zero or negative outside."""
    out = np.empty(len(container))
    width = placed.vertices.shape[1]
    for part in _chunks(len(container), width):
        v = placed.vertices[container[part]]
        n = placed.normals[container[part]]
        p = placed.centre[inner[part]]
        # n_k . (v_k - p): positive when p is behind edge k
        behind = n[..., 0] * (v[..., 0] - p[:, None, 0]) + n[..., 1] * (v[..., 1] - p[:, None, 1])
        out[part] = behind.min(axis=1)
    # a circle container: its radius less the centre's distance
    r = placed.radius[container]
    ring = r > 0.0
    d = placed.centre[inner[ring]] - placed.centre[container[ring]]
    out[ring] = r[ring] - np.hypot(d[:, 0], d[:, 1])
    return out
