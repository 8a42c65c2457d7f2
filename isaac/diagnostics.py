"""Physical summaries of a state: energies, momenta, and a hash of the exact state bits.

Sums run over bodies that exist and are not concrete (a concrete body has infinite mass and never
moves). They are vectorised numpy reductions: deterministic for the same arrays on the same machine
(numpy's pairwise summation is fixed by the array length), which is all the log needs.
"""

from __future__ import annotations

import hashlib

import numpy as np

from isaac.records import StepRecord


def _weights(model, record: StepRecord) -> np.ndarray:
    """Mass of each moving body (kg), 0 for concrete or absent bodies."""
    return np.where(record.exists & ~model.concrete, model.mass, 0.0)


def kinetic_energy(model, record: StepRecord) -> float:
    """Translational plus rotational kinetic energy (J): sum of m v^2 / 2 + I w^2 / 2."""
    m = _weights(model, record)
    inertia = np.where(m > 0.0, model.inertia, 0.0)
    v = record.velocity
    w = record.angular_velocity
    return float(np.sum(0.5 * m * (v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1]) + 0.5 * inertia * w * w))


def potential_energy(model, record: StepRecord, gravity) -> float:
    """Gravitational potential energy (J) relative to the world origin: sum of -m g . x."""
    m = _weights(model, record)
    p = record.position
    return float(-np.sum(m * (gravity[0] * p[:, 0] + gravity[1] * p[:, 1])))


def linear_momentum(model, record: StepRecord) -> np.ndarray:
    """Total linear momentum (kg m/s, world), shape (2,)."""
    m = _weights(model, record)
    return np.array([np.sum(m * record.velocity[:, 0]), np.sum(m * record.velocity[:, 1])])


def angular_momentum(model, record: StepRecord) -> float:
    """Total angular momentum about the world origin (kg m^2/s, counter-clockwise positive)."""
    m = _weights(model, record)
    inertia = np.where(m > 0.0, model.inertia, 0.0)
    p, v = record.position, record.velocity
    orbital = m * (p[:, 0] * v[:, 1] - p[:, 1] * v[:, 0])
    return float(np.sum(orbital + inertia * record.angular_velocity))


def state_hash(record: StepRecord) -> str:
    """sha256 (hex) of the exact bits of the body state after the step.

    Covers position, angle, velocity, angular velocity and existence, as little-endian float64 /
    uint8 in body order. Two runs agree bit for bit exactly when their hashes agree.
    """
    h = hashlib.sha256()
    for arr in (record.position, record.angle, record.velocity, record.angular_velocity):
        h.update(np.ascontiguousarray(arr, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(record.exists, dtype=np.uint8).tobytes())
    return h.hexdigest()
