"""The engine: physics only. World state, the stages of a step, the step, its records and the
`Simulation` that runs it.

- `world`: the constant `Model` (per-body mass, inertia, local vertices, ...) and the evolving
  `State` (positions, angles, velocities, existence), structure-of-arrays, indexed by body.
- the stages, in the order a step runs them: `geometry` (world vertices and boxes),
  `broad_phase` (MaxDist circles inside a sort-and-sweep), `narrow_phase` (SAT, MTD, contact
  points), `push_out` (MTD push along the normal), `solver` (impulses: the seed's pass or the
  sequential solver), `integrate` (gravity, positions, divergence check).
- `step`: one function that lists the stages; `records` (`StepRecord`, `Contacts`, the state
  hash); `diagnostics` (energies, momenta); `simulation` (the scripting API);
  `compile_ahead` (a cold numba cache compiled in two processes at once).

May import: the standard library, numpy, numba, `isaac.errors` and `isaac.scene` (the contract
a model is built from). Never an I/O library, `recorder`, `replay` or `isaac.app`.
"""

# The physics version: bumped whenever the engine's results change on purpose (CHANGELOG.md
# lists each change). Logs record it beside the engine version; a log without it is version 1.
# `isaac replay` refuses a log of another physics version unless given --tolerance.
PHYSICS_VERSION = 3
