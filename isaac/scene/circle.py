"""Circles: mass properties, the same bits wherever they are computed (checks and world).

A circle of radius r (m) centred on its body's position has area pi r^2 and polar second
moment of area pi r^4 / 2 about its centre, so mass = pi r^2 density and moment of inertia
I = m r^2 / 2 (a uniform disc).
"""

from __future__ import annotations

import math

import numpy as np


def mass_properties(radius) -> tuple[np.ndarray, np.ndarray]:
    """(area m^2, second moment m^4) of circles of `radius` (m; a number or an array).

    The second moment is area * r^2 / 2, evaluated in this order so every caller gets the same
    bits (numpy's float64 multiply is IEEE, so array and scalar give the same)."""
    r = np.asarray(radius, dtype=np.float64)
    area = math.pi * (r * r)
    return area, 0.5 * (area * (r * r))
