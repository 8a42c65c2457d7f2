"""Quality figures measured the same way for every engine, from poses alone.

Nobody is faster by being wrong: each timing row carries a figure computed here from the
engine's final poses (positions of the centres of mass and angles) and the scene's own vertices,
never from the engine's narrow phase or contact list.

- `max_overlap`: the largest penetration depth (m) over every pair of touching polygons, by an
  independent separating-axis test (SAT) over both polygons' face normals (follows Ericson 4.4 /
  Box2D's b2FindMaxSeparation: for convex polygons the deepest face separation is the
  minimum-translation distance along face normals).
- `pyramid_quality`: how far the top box drifted from its start, and whether every box stayed
  within a tolerance of its start (the pyramid "stands").
- `exchange_error`: how far two equal masses' final velocities are from exchanged velocities.
"""

from __future__ import annotations

import numpy as np

from bench.geometry import LocalPolygons


def world_vertices(polys: LocalPolygons, positions: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(n, V, 2) world vertices (m) from local vertices (about the centre of mass) and poses."""
    c = np.cos(angles)[:, None]
    s = np.sin(angles)[:, None]
    x = polys.vertices_local[:, :, 0]
    y = polys.vertices_local[:, :, 1]
    out = np.empty_like(polys.vertices_local)
    out[:, :, 0] = c * x - s * y + positions[:, 0:1]
    out[:, :, 1] = s * x + c * y + positions[:, 1:2]
    return out


def candidate_pairs(
    verts_world: np.ndarray, skip: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i < j) whose axis-aligned boxes overlap, by sort-and-sweep on x (vectorised).

    skip: (n,) bool; pairs where both bodies are flagged (e.g. two static walls) are dropped.
    Returned sorted by (i, j).
    """
    n = verts_world.shape[0]
    if n < 2:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    lo = verts_world.min(axis=1)
    hi = verts_world.max(axis=1)
    order = np.argsort(lo[:, 0], kind="stable")
    xmin_sorted = lo[order, 0]
    # every body k after position p in the sorted order with xmin_k <= xmax_p is a candidate
    end = np.searchsorted(xmin_sorted, hi[order, 0], side="right")
    count = np.maximum(end - np.arange(n) - 1, 0)
    total = int(count.sum())
    p = np.repeat(np.arange(n), count)
    start = np.cumsum(count) - count
    q = p + 1 + (np.arange(total) - np.repeat(start, count))
    a = order[p]
    b = order[q]
    keep = (lo[a, 1] <= hi[b, 1]) & (lo[b, 1] <= hi[a, 1])
    keep &= (lo[a, 0] <= hi[b, 0]) & (lo[b, 0] <= hi[a, 0])
    if skip is not None:
        keep &= ~(skip[a] & skip[b])
    a, b = a[keep], b[keep]
    i = np.minimum(a, b)
    j = np.maximum(a, b)
    sort = np.lexsort((j, i))
    return i[sort], j[sort]


def _max_face_separation(
    va: np.ndarray, ca: np.ndarray, vb: np.ndarray, cb: np.ndarray
) -> np.ndarray:
    """For each pair, max over a's faces of min over b's vertices of n_face . (v_b - v_face).

    va, vb: (P, V, 2) world vertices, counter-clockwise, padded by repeating the last vertex;
    ca: (P,) vertex count of a; cb: (P,) vertex count of b. Padded faces (zero length) and padded
    vertices (duplicates of a real one) do not change the answer: a zero-length face is skipped
    and a duplicate vertex gives the same projection as the original.
    """
    nxt = np.roll(va, -1, axis=1)
    v_idx = np.arange(va.shape[1])[None, :]
    # the closing edge of a k-gon runs from vertex k-1 to vertex 0
    last = v_idx == (ca[:, None] - 1)
    nxt = np.where(last[:, :, None], va[:, 0:1, :], nxt)
    edge = nxt - va
    length = np.hypot(edge[:, :, 0], edge[:, :, 1])
    valid = (v_idx < ca[:, None]) & (length > 0.0)
    safe = np.where(valid, length, 1.0)
    # outward normal of a counter-clockwise polygon: edge rotated clockwise, (ey, -ex)
    nx = edge[:, :, 1] / safe
    ny = -edge[:, :, 0] / safe
    # (P, faces, vertices of b)
    dx = vb[:, None, :, 0] - va[:, :, None, 0]
    dy = vb[:, None, :, 1] - va[:, :, None, 1]
    proj = nx[:, :, None] * dx + ny[:, :, None] * dy
    sep = proj.min(axis=2)
    sep = np.where(valid, sep, -np.inf)
    return sep.max(axis=1)


def pair_depths(
    polys: LocalPolygons, positions: np.ndarray, angles: np.ndarray, *, chunk: int = 20000
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(i, j, depth) of every candidate pair; depth > 0 means the polygons overlap by that (m)."""
    verts = world_vertices(polys, np.asarray(positions, float), np.asarray(angles, float))
    i, j = candidate_pairs(verts, skip=polys.concrete)
    depth = np.empty(i.shape[0])
    for s in range(0, i.shape[0], chunk):
        a, b = i[s : s + chunk], j[s : s + chunk]
        va, vb = verts[a], verts[b]
        ca, cb = polys.vertex_count[a], polys.vertex_count[b]
        sep = np.maximum(_max_face_separation(va, ca, vb, cb), _max_face_separation(vb, cb, va, ca))
        depth[s : s + chunk] = -sep
    return i, j, depth


def overlap_stats(polys: LocalPolygons, positions: np.ndarray, angles: np.ndarray) -> dict:
    """max_overlap_m: deepest penetration over touching pairs (0 if none);
    touching_pairs: number of overlapping pairs; p99_overlap_m: 99th percentile of their depths."""
    _, _, depth = pair_depths(polys, positions, angles)
    touching = depth[depth > 0.0]
    if touching.size == 0:
        return dict(max_overlap_m=0.0, p99_overlap_m=0.0, touching_pairs=0)
    return dict(
        max_overlap_m=float(touching.max()),
        p99_overlap_m=float(np.percentile(touching, 99)),
        touching_pairs=int(touching.size),
    )


def max_overlap(polys: LocalPolygons, positions: np.ndarray, angles: np.ndarray) -> float:
    """The deepest penetration (m) over all touching pairs, 0 when nothing overlaps."""
    return overlap_stats(polys, positions, angles)["max_overlap_m"]


def pyramid_quality(
    start: np.ndarray,
    end: np.ndarray,
    start_angle: np.ndarray,
    end_angle: np.ndarray,
    dynamic: np.ndarray,
    top: int,
    *,
    tolerance: float,
    angle_tolerance: float = 0.05,
) -> dict:
    """Top box drift (m) from its start, and whether the pyramid stands: every dynamic box within
    `tolerance` (m) of its start sideways, not lower than its start by more than `tolerance`, and
    turned by at most `angle_tolerance` (rad). The bench uses half a box and 0.1 rad: a box that
    has moved half its width has left its support; a settling pyramid compresses and shifts by a
    few tenths of that (pymunk's 40 rows: 0.2 m, steady), a collapsing one by metres. Rising is
    allowed: Box2D rests polygons on a 1 cm skin, so each row of its pyramid sits about 1.5 cm
    higher than the one below by design."""
    d = end[dynamic] - start[dynamic]
    turned = end_angle[dynamic] - start_angle[dynamic]
    turn = np.abs(np.remainder(turned + np.pi, 2 * np.pi) - np.pi)
    top_d = end[top] - start[top]
    return dict(
        top_drift_m=float(np.hypot(*top_d)),
        top_drift_xy_m=[float(top_d[0]), float(top_d[1])],
        max_sideways_m=float(np.abs(d[:, 0]).max()),
        max_sink_m=float(max(0.0, -d[:, 1].min())),
        max_turn_rad=float(turn.max()),
        standing=bool(
            np.abs(d[:, 0]).max() <= tolerance
            and -d[:, 1].min() <= tolerance
            and turn.max() <= angle_tolerance
        ),
    )


def exchange_error(v0: np.ndarray, v_end: np.ndarray) -> float:
    """Sum over the two bodies of |v_final - v_other_initial| (m/s): 0 for a perfect exchange."""
    return float(np.hypot(*(v_end[0] - v0[1])) + np.hypot(*(v_end[1] - v0[0])))
