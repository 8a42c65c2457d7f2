"""The scripting API: a `Simulation` of one scene, stepped one `StepRecord` at a time."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from isaac.engine.integrate import DIVERGED_ANGLE, DIVERGED_POSITION, DIVERGED_SPEED, diverged_body
from isaac.engine.records import Contacts, StepRecord
from isaac.engine.step import ContactCache, StepSettings, Workspace, detect, step
from isaac.engine.world import Model, State, build_model, initial_state
from isaac.errors import SimulationError
from isaac.scene import Scene

__all__ = ["DIVERGED_ANGLE", "DIVERGED_POSITION", "DIVERGED_SPEED", "BodyView", "Simulation"]
_FIELDS = ("position", "velocity", "angle", "angular velocity")


class Simulation:
    """A running simulation of a validated scene.

    `record()` is the current state (step 0: the scene's initial state); `step()` advances one
    step of `scene.world.dt` seconds and returns its record. `start` resumes from a logged record
    (a keyframe): its state and its contacts (for warm starting and axis hysteresis) are exactly
    what the next step needs, so resuming gives the same bits as running through.
    """

    def __init__(
        self, scene: Scene, *, start: StepRecord | None = None, compile_ahead: bool = True
    ) -> None:
        """compile_ahead: on a machine whose numba cache lacks the solver, compile the step's
        kernels in two processes at once before the first step (`isaac.engine.compile_ahead`)."""
        self.scene = scene
        self.model: Model = build_model(scene)
        self.settings = StepSettings.of(scene.world)
        self._work = Workspace(self.model)
        self.state: State = initial_state(scene, self.model)
        self._contacts = Contacts.empty()
        self._cache = ContactCache.of(self._contacts, self.model.n_bodies)
        self._last = self.record()
        if start is not None:
            self.resume(start)
        if compile_ahead:
            from isaac.engine.compile_ahead import prepare

            prepare(self.settings, scene.world)

    def resume(self, record: StepRecord) -> None:
        """Continue from a record of this scene (a logged keyframe), keeping the model.

        The record's state and its contacts (feature ids and impulses, which the next step reads
        for axis hysteresis and warm starting) are all the next step needs, so stepping on from
        here gives the same bits as a run that went through it.
        """
        self._restore(record)
        self._contacts = record.contacts
        self._cache = ContactCache.of(record.contacts, self.model.n_bodies)
        self._last = self.record()

    @property
    def n_bodies(self) -> int:
        return self.model.n_bodies

    @property
    def step_index(self) -> int:
        """Index of the current state (number of steps taken from the scene's start)."""
        return self.state.step

    @property
    def time(self) -> float:
        """Simulated time of the current state (s): step_index * dt."""
        return self.state.step * self.scene.world.dt

    def record(self) -> StepRecord:
        """An immutable copy of the current state and the contacts of the step that made it."""
        s = self.state
        return StepRecord(
            step=s.step,
            time=s.step * self.scene.world.dt,
            position=s.position.copy(),
            angle=s.angle.copy(),
            velocity=s.velocity.copy(),
            angular_velocity=s.angular_velocity.copy(),
            exists=s.exists.copy(),
            contacts=self._contacts,
        )

    def step(self) -> StepRecord:
        """Advance one step (dt seconds) and return the new state's record.

        Raises SimulationError (naming the step and body) if the state becomes NaN, infinite or
        absurdly large; the state before the failing step is what `record()` returned last.
        """
        contacts, cache = step(
            self.model, self.settings, self.scene.world.dt, self.state, self._work, self._cache
        )
        body, field = self._diverged()
        if body >= 0:
            failed = self.state.step
            self._restore(self._last)
            name = self.model.names[body]
            raise SimulationError(
                f"step {failed}: body {name!r} (index {body}) has a non-finite or diverged "
                f"{_FIELDS[field]}; the simulation stopped (try a smaller dt or more substeps)",
                step=failed,
                body=name,
            )
        self._contacts, self._cache = contacts, cache
        self._last = self.record()
        return self._last

    def _diverged(self) -> tuple[int, int]:
        """(body, index into _FIELDS) of the first body whose state is non-finite or beyond the
        DIVERGED_* bounds, or (-1, -1)."""
        return diverged_body(self.state)

    def run(self, steps: int | None = None) -> Iterator[StepRecord]:
        """Yield the records of the next `steps` steps (default: the scene's `world.steps`)."""
        for _ in range(self.scene.world.steps if steps is None else steps):
            yield self.step()

    def detect(self) -> Contacts:
        """The contacts at the current pose (broad and narrow phase only; nothing moves).

        Push vectors, impulses and restitution are zero: they exist only once a step resolves
        the contacts.
        """
        rows = detect(self.model, self.settings, self.state, self._work, self._cache)
        found = self._work.contacts(rows, 0)
        for resolved in (
            found.push_a,
            found.push_b,
            found.impulse,
            found.tangent_impulse,
            found.restitution,
        ):
            resolved[...] = 0.0
        return found

    def body(self, name: str) -> BodyView:
        """A read-only view of one body's current state, by name."""
        try:
            return BodyView(self, self.model.names.index(name))
        except ValueError:
            raise KeyError(f"no body named {name!r}") from None

    def _restore(self, record: StepRecord) -> None:
        self.state = State(
            int(record.step),
            np.array(record.position, dtype=np.float64),
            np.array(record.angle, dtype=np.float64),
            np.array(record.velocity, dtype=np.float64),
            np.array(record.angular_velocity, dtype=np.float64),
            np.array(record.exists, dtype=bool),
        )


@dataclass(frozen=True)
class BodyView:
    """A thin window onto one body of a simulation (SI units, world frame)."""

    sim: Simulation
    index: int

    @property
    def name(self) -> str:
        return self.sim.model.names[self.index]

    @property
    def position(self) -> np.ndarray:
        """Centre of mass (m, world), a copy."""
        return self.sim.state.position[self.index].copy()

    @property
    def angle(self) -> float:
        """rad, counter-clockwise."""
        return float(self.sim.state.angle[self.index])

    @property
    def velocity(self) -> np.ndarray:
        """m/s, world, a copy."""
        return self.sim.state.velocity[self.index].copy()

    @property
    def angular_velocity(self) -> float:
        """rad/s, counter-clockwise."""
        return float(self.sim.state.angular_velocity[self.index])

    @property
    def mass(self) -> float:
        """kg (area * density)."""
        return float(self.sim.model.mass[self.index])

    @property
    def inertia(self) -> float:
        """kg m^2 about the centre of mass."""
        return float(self.sim.model.inertia[self.index])

    @property
    def exists(self) -> bool:
        return bool(self.sim.state.exists[self.index])
