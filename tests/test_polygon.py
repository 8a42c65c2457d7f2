"""Polygon geometry: closed-form mass properties and every class of invalid outline."""

import math

import numpy as np
import pytest

from isaac.scene.polygon import box_vertices, mass_properties, regular_vertices, validate_polygon

REL = 1e-12


def test_box_vertices_are_ccw_and_centred():
    v = box_vertices(2.0, 1.0)
    assert v.shape == (4, 2)
    assert np.array_equal(v.mean(axis=0), [0.0, 0.0])
    assert np.array_equal(validate_polygon(v), v)  # unchanged: already CCW


def test_box_mass_properties_match_closed_form():
    w, h = 2.0, 0.5
    area, centroid, second_moment = mass_properties(box_vertices(w, h))
    assert area == pytest.approx(w * h, rel=REL)
    assert np.allclose(centroid, [0.0, 0.0], atol=1e-15)
    # I = m (w^2 + h^2) / 12 with m = area (unit density)
    assert second_moment == pytest.approx(w * h * (w * w + h * h) / 12.0, rel=REL)


def test_right_triangle_mass_properties_match_closed_form():
    a, b = 3.0, 2.0
    area, centroid, second_moment = mass_properties([[0.0, 0.0], [a, 0.0], [0.0, b]])
    assert area == pytest.approx(a * b / 2.0, rel=REL)
    assert np.allclose(centroid, [a / 3.0, b / 3.0], rtol=REL)
    # polar moment about the centroid = I_x + I_y = b a^3/36 + a b^3/36
    assert second_moment == pytest.approx(a * b * (a * a + b * b) / 36.0, rel=REL)


def test_regular_50_gon_mass_properties_match_closed_form():
    n, radius = 50, 0.7
    v = regular_vertices(n, radius, phase=0.3)
    area, centroid, second_moment = mass_properties(validate_polygon(v))
    alpha = 2.0 * math.pi / n
    # n isosceles triangles of apex angle alpha: A = n R^2 sin(alpha) / 2,
    # J = n R^4 sin(alpha) (2 + cos(alpha)) / 12, i.e. I = m R^2 (2 + cos(alpha)) / 6.
    assert area == pytest.approx(n * radius**2 * math.sin(alpha) / 2.0, rel=REL)
    assert np.allclose(centroid, [0.0, 0.0], atol=1e-15)
    assert second_moment / area == pytest.approx(radius**2 * (2.0 + math.cos(alpha)) / 6.0, rel=REL)


def test_regular_vertex_k_sits_at_phase_plus_k_steps():
    v = regular_vertices(6, 2.0, phase=0.25)
    k = 4
    assert v[k] == pytest.approx(
        [2.0 * math.cos(0.25 + 2 * math.pi * k / 6), 2.0 * math.sin(0.25 + 2 * math.pi * k / 6)]
    )


def test_clockwise_input_is_reversed_to_ccw_with_identical_bits():
    ccw = [[0.0, 0.0], [1.0, 0.0], [1.5, 0.7], [0.2, 1.1]]
    out = validate_polygon(ccw[::-1])
    assert np.array_equal(out, np.array(ccw[::-1])[::-1])
    assert out.dtype == np.float64


def test_winding_and_offset_do_not_change_mass_or_inertia():
    base = np.array([[0.0, 0.0], [1.0, 0.0], [1.5, 0.7], [0.2, 1.1], [-0.3, 0.5]])
    ref_area, ref_c, ref_j = mass_properties(validate_polygon(base))
    offset = np.array([1.0e6, -2.5e5])
    cw_far = validate_polygon((base + offset)[::-1])
    area, centroid, second_moment = mass_properties(cw_far)
    assert area == pytest.approx(ref_area, rel=1e-9)
    assert np.allclose(centroid - offset, ref_c, atol=1e-9)
    assert second_moment == pytest.approx(ref_j, rel=1e-8)


def test_nearly_collinear_vertex_on_a_convex_polygon_is_accepted():
    # a box whose bottom edge has a midpoint bulging outwards by 1e-12 m, and one exactly on it
    bulge = [[-1.0, 0.0], [0.0, -1e-12], [1.0, 0.0], [1.0, 1.0], [-1.0, 1.0]]
    on_edge = [[-1.0, 0.0], [0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [-1.0, 1.0]]
    assert validate_polygon(bulge).shape == (5, 2)
    assert mass_properties(validate_polygon(on_edge))[0] == pytest.approx(2.0, rel=REL)


@pytest.mark.parametrize(
    "vertices, reason",
    [
        ([[0, 0], [1, 0]], "at least 3"),
        (regular_vertices(51, 1.0), "at most 50"),
        ([[0, 0], [1, 0], [1, 0], [0, 1]], "duplicate"),
        ([[0, 0], [1, 1], [2, 2]], "collinear"),
        ([[0, 0], [1, 0], [1, 1], [0.9, 0.1], [0, 1]], "not convex"),
        ([[0, 0], [2, 1], [2, 0], [0, 1.5]], "self-intersecting"),
        ([[0, 0], [1, 1], [1, 0], [0, 1]], "self-intersecting"),
        (regular_vertices(5, 1.0)[[0, 2, 4, 1, 3]], "self-intersecting"),  # pentagram
        ([[0, 0], [1, 0], [0.5, 1.5e-9]], "too small"),
        ([[0, 0], [1, float("nan")], [0, 1]], "finite"),
    ],
)
def test_invalid_polygon_raises_value_error_naming_the_reason(vertices, reason):
    with pytest.raises(ValueError, match=reason):
        validate_polygon(vertices)


def test_a_vertex_tuple_surveyed_again_gives_the_bits_of_a_fresh_survey():
    from isaac.scene import polygon

    box = ((-0.5, -0.25), (-0.5, 0.25), (0.5, 0.25), (0.5, -0.25))  # clockwise: a problem
    shapes = [
        tuple((float(x), float(y)) for x, y in box_vertices(1.0, 0.3)),
        tuple((float(x), float(y)) for x, y in regular_vertices(7, 0.4, 0.1)),
        box,
        ((0.0, 0.0), (1.0, 0.0)),
    ]
    first = polygon.survey(shapes)
    assert all(id(s) in polygon._SURVEYED for s in shapes)
    again = polygon.survey(shapes)  # from the memo
    fresh = polygon.survey([tuple(tuple(p) for p in s) for s in shapes])  # equal, new tuples
    for facts in (again, fresh):
        assert facts.problems == first.problems
        for name in ("extents", "largest_coordinates", "areas", "second_moments"):
            assert getattr(facts, name).tobytes() == getattr(first, name).tobytes()
    assert first.problems[2] is not None and first.problems[3] is not None
    # a list (mutable) is surveyed each time, never remembered
    listed = [list(p) for p in shapes[0]]
    polygon.survey([listed])
    assert id(listed) not in polygon._SURVEYED
