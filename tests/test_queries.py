"""World queries (isaac/engine/queries.py) against independent computations.

The oracles here share no code with the engine: world vertices from math.cos/math.sin, ray
hits of polygons by exact rational segment intersection (fractions.Fraction) with every edge,
ray hits of circles by the textbook quadratic root in 50-digit decimal arithmetic, overlaps by
vertex containment and edge crossings, distances by point-to-segment in plain floats, all over
every body (no broad phase).
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from decimal import Decimal, localcontext
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from isaac.engine import queries
from isaac.engine.queries import QueryFilter
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene_text

ROOT = Path(__file__).resolve().parents[1]
TOL = 1e-12


def _sim(text: str) -> Simulation:
    return Simulation(load_scene_text(text, "<test>"), compile_ahead=False)


def random_scene_text(seed: int, rows: int = 6, columns: int = 8, spacing: float = 1.0) -> str:
    """Convex polygons (random vertices on a circle) and circles on a jittered grid, at random
    angles: never overlapping at spacing 1 m (each inside its own cell); at a smaller spacing
    they overlap, and every seventh is four times larger (bodies of many sizes in one grid)."""
    rng = np.random.default_rng(seed)
    lines = ["world: {gravity: [0, 0], dt: 1/60, steps: 1}", "bodies:"]
    for r in range(rows):
        for c in range(columns):
            x = spacing * c + rng.uniform(-0.1, 0.1)
            y = spacing * r + rng.uniform(-0.1, 0.1)
            scale = 4.0 if spacing < 1.0 and (r * columns + c) % 7 == 0 else 1.0
            angle = rng.uniform(-3.0, 3.0)
            name = f"b{r}_{c}"
            if rng.uniform() < 0.3:
                radius = scale * rng.uniform(0.1, 0.35)
                shape = f"{{circle: {{radius: {radius!r}}}}}"
            else:
                k = int(rng.integers(3, 9))
                turns = np.sort(rng.uniform(0.0, 2.0 * np.pi, size=k))
                turns += np.arange(k) * 1e-3  # no two vertices close
                radius = scale * rng.uniform(0.15, 0.38)
                pts = [[radius * math.cos(t), radius * math.sin(t)] for t in turns]
                shape = "{polygon: " + json.dumps(pts) + "}"
            lines.append(
                f"  - {{name: {name}, shape: {shape}, position: [{x!r}, {y!r}], angle: {angle!r}}}"
            )
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def scene_sim():
    return _sim(random_scene_text(7))


@pytest.fixture(scope="module")
def dense_sim():
    return _sim(random_scene_text(11, rows=12, columns=16, spacing=0.4))


# ---- independent oracle ------------------------------------------------------------------------


def world_shapes(sim):
    """[('circle', (cx, cy), r) | ('polygon', [(x, y), ...]) | None] per body (None: absent),
    placed with math.cos / math.sin."""
    m, s = sim.model, sim.state
    out = []
    for i in range(m.n_bodies):
        if not s.exists[i]:
            out.append(None)
            continue
        px, py = (float(v) for v in s.position[i])
        a = float(s.angle[i])
        c, sn = math.cos(a), math.sin(a)
        k = int(m.vertex_count[i])
        pts = [
            (px + (c * lx - sn * ly), py + (sn * lx + c * ly))
            for lx, ly in m.vertices_local[i, :k].tolist()
        ]
        if k == 1:
            out.append(("circle", pts[0], float(m.radius[i])))
        else:
            out.append(("polygon", pts))
    return out


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def oracle_ray_polygon(o, d, pts, max_fraction):
    """(t, normal, ambiguous) of the first entry of o + t d into the polygon, exact rationals;
    None from inside or on the boundary, or for a miss. ambiguous: the hit is within 1e-9 of
    an edge's end or the ray nearly parallel to the hit edge."""
    ox, oy, dx, dy = (Fraction(v) for v in (*o, *d))
    verts = [(Fraction(x), Fraction(y)) for x, y in pts]
    nxt = verts[1:] + verts[:1]
    edges = [(b[0] - a[0], b[1] - a[1]) for a, b in zip(verts, nxt)]
    if all(_cross(ex, ey, ox - v[0], oy - v[1]) >= 0 for (ex, ey), v in zip(edges, verts)):
        return None
    best = None
    for j, ((ex, ey), (vx, vy)) in enumerate(zip(edges, verts)):
        den = _cross(dx, dy, ex, ey)
        if den == 0:
            continue
        wx, wy = vx - ox, vy - oy
        t = _cross(wx, wy, ex, ey) / den
        u = _cross(wx, wy, dx, dy) / den
        if 0 <= t <= Fraction(max_fraction) and 0 <= u <= 1 and (best is None or t < best[0]):
            best = (t, j, u, den)
    if best is None:
        return None
    t, j, u, den = best
    ex, ey = (float(v) for v in edges[j])
    length = math.sqrt(ex * ex + ey * ey)
    sine = abs(float(den)) / (length * math.hypot(float(dx), float(dy)))
    ambiguous = min(float(u), 1.0 - float(u)) < 1e-9 or sine < 1e-6
    return float(t), (ey / length, -ex / length), ambiguous


def oracle_ray_circle(o, d, centre, r, max_fraction):
    """(t, normal, ambiguous) by the textbook root (-b - sqrt(b^2 - a c)) / a in 50 digits."""
    with localcontext() as ctx:
        ctx.prec = 50
        ox, oy, dx, dy, cx, cy, rr = (Decimal(v) for v in (*o, *d, *centre, r))
        sx, sy = ox - cx, oy - cy
        a = dx * dx + dy * dy
        b = sx * dx + sy * dy
        c = sx * sx + sy * sy - rr * rr
        disc = b * b - a * c
        if c <= 0 or b >= 0 or disc < 0:
            return None
        t = (-b - disc.sqrt()) / a
        if t > Decimal(max_fraction):
            return None
        nx = (sx + t * dx) / rr
        ny = (sy + t * dy) / rr
        ambiguous = disc / (a * rr * rr) < Decimal("1e-12")
        return float(t), (float(nx), float(ny)), ambiguous


def oracle_first_hit(shapes, o, d, max_fraction=1.0):
    """(body, t, normal, ambiguous) over every body, or None; ambiguous also when a second
    body's hit is within 1e-9 of the first's."""
    hits = []
    for i, shape in enumerate(shapes):
        if shape is None:
            continue
        if shape[0] == "circle":
            h = oracle_ray_circle(o, d, shape[1], shape[2], max_fraction)
        else:
            h = oracle_ray_polygon(o, d, shape[1], max_fraction)
        if h is not None:
            hits.append((h[0], i, h[1], h[2]))
    if not hits:
        return None
    hits.sort(key=lambda h: (h[0], h[1]))
    t, i, normal, ambiguous = hits[0]
    if len(hits) > 1 and hits[1][0] - t < 1e-9:
        ambiguous = True
    return i, t, normal, ambiguous


def _random_rays(seed, count, lo=(-1.5, -1.5), hi=(8.5, 6.5), length=(0.5, 6.0)):
    rng = np.random.default_rng(seed)
    origins = rng.uniform(lo, hi, size=(count, 2))
    turn = rng.uniform(-np.pi, np.pi, size=count)
    size = rng.uniform(*length, size=count)
    return origins, np.stack([size * np.cos(turn), size * np.sin(turn)], axis=1)


# ---- rays ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("which", ["sparse", "dense"])
def test_ray_fractions_points_and_normals_equal_exact_intersection_with_every_shape(
    which, scene_sim, dense_sim
):
    """Every ray's first hit against the oracle over every body: the sparse scene (one body a
    cell) and a dense one of overlapping bodies of many sizes, where the grid's walk must not
    stop at the first hit it meets (a body binned in an earlier cell may be hit later)."""
    sim = scene_sim if which == "sparse" else dense_sim
    shapes = world_shapes(sim)
    origins, directions = _random_rays(1, 600)
    hits = sim.ray_cast_many(origins, directions)
    checked = hit = 0
    for k in range(len(origins)):
        o, d = origins[k].tolist(), directions[k].tolist()
        want = oracle_first_hit(shapes, o, d)
        if want is None:
            assert hits.body[k] == -1 and not hits.hit[k]
            assert np.isnan(hits.fraction[k]) and np.isnan(hits.point[k]).all()
            checked += 1
            continue
        body, t, normal, ambiguous = want
        if ambiguous:
            continue
        checked += 1
        hit += 1
        assert hits.body[k] == body, k
        assert abs(hits.fraction[k] - t) <= TOL
        point = (o[0] + t * d[0], o[1] + t * d[1])
        assert np.abs(hits.point[k] - point).max() <= TOL
        assert np.abs(hits.normal[k] - normal).max() <= TOL
        assert abs(math.hypot(*hits.normal[k]) - 1.0) <= TOL
    assert checked >= 570 and hit >= 200, (checked, hit)


BOX_AND_BALL = """
world: {gravity: [0, 0], dt: 1/60, steps: 1}
bodies:
  - {name: box, shape: {box: [2, 1]}, position: [3, 0]}
  - {name: ball, shape: {circle: {radius: 0.5}}, position: [6, 0]}
"""


def test_a_ray_through_a_vertex_hits_it_at_the_exact_fraction():
    sim = _sim(BOX_AND_BALL)  # the box spans [2, 4] x [-0.5, 0.5]
    hit = sim.ray_cast((0.0, 2.5), (2.0, -2.0))  # reaches the corner (2, 0.5) at t = 1
    assert hit.hit and hit.name == "box" and hit.fraction == 1.0 and hit.point == (2.0, 0.5)
    assert hit.normal in ((-1.0, 0.0), (0.0, 1.0), (-1.0, -0.0))
    # max_fraction is inclusive; a hair shorter misses
    assert not sim.ray_cast((0.0, 2.5), (2.0, -2.0), max_fraction=1.0 - 2**-40).hit


def test_a_ray_along_an_edge_or_tangent_to_a_circle_grazes_it():
    sim = _sim(BOX_AND_BALL)
    along = sim.ray_cast((0.0, 0.5), (10.0, 0.0))  # along the box's top edge
    assert along.body == 0 and along.fraction == 0.2 and along.point == (2.0, 0.5)
    assert along.normal[0] == -1.0 and along.normal[1] == 0.0
    assert not sim.ray_cast((0.0, 0.5 + 1e-9), (1.0, 0.0), max_fraction=4.0).hit
    tangent = sim.ray_cast((4.5, 0.5), (3.0, 0.0))  # touches the ball's top at (6, 0.5)
    assert tangent.body == 1 and tangent.fraction == 0.5 and tangent.point == (6.0, 0.5)
    assert tangent.normal == (0.0, 1.0)
    assert not sim.ray_cast((4.5, 0.5 + 1e-9), (3.0, 0.0)).hit


def test_a_ray_from_inside_or_on_a_shape_reports_the_next_shape_it_enters():
    sim = _sim(BOX_AND_BALL)
    from_box = sim.ray_cast((3.0, 0.0), (5.0, 0.0))
    assert from_box.name == "ball" and from_box.fraction == 0.5  # (5.5, 0)
    from_edge = sim.ray_cast((2.0, 0.0), (5.0, 0.0))  # on the box's left edge, going in
    assert from_edge.name == "ball"
    from_ball = sim.ray_cast((6.0, 0.0), (-4.0, 0.0))  # inside the ball, towards the box
    assert from_ball.name == "box" and from_ball.fraction == 0.5 and from_ball.normal[0] == 1.0
    on_ball = sim.ray_cast((5.5, 0.0), (1.0, 0.0))  # on the ball's surface, going in
    assert not on_ball.hit


def test_a_far_grazing_ray_keeps_its_fraction_where_the_textbook_root_cancels():
    """Circle of radius 1, a ray from 3e4 m away passing 1e-7 m inside its top: the textbook
    discriminant b^2 - a c subtracts two numbers of about 4e18 that agree in 11 digits (its
    fraction is wrong by about 1e-9); the engine's form keeps it to 1e-12."""
    sim = _sim(
        "world: {gravity: [0, 0], dt: 1/60, steps: 1}\n"
        "bodies:\n  - {name: c, shape: {circle: {radius: 1}}, position: [0, 0]}\n"
    )
    o, d = (-31415.9, 0.9999999), (62831.3, 0.0)
    hit = sim.ray_cast(o, d)
    t, normal, _ = oracle_ray_circle(o, d, (0.0, 0.0), 1.0, 1.0)
    assert hit.hit and abs(hit.fraction - t) <= TOL
    assert np.abs(np.subtract(hit.normal, normal)).max() <= 1e-9
    # the textbook float root is not that accurate (the reason for the stable form)
    sx, sy, dx, dy = o[0], o[1], d[0], d[1]
    a, b, c = dx * dx + dy * dy, sx * dx + sy * dy, sx * sx + sy * sy - 1.0
    naive = (-b - math.sqrt(b * b - a * c)) / a
    assert abs(naive - t) > 1e-10


TIES = """
world: {{gravity: [0, 0], dt: 1/60, steps: 1}}
bodies:
  - {{name: {0}, shape: {{box: [{1}, 1]}}, position: [{2}, 0]}}
  - {{name: {3}, shape: {{box: [{4}, 1]}}, position: [{5}, 0]}}
  - {{name: twin, shape: {{box: [1, 1]}}, position: [0.5, 0]}}
"""


@pytest.mark.parametrize("big_first", [True, False])
def test_ties_go_to_the_lowest_body_index(big_first):
    """A long box over [0, 8] and two unit boxes over [0, 1]: rays entering at x = 0 or
    through the shared top meet all three at the same fraction, the long box also in cells
    the short ones are not in."""
    big, small = ("big", 8, 4), ("small", 1, 0.5)
    first, second = (big, small) if big_first else (small, big)
    sim = _sim(TIES.format(*first, *second))
    lowest = first[0]
    assert sim.ray_cast((-1.0, 0.0), (2.0, 0.0)).name == lowest
    assert sim.ray_cast((0.5, 2.0), (0.0, -2.0)).name == lowest
    assert sim.ray_cast((10.0, 0.0), (-2.0, 0.0)).name == "big"  # its right face is first


FILTERED = """
world: {gravity: [0, 0], dt: 1/60, steps: 1}
bodies:
  - {name: late, shape: {box: [1, 1]}, position: [1, 0], enters_at: 1.0}
  - {name: ghost, shape: {box: [1, 1]}, position: [3, 0], category: 2, mask: 1}
  - {name: team, shape: {box: [1, 1]}, position: [5, 0], group: -3}
  - {name: wall, shape: {box: [1, 1]}, position: [7, 0]}
  - {name: club, shape: {box: [1, 1]}, position: [9, 0], group: 5}
"""


def test_bodies_absent_now_are_never_reported():
    sim = _sim(FILTERED)
    assert not sim.state.exists[0]
    assert sim.ray_cast((0.0, 0.0), (10.0, 0.0)).name == "ghost"
    assert 0 not in sim.query_box((0.0, -1.0), (1.5, 1.0)).tolist()
    assert 0 not in sim.overlaps(0.3, (1.0, 0.0)).tolist()
    assert sim.closest((1.0, 0.0)).name == "ghost"


def test_a_query_filter_follows_the_collision_rule():
    sim = _sim(FILTERED)
    o, d = (0.0, 0.0), (10.0, 0.0)
    # the ghost's mask (1) lacks the filter's category 2: passed over
    assert sim.ray_cast(o, d, filter=QueryFilter(category=2)).name == "team"
    # the ghost's category is not in this mask
    assert sim.ray_cast(o, d, filter=QueryFilter(mask=1)).name == "team"
    # group -3 leaves out team (a negative shared group never meets)
    assert sim.ray_cast(o, d, filter=QueryFilter(mask=1, group=-3)).name == "wall"
    # no bits meet nothing, but a positive shared group meets whatever the bits
    assert sim.ray_cast(o, d, filter=QueryFilter(category=0, mask=0, group=-3)).hit is False
    assert sim.ray_cast(o, d, filter=QueryFilter(category=0, mask=0, group=5)).name == "club"
    assert sim.query_box((2.5, -1), (5.5, 1), filter=QueryFilter(mask=1)).tolist() == [2]
    assert sim.overlaps(0.2, (3.0, 0.0), filter=QueryFilter()).tolist() == [1]
    assert sim.overlaps(0.2, (3.0, 0.0), filter=QueryFilter(category=2)).tolist() == []
    assert sim.closest((3.0, 0.0), filter=QueryFilter(mask=1)).name == "team"


def test_a_batch_equals_a_loop_of_single_rays_bit_for_bit(scene_sim):
    origins, directions = _random_rays(2, 300)
    fractions = np.random.default_rng(3).uniform(0.0, 1.5, size=300)
    many = scene_sim.ray_cast_many(origins, directions, fractions)
    for k in range(300):
        one = scene_sim.ray_cast(origins[k], directions[k], float(fractions[k]))
        assert one.body == many.body[k] and one.hit == many.hit[k]
        same = np.array([one.fraction, *one.point, *one.normal]).tobytes()
        assert same == np.array([many.fraction[k], *many.point[k], *many.normal[k]]).tobytes()


def _digest(sim) -> str:
    """Every query's results on fixed input, as exact bytes (hex)."""
    origins, directions = _random_rays(4, 200)
    hits = sim.ray_cast_many(origins, directions)
    parts = [hits.body, hits.fraction, hits.point, hits.normal]
    parts.append(sim.query_box((1.2, 0.7), (4.9, 3.1)))
    parts.append(sim.overlaps([[0, 0], [2.5, 0.3], [1.0, 1.9]], (2.1, 1.4, 0.4)))
    parts.append(sim.overlaps(0.8, (5.3, 2.6)))
    c = sim.closest((3.33, 2.71))
    parts.append(np.array([c.body, *c.point, c.distance]))
    return "".join(np.ascontiguousarray(p).tobytes().hex() for p in parts)


def test_the_same_bits_without_the_compiler():
    code = (
        "import sys; sys.path.insert(0, 'tests'); from test_queries import _digest, _sim, "
        "random_scene_text; print(_digest(_sim(random_scene_text(7, rows=3, columns=4))))"
    )
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
        timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == _digest(_sim(random_scene_text(7, rows=3, columns=4)))


def test_bodies_far_larger_than_most_keep_the_grid_small_and_the_hits_right():
    """Half the bodies 100 m boxes over 41 tiny discs: cells sized for the discs would list
    each box in every cell; the grid coarsens until it lists at most 16 entries a body."""
    lines = ["world: {gravity: [0, 0], dt: 1/60, steps: 1}", "bodies:"]
    disc, box = "{circle: {radius: 0.01}}", "{box: [100, 100]}"
    lines += [f"  - {{name: d{k}, shape: {disc}, position: [{2.5 * k}, 60]}}" for k in range(41)]
    lines += [f"  - {{name: b{k}, shape: {box}, position: [{50 + k / 100}, 0]}}" for k in range(40)]
    sim = _sim("\n".join(lines) + "\n")
    world = queries._world(sim.model, sim.state)
    *_, start, bodies = queries.build_grid(world.aabb, np.ones(sim.n_bodies, dtype=bool))
    assert len(bodies) <= 16 * sim.n_bodies + 16
    shapes = world_shapes(sim)
    origins, directions = _random_rays(5, 200, lo=(-5.0, 40.0), hi=(105.0, 70.0), length=(5, 60))
    hits = sim.ray_cast_many(origins, directions)
    for k in range(200):
        want = oracle_first_hit(shapes, origins[k].tolist(), directions[k].tolist())
        if want is None:
            assert hits.body[k] == -1
        elif not want[3]:
            assert hits.body[k] == want[0] and abs(hits.fraction[k] - want[1]) <= TOL


def test_a_record_of_another_scene_is_refused():
    sim = _sim(BOX_AND_BALL)
    other = _sim(FILTERED).record()
    with pytest.raises(ValueError, match="the model has 2"):
        queries.ray_cast(sim.model, other, (0.0, 0.0), (1.0, 0.0))


# ---- box, shape and point queries --------------------------------------------------------------


def _box_of(shape):
    if shape[0] == "circle":
        (cx, cy), r = shape[1], shape[2]
        return cx - r, cy - r, cx + r, cy + r
    xs, ys = zip(*shape[1])
    return min(xs), min(ys), max(xs), max(ys)


coordinate = st.floats(-2.0, 9.0, allow_nan=False)


@settings(max_examples=150, deadline=None)
@given(coordinate, coordinate, st.floats(0.0, 4.0), st.floats(0.0, 4.0))
def test_query_box_gives_the_bodies_whose_boxes_meet_it(scene_sim, x, y, w, h):
    lo, hi = (x, y - 3.0), (x + w, y - 3.0 + h)
    got = scene_sim.query_box(lo, hi)
    assert got.dtype == np.int64 and (np.diff(got) > 0).all()
    want = []
    for i, shape in enumerate(world_shapes(scene_sim)):
        x0, y0, x1, y1 = _box_of(shape)
        gaps = (x0 - hi[0], lo[0] - x1, y0 - hi[1], lo[1] - y1)
        if max(gaps) <= 0.0:
            want.append(i)
        assume(abs(max(gaps)) >= 1e-12)  # on the boundary either answer is the float's
    assert got.tolist() == want


def _inside_polygon(p, pts):
    k = len(pts)
    return all(
        _cross(pts[(j + 1) % k][0] - pts[j][0], pts[(j + 1) % k][1] - pts[j][1],
               p[0] - pts[j][0], p[1] - pts[j][1]) >= 0.0
        for j in range(k)
    )  # fmt: skip


def _segment_distance(p, a, b):
    ex, ey = b[0] - a[0], b[1] - a[1]
    u = ((p[0] - a[0]) * ex + (p[1] - a[1]) * ey) / (ex * ex + ey * ey)
    u = min(max(u, 0.0), 1.0)
    q = (a[0] + u * ex, a[1] + u * ey)
    return math.hypot(p[0] - q[0], p[1] - q[1]), q


def oracle_distance(p, shape):
    """(distance, nearest point) from p to a shape, 0 and p itself inside."""
    if shape[0] == "circle":
        (cx, cy), r = shape[1], shape[2]
        dist = math.hypot(p[0] - cx, p[1] - cy)
        if dist <= r:
            return 0.0, p
        return dist - r, (cx + (p[0] - cx) * r / dist, cy + (p[1] - cy) * r / dist)
    pts = shape[1]
    if _inside_polygon(p, pts):
        return 0.0, p
    k = len(pts)
    return min(_segment_distance(p, pts[j], pts[(j + 1) % k]) for j in range(k))


def _segments_cross(a, b, c, d):
    d1 = _cross(b[0] - a[0], b[1] - a[1], c[0] - a[0], c[1] - a[1])
    d2 = _cross(b[0] - a[0], b[1] - a[1], d[0] - a[0], d[1] - a[1])
    d3 = _cross(d[0] - c[0], d[1] - c[1], a[0] - c[0], a[1] - c[1])
    d4 = _cross(d[0] - c[0], d[1] - c[1], b[0] - c[0], b[1] - c[1])
    return d1 * d2 <= 0.0 and d3 * d4 <= 0.0


def oracle_overlap(a, b):
    """(overlap, clearance): whether two shapes overlap, by containment and crossing edges (no
    separating axis), and how far the decision is from flipping (m)."""
    if a[0] == "circle" and b[0] == "circle":
        gap = math.hypot(a[1][0] - b[1][0], a[1][1] - b[1][1]) - a[2] - b[2]
        return gap <= 0.0, abs(gap)
    if a[0] == "circle" or b[0] == "circle":
        circle, poly = (a, b) if a[0] == "circle" else (b, a)
        gap = oracle_distance(circle[1], poly)[0] - circle[2]
        return gap <= 0.0, abs(gap)
    pa, pb = a[1], b[1]
    meets = any(_inside_polygon(p, pb) for p in pa) or any(_inside_polygon(p, pa) for p in pb)
    ka, kb = len(pa), len(pb)
    meets = meets or any(
        _segments_cross(pa[i], pa[(i + 1) % ka], pb[j], pb[(j + 1) % kb])
        for i in range(ka)
        for j in range(kb)
    )
    # clearance: the smallest vertex-to-edge distance either way (the decision's margin)
    clearance = min(
        min(oracle_distance(p, b)[0] for p in pa) if not meets else 1.0,
        min(min(_segment_distance(p, pa[i], pa[(i + 1) % ka])[0] for i in range(ka)) for p in pb),
    )
    return meets, clearance


def _placed(shape, pose):
    x, y, angle = pose
    c, s = math.cos(angle), math.sin(angle)
    if np.ndim(shape) == 0:
        return ("circle", (x, y), float(shape))
    return ("polygon", [(x + (c * u - s * v), y + (s * u + c * v)) for u, v in shape])


query_shapes = st.one_of(
    st.floats(0.05, 1.5),
    st.sampled_from(
        [
            [[0.0, 0.0], [1.2, 0.0], [1.2, 0.4], [0.0, 0.4]],
            [[-0.5, -0.3], [0.7, -0.1], [0.1, 0.9]],
            [[math.cos(t) * 0.6, math.sin(t) * 0.6] for t in np.linspace(0, 6, 7)],
        ]
    ),
)


@settings(max_examples=150, deadline=None)
@given(query_shapes, coordinate, st.floats(-1.0, 6.0), st.floats(-3.0, 3.0))
def test_overlaps_gives_the_bodies_whose_shapes_meet_the_query_shape(scene_sim, shape, x, y, a):
    got = scene_sim.overlaps(shape, (x, y, a))
    query = _placed(shape, (x, y, a))
    want = []
    for i, body in enumerate(world_shapes(scene_sim)):
        meets, clearance = oracle_overlap(body, query)
        assume(clearance >= 1e-9)  # within 1e-9 m of touching: either answer
        if meets:
            want.append(i)
    assert got.tolist() == want


@settings(max_examples=150, deadline=None)
@given(coordinate, st.floats(-1.0, 6.5))
def test_closest_gives_the_nearest_shape_and_its_nearest_point(scene_sim, x, y):
    got = scene_sim.closest((x, y))
    found = [oracle_distance((x, y), s) for s in world_shapes(scene_sim)]
    best = min(d for d, _ in found)
    assert got.found and abs(got.distance - best) <= TOL
    assert abs(found[got.body][0] - best) <= TOL  # the body named is (one of) the nearest
    if sorted(d for d, _ in found)[1] - best > 1e-9:
        assert np.abs(np.subtract(got.point, found[got.body][1])).max() <= TOL
    assert got.name == scene_sim.model.names[got.body]


def test_closest_inside_a_shape_is_the_point_itself_at_distance_zero():
    sim = _sim(BOX_AND_BALL)
    assert sim.closest((3.2, 0.1)) == queries.Closest(True, 0, "box", (3.2, 0.1), 0.0)
    assert sim.closest((6.1, -0.2)).distance == 0.0
    far = sim.closest((10.0, 0.0))
    assert far.name == "ball" and far.distance == 3.5 and far.point == (6.5, 0.0)
    nothing = sim.closest((0.0, 0.0), filter=QueryFilter(category=0))
    assert not nothing.found and nothing.body == -1 and math.isnan(nothing.distance)


def test_query_box_is_by_boxes_and_overlaps_is_exact():
    sim = _sim(BOX_AND_BALL)
    corner = ((5.5, 0.4), (5.6, 0.5))  # inside the ball's box, outside the ball
    assert sim.query_box(*corner).tolist() == [1]
    assert sim.overlaps([[5.5, 0.4], [5.6, 0.4], [5.6, 0.5], [5.5, 0.5]], (0.0, 0.0)).size == 0
    assert sim.overlaps(0.5, (7.0, 0.0)).tolist() == [1]  # touching counts
    assert sim.overlaps([[0, 0], [1, 0], [1, 1], [0, 1]], (1.0, -0.5)).tolist() == [0]


# ---- guards -------------------------------------------------------------------------------------


@pytest.fixture
def no_kernels(monkeypatch):
    """Compiled code that fails if reached: a guard must refuse the input before it."""

    def reached(*args):
        raise AssertionError("compiled code reached")

    for name in ("transform", "build_grid", "cast_rays", "overlapping", "nearest"):
        monkeypatch.setattr(queries, name, reached)


@pytest.mark.parametrize(
    ("call", "error", "words"),
    [
        (lambda s: s.ray_cast((math.nan, 0), (1, 0)), ValueError, "origin must be finite"),
        (lambda s: s.ray_cast((0, 0, 0), (1, 0)), ValueError, "origin must be one (x, y)"),
        (lambda s: s.ray_cast(("a", 0), (1, 0)), TypeError, "origin must be numbers"),
        (lambda s: s.ray_cast((0, 0), (1, math.inf)), ValueError, "direction must be finite"),
        (lambda s: s.ray_cast((0, 0), (1, 0), -0.5), ValueError, "max_fraction must be >= 0"),
        (lambda s: s.ray_cast((0, 0), (1, 0), math.nan), ValueError, "max_fraction must be fin"),
        (lambda s: s.ray_cast((0, 0), (1, 0), True), TypeError, "max_fraction must be"),
        (lambda s: s.ray_cast((0, 0), (1, 0), [1, 2]), TypeError, "max_fraction must be one"),
        (lambda s: s.ray_cast((2e12, 0), (1, 0)), ValueError, "origin must be within 1e+12"),
        (lambda s: s.ray_cast((0, 0), (1e12, 0), 5.0), ValueError, "the rays' ends"),
        (lambda s: s.ray_cast((0, 0), (1, 0), filter=3), TypeError, "filter must be"),
        (lambda s: s.ray_cast_many([[0, 0]], [[1, 0], [0, 1]]), ValueError, "one row per"),
        (lambda s: s.ray_cast_many([0, 0], [1, 0]), ValueError, "origins must be an (m, 2)"),
        (lambda s: s.ray_cast_many([[0, 0]], [[1, 0]], [1, 2]), ValueError, "one per ray"),
        (lambda s: s.query_box((1, 1), (0, 2)), ValueError, "lo must be <= hi"),
        (lambda s: s.query_box((0, 0), None), TypeError, "hi must be numbers"),
        (lambda s: s.overlaps(-1.0, (0, 0)), ValueError, "radius must be"),
        (lambda s: s.overlaps(True, (0, 0)), TypeError, "shape must be a radius"),
        (lambda s: s.overlaps([[0, 0], [1, 0]], (0, 0)), ValueError, "shape: a polygon needs"),
        (
            lambda s: s.overlaps([[0, 0], [2, 0], [1, 0.2], [1, 2]], (0, 0)),
            ValueError,
            "shape:",
        ),
        (lambda s: s.overlaps(1.0, (0, 0, 0, 0)), ValueError, "pose must be (x, y)"),
        (lambda s: s.overlaps(1.0, (0, 0, 1e7)), ValueError, "pose angle must be within"),
        (lambda s: s.closest([math.nan, 1]), ValueError, "point must be finite"),
    ],
)
def test_bad_input_is_refused_in_python_naming_the_argument(no_kernels, call, error, words):
    sim = _sim(BOX_AND_BALL)
    with pytest.raises(error) as caught:
        call(sim)
    assert words in str(caught.value)
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize(
    ("fields", "error", "words"),
    [
        ({"category": 2**32}, ValueError, "category 4294967296 must be in 0.."),
        ({"mask": -1}, ValueError, "mask -1 must be in"),
        ({"group": 2**31}, ValueError, "group"),
        ({"category": 1.0}, TypeError, "category must be an int"),
        ({"mask": True}, TypeError, "mask must be an int"),
    ],
)
def test_a_query_filter_out_of_range_is_refused(fields, error, words):
    with pytest.raises(error, match=re.escape(words)):
        QueryFilter(**fields)


def test_a_replaced_state_is_checked_before_a_query():
    sim = _sim(BOX_AND_BALL)
    sim.state.position = np.array([[0.0, math.nan], [6.0, 0.0]])
    with pytest.raises(ValueError, match="position"):
        sim.ray_cast((0, 0), (1, 0))


def test_a_zero_direction_hits_nothing():
    sim = _sim(BOX_AND_BALL)
    assert not sim.ray_cast((0.0, 0.0), (0.0, 0.0)).hit
    assert not sim.ray_cast((3.0, 0.0), (0.0, 0.0)).hit  # even inside the box


def test_a_recorded_step_can_be_asked_what_a_ray_hits():
    sim = _sim(BOX_AND_BALL)
    record = sim.record()
    hit = queries.ray_cast(sim.model, record, (0.0, 0.0), (10.0, 0.0))
    assert hit == sim.ray_cast((0.0, 0.0), (10.0, 0.0))


# ---- the docs' example --------------------------------------------------------------------------


def test_the_python_api_docs_queries_example_runs():
    text = (ROOT / "docs" / "python-api.md").read_text()
    section = text.split("## Queries", 1)[1].split("\n## ", 1)[0]
    (example,) = re.findall(r"```python\n(.*?)```", section, re.S)
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        exec(compile(example, "docs/python-api.md", "exec"), {})
    finally:
        os.chdir(cwd)
