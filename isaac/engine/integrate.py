"""Integration of velocities and positions over one (sub)step of length h.

Two integrators (WorldSettings.integrator):
- explicit (the seed's body::Update): position and angle advance with the velocity the impulses
  left, then gravity goes into the velocity: x += v h; a += w h; v += g h.
  Free fall: y_n = y0 + v0 n h - g h^2 n (n - 1) / 2.
- semi-implicit (symplectic) Euler: gravity goes into the velocity first, *before* the impulses,
  so contacts see the velocity the body will move with (resting contacts cancel gravity exactly),
  then x += v h; a += w h. Free fall: y_n = y0 + v0 n h - g h^2 n (n + 1) / 2. It keeps the
  energy of a bouncing body bounded where the explicit one gains energy (docs/physics.md).

Angles are wrapped into [-pi, pi] each step by whole turns of the float 2*pi, which is exact for
|angle| < 4*pi (world.wrap_angle), so a long run loses no angle precision to the wrapping.
Only existing, movable bodies are integrated.
"""

from __future__ import annotations

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)

PI = np.pi
TWO_PI = 2.0 * np.pi
# A body whose angle moves more than this in one (sub)step (rad) has diverged: its angle is left
# unwrapped, which the divergence check stops at (DIVERGED_ANGLE). Turn by turn, wrapping it took
# |angle| / 2 pi subtractions, forever for an infinite angle or one past 2^54 (x - 2 pi == x):
# a step hung instead of failing. Above any scene's first step (|w| <= 1e6 rad/s, dt <= 1 s:
# isaac.scene.limits), and at most 1.6 million turns (about 2 ms) below it.
WRAP_LIMIT = 1e7


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def add_gravity(velocity, movable, exists, gx, gy, h):
    """v += g h (m/s) for every existing movable body."""
    for i in range(velocity.shape[0]):
        if exists[i] and movable[i]:
            velocity[i, 0] += gx * h
            velocity[i, 1] += gy * h


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def advance_positions(position, angle, velocity, angular_velocity, movable, exists, h):
    """x += v h (m); angle += w h (rad), wrapped into [-pi, pi] (left as it is beyond
    WRAP_LIMIT, or not finite: diverged)."""
    for i in range(position.shape[0]):
        if exists[i] and movable[i]:
            position[i, 0] += velocity[i, 0] * h
            position[i, 1] += velocity[i, 1] * h
            a = angle[i] + angular_velocity[i] * h
            if abs(a) <= WRAP_LIMIT:
                while a > PI:
                    a -= TWO_PI
                while a < -PI:
                    a += TWO_PI
            angle[i] = a


# Beyond these the state has diverged (a 1 km body at 1e6 m moving at 1e4 m/s is far inside).
DIVERGED_POSITION = 1e12  # m
DIVERGED_SPEED = 1e12  # m/s or rad/s
DIVERGED_ANGLE = 8.0  # rad: wrapped angles stay within pi


def diverged_body(state) -> tuple[int, int]:
    """`first_diverged` of an `isaac.engine.world.State` against the DIVERGED_* bounds."""
    s = state
    return first_diverged(
        s.position,
        s.angle,
        s.velocity,
        s.angular_velocity,
        s.exists,
        DIVERGED_POSITION,
        DIVERGED_SPEED,
        DIVERGED_ANGLE,
    )


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def first_diverged(
    position, angle, velocity, angular_velocity, exists, position_limit, speed_limit, angle_limit
):
    """(body index, field code) of the first existing body whose state is NaN, infinite or
    beyond the limits (m, m/s and rad/s, rad), or (-1, -1). Field codes: 0 position,
    1 velocity, 2 angle, 3 angular velocity. `not (x <= limit)` is also true for NaN."""
    for i in range(position.shape[0]):
        if not exists[i]:
            continue
        if not (abs(position[i, 0]) <= position_limit and abs(position[i, 1]) <= position_limit):
            return i, 0
        if not (abs(velocity[i, 0]) <= speed_limit and abs(velocity[i, 1]) <= speed_limit):
            return i, 1
        if not abs(angle[i]) <= angle_limit:
            return i, 2
        if not abs(angular_velocity[i]) <= speed_limit:
            return i, 3
    return -1, -1
