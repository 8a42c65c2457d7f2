"""`isaac tradeoff SCENE.yaml`: what each fidelity setting buys (error) and costs (time).

Outline:

1. grid       the settings to compare: presets x dt values by default (`--grid KEY=V1,V2 ...` for
              any other axes); every point is the scene with those world settings.
2. reference  the `accurate` preset at a small dt (default: the scene's dt / 8), or the closed
              form for scenes it knows how to solve (`--reference analytic`: a lone body in free
              flight, a body dropped flat on level concrete ground, a 1D head-on hit).
3. measure    each point once with per-step checks (samples, penetration, tunneling), then
              `repeats` timed runs without them; cost is the median of the timed runs, measured
              after a warm-up step has compiled (or loaded) the kernels.
4. compare    at common times (multiples of the coarsest dt), so runs of different dt are
              compared where they all have a state: position RMS over bodies and sample times,
              energy drift and error, centre-of-mass error, momentum error, max penetration,
              tunneling through concrete bodies.
5. report     a table on stdout, a CSV and a PNG of error against cost with the Pareto front.

Cost is given per step (ms/step, steps/s) and per simulated second (ms/sim-s, the fair axis when
dt differs: halving dt doubles the steps). For chaotic scenes (a pile) the position RMS is
dominated by chaos, not by accuracy: two equally good runs diverge body by body. The columns
that stay meaningful there are energy, penetration, the centre of mass (settled height) and
tunneling (docs/tradeoff.md).

matplotlib is imported only when a plot is written; the engine never imports this module.
"""

from __future__ import annotations

import argparse
import csv
import gc
import itertools
import math
import statistics
import sys
import time
from dataclasses import dataclass, field, fields, replace
from fractions import Fraction
from pathlib import Path

import numpy as np

from isaac.engine import diagnostics
from isaac.engine.records import Contacts, StepRecord
from isaac.errors import IsaacError, SceneError, SimulationError
from isaac.scene import PRESETS, Scene, WorldSettings, load_scene, load_scene_text

PRESET_ORDER = ("seed", "fast", "balanced", "accurate")
DEFAULT_DT_FACTORS = (2.0, 1.0, 0.5)  # the default dt axis: the scene's dt times these
REFERENCE_DT_DIVISOR = 8  # default reference: `accurate` at the scene's dt / 8
# world settings a grid axis may vary (dt and preset are axes too)
SETTING_KEYS = tuple(
    f.name for f in fields(WorldSettings) if f.name not in ("gravity", "dt", "steps", "fidelity")
)
# a body "tunneled" when its centre's path crossed a concrete body (see `_crossed_concrete`)


class TradeoffError(IsaacError):
    """Bad `isaac tradeoff` arguments (grid, reference) for this scene."""


# --- grid -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class GridPoint:
    """One setting of the grid: a label, the dt (s) and the world-setting overrides."""

    label: str
    dt: float
    overrides: tuple[tuple[str, object], ...] = ()

    def world(self, base: WorldSettings, duration: float) -> WorldSettings:
        """The base world with this point's settings: a preset's settings replace the scene's
        fidelity settings; other overrides come after; gravity, friction and rules stay."""
        values: dict[str, object] = {}
        for key, value in self.overrides:
            if key == "preset":
                values.update(PRESETS[str(value)])
                values["fidelity"] = value
            else:
                values[key] = value
        steps = max(1, math.ceil(duration / self.dt - 1e-9))
        return replace(base, dt=self.dt, steps=steps, **values)


def parse_dt(text: str, scene_dt: float) -> float:
    """A dt value: seconds ("0.01", "1e-3"), a fraction ("1/60"), or a multiple of the scene's
    dt ("x2", "x1/2")."""
    text = text.strip()
    try:
        if text.startswith("x"):
            value = float(Fraction(text[1:])) * scene_dt
        else:
            value = float(Fraction(text)) if "/" in text else float(text)
    except (ValueError, ZeroDivisionError):
        raise TradeoffError(
            f"--grid dt: cannot read {text!r} as a time step (use 0.01, 1/60 or "
            f"x2 for twice the scene's dt)"
        ) from None
    if not (0.0 < value <= 1.0):
        raise TradeoffError(f"--grid dt: {text!r} = {value!r} s is out of range (0, 1]")
    return value


def _check_setting(key: str, raw: str):
    """Read and validate one world-setting value through the scene loader (same rules and
    messages as a scene file)."""
    try:
        scene = load_scene_text(
            f"world: {{{key}: {raw}}}\nbodies: [{{shape: {{box: [1, 1]}}}}]", source=f"--grid {key}"
        )
    except SceneError as exc:
        raise TradeoffError(str(exc)) from None
    return getattr(scene.world, key)


def parse_grid(specs: list[str] | None, scene_dt: float) -> list[GridPoint]:
    """Grid points from `--grid KEY=V1,V2` specs (the product of the axes).

    Keys: `preset` (seed, fast, balanced, accurate), `dt` (see `parse_dt`) and any world
    setting (`iterations=4,10,20`, `ccd=off,speculative`, ...). Without a `dt` axis the dt
    values are the scene's dt times 2, 1 and 1/2. Without any preset or setting axis the presets
    are the axis; with setting axes but no preset the scene's own settings are the base.
    """
    axes: dict[str, list] = {}
    for spec in specs or []:
        for part in spec.split(";"):
            part = part.strip()
            if not part:
                continue
            key, sep, values = part.partition("=")
            key = key.strip()
            if not sep or not values.strip():
                raise TradeoffError(f"--grid: expected KEY=V1,V2,..., got {part!r}")
            if key in axes:
                raise TradeoffError(f"--grid: axis {key!r} given twice")
            items = [v.strip() for v in values.split(",") if v.strip()]
            if key == "preset":
                for v in items:
                    if v not in PRESETS:
                        raise TradeoffError(
                            f"--grid preset: unknown preset {v!r} "
                            f"(valid: {', '.join(PRESET_ORDER)})"
                        )
                axes[key] = items
            elif key == "dt":
                axes[key] = [parse_dt(v, scene_dt) for v in items]
            elif key in SETTING_KEYS:
                axes[key] = [_check_setting(key, v) for v in items]
            else:
                valid = ", ".join(("preset", "dt") + SETTING_KEYS)
                raise TradeoffError(f"--grid: unknown axis {key!r} (valid: {valid})")
    if "dt" not in axes:
        axes["dt"] = [scene_dt * f for f in DEFAULT_DT_FACTORS]
    if len(axes) == 1:
        axes["preset"] = list(PRESET_ORDER)
    keys = [k for k in axes if k != "dt"]
    points = []
    for combo in itertools.product(*(axes[k] for k in keys)):
        overrides = tuple(zip(keys, combo))
        label = " ".join(str(v) if k == "preset" else f"{k}={v}" for k, v in overrides)
        for dt in axes["dt"]:
            points.append(GridPoint(label=label or "scene", dt=float(dt), overrides=overrides))
    return points


# --- trajectories ---------------------------------------------------------------------------


@dataclass
class Trajectory:
    """A run sampled at common times.

    times: (S,) s. position, velocity: (S, n, 2) world (m, m/s). angle, angular_velocity: (S, n).
    exists: (S, n) bool. max_depth: largest penetration (m) any contact had during the run.
    tunneled: names of bodies whose centre crossed a concrete body. error: why it stopped early
    (a SimulationError message), else None.
    """

    times: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    angle: np.ndarray
    angular_velocity: np.ndarray
    exists: np.ndarray
    max_depth: float = 0.0
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
    """(normals (k, 2), offsets (k,)) of the edges of each concrete body in the world frame."""
    planes = []
    for i in np.flatnonzero(model.concrete):
        k = int(model.vertex_count[i])
        c, s = math.cos(state.angle[i]), math.sin(state.angle[i])
        rot = np.array([[c, -s], [s, c]])
        verts = model.vertices_local[i, :k] @ rot.T + state.position[i]
        normals = model.normals_local[i, :k] @ rot.T
        planes.append((normals, np.einsum("ij,ij->i", normals, verts)))
    return planes


def _crossed_concrete(planes, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """(m,) bool: the segment p0 -> p1 of each body's centre meets some concrete polygon.

    Cyrus-Beck clipping of the segment against each convex polygon (inside: n . x <= d on
    every edge). A body resting on a concrete body never has its centre inside it, so a hit
    means the body went (at least half) through.
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
    return hit


def sample_times(duration: float, sample_dt: float) -> np.ndarray:
    """0, sample_dt, 2 sample_dt, ... up to `duration` (s)."""
    count = math.floor(duration / sample_dt + 1e-9)
    return np.arange(count + 1) * sample_dt


def simulate(scene: Scene, times: np.ndarray, *, check: bool = True) -> Trajectory:
    """Run `scene` for `scene.world.steps` steps; sample the state at `times` (linear
    interpolation between the two steps around a time that is not a multiple of dt).

    With `check`, also tracks the largest contact depth and tunneling through concrete bodies.
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
    planes = _concrete_planes(sim.model, sim.state) if check else []
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
                if planes:
                    alive = movable & rec.exists & prev.exists
                    crossed = _crossed_concrete(planes, prev.position, rec.position) & alive
                    tunneled |= crossed
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


# --- the analytic reference -----------------------------------------------------------------


def _world_vertices(body) -> np.ndarray:
    """Vertices (m, world) of a body at its starting pose, about its centroid."""
    from isaac.scene import polygon

    raw = np.asarray(body.vertices, dtype=np.float64)
    _, centroid, _ = polygon.mass_properties(raw)
    c, s = math.cos(body.angle), math.sin(body.angle)
    local = raw - centroid
    return np.column_stack(
        (c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1])
    ) + np.asarray(body.position)


def _combine(rule: str, x: float, y: float) -> float:
    return {"max": max(x, y), "min": min(x, y), "mean": 0.5 * (x + y), "product": x * y}[rule]


def _flat_extreme(
    verts: np.ndarray, axis: int, top: bool, tol: float
) -> tuple[float, float, float] | None:
    """The extreme coordinate along `axis` if it is taken by a whole edge (two or more vertices
    within `tol`): (coordinate, low, high) of that edge's extent along the other axis."""
    coord = verts[:, axis]
    extreme = coord.max() if top else coord.min()
    on = np.abs(coord - extreme) <= tol
    if on.sum() < 2:
        return None
    other = verts[on, 1 - axis]
    return float(extreme), float(other.min()), float(other.max())


ANALYTIC_MODELS = ("ballistic", "drop", "head_on")


def analytic_model(scene: Scene) -> str | None:
    """Which closed form solves `scene`, or None: "ballistic" (one body, nothing to hit),
    "drop" (one body falling flat, without spin, onto level concrete ground under vertical
    gravity) or "head_on" (two bodies, no gravity, moving along x, faces vertical and centred on
    the same line). Detected from the bodies; a scene may also name it (`analytic: {model: ...}`).
    """
    declared = (scene.analytic or {}).get("model") if scene.analytic else None
    w = scene.world
    bodies = scene.bodies
    if any(b.enters_at > 0.0 or b.leaves_at is not None for b in bodies):
        return None
    moving = [b for b in bodies if not b.concrete]
    fixed = [b for b in bodies if b.concrete]
    found = None
    if len(moving) == 1 and not fixed:
        found = "ballistic"
    elif len(moving) == 1 and len(fixed) == 1 and w.gravity[0] == 0.0 and w.gravity[1] < 0.0:
        body, ground = moving[0], fixed[0]
        vb, vg = _world_vertices(body), _world_vertices(ground)
        tol = 1e-9 * (1.0 + float(np.abs(vb).max()))
        bottom = _flat_extreme(vb, 1, False, tol)
        top = _flat_extreme(vg, 1, True, tol)
        if (
            bottom
            and top
            and body.angular_velocity == 0.0
            and bottom[0] >= top[0] - tol
            and (body.velocity[0] == 0.0 or not w.friction)
        ):
            # the flat bottom must stay over the flat top for the whole run
            t_end = w.steps * w.dt
            shift = body.velocity[0] * t_end
            lo, hi = bottom[1] + min(0.0, shift), bottom[2] + max(0.0, shift)
            if lo >= top[1] and hi <= top[2]:
                found = "drop"
    elif len(moving) == 2 and not fixed and w.gravity == (0.0, 0.0):
        a, b = sorted(moving, key=lambda x: x.position[0])
        va, vb = _world_vertices(a), _world_vertices(b)
        tol = 1e-9 * (1.0 + float(max(np.abs(va).max(), np.abs(vb).max())))
        face_a, face_b = _flat_extreme(va, 0, True, tol), _flat_extreme(vb, 0, False, tol)
        if (
            face_a
            and face_b
            and a.velocity[1] == 0.0
            and b.velocity[1] == 0.0
            and a.angular_velocity == 0.0
            and b.angular_velocity == 0.0
            and abs(a.position[1] - b.position[1]) <= tol
            and abs(face_a[1] + face_a[2] - 2 * a.position[1]) <= tol
            and abs(face_b[1] + face_b[2] - 2 * b.position[1]) <= tol
            and face_a[0] <= face_b[0] + tol
        ):
            found = "head_on"
    if declared is not None and declared != found:
        seen = "no known closed form" if found is None else f"the closed form {found!r}"
        raise TradeoffError(
            f"the scene declares analytic model {declared!r} but its bodies fit "
            f"{seen} (known: {', '.join(ANALYTIC_MODELS)})"
        )
    return found


def analytic_trajectory(scene: Scene, times: np.ndarray) -> Trajectory:
    """The closed-form motion of an `analytic_model` scene at `times` (s)."""
    kind = analytic_model(scene)
    if kind is None:
        raise TradeoffError(
            "--reference analytic: no closed form known for this scene (known: "
            "a lone body in flight, a flat drop on level concrete ground, a "
            "1D head-on hit of two bodies without gravity)"
        )
    from isaac.engine.world import build_model

    model = build_model(scene)
    w = scene.world
    n, s_count = len(scene.bodies), times.shape[0]
    pos = np.zeros((s_count, n, 2))
    vel = np.zeros((s_count, n, 2))
    ang = np.zeros((s_count, n))
    angvel = np.zeros((s_count, n))
    g = np.asarray(w.gravity, dtype=np.float64)
    for i, b in enumerate(scene.bodies):
        pos[:, i] = b.position
        ang[:, i] = b.angle
        if b.concrete:
            continue
        # free flight: x = x0 + v0 t + g t^2 / 2, angle = angle0 + w t
        pos[:, i] = (
            np.asarray(b.position) + np.outer(times, b.velocity) + 0.5 * np.outer(times * times, g)
        )
        vel[:, i] = np.asarray(b.velocity) + np.outer(times, g)
        ang[:, i] = b.angle + b.angular_velocity * times
        angvel[:, i] = b.angular_velocity
    if kind == "drop":
        i = next(k for k, b in enumerate(scene.bodies) if not b.concrete)
        ground = next(b for b in scene.bodies if b.concrete)
        body = scene.bodies[i]
        e = _combine(w.restitution_rule, body.restitution, ground.restitution)
        gy = -w.gravity[1]
        rest_y = body.position[1] - (
            _world_vertices(body)[:, 1].min() - _world_vertices(ground)[:, 1].max()
        )
        pos[:, i, 1], vel[:, i, 1] = _bounce_y(
            body.position[1], body.velocity[1], rest_y, gy, e, w.restitution_threshold, times
        )
    elif kind == "head_on":
        ia, ib = sorted(
            (k for k, b in enumerate(scene.bodies) if not b.concrete),
            key=lambda k: scene.bodies[k].position[0],
        )
        a, b = scene.bodies[ia], scene.bodies[ib]
        gap = _world_vertices(b)[:, 0].min() - _world_vertices(a)[:, 0].max()
        closing = a.velocity[0] - b.velocity[0]
        if closing > 0.0:
            t_hit = max(gap, 0.0) / closing
            e = _combine(w.restitution_rule, a.restitution, b.restitution)
            if closing < w.restitution_threshold:
                e = 0.0
            ma, mb = float(model.mass[ia]), float(model.mass[ib])
            p = ma * a.velocity[0] + mb * b.velocity[0]
            # 1D impact with restitution e: momentum kept, separation speed = e * closing speed
            va2 = (p - mb * e * closing) / (ma + mb)
            vb2 = (p + ma * e * closing) / (ma + mb)
            after = times > t_hit
            for k, v2 in ((ia, va2), (ib, vb2)):
                x_hit = scene.bodies[k].position[0] + scene.bodies[k].velocity[0] * t_hit
                pos[after, k, 0] = x_hit + v2 * (times[after] - t_hit)
                vel[after, k, 0] = v2
    exists = np.ones((s_count, n), dtype=bool)
    return Trajectory(
        times=times, position=pos, velocity=vel, angle=ang, angular_velocity=angvel, exists=exists
    )


def _bounce_y(
    y0: float, v0: float, rest_y: float, g: float, e: float, threshold: float, times: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Height and vertical velocity of a body bouncing on a floor: free fall under g (m/s^2,
    downward) until the centre reaches `rest_y`, then the speed is reversed and scaled by e
    (zero when the impact speed is below `threshold`); at rest once a bounce is too small."""
    y = np.full(times.shape, rest_y)
    v = np.zeros(times.shape)
    t0, h, u = 0.0, y0 - rest_y, v0  # flight start time, height above rest, upward speed
    while True:
        # h + u t - g t^2 / 2 = 0, positive root
        t_fly = (u + math.sqrt(u * u + 2.0 * g * max(h, 0.0))) / g
        in_flight = (times >= t0) & (times <= t0 + t_fly)
        tau = times[in_flight] - t0
        y[in_flight] = rest_y + h + u * tau - 0.5 * g * tau * tau
        v[in_flight] = u - g * tau
        impact = g * t_fly - u  # downward speed at impact
        t0 += t_fly
        if impact < threshold or e == 0.0 or e * impact < 1e-9 or t0 > times[-1]:
            break
        h, u = 0.0, e * impact
    return y, v


# --- metrics --------------------------------------------------------------------------------


def _series(scene: Scene, model, traj: Trajectory) -> dict[str, np.ndarray]:
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


# --- the whole measurement ------------------------------------------------------------------

COLUMNS = (
    "setting",
    "dt",
    "ms_per_step",
    "steps_per_s",
    "ms_per_sim_s",
    "rms_error_m",
    "max_error_m",
    "energy_drift",
    "energy_error",
    "com_error_m",
    "momentum_error_mps",
    "max_penetration_m",
    "tunneled",
    "diverged",
    "pareto",
)


@dataclass
class TradeoffResult:
    """Rows (dicts keyed by COLUMNS) for the grid points, plus the reference row."""

    scene: str
    reference: str  # "analytic (drop)" or "accurate, dt=..."
    duration: float
    sample_dt: float
    rows: list[dict]
    reference_row: dict


def _pareto(points: list[tuple[float, float]]) -> list[bool]:
    """Which (cost, error) points no other point beats in both (lower is better)."""
    marks = []
    for i, (c, e) in enumerate(points):
        if not (math.isfinite(c) and math.isfinite(e)):
            marks.append(False)
            continue
        dominated = any(
            j != i
            and math.isfinite(c2)
            and math.isfinite(e2)
            and c2 <= c
            and e2 <= e
            and (c2 < c or e2 < e)
            for j, (c2, e2) in enumerate(points)
        )
        marks.append(not dominated)
    return marks


def measure(
    scene: Scene,
    grid: list[GridPoint],
    *,
    reference: str = "accurate",
    reference_dt: float | None = None,
    duration: float | None = None,
    repeats: int = 3,
    min_seconds: float = MIN_TIMED_SECONDS,
    progress: bool = False,
) -> TradeoffResult:
    """Run every grid point against the reference and measure cost and error.

    reference: "accurate" (the `accurate` preset at `reference_dt`, default the smaller of the
        scene's dt / 8 and the smallest grid dt / 4) or "analytic" (`analytic_trajectory`).
    duration: simulated seconds (default: the scene's steps * dt).
    repeats: rounds of timed runs over the whole grid; a point's cost is the median of its timed
        runs. Short runs are repeated until `min_seconds` were timed (timer noise).
    """
    from isaac.engine.world import build_model

    if repeats < 1:
        raise TradeoffError(f"--repeats must be >= 1, got {repeats}")
    if not grid:
        raise TradeoffError("the grid is empty")
    w = scene.world
    duration = w.steps * w.dt if duration is None else float(duration)
    if not duration > 0.0:
        raise TradeoffError(f"--duration must be > 0, got {duration}")
    sample_dt = max(p.dt for p in grid)
    times = sample_times(duration, sample_dt)
    if times.shape[0] < 2:
        raise TradeoffError(
            f"the run ({duration} s) is shorter than the coarsest dt "
            f"({sample_dt} s): nothing to compare"
        )
    duration = float(times[-1])
    model = build_model(scene)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(
            total=1 + len(grid) * (1 + repeats),
            unit="run",
            desc=scene.name,
            leave=False,
            file=sys.stderr,
        )
    try:
        if reference == "analytic":
            kind = analytic_model(scene)
            ref = analytic_trajectory(scene, times)
            ref_label = f"analytic ({kind})"
            ref_row = dict(setting="analytic", dt=0.0)
            ref_cost = math.nan
        elif reference == "accurate":
            ref_dt = reference_dt or min(w.dt / REFERENCE_DT_DIVISOR, min(p.dt for p in grid) / 4)
            ref_point = GridPoint("accurate (reference)", ref_dt, (("preset", "accurate"),))
            ref_scene = replace(scene, world=ref_point.world(w, duration))
            if bar:
                bar.set_postfix_str(f"reference dt={ref_dt:.3g}")
            warm_up(ref_scene)
            ref = simulate(ref_scene, times)
            if ref.error is not None:
                raise TradeoffError(f"the reference run failed: {ref.error}")
            ref_cost = statistics.median(time_runs(ref_scene, 1, min_seconds))
            ref_label = f"accurate, dt={ref_dt:.6g} s"
            ref_row = dict(
                setting=ref_point.label,
                dt=ref_dt,
                max_penetration_m=ref.max_depth,
                tunneled=len(ref.tunneled),
            )
        else:
            raise TradeoffError(f"--reference must be accurate or analytic, got {reference!r}")
        if bar:
            bar.update(1)
        ref_series = _series(scene, model, ref)
        ref_row.update(compare(scene, model, ref, ref, ref_series), diverged="")
        if math.isfinite(ref_cost):
            steps = math.ceil(duration / ref_row["dt"] - 1e-9)
            ref_row.update(_cost(ref_cost, steps, ref_row["dt"]))
        # measure: one untimed run per point with the per-step checks
        rows, timed = [], []
        for point in grid:
            if bar:
                bar.set_postfix_str(f"{point.label} dt={point.dt:.3g}")
            run_scene = replace(scene, world=point.world(w, duration))
            warm_up(run_scene)
            run = simulate(run_scene, times)
            row = dict(setting=point.label, dt=point.dt)
            row.update(compare(scene, model, run, ref, ref_series))
            row.update(
                max_penetration_m=run.max_depth,
                tunneled=len(run.tunneled),
                diverged=run.error or "",
                ms_per_step=math.nan,
                steps_per_s=math.nan,
                ms_per_sim_s=math.nan,
            )
            rows.append(row)
            timed.append((row, run_scene, []) if run.error is None else None)
            if bar:
                bar.update(1)
        # time: `repeats` rounds over the whole grid, so a burst of load from elsewhere on the
        # machine falls on every setting alike instead of on one
        for _ in range(repeats):
            for entry in timed:
                if entry is None:
                    continue
                row, run_scene, costs = entry
                if bar:
                    bar.set_postfix_str(f"timing {row['setting']} dt={row['dt']:.3g}")
                costs.extend(time_runs(run_scene, 1, min_seconds / repeats))
                if bar:
                    bar.update(1)
        for entry in timed:
            if entry is not None:
                row, run_scene, costs = entry
                row.update(_cost(statistics.median(costs), run_scene.world.steps, row["dt"]))
    finally:
        if bar:
            bar.close()
    marks = _pareto([(r["ms_per_sim_s"], r["rms_error_m"]) for r in rows])
    for row, mark in zip(rows, marks):
        row["pareto"] = "*" if mark else ""
    ref_row.setdefault("pareto", "")
    return TradeoffResult(
        scene=scene.name,
        reference=ref_label,
        duration=duration,
        sample_dt=sample_dt,
        rows=rows,
        reference_row=ref_row,
    )


def _cost(seconds: float, steps: int, dt: float) -> dict[str, float]:
    ms_per_step = 1e3 * seconds / steps
    return dict(
        ms_per_step=ms_per_step, steps_per_s=1e3 / ms_per_step, ms_per_sim_s=ms_per_step / dt
    )


# --- output ---------------------------------------------------------------------------------


def _fmt(value, key: str) -> str:
    if value is None or value == "":
        return ""
    if isinstance(value, str):
        return value
    if key in ("tunneled",):
        return str(int(value))
    if isinstance(value, float) and math.isnan(value):
        return "-"
    if key == "dt":
        return f"{value:.5g}" if value else "-"
    if key == "steps_per_s":
        return f"{value:.0f}"
    return f"{value:.3g}"


def write_csv(result: TradeoffResult, path) -> None:
    """One row per grid point plus the reference row (first), columns COLUMNS."""
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(("scene", "reference") + COLUMNS)
        for row in [result.reference_row] + result.rows:
            values = []
            for key in COLUMNS:
                v = row.get(key, "")
                values.append(repr(v) if isinstance(v, float) else v)
            writer.writerow((result.scene, result.reference, *values))


TABLE_COLUMNS = (
    ("setting", "setting"),
    ("dt", "dt s"),
    ("ms_per_step", "ms/step"),
    ("steps_per_s", "steps/s"),
    ("ms_per_sim_s", "ms/sim-s"),
    ("rms_error_m", "RMS err m"),
    ("energy_drift", "E drift"),
    ("energy_error", "E err"),
    ("com_error_m", "COM err m"),
    ("momentum_error_mps", "P err m/s"),
    ("max_penetration_m", "max pen m"),
    ("tunneled", "tunnel"),
    ("pareto", "pareto"),
)


def format_table(result: TradeoffResult, *, markdown: bool = False) -> str:
    """The table as aligned text (or a Markdown table), reference row first."""
    header = [title for _, title in TABLE_COLUMNS]
    body = []
    for row in [result.reference_row] + result.rows:
        cells = [_fmt(row.get(key, ""), key) for key, _ in TABLE_COLUMNS]
        if row.get("diverged"):
            cells[-1] = "DIVERGED"
        body.append(cells)
    if markdown:
        lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        lines += ["| " + " | ".join(c or " " for c in cells) + " |" for cells in body]
        return "\n".join(lines)
    widths = [max(len(r[i]) for r in [header] + body) for i in range(len(header))]
    lines = ["  ".join(h.ljust(wd) for h, wd in zip(header, widths))]
    lines += ["  ".join(c.ljust(wd) for c, wd in zip(cells, widths)) for cells in body]
    return "\n".join(lines)


def plot(result: TradeoffResult, path, *, second: str = "max_penetration_m") -> None:
    """PNG: error against cost (ms per simulated second, log-log), one marker per setting and
    dt, the Pareto front joined; a second panel shows `second` (a physically meaningful error)."""
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    titles = {
        "rms_error_m": "trajectory RMS error vs reference (m)",
        "max_penetration_m": "max penetration (m)",
        "energy_error": "energy error (rel.)",
        "com_error_m": "centre-of-mass error (m)",
    }
    fig, axes = plt.subplots(1, 2, figsize=(10.5, 4.2), dpi=90)
    labels = list(dict.fromkeys(r["setting"] for r in result.rows))
    dts = sorted({r["dt"] for r in result.rows}, reverse=True)
    markers = "osD^v<>ph*"
    cmap = plt.get_cmap("viridis")
    for ax, metric in zip(axes, ("rms_error_m", second)):
        pts = []
        values = [r[metric] for r in result.rows if math.isfinite(r[metric])]
        positive = [v for v in values if v > 0.0]
        floor = min(positive) / 10.0 if positive else 1e-6
        floor_note = f"0 plotted at {floor:.2g}" if len(positive) < len(values) else ""
        for r in result.rows:
            c, e = r["ms_per_sim_s"], r[metric]
            if not (math.isfinite(c) and math.isfinite(e)):
                continue
            e_plot = max(e, floor)
            li, di = labels.index(r["setting"]), dts.index(r["dt"])
            ax.scatter(
                c,
                e_plot,
                marker=markers[li % len(markers)],
                s=55,
                color=cmap(di / max(1, len(dts) - 1) * 0.85),
                edgecolor="black",
                linewidth=0.5,
                zorder=3,
            )
            pts.append((c, e_plot))
        marks = _pareto(pts)
        front = sorted(p for p, m in zip(pts, marks) if m)
        if front:
            ax.plot(*zip(*front), "--", color="crimson", lw=1.2, zorder=2, label="Pareto front")
            ax.scatter(*zip(*front), s=140, facecolor="none", edgecolor="crimson", zorder=4)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        if floor_note:
            ax.text(0.02, 0.02, floor_note, transform=ax.transAxes, fontsize=7, color="dimgray")
        ax.set_xlabel("cost: ms of wall time per simulated second")
        ax.set_ylabel(titles.get(metric, metric))
        ax.grid(True, which="both", alpha=0.25)
    from matplotlib.lines import Line2D

    handles = [
        Line2D(
            [],
            [],
            marker=markers[i % len(markers)],
            ls="",
            color="grey",
            markeredgecolor="black",
            label=lab,
        )
        for i, lab in enumerate(labels)
    ]
    handles += [
        Line2D(
            [],
            [],
            marker="o",
            ls="",
            color=cmap(i / max(1, len(dts) - 1) * 0.85),
            label=f"dt = {_dt_text(d)}",
        )
        for i, d in enumerate(dts)
    ]
    handles.append(Line2D([], [], ls="--", color="crimson", label="Pareto front"))
    axes[1].legend(handles=handles, fontsize=7, loc="best", framealpha=0.8)
    fig.suptitle(
        f"{result.scene}: error vs cost (reference: {result.reference}; "
        f"{result.duration:.3g} s simulated)",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _dt_text(dt: float) -> str:
    inverse = 1.0 / dt
    if abs(inverse - round(inverse)) < 1e-6 * inverse:
        return f"1/{round(inverse)} s"
    return f"{dt:.3g} s"


# --- command line ---------------------------------------------------------------------------


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "tradeoff",
        help="measure error against cost of fidelity settings on a scene",
        description="Run SCENE under a grid of settings (default: the presets x the scene's dt "
        "times 2, 1 and 1/2), each against a reference, and report cost (ms/step, "
        "median of repeats) and error. Writes a CSV and a PNG (error vs cost, "
        "Pareto front marked).",
    )
    p.add_argument("scene", help="scene YAML file")
    p.add_argument(
        "--grid",
        action="append",
        metavar="KEY=V1,V2",
        help="a grid axis (repeatable; or several joined by ';'): preset=..., "
        "dt=1/60,1/120 (or x2 for twice the scene's dt), or any world setting "
        "(iterations=4,10, ccd=off,speculative, ...)",
    )
    p.add_argument(
        "--reference",
        choices=("accurate", "analytic"),
        default=None,
        help="accurate: the accurate preset at a small dt (default, unless the scene "
        "declares `analytic:`); analytic: the closed form (free flight, a flat "
        "drop on level ground, a 1D head-on hit)",
    )
    p.add_argument(
        "--reference-dt",
        type=float,
        default=None,
        metavar="S",
        help="dt of the accurate reference (default: the scene's dt / 8)",
    )
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="simulated seconds (default: the scene's steps x dt)",
    )
    p.add_argument("--repeats", type=int, default=3, help="timed runs per setting (median)")
    p.add_argument(
        "--min-time",
        type=float,
        default=MIN_TIMED_SECONDS,
        metavar="S",
        help=f"repeat short runs until this many seconds were timed (default {MIN_TIMED_SECONDS})",
    )
    p.add_argument("--csv", metavar="OUT.csv", help="CSV path (default: SCENE_tradeoff.csv here)")
    p.add_argument("--png", metavar="OUT.png", help="plot path (default: SCENE_tradeoff.png)")
    p.add_argument("--no-plot", action="store_true", help="do not write the plot")
    p.add_argument(
        "--second",
        default="max_penetration_m",
        choices=("max_penetration_m", "energy_error", "com_error_m"),
        help="error shown in the plot's second panel",
    )
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_tradeoff)


def cmd_tradeoff(args: argparse.Namespace) -> int:
    scene = load_scene(args.scene)
    grid = parse_grid(args.grid, scene.world.dt)
    reference = args.reference or ("analytic" if scene.analytic else "accurate")
    result = measure(
        scene,
        grid,
        reference=reference,
        reference_dt=args.reference_dt,
        duration=args.duration,
        repeats=args.repeats,
        min_seconds=args.min_time,
        progress=not args.quiet and sys.stderr.isatty(),
    )
    stem = Path(args.scene).stem
    csv_path = Path(args.csv or f"{stem}_tradeoff.csv")
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    write_csv(result, csv_path)
    print(
        f"scene {result.scene!r}: {result.duration:.6g} s simulated, compared every "
        f"{result.sample_dt:.6g} s; reference: {result.reference}; cost: median of "
        f"{args.repeats} rounds of timed runs (at least {args.min_time} s each point) after "
        f"a warm-up step"
    )
    print(format_table(result, markdown=args.markdown))
    print(f"wrote {csv_path}")
    if not args.no_plot:
        png_path = Path(args.png or f"{stem}_tradeoff.png")
        png_path.parent.mkdir(parents=True, exist_ok=True)
        plot(result, png_path, second=args.second)
        print(f"wrote {png_path}")
    diverged = [r for r in result.rows if r["diverged"]]
    for r in diverged:
        print(f"note: {r['setting']} dt={r['dt']:.6g} stopped: {r['diverged']}", file=sys.stderr)
    return 0
