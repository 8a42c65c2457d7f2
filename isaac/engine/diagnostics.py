"""Physical summaries of a state: energies, momenta, and a hash of the exact state bits.

Sums run over bodies that exist and are not concrete (a concrete body has infinite mass and never
moves), left to right in body order in one compiled pass (determinism: a fixed order), so the
recorder's per-step `/stats` cost one kernel call rather than a dozen numpy reductions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.records import StepRecord, state_hash  # noqa: F401 - re-exported


@dataclass(frozen=True)
class Summary:
    """kinetic_energy (J): sum of m v^2 / 2 + I w^2 / 2; potential_energy (J): sum of -m g . x
    (relative to the world origin); linear_momentum (kg m/s, world, x and y); angular_momentum
    (kg m^2/s about the world origin, counter-clockwise positive)."""

    kinetic_energy: float
    potential_energy: float
    linear_momentum: tuple[float, float]
    angular_momentum: float


@numba.njit(cache=True, nogil=True, inline="always")
def _body_energy(m, inertia, position, vx, vy, w, gx, gy):
    """One body's (kinetic, potential) energy (J): m v^2 / 2 + I w^2 / 2, and -m g . x relative
    to the world origin (the one definition every energy here sums)."""
    return (
        0.5 * m * (vx * vx + vy * vy) + 0.5 * inertia * w * w,
        -(m * (gx * position[0] + gy * position[1])),
    )


@numba.njit(cache=True, nogil=True)
def _sums(mass, inertia, concrete, exists, position, velocity, angular_velocity, gx, gy):
    ke = 0.0
    pe = 0.0
    px = 0.0
    py = 0.0
    ang = 0.0
    for i in range(mass.shape[0]):
        if not exists[i] or concrete[i]:
            continue
        m = mass[i]
        vx = velocity[i, 0]
        vy = velocity[i, 1]
        w = angular_velocity[i]
        k, p = _body_energy(m, inertia[i], position[i], vx, vy, w, gx, gy)
        ke += k
        pe += p
        px += m * vx
        py += m * vy
        ang += m * (position[i, 0] * vy - position[i, 1] * vx) + inertia[i] * w
    return ke, pe, px, py, ang


@numba.njit(cache=True, nogil=True)
def _batch_energies(
    mass, inertia, concrete, gx, gy, before, position, velocity, angular_velocity, exists
):
    """Per step s of a batch: total[s], the scene's energy (J, `_sums`' kinetic + potential),
    and entered[s], the energy bodies brought in at step s (J: a body entering adds its energy
    at s, one leaving takes out its energy at s - 1). before: (position, velocity,
    angular_velocity, exists) of the step before the batch's first."""
    steps = position.shape[0]
    total = np.empty(steps)
    entered = np.zeros(steps)
    p0, v0, w0, e0 = before
    for s in range(steps):
        ke, pe, _, _, _ = _sums(
            mass, inertia, concrete, exists[s], position[s], velocity[s], angular_velocity[s],
            gx, gy,
        )  # fmt: skip
        total[s] = ke + pe
        for i in range(mass.shape[0]):
            was = e0[i] if s == 0 else exists[s - 1, i]
            if was == exists[s, i] or concrete[i]:
                continue
            if exists[s, i]:
                k, p = _body_energy(
                    mass[i], inertia[i], position[s, i], velocity[s, i, 0], velocity[s, i, 1],
                    angular_velocity[s, i], gx, gy,
                )  # fmt: skip
                entered[s] += k + p
            elif s == 0:
                k, p = _body_energy(
                    mass[i], inertia[i], p0[i], v0[i, 0], v0[i, 1], w0[i], gx, gy
                )  # fmt: skip
                entered[s] -= k + p
            else:
                k, p = _body_energy(
                    mass[i], inertia[i], position[s - 1, i], velocity[s - 1, i, 0],
                    velocity[s - 1, i, 1], angular_velocity[s - 1, i], gx, gy,
                )  # fmt: skip
                entered[s] -= k + p
    return total, entered


def batch_energies(model, before: StepRecord, batch, gravity) -> tuple[np.ndarray, np.ndarray]:
    """(total, entered) per step of a `StepBatch` (J, arrays of batch.steps): the energy of
    `summary` (kinetic + gravitational potential relative to the world origin) after each step,
    and the energy bodies entering at that step brought in (less that of bodies leaving, at
    their last step). before: the record of the step before the batch's first. One compiled
    pass over the batch."""
    return _batch_energies(
        model.mass,
        model.inertia,
        model.concrete,
        float(gravity[0]),
        float(gravity[1]),
        (before.position, before.velocity, before.angular_velocity, before.exists),
        batch.position,
        batch.velocity,
        batch.angular_velocity,
        batch.exists,
    )


def record_energies(model, before: StepRecord, record: StepRecord, gravity) -> tuple[float, float]:
    """(total, entered) of one record after `before` (J; `batch_energies` of a batch of one)."""
    one = tuple(
        np.asarray(getattr(record, f))[None]
        for f in ("position", "velocity", "angular_velocity", "exists")
    )
    total, entered = _batch_energies(
        model.mass,
        model.inertia,
        np.asarray(model.concrete, dtype=bool),
        float(gravity[0]),
        float(gravity[1]),
        (before.position, before.velocity, before.angular_velocity, before.exists),
        *one,
    )
    return float(total[0]), float(entered[0])


def summary(model, record: StepRecord, gravity) -> Summary:
    """Energies and momenta of a record in one pass (see Summary for units and frames)."""
    ke, pe, px, py, ang = _sums(
        model.mass,
        model.inertia,
        model.concrete,
        record.exists,
        record.position,
        record.velocity,
        record.angular_velocity,
        float(gravity[0]),
        float(gravity[1]),
    )
    return Summary(ke, pe, (px, py), ang)


def kinetic_energy(model, record: StepRecord) -> float:
    """Translational plus rotational kinetic energy (J): sum of m v^2 / 2 + I w^2 / 2."""
    return summary(model, record, (0.0, 0.0)).kinetic_energy


def potential_energy(model, record: StepRecord, gravity) -> float:
    """Gravitational potential energy (J) relative to the world origin: sum of -m g . x."""
    return summary(model, record, gravity).potential_energy


def linear_momentum(model, record: StepRecord) -> np.ndarray:
    """Total linear momentum (kg m/s, world), shape (2,)."""
    return np.array(summary(model, record, (0.0, 0.0)).linear_momentum)


def angular_momentum(model, record: StepRecord) -> float:
    """Total angular momentum about the world origin (kg m^2/s, counter-clockwise positive)."""
    return summary(model, record, (0.0, 0.0)).angular_momentum


@numba.njit(cache=True, nogil=True)
def _finite(arrays):
    for a in arrays:
        for i in range(a.shape[0]):
            if not np.isfinite(a[i]):
                return False
    return True


def all_finite(record: StepRecord) -> bool:
    """Whether every float of the record (state and contacts) is finite: one compiled pass,
    for the recorder's never-write-NaN check on every step."""
    c = record.contacts
    arrays = (
        record.position,
        record.angle,
        record.velocity,
        record.angular_velocity,
        c.point,
        c.normal,
        c.depth,
        c.push_a,
        c.push_b,
        c.impulse,
        c.tangent_impulse,
        c.restitution,
    )
    # flat float64 views (no copies for the engine's contiguous arrays): one tuple type
    return bool(_finite(tuple(np.ravel(np.asarray(a, dtype=np.float64)) for a in arrays)))
