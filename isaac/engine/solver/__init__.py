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

from isaac.engine.solver.mixing import RULE_CODES
from isaac.engine.solver.seed import solve_seed
from isaac.engine.solver.sequential import grown_scratch, solve_sequential

__all__ = ["RULE_CODES", "solve_contacts"]


def solve_contacts(
    rows,
    c_a,
    c_b,
    c_feature,
    c_slot,
    c_point,
    c_normal,
    c_depth,
    c_previous,
    position,
    velocity,
    angular_velocity,
    inv_mass,
    inv_inertia,
    gravity_dv,
    restitution,
    friction,
    restitution_rule,
    friction_rule,
    restitution_threshold,
    friction_on,
    seed_solver,
    iterations,
    warm_starting,
    h,
    prev_impulse,
    prev_tangent,
    c_impulse,
    c_tangent,
    c_restitution,
    c_push_a,
    c_push_b,
    table,
    joints,
    joint_scratch,
):
    """Resolve every contact row; writes the impulses applied (N s) and the restitution used.

    gravity_dv: (2,) velocity (m/s) gravity added to every moving body just before this solve
    (g h with semi-implicit Euler, zero with explicit). The bounce is computed from the approach
    velocity the bodies *arrived* with, without it: a resting body (arrived at 0) does not bounce
    off the gravity of its own step, and a falling body bounces back with the speed it hit with;
    reflecting the gravity increment too gained about 0.4 % of the energy per bounce.
    A speculative contact that meets within the step (gap g closed at speed u = -vn0, which
    includes this step's gravity since the impact comes after it) leaves with the bounce
    velocity e u and is moved back by (1 + e) g, shared by inverse mass: it ends the step e times
    as far from the surface as it would have sunk through it, the reflection at the surface, not
    in the air g above it. That displacement is added to the pair's push_a / push_b. (With
    semi-implicit Euler this keeps an e = 1 bounce's energy within 0.5 % over 60 s; reflecting
    the arrival velocity at the mirrored position lost 23 %.)
    table: (m,) float64 scratch for the sequential solver, kept by the caller from step to step
    (allocating its several hundred kB afresh every step cost more in page faults than the
    passes over it); returns it, or a larger replacement when it was too small (the solver
    says how much it needs and changes nothing then: it is called again with the larger one).

    The two solvers are separate compiled kernels chosen here, so each is compiled only when a
    run first uses it.
    joints, joint_scratch: the joint table and its prepared rows (`isaac.engine.joints`),
    solved by the sequential solver between its passes; the seed's solver has no joint rows
    (a scene with joints cannot choose it: the scene loader refuses).
    """
    if seed_solver:
        solve_seed(
            rows,
            c_a,
            c_b,
            c_feature,
            c_slot,
            c_point,
            c_normal,
            c_depth,
            position,
            velocity,
            angular_velocity,
            inv_mass,
            inv_inertia,
            gravity_dv,
            restitution,
            friction,
            restitution_rule,
            friction_rule,
            restitution_threshold,
            friction_on,
            h,
            c_impulse,
            c_tangent,
            c_restitution,
            c_push_a,
            c_push_b,
        )
        return table
    while True:
        need = solve_sequential(
            rows,
            c_a,
            c_b,
            c_feature,
            c_slot,
            c_point,
            c_normal,
            c_depth,
            c_previous,
            position,
            velocity,
            angular_velocity,
            inv_mass,
            inv_inertia,
            gravity_dv,
            restitution,
            friction,
            restitution_rule,
            friction_rule,
            restitution_threshold,
            friction_on,
            iterations,
            warm_starting,
            h,
            prev_impulse,
            prev_tangent,
            c_impulse,
            c_tangent,
            c_restitution,
            c_push_a,
            c_push_b,
            table,
            # (None without joints: the solver's specialisation without the joints' code)
            joints if joint_scratch.shape[0] else None,
            joint_scratch if joint_scratch.shape[0] else None,
        )
        if need == 0:
            return table
        table = grown_scratch(table, need)
