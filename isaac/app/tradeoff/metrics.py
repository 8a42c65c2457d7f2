"""Errors of a run against the reference at common times: position RMS, energy, centre of mass,
momentum, penetration, tunneling."""

from __future__ import annotations

import math

import numpy as np

from isaac.app.tradeoff.trajectory import Trajectory
from isaac.scene import Scene


def _series(scene: Scene, model, traj: Trajectory) -> dict[str, np.ndarray]:
    from isaac.engine import diagnostics  # compiled: not loaded for the command line's --help

    g = scene.world.gravity
    energy, momentum = [], []
    for k in range(traj.times.shape[0]):
        rec = traj.record(k)
        energy.append(
            diagnostics.kinetic_energy(model, rec) + diagnostics.potential_energy(model, rec, g)
        )
        momentum.append(diagnostics.linear_momentum(model, rec))
    weights = np.where(traj.exists & ~model.concrete, model.mass, 0.0)  # (S, n)
    total = weights.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        com = np.einsum("sn,snd->sd", weights, np.nan_to_num(traj.position)) / total
    return dict(energy=np.array(energy), momentum=np.array(momentum), com=com, mass=total[:, 0])


def compare(
    scene: Scene, model, run: Trajectory, ref: Trajectory, ref_series: dict | None = None
) -> dict[str, float]:
    """Error measures of `run` against `ref` (same sample times).

    rms_error_m: sqrt(mean over moving bodies and sample times of |x_run - x_ref|^2).
    max_error_m: the largest such distance.
    energy_drift: (E(T) - E(0)) / |E(0)| of the run itself (E = kinetic + potential about the
        origin); physical losses (e < 1, friction) count in it, so read it next to the
        reference's own drift.
    energy_error: RMS over sample times of (E_run - E_ref) / |E_ref(0)|.
    com_error_m: distance between the centres of mass of the moving bodies at the end (settled
        height and stack drift: insensitive to chaos).
    momentum_error_mps: RMS over sample times of |P_run - P_ref| / total moving mass (the
        centre-of-mass velocity error, m/s). RMS rather than max: a bounce that lands one step
        early differs by twice the impact speed for that one step.
    """
    moving = ~model.concrete
    both = run.exists & ref.exists & moving  # (S, n)
    d = np.linalg.norm(run.position - ref.position, axis=2)  # (S, n), NaN after a failure
    dist = d[both]
    s_run = _series(scene, model, run)
    s_ref = ref_series if ref_series is not None else _series(scene, model, ref)
    e0_ref = abs(s_ref["energy"][0]) or 1.0
    e0_run = abs(s_run["energy"][0]) or 1.0
    mass = np.where(s_ref["mass"] > 0.0, s_ref["mass"], 1.0)
    nan = math.nan
    if run.error is not None or not np.all(np.isfinite(dist)):
        rms = mx = nan
    else:
        rms = float(np.sqrt(np.mean(dist * dist))) if dist.size else 0.0
        mx = float(dist.max()) if dist.size else 0.0
    energy_error = float(np.sqrt(np.mean((s_run["energy"] - s_ref["energy"]) ** 2)) / e0_ref)
    dp = np.linalg.norm(s_run["momentum"] - s_ref["momentum"], axis=1) / mass
    return dict(
        rms_error_m=rms,
        max_error_m=mx,
        energy_drift=float((s_run["energy"][-1] - s_run["energy"][0]) / e0_run),
        energy_error=energy_error,
        com_error_m=float(np.linalg.norm(s_run["com"][-1] - s_ref["com"][-1])),
        momentum_error_mps=float(np.sqrt(np.mean(dp * dp))),
    )
