"""Running one grid point: sampled states, per-step checks (penetration, tunneling) and timed
runs."""

from __future__ import annotations

import gc
import math
import time
from dataclasses import dataclass, field

import numpy as np

from isaac.engine.records import Contacts, StepRecord
from isaac.errors import SimulationError
from isaac.scene import Scene


@dataclass
class Trajectory:
    """A run sampled at common times.

    times: (S,) s. position, velocity: (S, n, 2) world (m, m/s). angle, angular_velocity: (S, n).
    exists: (S, n) bool. max_depth: largest penetration (m) any contact had during the run.
    max_joint_error: the largest position error (m) a joint was left with after a step's
    position pass (`JointRows.error`, column 0), 0 without joints. tunneled: names of bodies
    whose centre crossed a concrete body that could have stopped it (`_Obstacles`). error: why
    it stopped early (a SimulationError message), else None.
    """

    times: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    angle: np.ndarray
    angular_velocity: np.ndarray
    exists: np.ndarray
    max_depth: float = 0.0
    max_joint_error: float = 0.0
    tunneled: list[str] = field(default_factory=list)
    error: str | None = None

    def record(self, k: int) -> StepRecord:
        return StepRecord(
            step=k,
            time=float(self.times[k]),
            position=self.position[k],
            angle=self.angle[k],
            velocity=self.velocity[k],
            angular_velocity=self.angular_velocity[k],
            exists=self.exists[k],
            contacts=Contacts.empty(),
        )


def _concrete_planes(model, state) -> list[tuple[np.ndarray, np.ndarray]]:
    """(normals (k, 2), offsets (k,)) of the edges of each concrete polygon in the world frame
    (concrete circles: `_concrete_discs`)."""
    planes = []
    for i in np.flatnonzero(model.concrete & (model.vertex_count > 1)):
        k = int(model.vertex_count[i])
        c, s = math.cos(state.angle[i]), math.sin(state.angle[i])
        rot = np.array([[c, -s], [s, c]])
        verts = model.vertices_local[i, :k] @ rot.T + state.position[i]
        normals = model.normals_local[i, :k] @ rot.T
        planes.append((normals, np.einsum("ij,ij->i", normals, verts)))
    return planes


def _concrete_discs(model, state) -> list[tuple[np.ndarray, float]]:
    """(centre (2,) m, radius m) of each concrete circle."""
    return [
        (state.position[i].copy(), float(model.radius[i]))
        for i in np.flatnonzero(model.concrete & (model.vertex_count == 1))
    ]


def _crossed_concrete(planes, p0: np.ndarray, p1: np.ndarray, discs=()) -> np.ndarray:
    """(m,) bool: the segment p0 -> p1 of each body's centre meets some concrete polygon or
    disc.

    Cyrus-Beck clipping of the segment against each convex polygon (inside: n . x <= d on
    every edge); for a disc, the segment's closest point to its centre within its radius. A
    body resting on a concrete body never has its centre inside it, so a hit means the body
    went (at least half) through.
    """
    hit = np.zeros(p0.shape[0], dtype=bool)
    d = p1 - p0
    for normals, offsets in planes:
        t_in = np.zeros(p0.shape[0])
        t_out = np.ones(p0.shape[0])
        outside = np.zeros(p0.shape[0], dtype=bool)
        for n, off in zip(normals, offsets):
            num = off - p0 @ n
            den = d @ n
            with np.errstate(divide="ignore", invalid="ignore"):
                t = num / den
            outside |= (den == 0.0) & (num < 0.0)
            t_in = np.where(den < 0.0, np.maximum(t_in, t), t_in)
            t_out = np.where(den > 0.0, np.minimum(t_out, t), t_out)
        hit |= ~outside & (t_in <= t_out)
    length2 = np.einsum("ij,ij->i", d, d)
    for centre, r in discs:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.clip(np.einsum("ij,ij->i", centre - p0, d) / length2, 0.0, 1.0)
        t = np.where(length2 > 0.0, t, 0.0)
        closest = p0 + t[:, None] * d - centre
        hit |= np.einsum("ij,ij->i", closest, closest) < r * r
    return hit


def _kept_apart(model, c: int) -> np.ndarray | None:
    """The bodies the broad phase never pairs with concrete body `c` (sorted indices; None
    when there are none): those the collision filter keeps from it
    (`isaac.collision_filter.collides`) and those a joint connects to it without
    `collide_connected` (`model.no_collide`, the broad phase's own keys). A path through `c`
    of one of them is no tunnel: nothing was there to stop it (a blade on an axle through a
    concrete hub, a body whose mask leaves out a concrete ledge)."""
    from isaac.collision_filter import collides

    if not model.filtered:  # every filter the default, no joint keeps a pair apart
        return None
    n = model.n_bodies
    others = np.arange(n)
    ok = collides(
        model.category[c], model.mask[c], model.group[c], model.category, model.mask, model.group
    )
    if model.no_collide.size:
        keys = np.minimum(others, c) * n + np.maximum(others, c)
        ok &= ~np.isin(keys, model.no_collide)
    ok[c] = True  # itself: not a moving body
    apart = np.flatnonzero(~ok)
    return apart if apart.size else None


def _concrete_comes_and_goes(model) -> bool:
    """Whether some concrete body enters after time 0 or leaves (`enters_at`, `leaves_at`): a
    path then crosses it only in the steps it exists at both ends of, as the broad phase pairs
    no absent body."""
    if not model.timed:
        return False
    timed = (model.enters_at > 0.0) | np.isfinite(model.leaves_at)
    return bool(np.any(timed & model.concrete))


class _Obstacles:
    """The concrete bodies a centre's path is clipped against, each with the moving bodies it
    could have stopped (`_kept_apart`, `_concrete_comes_and_goes`: the rule the sweep's
    `tunneled` metric applies too). Concrete bodies never move: built from the first state."""

    def __init__(self, model, state) -> None:
        self.planes = _concrete_planes(model, state)
        self.discs = _concrete_discs(model, state)
        polygons = np.flatnonzero(model.concrete & (model.vertex_count > 1))
        circles = np.flatnonzero(model.concrete & (model.vertex_count == 1))
        # one (planes, discs) per concrete body, and its index
        self.each = [([p], []) for p in self.planes] + [([], [d]) for d in self.discs]
        self.bodies = np.concatenate([polygons, circles])
        self.timed = _concrete_comes_and_goes(model)
        self.may_hit = []  # (n,) bool per concrete body: the bodies it could have stopped
        for c in self.bodies:
            may = np.ones(model.n_bodies, dtype=bool)
            apart = _kept_apart(model, int(c))
            if apart is not None:
                may[apart] = False
            self.may_hit.append(None if apart is None else may)
        self.pairwise = self.timed or any(m is not None for m in self.may_hit)

    def crossed(self, p0, p1, e0, e1) -> np.ndarray:
        """(n,) bool: body i's centre went from p0[i] to p1[i] (m, world) through a concrete
        body that could have stopped it, one existing at both ends of the step (e0, e1: (n,)
        existence before and after)."""
        if not self.pairwise:  # every pair may collide: one call
            return _crossed_concrete(self.planes, p0, p1, self.discs)
        hit = np.zeros(p0.shape[0], dtype=bool)
        for (planes, discs), c, may in zip(self.each, self.bodies, self.may_hit):
            if self.timed and not (e0[c] and e1[c]):
                continue
            crossed = _crossed_concrete(planes, p0, p1, discs)
            hit |= crossed if may is None else crossed & may
        return hit

    def __bool__(self) -> bool:
        return bool(self.each)


def sample_times(duration: float, sample_dt: float) -> np.ndarray:
    """0, sample_dt, 2 sample_dt, ... up to `duration` (s)."""
    count = math.floor(duration / sample_dt + 1e-9)
    return np.arange(count + 1) * sample_dt


def simulate(scene: Scene, times: np.ndarray, *, check: bool = True) -> Trajectory:
    """Run `scene` for `scene.world.steps` steps; sample the state at `times` (linear
    interpolation between the two steps around a time that is not a multiple of dt).

    With `check`, also tracks the largest contact depth, the largest joint error and tunneling
    through the concrete bodies that could have stopped each body (`_Obstacles`: not one the
    collision filter or a joint keeps from it, nor one absent at either end of the step).
    A SimulationError ends the run: samples after it are NaN and `error` says why.
    """
    from isaac.engine.simulation import Simulation

    sim = Simulation(scene)
    dt = scene.world.dt
    n, s_count = sim.n_bodies, times.shape[0]
    out = Trajectory(
        times=times,
        position=np.full((s_count, n, 2), np.nan),
        velocity=np.full((s_count, n, 2), np.nan),
        angle=np.full((s_count, n), np.nan),
        angular_velocity=np.full((s_count, n), np.nan),
        exists=np.zeros((s_count, n), dtype=bool),
    )
    # sample k lies between steps lo[k] and lo[k] + 1, at fraction frac[k]
    where = times / dt
    lo = np.floor(where + 1e-9).astype(np.int64)
    frac = np.clip(where - lo, 0.0, 1.0)
    frac[np.abs(frac) < 1e-9] = 0.0
    obstacles = _Obstacles(sim.model, sim.state) if check else None
    movable = ~sim.model.concrete
    tunneled = np.zeros(n, dtype=bool)
    prev = sim.record()
    k = 0

    def take(rec_lo: StepRecord, rec_hi: StepRecord | None, f: float, j: int) -> None:
        if rec_hi is None or f == 0.0:
            rec_hi, f = rec_lo, 0.0
        out.position[j] = (1.0 - f) * rec_lo.position + f * rec_hi.position
        out.velocity[j] = (1.0 - f) * rec_lo.velocity + f * rec_hi.velocity
        out.angle[j] = rec_lo.angle if f < 0.5 else rec_hi.angle
        out.angular_velocity[j] = (1.0 - f) * rec_lo.angular_velocity + f * rec_hi.angular_velocity
        out.exists[j] = rec_lo.exists & rec_hi.exists

    while k < s_count and lo[k] == 0 and frac[k] == 0.0:
        take(prev, None, 0.0, k)
        k += 1
    try:
        for step_index in range(1, scene.world.steps + 1):
            rec = sim.step()
            if check:
                if len(rec.contacts):
                    out.max_depth = max(out.max_depth, float(rec.contacts.depth.max()))
                if rec.joints is not None and len(rec.joints.error):
                    worst = float(rec.joints.error[:, 0].max())
                    out.max_joint_error = max(out.max_joint_error, worst)
                if obstacles:
                    alive = movable & rec.exists & prev.exists
                    tunneled |= alive & obstacles.crossed(
                        prev.position, rec.position, prev.exists, rec.exists
                    )
            while k < s_count and lo[k] <= step_index:
                if lo[k] == step_index:
                    if frac[k] == 0.0:
                        take(rec, None, 0.0, k)
                    else:
                        break  # needs the next step too
                else:  # lo[k] == step_index - 1
                    take(prev, rec, float(frac[k]), k)
                k += 1
            prev = rec
    except SimulationError as exc:
        out.error = str(exc)
    out.tunneled = [sim.model.names[i] for i in np.flatnonzero(tunneled)]
    return out


def time_run(scene: Scene) -> float:
    """Wall-clock seconds of `scene.world.steps` steps (Simulation built before the clock
    starts, garbage collector paused); inf if the run stops with a SimulationError."""
    from isaac.engine.simulation import Simulation

    sim = Simulation(scene)
    collecting = gc.isenabled()
    gc.disable()
    start = time.perf_counter()
    try:
        for _ in range(scene.world.steps):
            sim.step()
    except SimulationError:
        return math.inf
    finally:
        if collecting:
            gc.enable()
    return time.perf_counter() - start


MIN_TIMED_SECONDS = 0.5  # short runs are repeated until this much was timed (timer noise)
MAX_TIMED_RUNS = 50


def time_runs(scene: Scene, repeats: int, min_seconds: float = MIN_TIMED_SECONDS) -> list[float]:
    """At least `repeats` timed runs, more (up to MAX_TIMED_RUNS) while under `min_seconds`
    in total: seconds per run."""
    costs: list[float] = []
    while len(costs) < repeats or (sum(costs) < min_seconds and len(costs) < MAX_TIMED_RUNS):
        costs.append(time_run(scene))
        if not math.isfinite(costs[-1]):
            break
    return costs


def warm_up(scene: Scene) -> None:
    """One step, so the kernels this setting uses are compiled (or loaded) before timing."""
    from isaac.engine.simulation import Simulation

    try:
        Simulation(scene).step()
    except SimulationError:
        pass
