"""Collision impulses: the seed's single pass, or an iterative sequential-impulse solver.

The seed's impulse (from myphysicslab's collision derivation), for a contact point P with unit
normal n from a to b:

    j = -(1 + e) v_ab . n / (1/m_a + 1/m_b + (r_ap x n)^2 / I_a + (r_bp x n)^2 / I_b)

with r_ap = P - x_a, r_bp = P - x_b. Here v_ab . n is `vn`, the normal velocity of b's point
relative to a's, (v_b + w_b x r_bp - v_a - w_a x r_ap) . n, negative when they approach; the
denominator is `k_normal` (1/kg). j >= 0 is applied as -j n to a and +j n to b:
v_a -= j n / m_a, w_a -= (r_ap x j n) / I_a, v_b += j n / m_b, w_b += (r_bp x j n) / I_b.
The seed applies it only when the bodies approach (vn < 0).

- solver "seed": one pass over the contacts in order, each seeing the velocities the previous ones
  left (Gauss-Seidel), exactly the formula above.
- solver "sequential": `iterations` passes; each contact accumulates its impulse, clamped to stay
  >= 0 (contacts push, never pull), towards the target normal velocity -e vn0 (vn0 = normal
  velocity before solving). Warm starting applies last step's accumulated impulses first.
  This converges to the simultaneous solution of all contacts (stacks, two-point manifolds).
- restitution_threshold: a contact approaching slower than this does not bounce (e = 0).
- friction (Coulomb, optional): a tangent impulse along t = (-n_y, n_x), clamped to
  |jt| <= mu j, aiming at zero tangential velocity.
- speculative rows (depth < 0: a gap g = -depth still open) allow the bodies to close the gap in
  this step but not more: target normal velocity -g / h; when they would meet within this step
  the contact bounces now with the same formula (the bounce happens up to g early).
"""

from __future__ import annotations

import numba
import numpy as np

from isaac.narrow_phase import find_previous

# pair restitution rules (WorldSettings.restitution_rule)
RULE_MAX = 0
RULE_MIN = 1
RULE_MEAN = 2
RULE_PRODUCT = 3
RULE_SQRT = 4  # geometric mean (friction's default)
RULE_CODES = {"max": RULE_MAX, "min": RULE_MIN, "mean": RULE_MEAN, "product": RULE_PRODUCT,
              "sqrt": RULE_SQRT}


@numba.njit(cache=True)
def combine(rule, x, y):
    """Mix two bodies' coefficients (restitution or friction) by a pair rule."""
    if rule == RULE_MAX:
        return max(x, y)
    if rule == RULE_MIN:
        return min(x, y)
    if rule == RULE_MEAN:
        return 0.5 * (x + y)
    if rule == RULE_PRODUCT:
        return x * y
    return np.sqrt(x * y)


@numba.njit(cache=True)
def _apply(a, b, px, py, rax, ray, rbx, rby, inv_mass, inv_inertia, velocity, angular_velocity):
    """Apply impulse P = (px, py) (N s) as -P at a's point and +P at b's point."""
    velocity[a, 0] -= px * inv_mass[a]
    velocity[a, 1] -= py * inv_mass[a]
    angular_velocity[a] -= (rax * py - ray * px) * inv_inertia[a]
    velocity[b, 0] += px * inv_mass[b]
    velocity[b, 1] += py * inv_mass[b]
    angular_velocity[b] += (rbx * py - rby * px) * inv_inertia[b]


@numba.njit(cache=True)
def _relative_velocity(a, b, rax, ray, rbx, rby, velocity, angular_velocity):
    """Velocity (m/s) of b's material point minus a's, at the contact (w x r = w (-r_y, r_x))."""
    vx = (velocity[b, 0] - angular_velocity[b] * rby) - (velocity[a, 0] - angular_velocity[a] * ray)
    vy = (velocity[b, 1] + angular_velocity[b] * rbx) - (velocity[a, 1] + angular_velocity[a] * rax)
    return vx, vy


@numba.njit(cache=True)
def solve_contacts(rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_depth,
                   position, velocity, angular_velocity, inv_mass, inv_inertia,
                   restitution, friction, restitution_rule, friction_rule, restitution_threshold,
                   friction_on, seed_solver, iterations, warm_starting, h, n_bodies,
                   prev_key, prev_feature, prev_slot, prev_impulse, prev_tangent,
                   c_impulse, c_tangent, c_restitution):
    """Resolve every contact row; writes the impulses applied (N s) and the restitution used."""
    r_a = np.empty((rows, 2))
    r_b = np.empty((rows, 2))
    k_normal = np.empty(rows)
    k_tangent = np.empty(rows)
    target = np.empty(rows)
    mu = np.empty(rows)
    for k in range(rows):
        a = c_a[k]
        b = c_b[k]
        rax = c_point[k, 0] - position[a, 0]
        ray = c_point[k, 1] - position[a, 1]
        rbx = c_point[k, 0] - position[b, 0]
        rby = c_point[k, 1] - position[b, 1]
        r_a[k, 0] = rax
        r_a[k, 1] = ray
        r_b[k, 0] = rbx
        r_b[k, 1] = rby
        nx = c_normal[k, 0]
        ny = c_normal[k, 1]
        rna = rax * ny - ray * nx
        rnb = rbx * ny - rby * nx
        k_normal[k] = (inv_mass[a] + inv_mass[b] + rna * rna * inv_inertia[a]
                       + rnb * rnb * inv_inertia[b])
        rta = rax * nx + ray * ny  # r x t with t = (-n_y, n_x)
        rtb = rbx * nx + rby * ny
        k_tangent[k] = (inv_mass[a] + inv_mass[b] + rta * rta * inv_inertia[a]
                        + rtb * rtb * inv_inertia[b])
        mu[k] = combine(friction_rule, friction[a], friction[b]) if friction_on else 0.0
        vx, vy = _relative_velocity(a, b, rax, ray, rbx, rby, velocity, angular_velocity)
        vn0 = vx * nx + vy * ny
        gap = -c_depth[k]
        hits = vn0 < 0.0 if gap <= 0.0 else vn0 * h < -gap
        e = 0.0
        if hits and -vn0 >= restitution_threshold:
            e = combine(restitution_rule, restitution[a], restitution[b])
        c_restitution[k] = e
        if gap <= 0.0:
            target[k] = -e * vn0
        elif hits:
            target[k] = max(-gap / h, -e * vn0)
        else:
            target[k] = -gap / h
        c_impulse[k] = 0.0
        c_tangent[k] = 0.0

    if seed_solver:
        for k in range(rows):
            a = c_a[k]
            b = c_b[k]
            if k_normal[k] <= 0.0:
                continue
            nx = c_normal[k, 0]
            ny = c_normal[k, 1]
            vx, vy = _relative_velocity(a, b, r_a[k, 0], r_a[k, 1], r_b[k, 0], r_b[k, 1],
                                        velocity, angular_velocity)
            vn = vx * nx + vy * ny
            gap = -c_depth[k]
            if gap <= 0.0:
                if vn >= 0.0:
                    continue
                # the seed's formula, literally
                j = -(1.0 + c_restitution[k]) * vn / k_normal[k]
            else:
                if vn >= target[k]:
                    continue
                j = (target[k] - vn) / k_normal[k]
            _apply(a, b, j * nx, j * ny, r_a[k, 0], r_a[k, 1], r_b[k, 0], r_b[k, 1],
                   inv_mass, inv_inertia, velocity, angular_velocity)
            c_impulse[k] = j
            if mu[k] > 0.0 and k_tangent[k] > 0.0:
                vx, vy = _relative_velocity(a, b, r_a[k, 0], r_a[k, 1], r_b[k, 0], r_b[k, 1],
                                            velocity, angular_velocity)
                vt = -vx * ny + vy * nx
                jt = -vt / k_tangent[k]
                limit = mu[k] * j
                jt = min(max(jt, -limit), limit)
                _apply(a, b, -jt * ny, jt * nx, r_a[k, 0], r_a[k, 1], r_b[k, 0], r_b[k, 1],
                       inv_mass, inv_inertia, velocity, angular_velocity)
                c_tangent[k] = jt
        return

    if warm_starting and prev_key.shape[0] > 0:
        for k in range(rows):
            a = c_a[k]
            b = c_b[k]
            p = find_previous(prev_key, a * n_bodies + b)
            if p < 0:
                continue
            key = prev_key[p]
            while p < prev_key.shape[0] and prev_key[p] == key:
                if prev_feature[p] == c_feature[k] and prev_slot[p] == c_slot[k]:
                    pn = prev_impulse[p]
                    pt = prev_tangent[p] if mu[k] > 0.0 else 0.0
                    nx = c_normal[k, 0]
                    ny = c_normal[k, 1]
                    c_impulse[k] = pn
                    c_tangent[k] = pt
                    _apply(a, b, pn * nx - pt * ny, pn * ny + pt * nx, r_a[k, 0], r_a[k, 1],
                           r_b[k, 0], r_b[k, 1], inv_mass, inv_inertia, velocity,
                           angular_velocity)
                    break
                p += 1

    for _ in range(iterations):
        for k in range(rows):
            if k_normal[k] <= 0.0:
                continue
            a = c_a[k]
            b = c_b[k]
            nx = c_normal[k, 0]
            ny = c_normal[k, 1]
            rax = r_a[k, 0]
            ray = r_a[k, 1]
            rbx = r_b[k, 0]
            rby = r_b[k, 1]
            vx, vy = _relative_velocity(a, b, rax, ray, rbx, rby, velocity, angular_velocity)
            vn = vx * nx + vy * ny
            old = c_impulse[k]
            new = max(old + (target[k] - vn) / k_normal[k], 0.0)
            c_impulse[k] = new
            dj = new - old
            _apply(a, b, dj * nx, dj * ny, rax, ray, rbx, rby, inv_mass, inv_inertia,
                   velocity, angular_velocity)
            if mu[k] > 0.0:
                vx, vy = _relative_velocity(a, b, rax, ray, rbx, rby, velocity, angular_velocity)
                vt = -vx * ny + vy * nx
                limit = mu[k] * new
                old_t = c_tangent[k]
                new_t = min(max(old_t - vt / k_tangent[k], -limit), limit)
                c_tangent[k] = new_t
                dt = new_t - old_t
                _apply(a, b, -dt * ny, dt * nx, rax, ray, rbx, rby, inv_mass, inv_inertia,
                       velocity, angular_velocity)
