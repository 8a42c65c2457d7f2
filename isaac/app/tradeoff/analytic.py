"""The closed-form reference for scenes it knows how to solve: a lone body in free flight, a
body dropped flat on level concrete ground, a 1D head-on hit."""

from __future__ import annotations

import math

import numpy as np

from isaac.app.tradeoff.grid import TradeoffError
from isaac.app.tradeoff.trajectory import Trajectory
from isaac.scene import Scene


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


def _flat_extreme(body, axis: int, top: bool, tol: float) -> tuple[float, float, float] | None:
    """A body's extreme coordinate along `axis` (0: x, 1: y; m, world, at its starting pose) if a
    flat face takes it: (coordinate, low, high) of that face's extent along the other axis. A
    polygon's face is a whole edge (two or more vertices within `tol`); a circle's is the one
    point of its rim on the axis through its centre (low = high), where a contact's normal
    passes through the centre, as a flat face's does through a face-centred body."""
    if body.circle is not None:
        centre = body.position[axis]
        across = float(body.position[1 - axis])
        return float(centre + body.circle if top else centre - body.circle), across, across
    verts = _world_vertices(body)
    coord = verts[:, axis]
    extreme = coord.max() if top else coord.min()
    on = np.abs(coord - extreme) <= tol
    if on.sum() < 2:
        return None
    other = verts[on, 1 - axis]
    return float(extreme), float(other.min()), float(other.max())


def _size(body) -> float:
    """The largest |coordinate| of a body's outline (m, world): the scale of its tolerances."""
    if body.circle is not None:
        return float(max(abs(body.position[0]), abs(body.position[1])) + body.circle)
    return float(np.abs(_world_vertices(body)).max())


ANALYTIC_MODELS = ("ballistic", "drop", "head_on")


def analytic_model(scene: Scene) -> str | None:
    """Which closed form solves `scene`, or None: "ballistic" (one body, nothing to hit),
    "drop" (one body falling flat, without spin, onto level concrete ground under vertical
    gravity) or "head_on" (two bodies, no gravity, moving along x, faces vertical and centred on
    the same line). A circle's rim point counts as a face (`_flat_extreme`). Detected from the
    bodies; a scene may also name it (`analytic: {model: ...}`). None for a scene with joints
    (its bodies are held, not free) or with bodies that enter or leave.
    """
    declared = (scene.analytic or {}).get("model") if scene.analytic else None
    found = _detect(scene)
    if declared is not None and declared != found:
        seen = "no known closed form" if found is None else f"the closed form {found!r}"
        if scene.joints:
            seen += " (it has joints)"
        raise TradeoffError(
            f"the scene declares analytic model {declared!r} but its bodies fit "
            f"{seen} (known: {', '.join(ANALYTIC_MODELS)})"
        )
    return found


def _detect(scene: Scene) -> str | None:
    w = scene.world
    bodies = scene.bodies
    if scene.joints or any(b.enters_at > 0.0 or b.leaves_at is not None for b in bodies):
        return None
    moving = [b for b in bodies if not b.concrete]
    fixed = [b for b in bodies if b.concrete]
    if len(moving) == 1 and not fixed:
        return "ballistic"
    if len(moving) == 1 and len(fixed) == 1 and w.gravity[0] == 0.0 and w.gravity[1] < 0.0:
        body, ground = moving[0], fixed[0]
        tol = 1e-9 * (1.0 + _size(body))
        bottom = _flat_extreme(body, 1, False, tol)
        top = _flat_extreme(ground, 1, True, tol)
        if (
            bottom
            and top
            and top[1] < top[2]  # a flat ground, not a circle's rim
            and body.angular_velocity == 0.0
            and bottom[0] >= top[0] - tol
            and (body.velocity[0] == 0.0 or not w.friction)
        ):
            # the flat bottom must stay over the flat top for the whole run
            t_end = w.steps * w.dt
            shift = body.velocity[0] * t_end
            lo, hi = bottom[1] + min(0.0, shift), bottom[2] + max(0.0, shift)
            if lo >= top[1] and hi <= top[2]:
                return "drop"
        return None
    if len(moving) == 2 and not fixed and w.gravity == (0.0, 0.0):
        a, b = sorted(moving, key=lambda x: x.position[0])
        tol = 1e-9 * (1.0 + max(_size(a), _size(b)))
        face_a, face_b = _flat_extreme(a, 0, True, tol), _flat_extreme(b, 0, False, tol)
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
            return "head_on"
    return None


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
            _flat_extreme(body, 1, False, math.inf)[0] - _flat_extreme(ground, 1, True, math.inf)[0]
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
        gap = _flat_extreme(b, 0, False, math.inf)[0] - _flat_extreme(a, 0, True, math.inf)[0]
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
