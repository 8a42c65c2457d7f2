"""World settings, the fidelity presets they come from, and their reading from a scene's
`world:` mapping."""

from __future__ import annotations

import dataclasses

from isaac.scene.limits import MAX_GRAVITY, MAX_ITERATIONS, MAX_STEPS, MAX_SUBSTEPS
from isaac.scene.reader import Reader, join_path, optional

# Fidelity presets: each sets the settings below; explicit keys in `world:` override a preset.
# `seed` reproduces the seed's algorithm exactly (docs/physics.md).
PRESETS: dict[str, dict[str, object]] = {
    "seed": dict(
        integrator="explicit",
        substeps=1,
        solver="seed",
        iterations=1,
        warm_starting=False,
        contact_points=1,
        position_correction="full",
        position_iterations=1,
        restitution_threshold=0.0,
        ccd="off",
        axis_hysteresis=False,
    ),
    "fast": dict(
        integrator="semi_implicit",
        substeps=1,
        solver="sequential",
        iterations=6,
        warm_starting=True,
        contact_points=2,
        position_correction="partial",
        position_iterations=1,
        restitution_threshold=0.5,
        ccd="off",
        axis_hysteresis=True,
    ),
    "balanced": dict(
        integrator="semi_implicit",
        substeps=1,
        solver="sequential",
        iterations=10,
        warm_starting=True,
        contact_points=2,
        position_correction="partial",
        position_iterations=3,
        restitution_threshold=1.0,
        ccd="speculative",
        axis_hysteresis=True,
    ),
    "accurate": dict(
        integrator="semi_implicit",
        substeps=4,
        solver="sequential",
        iterations=20,
        warm_starting=True,
        contact_points=2,
        position_correction="partial",
        position_iterations=4,
        restitution_threshold=1.0,
        ccd="speculative",
        axis_hysteresis=True,
    ),
}
DEFAULT_PRESET = "balanced"


@dataclasses.dataclass(frozen=True)
class WorldSettings:
    """Everything about the world a run needs, presets already resolved.

    gravity: (gx, gy) acceleration (m/s^2, world frame, y up).
    dt: time step (s), > 0.
    steps: default number of steps of a run.
    fidelity: the preset the settings came from (informative; the fields below are what counts).
    integrator: "explicit" (the seed: position with the old velocity, then gravity) or
        "semi_implicit" (gravity into velocity first, then position with the new velocity).
    substeps: each step is split into this many sub-steps of dt / substeps.
    solver: "seed" (one pass, the seed's impulse formula per contact) or "sequential"
        (iterative sequential impulses with accumulated, clamped impulses).
    iterations: velocity iterations of the sequential solver (1 for "seed").
    warm_starting: start the sequential solver from the previous step's impulses.
    contact_points: 1 (the seed's single point per pair) or 2 (clipped two-point manifolds).
    position_correction: "full" (the seed's whole MTD push), "partial" (push
        ``correction * (depth - slop)``) or "none".
    slop: penetration (m) left uncorrected by "partial".
    correction: fraction of (depth - slop) pushed out per step by "partial", in (0, 1].
    position_iterations: passes of the push-out over all pairs, each pushing only the depth the
        earlier passes left (1 is the seed's single push).
    restitution_rule: how two bodies' restitutions combine per contact: "max", "min", "mean",
        "product".
    restitution_threshold: approach speed (m/s) below which a contact does not bounce.
    friction: whether Coulomb friction is on at all.
    friction_rule: how two bodies' friction coefficients combine: "sqrt" (geometric mean),
        "min", "max", "mean", "product".
    ccd: "off" or "speculative" (speculative contacts against fast approach).
    axis_hysteresis: keep the previous step's separating axis for a pair while it is within a
        small tolerance of the best one, so near-ties do not flip the normal.
    """

    gravity: tuple[float, float] = (0.0, -9.81)
    dt: float = 0.01
    steps: int = 500
    fidelity: str = DEFAULT_PRESET
    integrator: str = "semi_implicit"
    substeps: int = 1
    solver: str = "sequential"
    iterations: int = 10
    warm_starting: bool = True
    contact_points: int = 2
    position_correction: str = "partial"
    slop: float = 0.005
    correction: float = 0.8
    position_iterations: int = 3
    restitution_rule: str = "max"
    restitution_threshold: float = 1.0
    friction: bool = False
    friction_rule: str = "sqrt"
    ccd: str = "speculative"
    axis_hysteresis: bool = True


_WORLD_FIELDS = tuple(f.name for f in dataclasses.fields(WorldSettings))
# The rules of `world:` (docs/scene-format.md), read from YAML by `read_world` and checked by
# `checks.world_problem` on WorldSettings however they were made.
WORLD_CHOICES = {
    "fidelity": tuple(PRESETS),
    "integrator": ("explicit", "semi_implicit"),
    "solver": ("seed", "sequential"),
    "position_correction": ("full", "partial", "none"),
    "restitution_rule": ("max", "min", "mean", "product"),
    "friction_rule": ("sqrt", "min", "max", "mean", "product"),
    "ccd": ("off", "speculative"),
}
WORLD_BOOLEANS = ("warm_starting", "friction", "axis_hysteresis")
# key: (kind, lowest, highest, lowest excluded); kind "pair" (two numbers), "time" (a number,
# or a fraction in YAML), "integer" or "number"
WORLD_RANGES = {
    "gravity": ("pair", -MAX_GRAVITY, MAX_GRAVITY, False),
    "dt": ("time", 0.0, 1.0, True),
    "steps": ("integer", 1, MAX_STEPS, False),
    "substeps": ("integer", 1, MAX_SUBSTEPS, False),
    "iterations": ("integer", 1, MAX_ITERATIONS, False),
    "position_iterations": ("integer", 1, MAX_ITERATIONS, False),
    "contact_points": ("integer", 1, 2, False),
    "slop": ("number", 0.0, 1.0, False),
    "correction": ("number", 0.0, 1.0, True),
    "restitution_threshold": ("number", 0.0, 1e3, False),
}


def _world_value(r: Reader, key: str, node, path: str):
    if key in WORLD_CHOICES:
        return r.choice(node, path, WORLD_CHOICES[key])
    if key in WORLD_BOOLEANS:
        return r.boolean(node, path)
    kind, lo, hi, lo_open = WORLD_RANGES[key]
    if kind == "integer":
        return r.integer(node, path, lo, hi)
    read = {"pair": r.pair, "time": r.time, "number": r.number}
    return read[kind](node, path, lo, hi, lo_open=lo_open)


def read_world(r: Reader, node) -> WorldSettings:
    """The WorldSettings of a scene's `world:` mapping `node` (None when left out)."""
    if node is None:
        m = {}
    else:
        m = r.mapping(node, "world", _WORLD_FIELDS)
    fidelity = optional(r.choice, m, "fidelity", "world", DEFAULT_PRESET, tuple(PRESETS))
    # resolution: dataclass defaults, then the preset, then every explicit key.
    values = {f.name: f.default for f in dataclasses.fields(WorldSettings)}
    values.update(PRESETS[fidelity])
    values["fidelity"] = fidelity
    for key, (_, value_node) in m.items():
        if key != "fidelity":
            values[key] = _world_value(r, key, value_node, join_path("world", key))
    return WorldSettings(**values)
