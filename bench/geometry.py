"""Polygons of a scene about their centres of mass, as every engine adapter builds them.

`BodySpec.vertices` are not re-centred; the engine (and so every peer here) re-centres them on
the polygon's area centroid, so a body's position is its centre of mass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isaac.scene import Scene


def polygon_centroid(vertices: np.ndarray) -> tuple[float, np.ndarray]:
    """(area, centroid) of a simple counter-clockwise polygon, shoelace formula."""
    x, y = vertices[:, 0], vertices[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    cx = ((x + xn) * cross).sum() / (6.0 * area)
    cy = ((y + yn) * cross).sum() / (6.0 * area)
    return float(area), np.array([cx, cy])


def local_vertices(vertices) -> list[tuple[float, float]]:
    """The polygon's vertices relative to its centroid (m), same order."""
    v = np.asarray(vertices, dtype=float)
    _, c = polygon_centroid(v)
    return [(float(px), float(py)) for px, py in v - c]


@dataclass(frozen=True)
class LocalPolygons:
    """vertices_local: (n, V, 2) vertices about the centre of mass, padded by repeating the last;
    vertex_count: (n,) int; concrete: (n,) bool; area: (n,) m^2."""

    vertices_local: np.ndarray
    vertex_count: np.ndarray
    concrete: np.ndarray
    area: np.ndarray

    @staticmethod
    def from_scene(scene: Scene) -> LocalPolygons:
        n = len(scene.bodies)
        vmax = max(len(b.vertices) for b in scene.bodies)
        verts = np.zeros((n, vmax, 2))
        count = np.zeros(n, dtype=np.int64)
        area = np.zeros(n)
        for k, body in enumerate(scene.bodies):
            v = np.asarray(body.vertices, dtype=float)
            a, c = polygon_centroid(v)
            verts[k, : len(v)] = v - c
            verts[k, len(v) :] = v[-1] - c
            count[k] = len(v)
            area[k] = a
        concrete = np.array([b.concrete for b in scene.bodies], dtype=bool)
        return LocalPolygons(verts, count, concrete, area)
