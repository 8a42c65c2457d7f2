"""isaac.trig: sin and cos from IEEE basic operations, within 1 ULP of libm's correctly rounded
values, and the same bits compiled and interpreted (the engine compiles it, the scene layer
interprets it)."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from isaac import trig
from isaac.engine import geometry

PI = math.pi
# the edges: zero of both signs, the quadrant boundaries, the engine's wrap threshold (angles are
# kept in [-pi, pi], integrate.py) and the floats either side of each, the tiny-angle cut-off,
# the scene's angle bound (1e6 rad, isaac.scene.limits.MAX_SPEED)
_EDGES = [0.0, -0.0, 2.0**-27, -(2.0**-27), 1e-300, 5e-324, 1e6, -1e6]
for _e in (PI / 4, PI / 2, 3 * PI / 4, PI):
    for _sign in (1.0, -1.0):
        _x = _sign * _e
        _EDGES += [_x, math.nextafter(_x, math.inf), math.nextafter(_x, -math.inf)]
EDGES = np.array(_EDGES)


def _angles() -> np.ndarray:
    rng = np.random.default_rng(17)
    return np.concatenate([rng.uniform(-PI, PI, 1_000_000), EDGES])


@numba.njit  # no cache: numba would not see a change in isaac/trig.py (a callee)
def _own(x):
    s = np.empty_like(x)
    c = np.empty_like(x)
    for i in range(x.shape[0]):
        s[i], c[i] = geometry.sin_cos(x[i])
    return s, c


def _ordered(a: np.ndarray) -> np.ndarray:
    """Floats mapped to integers in the same order, one apart for adjacent floats."""
    i = a.view(np.int64)
    return np.where(i < 0, np.int64(-(2**63)) - i, i)


def _ulps(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(_ordered(a) - _ordered(b))


def test_within_one_ulp_of_libm_over_a_million_angles_and_the_edges():
    x = _angles()
    s, c = _own(x)
    libm_s = np.array([math.sin(v) for v in x.tolist()])
    libm_c = np.array([math.cos(v) for v in x.tolist()])
    assert _ulps(s, libm_s).max() <= 1
    assert _ulps(c, libm_c).max() <= 1
    # most values are libm's (glibc's are correctly rounded); fdlibm's kernels are faithful, not
    # correctly rounded: measured 96.9 % of sin and 96.9 % of cos equal, the rest 1 ULP away
    assert (s == libm_s).mean() > 0.9 and (c == libm_c).mean() > 0.9


def test_exact_values_at_the_edges():
    assert trig.sin_cos(0.0) == (0.0, 1.0)
    s, c = trig.sin_cos(-0.0)
    assert math.copysign(1.0, s) == -1.0 and c == 1.0
    assert trig.sin(PI / 2) == 1.0 and trig.sin(-PI / 2) == -1.0
    assert trig.cos(PI) == -1.0 and trig.cos(-PI) == -1.0
    # sin(float pi) is pi - float(pi) = 1.2246467991473532e-16 to 17 digits, not 0
    assert trig.sin(PI) == math.sin(PI) == 1.2246467991473532e-16
    assert trig.sin(-PI) == -1.2246467991473532e-16


def test_nan_for_what_cannot_be_reduced():
    for x in (math.inf, -math.inf, math.nan, 2.0**50, -1e300):
        s, c = trig.sin_cos(x)
        assert math.isnan(s) and math.isnan(c)
        s, c = geometry.sin_cos(x)
        assert math.isnan(s) and math.isnan(c)


def test_compiled_and_interpreted_give_the_same_bits():
    x = _angles()
    s, c = _own(x)
    pure = [trig.sin_cos(v) for v in x.tolist()]
    assert np.array_equal(s.view(np.int64), np.array([p[0] for p in pure]).view(np.int64))
    assert np.array_equal(c.view(np.int64), np.array([p[1] for p in pure]).view(np.int64))


def test_the_engine_rotates_by_the_own_sin_cos():
    # one box at three angles: world vertices x + (c lx - s ly), y + (s lx + c ly), recomputed
    # here from trig.sin_cos (libm's values would differ in the last bit somewhere)
    local = np.array([[-0.5, -0.25], [0.5, -0.25], [0.5, 0.25], [-0.5, 0.25]])
    angles = np.array([0.3, -2.9, PI])
    n = len(angles)
    position = np.array([[1.0, 2.0]] * n)
    vertices_local = np.array([local] * n)
    normals_local = np.array([[[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]]] * n)
    vertices = np.zeros((n, 4, 2))
    normals = np.zeros((n, 4, 2))
    aabb = np.zeros((n, 4))
    exists = np.ones(n, dtype=np.bool_)
    count = np.full(n, 4, dtype=np.int64)
    radius = np.full(n, 0.7)
    geometry.transform(
        position, angles, exists, vertices_local, normals_local, count, radius, vertices,
        normals, aabb,
    )  # fmt: skip
    for i, a in enumerate(angles):
        s, c = trig.sin_cos(float(a))
        for k, (lx, ly) in enumerate(local.tolist()):
            assert vertices[i, k, 0] == 1.0 + (c * lx - s * ly)
            assert vertices[i, k, 1] == 2.0 + (s * lx + c * ly)


@pytest.mark.parametrize("sides", [3, 5, 8])
def test_regular_polygons_use_the_own_sin_cos_and_the_log_text_keeps_their_bits(sides):
    from isaac.scene import load_scene_text, scene_to_yaml
    from isaac.scene.polygon import regular_vertices

    phase = 0.7
    v = regular_vertices(sides, 0.5, phase)
    for k in range(sides):
        s, c = trig.sin_cos(phase + 2.0 * math.pi * k / sides)
        assert (v[k, 0], v[k, 1]) == (0.5 * c, 0.5 * s)
    text = (
        "name: r\nworld: {steps: 1}\nbodies:\n"
        f"  - {{name: p, shape: {{regular: {{sides: {sides}, radius: 0.5, phase: {phase}}}}}}}\n"
    )
    scene = load_scene_text(text)
    # the embedded scene (recorder: scene_to_yaml) lists the expanded vertices; read back, they
    # are the same floats, so a replay never recomputes them
    again = load_scene_text(scene_to_yaml(scene))
    assert again.bodies[0].vertices == scene.bodies[0].vertices
    assert "polygon:" in scene_to_yaml(scene) and "regular" not in scene_to_yaml(scene)
