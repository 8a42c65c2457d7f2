"""What the recorder derives from a step record: the ``/stats`` values, and the NaN/infinity check
that stops a run naming the step and the body before anything of that step is written."""

from __future__ import annotations

import math

import numpy as np

from isaac.engine.records import StepRecord, state_hash
from isaac.errors import SimulationError

_CONTACT_FLOATS = (
    "point",
    "normal",
    "depth",
    "push_a",
    "push_b",
    "impulse",
    "tangent_impulse",
    "restitution",
)
_BODY_FLOATS = ("position", "angle", "velocity", "angular_velocity")


def compute_stats(model, gravity, record: StepRecord, with_hash: bool = True) -> dict:
    """The ``/stats`` values of one record (SI units; see isaac.engine.diagnostics).

    with_hash: False leaves out ``state_hash``; the MCAP writer then computes it in its thread.
    """
    from isaac.engine import diagnostics  # compiled kernels: not imported by the writer processes

    totals = diagnostics.summary(model, record, gravity)
    ke, pe = totals.kinetic_energy, totals.potential_energy
    p = totals.linear_momentum
    c = record.contacts
    n = len(c)
    stats = {
        "kinetic_energy": ke,
        "potential_energy": pe,
        "total_energy": ke + pe,
        "linear_momentum_x": float(p[0]),
        "linear_momentum_y": float(p[1]),
        "angular_momentum": totals.angular_momentum,
        "contact_count": n,
        "max_depth": float(np.max(c.depth)) if n else 0.0,
        "max_impulse": float(np.max(c.impulse)) if n else 0.0,
    }
    if with_hash:
        stats["state_hash"] = state_hash(record)
    return stats


def _first_bad_row(arr: np.ndarray) -> int | None:
    """Index of the first row holding a NaN or infinity, or None when all are finite.

    Fast path: a sum is finite only if every term is (NaN and inf propagate; inf - inf is NaN),
    so one reduction per array decides; overflow to inf merely sends it to the exact check.
    """
    if arr.size == 0 or math.isfinite(float(np.add.reduce(arr, axis=None))):
        return None
    bad = ~np.isfinite(arr.reshape(arr.shape[0], -1)).all(axis=1)
    rows = np.flatnonzero(bad)
    return int(rows[0]) if rows.size else None


def check_finite(names, record: StepRecord) -> None:
    """Raise `SimulationError` (naming step and body) if the record holds a NaN or infinity."""
    from isaac.engine import diagnostics

    joints = record.joints
    if joints is not None:
        from isaac.engine.records import JOINT_FIELDS

        for field in JOINT_FIELDS:
            k = _first_bad_row(np.asarray(getattr(joints, field)))
            if k is not None:
                raise SimulationError(
                    f"step {record.step}: joint {k} has a non-finite {field}; the log keeps "
                    f"steps up to {record.step - 1}",
                    step=record.step,
                )
    if diagnostics.all_finite(record):
        return
    for field in _BODY_FLOATS:
        k = _first_bad_row(getattr(record, field))
        if k is not None:
            name = str(names[k])
            raise SimulationError(
                f"step {record.step}: body {name!r} (index {k}) has a non-finite {field}; "
                f"the log keeps steps up to {record.step - 1}",
                step=record.step,
                body=name,
            )
    c = record.contacts
    for field in _CONTACT_FLOATS:
        row = _first_bad_row(getattr(c, field))
        if row is not None:
            a, b = int(c.a[row]), int(c.b[row])
            name = str(names[a])
            raise SimulationError(
                f"step {record.step}: contact between {name!r} and {str(names[b])!r} has a "
                f"non-finite {field}; the log keeps steps up to {record.step - 1}",
                step=record.step,
                body=name,
            )
