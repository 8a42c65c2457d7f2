"""The energy check: a run whose energy rises beyond what its sources can supply.

With no motor, the only sources of energy in a run are the bodies that enter it; everything else
the step does (gravity, joints, contacts, friction, restitution <= 1) conserves or removes energy,
apart from the little a position push-out or a sequential-impulse bounce adds. So a run's
energy E(s) (`isaac.engine.diagnostics`: kinetic + gravitational potential, the one definition
the recorder's `/stats` also use) should never pass its budget

    B(s) = E(0) + (energy of the bodies entered up to s) - (energy of those that left)

by more than a small share of the scene's energy scale. The excess X(s) = E(s) - B(s) does not
depend on where y = 0 is (moving the datum adds the same M g h to E(s) and B(s)). The check
flags the first step where

    X(s) > ENERGY_TOLERANCE * S,    S = KE(0) + |g| * M * L

with M the mass of the movable bodies, KE(0) their kinetic energy as the scene gives it, and L
the scene's size: the larger side of the box holding every body's bounding circle at step 0.
M |g| L is more than the scene can release by falling its own height, so an energy gain past
S is energy from nowhere, not a conversion the numbers blurred.

A scene with a motor has a source the step does not expose as work (a motor's impulses do work
at velocities inside the step): its budget is unbounded and it is not checked (`checked` is
False). docs/physics.md (Energy check) gives the calibration and what fixes a flagged scene.

Numpy only, no compiled code: the batch sums come from `diagnostics.batch_energies`.
"""

from __future__ import annotations

import math

import numpy as np

# X(s) / S past which a run is flagged (docs/physics.md, Energy check: the largest share a
# shipped, bench or golden-corpus scene reaches, and the smallest a repro reaches)
ENERGY_TOLERANCE = 0.5

FIX_HINT = (
    "the step cannot hold this scene: add sub-steps (world.substeps; `isaac check` says how "
    "many a joint needs) or a smaller world.dt"
)


def energy_scale(mass, concrete, position, velocity, angular_velocity, inertia, radius, gravity):
    """S (J): kinetic energy of the movable bodies at step 0 plus |g| * M * L (module
    docstring). Every body counts, whether or not it exists at step 0 (a body entering later
    belongs to the scene as well). Arrays (n,) or (n, 2), world frame, SI units."""
    movable = ~np.asarray(concrete, dtype=bool)
    m = np.asarray(mass)[movable]
    v = np.asarray(velocity)[movable]
    w = np.asarray(angular_velocity)[movable]
    each = (
        0.5 * m * (v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1])
        + 0.5 * np.asarray(inertia)[movable] * w * w
    )
    kinetic = _in_order(each)
    if not len(position):
        return kinetic
    r = np.asarray(radius)[:, None]
    lo = np.min(np.asarray(position) - r, axis=0)
    hi = np.max(np.asarray(position) + r, axis=0)
    size = float(np.max(hi - lo))
    g = math.sqrt(gravity[0] * gravity[0] + gravity[1] * gravity[1])
    return kinetic + g * _in_order(m) * size


def _in_order(values: np.ndarray) -> float:
    """The sum of `values` taken left to right: np.sum groups pairwise by the array's length,
    and the scale decides a flag that must be the same on every machine (determinism)."""
    total = 0.0
    for x in values.tolist():
        total += x
    return total


class EnergyCheck:
    """The energy check over a run, fed the energies step by step in batches (`add`).

    start_step, start_energy (J): the first step and its energy E(0); scale (J): S; motors: the
    scene has a motor (then nothing is checked). After the feeding: `flagged`, and for a flagged
    run `step` (the first step past the threshold) and `rise` (J, X at that step); `max_excess`
    (J) and `max_excess_step` over the run; `threshold` (J)."""

    def __init__(self, start_step: int, start_energy: float, scale: float, *, motors: bool):
        self.checked = not motors
        self.start_energy = float(start_energy)
        self.scale = float(scale)
        self.threshold = ENERGY_TOLERANCE * self.scale
        self.entered = 0.0
        self.next_step = start_step + 1
        self.step: int | None = None
        self.rise = 0.0
        self.max_excess = 0.0
        self.max_excess_step: int | None = None

    @classmethod
    def of(cls, model, record, gravity, start_energy: float, *, motors: bool) -> EnergyCheck:
        """The check of a run from `record` (its first step, energy `start_energy` J): model
        holds mass, inertia, concrete and radius (n,) (`isaac.engine.world.Model`, or a log's
        world table with its radius)."""
        scale = energy_scale(
            model.mass,
            model.concrete,
            record.position,
            record.velocity,
            record.angular_velocity,
            model.inertia,
            model.radius,
            gravity,
        )
        return cls(record.step, start_energy, scale, motors=motors)

    @property
    def flagged(self) -> bool:
        return self.step is not None

    def add(self, total, entered) -> None:
        """The next steps' energies: total (J, E(s)) and entered (J, energy brought in by
        bodies entering less that of bodies leaving at s), arrays of one length."""
        total = np.asarray(total, dtype=np.float64)
        if not self.checked or not len(total):
            self.next_step += len(total)
            return
        budget = self.start_energy + self.entered + np.cumsum(entered)
        self.entered = float(budget[-1] - self.start_energy)
        excess = total - budget
        # a non-finite energy stops the run elsewhere; here it is simply the worst excess
        excess = np.where(np.isnan(excess), np.inf, excess)
        k = int(np.argmax(excess))
        if self.max_excess_step is None or excess[k] > self.max_excess:
            self.max_excess, self.max_excess_step = float(excess[k]), self.next_step + k
        if self.step is None:
            over = np.flatnonzero(excess > self.threshold)
            if len(over):
                self.step = self.next_step + int(over[0])
                self.rise = float(excess[over[0]])
        self.next_step += len(total)

    def warning(self) -> str | None:
        """The one-line warning of a flagged run, None otherwise."""
        if not self.flagged:
            return None
        return (
            f"energy rose by {self.rise:.3g} J beyond its sources at step {self.step} "
            f"(threshold {self.threshold:.3g} J = {ENERGY_TOLERANCE:g} x the scene's energy "
            f"scale {self.scale:.3g} J; largest rise {self.max_excess:.3g} J at step "
            f"{self.max_excess_step}): {FIX_HINT} (docs/physics.md, Energy check)"
        )

    def summary(self) -> str:
        """What the run's summary says of the check, one phrase."""
        if not self.checked:
            return "energy check: not checked (a motor is an unbounded source)"
        if self.flagged:
            return (
                f"energy check: ROSE by {self.rise:.3g} J beyond its sources at step {self.step} "
                f"(threshold {self.threshold:.3g} J)"
            )
        return (
            f"energy check: ok (largest rise {self.max_excess:.3g} J, threshold "
            f"{self.threshold:.3g} J)"
        )
