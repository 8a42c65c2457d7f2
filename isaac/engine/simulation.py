"""The scripting API: a `Simulation` of one scene, stepped one `StepRecord` at a time."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from isaac.engine import compile_ahead as _ahead
from isaac.engine.counts import count
from isaac.engine.driver import STAGES, Stepper
from isaac.engine.guards import check_state, checked_record
from isaac.engine.integrate import DIVERGED_ANGLE, DIVERGED_POSITION, DIVERGED_SPEED, diverged_body
from isaac.engine.joints import JOINT_IMPULSES
from isaac.engine.records import (
    CONTACT_FIELDS,
    JOINT_FIELDS,
    Contacts,
    JointRows,
    StepBatch,
    StepRecord,
    _BatchRecord,
)
from isaac.engine.step import (
    ContactCache,
    StepSettings,
    Workspace,
    detect,
    initial_joint_rows,
    joint_rows,
    step,
)
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
        self,
        scene: Scene,
        *,
        start: StepRecord | None = None,
        compile_ahead: bool = True,
        staged: bool = False,
        profile: bool = False,
        tiered: bool = False,
    ) -> None:
        """compile_ahead: on a machine whose numba cache lacks the solver, compile the step's
        kernels in two processes at once before the first step (`isaac.engine.compile_ahead`).
        staged: never use the compiled driver (`isaac.engine.driver`): `run`, `advance` and
        `batches` then step through `isaac.engine.step.step` too, one compiled call per stage
        from Python. Both give the same bits.
        profile: `run`, `advance` and `batches` call the timed driver, which adds up the time
        of each stage inside compiled code (`stage_times`; `isaac run --profile`); the same
        bits. Compiled apart from the plain driver, on first use. (`step()` is timed once it
        takes the driver; not on the staged path.)

        tiered: with compile_ahead, when numba's cache lacks the driver, a helper process
        compiles it (7-10 s on the 2-core machine), and meanwhile `run`, `advance` and
        `batches` take the staged path, whose kernels are ready first; they take the driver
        from the first batch after the helper is done (the same bits either way).
        `finish_compiling` waits for the helper (at exit at the latest). Not with `profile`.

        `step()` takes the driver too, for one step a call, once numba has it (loaded or in
        its cache: `_step_takes_driver`), and the staged path before.
        """
        self.scene = scene
        self.model: Model = build_model(scene)
        self.settings = StepSettings.of(scene.world)
        self._work = Workspace(self.model)
        self._stepper = (
            None
            if staged
            else Stepper(self.model, self.settings, scene.world.dt, self._work, timed=bool(profile))
        )
        self.state: State = initial_state(scene, self.model)
        self._state_checked()
        if self._stepper is not None:  # (the driver's calls check a state they have not had)
            self._stepper.check_state = self._check_state
        self._contacts = Contacts.empty()
        self._rows_from = None  # a batch's record whose rows are the current ones (_rows_of)
        self._step_driver = False  # step() takes the driver (_step_takes_driver)
        self._joints = initial_joint_rows(self.model, self.state, self._work)
        self._cache = ContactCache.of(self._contacts, self.model.n_bodies, self._no_impulses())
        self._carry_in_stepper = False  # which of _cache and the stepper's Carry is current
        self._last = self.record()
        if start is not None:
            self.resume(start)
        self._compiling = None  # the helper compiling the driver (tiered), while it runs
        if compile_ahead:
            self._compiling = _ahead.prepare(
                self.settings,
                scene.world,
                joints=bool(self.model.joints.kind.shape[0]),
                tiered=tiered and self._stepper is not None and not profile,
            )

    def resume(self, record: StepRecord) -> None:
        """Continue from a record of this scene (a logged keyframe), keeping the model.

        The record's state and its contacts (feature ids and impulses, which the next step reads
        for axis hysteresis and warm starting) are all the next step needs, so stepping on from
        here gives the same bits as a run that went through it.

        The record is checked against the scene first (`isaac.engine.guards.checked_record`):
        TypeError for anything but a `StepRecord`, `isaac.errors.StateError` (a ValueError)
        naming what differs for a record of another scene (its body or joint count, dt,
        existence) or with arrays of another shape or dtype, or not finite. The simulation
        keeps private copies: the record may be changed afterwards.
        """
        w = self.scene.world
        state, contacts, joints = checked_record(record, self.model, w.dt, w.substeps)
        self.state = state
        self._state_checked()
        self._rows_from = None
        self._contacts = contacts
        self._joints = joints
        impulses = self._no_impulses() if joints is None else joints.impulses
        self._cache = ContactCache.of(contacts, self.model.n_bodies, impulses)
        self._carry_in_stepper = False
        self._last = self.record()

    def _state_checked(self) -> None:
        """Note the state's arrays as checked: made or checked by the engine."""
        s = self.state
        self._checked = (s, s.position, s.angle, s.velocity, s.angular_velocity, s.exists)

    def _check_state(self) -> None:
        """Before compiled code reads the state: check it (`isaac.engine.guards.check_state`)
        when it or one of its arrays is not the one last checked (a caller replaced it
        between steps, `sim.state.velocity = ...`), or its step is not an int; else (the
        common case) nothing more than these identity checks. The staged path calls it a step,
        the driver's calls only when their kit's pose is not the state's (`BatchCall.kit`)."""
        s, c = self.state, self._checked
        if not (
            s is c[0]
            and s.position is c[1]
            and s.angle is c[2]
            and s.velocity is c[3]
            and s.angular_velocity is c[4]
            and s.exists is c[5]
            and type(s.step) is int
        ):
            check_state(s, self.model.names)
            self._state_checked()

    def _no_impulses(self) -> np.ndarray:
        return np.zeros((self.model.joints.kind.shape[0], JOINT_IMPULSES))

    def _staged_cache(self) -> ContactCache:
        """What the next step reads of the last one's contacts, for the staged path."""
        if self._carry_in_stepper:
            self._cache = ContactCache(*self._stepper.cache_arrays())
            self._carry_in_stepper = False
        return self._cache

    def _drive(self, steps: int, batch: tuple | None):
        """`Stepper.run`, once the driver can take over (`_to_driver`)."""
        self._to_driver()
        return self._stepper.run(self.state, steps, batch)

    def _to_driver(self) -> None:
        """Before a driver call: the carry handed over from the staged path when it was there,
        and the joints' kernels, which the driver's compile links, waited for."""
        if not self._carry_in_stepper:
            self._stepper.set_carry(self._cache)
            self._carry_in_stepper = True
        if _ahead.WAITING:
            _ahead.finish()

    def _driver_ready(self) -> bool:
        """Whether the next steps take the driver: there is one, and no helper is compiling it
        any more (tiered; a helper that failed leaves the driver to compile at its call)."""
        return self._stepper is not None and not self.compiling_driver

    @property
    def compiling_driver(self) -> bool:
        """Whether a helper process is compiling the driver (`tiered`) at this moment."""
        if self._compiling is not None and _ahead.exited(self._compiling):
            self._compiling = None
        return self._compiling is not None

    def finish_compiling(self, *, stop: bool = False) -> bool:
        """Wait for the helper compiling the driver (`tiered`), if it still runs, so that the
        next run finds the driver in numba's cache; stop: kill it instead (the driver is then
        compiled by a later run). Returns whether there was one still running."""
        if not self.compiling_driver:
            return False
        (_ahead.stop_helper if stop else _ahead.wait_helper)(self._compiling)
        self._compiling = None
        return True

    def stage_times(self) -> dict[str, float]:
        """Seconds spent in each stage of the step inside the timed driver (`profile=True`),
        over every call so far: geometry, broad phase, narrow phase, push-out, impulses,
        integration, and "driver" (its own bookkeeping: undo copies, carried contacts, the
        divergence check, batch rows); "total" is the whole of those calls, of which the
        stages are disjoint parts (the rest: the clock reads themselves). Zeros when not
        profiling or on the staged path."""
        if self._stepper is None:
            return dict.fromkeys((*STAGES, "total"), 0.0)
        return self._stepper.stage_seconds()

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
        self._check_state()
        s = self.state
        return StepRecord(
            step=s.step,
            time=s.step * self.scene.world.dt,
            position=s.position.copy(),
            angle=s.angle.copy(),
            velocity=s.velocity.copy(),
            angular_velocity=s.angular_velocity.copy(),
            exists=s.exists.copy(),
            contacts=self._contacts_now(),
            joints=self._joints,
        )

    def step(self) -> StepRecord:
        """Advance one step (dt seconds) and return the new state's record.

        Raises SimulationError (naming the step and body) if the state becomes NaN, infinite or
        absurdly large; the state before the failing step is what `record()` returned last.
        StateError if the state's arrays were replaced by ones that do not fit (`resume`).
        """
        if self._step_driver or self._step_takes_driver():
            return self._driven_step()
        return self._staged_step()

    @property
    def driver_cached(self) -> bool:
        """Whether the compiled driver is at hand without compiling it: loaded in this process
        or in numba's cache (what `step()` waits for before it takes the driver). A replay
        takes its steps a batch at a time only then, so that on a cold cache it never waits
        7-10 s for the driver (`replay.replayed`)."""
        return self._step_driver or self._step_takes_driver()

    def _step_takes_driver(self) -> bool:
        """Whether `step()` calls the driver for its one step: when the driver is ready and
        numba has it (loaded, or in its cache). While the driver is still to be compiled,
        `step()` keeps to the staged path, whose kernels are ready sooner
        (`isaac.engine.compile_ahead`): a program that only steps (a replay) does not wait
        7-10 s for the driver at its first step. The same bits either way."""
        if not self._driver_ready():
            return False
        kernel = self._stepper.kernel
        self._step_driver = bool(getattr(kernel, "signatures", ())) or not _ahead.is_cold(kernel)
        return self._step_driver

    def _driven_step(self) -> StepRecord:
        """One step in one driver call (one object crosses into compiled code: see
        `isaac.engine.driver_kit`); its record holds a slot's arrays, as `run`'s do."""
        self._to_driver()
        last, body, field = self._stepper.one_step(self.state)
        if last is None:
            self._fail(self.state.step + 1, body, field)
        self._rows_of(last)
        return last

    def _staged_step(self) -> StepRecord:
        self._check_state()
        if self._last is None:  # after advance(): what a failing step goes back to
            self._last = self.record()
        contacts, cache = step(
            self.model,
            self.settings,
            self.scene.world.dt,
            self.state,
            self._work,
            self._staged_cache(),
        )
        body, field = self._diverged()
        if body >= 0:
            failed = self.state.step
            self._restore(self._last)
            self._fail(failed, body, field)
        self._contacts, self._cache = contacts, cache
        self._rows_from = None
        self._joints = joint_rows(self.model, self.state, self._work)
        self._last = self.record()
        return self._last

    def _fail(self, failed: int, body: int, field: int) -> None:
        name = self.model.names[body]
        raise SimulationError(
            f"step {failed}: body {name!r} (index {body}) has a non-finite or diverged "
            f"{_FIELDS[field]}; the simulation stopped (try a smaller dt or more substeps)",
            step=failed,
            body=name,
        )

    def advance(self, steps: int) -> None:
        """Advance `steps` steps now, without making a record of each (the fastest path: one
        compiled call). Eager, unlike `run`: the steps are taken before it returns.
        `record()` afterwards gives the last state and its step's contacts. Raises
        SimulationError like `step()`, with the state left before the failing step.
        steps: an int >= 0 (`isaac.engine.counts.count`: TypeError or ValueError else)."""
        steps = count(steps, "steps")
        while steps > 0 and not self._driver_ready():
            self._staged_step()
            steps -= 1
        if steps <= 0:
            return
        taken, body, field, _ = self._drive(steps, None)
        if body >= 0:
            # advance keeps no contacts: the state is the one before the failing step
            if taken or self._contacts is None:
                self._contacts = Contacts.empty()
                self._joints = initial_joint_rows(self.model, self.state, self._work)
            self._last = self.record()
            self._fail(self.state.step + 1, body, field)
        # the last step's contacts (and joints) are computed again from its start if asked for
        # (record()): None marks both as not made yet
        self._contacts = None
        self._rows_from = None
        self._last = None

    def _rows_of(self, last: StepRecord) -> None:
        """Take a batch's record as the current state's: its rows are copied when first asked
        for (`_contacts_now`), not at every step (14 arrays: about 7 us)."""
        self._last = last
        self._contacts = None
        self._rows_from = last

    def _contacts_now(self) -> Contacts:
        """The contacts of the step that made the current state (and its joints, kept in
        self._joints)."""
        if self._contacts is None and self._rows_from is not None:
            self._keep_rows(self._rows_from.contacts, self._rows_from.joints)
        if self._contacts is None:
            batch = self._stepper.redo_last(self.state)
            if batch is None:
                self._contacts = Contacts.empty()
                self._joints = initial_joint_rows(self.model, self.state, self._work)
            else:
                made = StepBatch(self.state.step, self.scene.world.dt, batch, 1)
                self._keep_rows(made.contacts_of(0), made.joints_of(0))
        return self._contacts

    def _keep_rows(self, contacts: Contacts, joints: JointRows | None) -> None:
        """Keep private writable copies of a batch's rows as the current step's, like the staged
        step's: a record mixing writable state with a batch's read-only rows is typed apart by
        compiled consumers (all_finite raised a TypingError on it)."""
        self._rows_from = None
        self._contacts = Contacts(*(getattr(contacts, f).copy() for f in CONTACT_FIELDS))
        self._joints = (
            None
            if joints is None
            else JointRows(*(getattr(joints, f).copy() for f in JOINT_FIELDS))
        )

    def batches(self, steps: int | None = None, *, size: int = 64) -> Iterator[StepBatch]:
        """Advance `steps` steps (default: the scene's `world.steps`), `size` at a time, and
        yield each batch of their records (`StepBatch`: read-only arrays, one compiled call
        per batch). A diverging step ends the run with SimulationError after the batch of
        the steps before it was yielded. steps: an int >= 0, size: an int >= 1, checked at
        the call (`isaac.engine.counts.count`: TypeError or ValueError else); the steps are
        taken as the generator is iterated."""
        return self._batches(*self._counts(steps, size, "size"))

    def _counts(self, steps, size, name: str) -> tuple[int, int]:
        """(steps, batch size) of a `run` or `batches` call, checked."""
        steps = self.scene.world.steps if steps is None else count(steps, "steps")
        return steps, count(size, name, minimum=1)

    def _batches(self, left: int, size: int) -> Iterator[StepBatch]:
        while left > 0:
            k = min(size, left)
            left -= k
            yield from (self._driven_batch(k) if self._driver_ready() else self._staged_batch(k))

    def _driven_batch(self, k: int) -> Iterator[StepBatch]:
        """The next k steps' batch from one driver call (none when the first step fails)."""
        self._to_driver()
        batch, body, field = self._stepper.recorded(self.state, k)
        if batch is not None:
            self._rows_of(batch.record(batch.steps - 1))
            yield batch
        if body >= 0:
            self._fail(self.state.step + 1, body, field)

    def _staged_batch(self, k: int) -> Iterator[StepBatch]:
        """The next k steps' batch, a `step()` at a time (the same bits as the driver's)."""
        records, error = [], None
        for _ in range(k):
            try:
                records.append(self._staged_step())
            except SimulationError as exc:
                error = exc
                break
        if records:
            yield StepBatch.of_records(records, self.scene.world.dt)
        if error is not None:
            raise error

    def _diverged(self) -> tuple[int, int]:
        """(body, index into _FIELDS) of the first body whose state is non-finite or beyond the
        DIVERGED_* bounds, or (-1, -1)."""
        return diverged_body(self.state)

    def run(self, steps: int | None = None, *, batch: int = 16) -> Iterator[StepRecord]:
        """A generator of the records of the next `steps` steps (default: the scene's
        `world.steps`), computed `batch` steps per compiled call. (16: a batch of pile-100's
        records, about 35 KB a step, then stays in the cache while its steps are written and
        read: 70.6 against 73.0 us a step with 64; on 2 bodies a batch's own cost, about 3 us,
        is still a fraction of a microsecond a step.)

        Lazy: calling `run(n)` computes nothing; the steps are taken as the generator is
        iterated (`for record in sim.run(n)`, `list(sim.run(n))`). A `sim.run(n)` that is
        never iterated leaves the simulation where it was: to advance without records, call
        `advance(n)`, which takes the steps at once.

        The simulation runs ahead of what has been taken from the generator by up to
        `batch - 1` steps: stopping early leaves it past the last record taken. `step()` takes
        one step at a time; `resume(record)` goes back to any record, bit for bit.

        steps: an int >= 0, batch: an int >= 1, checked at the call, before iteration
        (`isaac.engine.counts.count`: TypeError or ValueError else)."""
        return self._records(self._batches(*self._counts(steps, batch, "batch")))

    @staticmethod
    def _records(batches: Iterator[StepBatch]) -> Iterator[StepRecord]:
        for chunk in batches:
            for s in range(chunk.steps):
                yield _BatchRecord.of(chunk, s)  # (s is a place of the batch: unchecked)

    def detect(self) -> Contacts:
        """The contacts at the current pose (broad and narrow phase only; nothing moves).

        Push vectors, impulses and restitution are zero: they exist only once a step resolves
        the contacts.
        """
        self._check_state()
        # the last step's contacts as they are, wherever they are: detect only reads them
        # (taking them out of the driver, and back at the next step, cost pile-100 15 us)
        if self._carry_in_stepper:
            cache = ContactCache(*self._stepper.cache_arrays(copy=False))
        else:
            cache = self._staged_cache()
        rows = detect(self.model, self.settings, self.state, self._work, cache)
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
        """Go back to a record this simulation made (trusted: not checked again)."""
        self.state = State(
            int(record.step),
            np.array(record.position, dtype=np.float64),
            np.array(record.angle, dtype=np.float64),
            np.array(record.velocity, dtype=np.float64),
            np.array(record.angular_velocity, dtype=np.float64),
            np.array(record.exists, dtype=bool),
        )
        self._state_checked()

    # ---- world queries (isaac.engine.queries): the current state, read without stepping -----
    # Units: m, world frame; a ray is origin + t * direction, t in [0, max_fraction] (direction
    # not normalised). filter: None (every existing body) or an
    # isaac.engine.queries.QueryFilter (the collision filter's rule). Bodies that do not exist
    # now are never reported. Bad input: TypeError or ValueError naming the argument.

    def ray_cast(self, origin, direction, max_fraction=1.0, filter=None):
        """The first shape the ray enters: an `isaac.engine.queries.RayHit` (hit, body, name,
        point (m, world), unit outward normal (world), fraction). A ray starting inside a
        shape does not hit it (Box2D's rule); ties go to the lowest body index."""
        from isaac.engine import queries

        self._check_state()
        return queries.ray_cast(self.model, self.state, origin, direction, max_fraction, filter)

    def ray_cast_many(self, origins, directions, max_fraction=1.0, filter=None):
        """`ray_cast` of m rays at once (origins, directions: (m, 2) m; max_fraction a number
        or (m,)): an `isaac.engine.queries.RayHits` of arrays, row k for ray k."""
        from isaac.engine import queries

        self._check_state()
        return queries.ray_cast_many(
            self.model, self.state, origins, directions, max_fraction, filter
        )

    def query_box(self, lo, hi, filter=None) -> np.ndarray:
        """Sorted indices of the bodies whose world AABB overlaps the box [lo, hi] ((x, y) m,
        world; touching counts): boxes only, as Box2D's b2World_OverlapAABB (exact: `overlaps`)."""
        from isaac.engine import queries

        self._check_state()
        return queries.query_box(self.model, self.state, lo, hi, filter)

    def overlaps(self, shape, pose, filter=None) -> np.ndarray:
        """Sorted indices of the bodies whose shape overlaps (or touches) `shape`, a circle's
        radius (m) or a convex polygon's (x, y) vertices (m, its own frame), placed at pose
        (x, y) or (x, y, angle) (m, world; rad)."""
        from isaac.engine import queries

        self._check_state()
        return queries.overlaps(self.model, self.state, shape, pose, filter)

    def closest(self, point, filter=None):
        """The body nearest to `point` ((x, y) m, world): an `isaac.engine.queries.Closest`
        (found, body, name, its nearest point (m, world), distance (m), 0 inside)."""
        from isaac.engine import queries

        self._check_state()
        return queries.closest(self.model, self.state, point, filter)


@dataclass(frozen=True, repr=False)
class BodyView:
    """A thin window onto one body of a simulation (SI units, world frame)."""

    sim: Simulation
    index: int

    def __repr__(self) -> str:
        s = self.sim.state
        i = self.index
        kind = "concrete" if self.sim.model.concrete[i] else f"{self.mass:.6g} kg"
        return (
            f"<BodyView {self.name!r} (index {i}, {kind}) at step {s.step}: "
            f"position ({s.position[i, 0]:.6g}, {s.position[i, 1]:.6g}) m, "
            f"angle {s.angle[i]:.6g} rad, velocity ({s.velocity[i, 0]:.6g}, "
            f"{s.velocity[i, 1]:.6g}) m/s, angular velocity {s.angular_velocity[i]:.6g} rad/s"
            f"{'' if s.exists[i] else ', not in the scene'}>"
        )

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
