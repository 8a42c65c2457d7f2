"""How bodies are drawn: polygons as their outlines, circles as a ring with a spoke.

A circle is a body of one vertex (its centre) with a radius (isaac.engine.world.Model). For the
viewers it becomes a closed strip that starts at the centre, runs out along the body's local x
axis to the rim and round it (CIRCLE_SIDES segments): the spoke turns with the body, so rolling
is visible.
"""

from __future__ import annotations

import numpy as np

CIRCLE_SIDES = 24


def circle_radii(model) -> np.ndarray:
    """(n,) each circle's radius (m), 0 for a polygon: a log's WorldTable has them as
    `circle_radius`; a Simulation's model marks a circle by vertex_count 1 (radius = its
    bounding radius)."""
    given = getattr(model, "circle_radius", None)
    if given is not None:
        return np.asarray(given, dtype=np.float64)
    counts = np.asarray(model.vertex_count)
    radius = getattr(model, "radius", None)
    if radius is None:  # a table of polygons only (no circle has fewer than one vertex)
        return np.zeros(counts.shape[0])
    return np.where(counts == 1, np.asarray(radius, dtype=np.float64), 0.0)


def drawn_shapes(model) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, V, 2) m in each body's frame, counts (n,)) to draw: the model's own for
    polygons; for circles the centre and CIRCLE_SIDES rim points (padding repeats the last)."""
    local = np.asarray(model.vertices_local, dtype=np.float64)
    counts = np.asarray(model.vertex_count, dtype=np.int64).copy()
    radii = circle_radii(model)
    circles = np.flatnonzero(radii > 0.0)
    if len(circles) == 0:
        return local, counts
    width = max(local.shape[1], CIRCLE_SIDES + 1)
    drawn = np.zeros((local.shape[0], width, 2))
    drawn[:, : local.shape[1]] = local
    drawn[:, local.shape[1] :] = local[:, -1:]
    phase = np.arange(CIRCLE_SIDES) * (2.0 * np.pi / CIRCLE_SIDES)
    ring = np.stack([np.cos(phase), np.sin(phase)], axis=1)  # for drawing only: not physics
    for k in circles:
        drawn[k, 0] = 0.0
        drawn[k, 1 : CIRCLE_SIDES + 1] = radii[k] * ring
        drawn[k, CIRCLE_SIDES + 1 :] = drawn[k, CIRCLE_SIDES]
        counts[k] = CIRCLE_SIDES + 1
    return drawn, counts


def joint_geometry(model, joints=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(a (m,) int64, b (m,) int64, local_a (m, 2) m, local_b (m, 2) m): each joint's bodies and
    its anchors in their frames, from ``joints`` (rows with keys a, b, local_a, local_b: a log's
    `WorldTable.joints`, `recorder.mcap_writer.joint_table_rows`) or else from ``model.joints``
    (such rows, or a Simulation model's `isaac.engine.joints.Joints` arrays); m = 0 without."""
    if joints is None:
        joints = getattr(model, "joints", None)
    if hasattr(joints, "local_a"):  # arrays, one row per joint
        cols = (joints.a, joints.b, joints.local_a, joints.local_b)
    elif joints:
        cols = tuple([row[key] for row in joints] for key in ("a", "b", "local_a", "local_b"))
    else:
        cols = ((), (), (), ())
    a, b = (np.ascontiguousarray(c, dtype=np.int64) for c in cols[:2])
    local_a, local_b = (np.ascontiguousarray(c, dtype=np.float64).reshape(-1, 2) for c in cols[2:])
    return a, b, local_a, local_b
