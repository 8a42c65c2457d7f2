"""World state as structure-of-arrays: the constant `Model` and the evolving `State`.

Conventions (every array indexed by body, in scene order):
- SI units, world frame x right / y up, angles counter-clockwise.
- Rotation: a body-frame vector r maps to the world as R(angle) @ r with
  R = [[cos, -sin], [sin, cos]] (counter-clockwise). This is what the seed's *code*
  (FillEnvSpaceList) computes; the seed's matrix *text* [[cos, sin], [-sin, cos]] is the transpose,
  a clockwise rotation, and is not used.
- Local vertices are re-centred on the polygon's centroid, so `position` is the centre of mass
  (the seed's COM) and LocalSpaceList is relative to it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isaac.collision_filter import colliders
from isaac.engine.joints import Joints, in_waves, joint_table
from isaac.scene import Scene, circle, polygon
from isaac.scene.validate import checked


@dataclass(frozen=True, eq=False)
class Model:
    """What does not change during a run.

    names: body names, in index order.
    vertices_local: (n, V, 2) vertices (m) in the body frame, centred on the centre of mass,
        counter-clockwise; rows past vertex_count[i] repeat the last vertex (padding).
    normals_local: (n, V, 2) outward unit normal of edge k (vertex k to k+1), body frame.
    vertex_count: (n,) int64 number of vertices of each body (3..50), or 1 for a circle: a
        circle is its centre (one vertex at the centre of mass) with a radius, the
        point-with-radius form of Box2D v3 (its normals are unused).
    radius: (n,) the seed's MaxDist: largest distance from centre of mass to a vertex (m); a
        circle's radius.
    thickness: (n,) the polygon's smallest width (m): over its edges, the largest depth of the
        polygon behind the edge, minimised; a circle's diameter. Tolerances that must stay below
        a body's size (the push-out's slop) are capped by it.
    mass: (n,) kg, area * density (also for concrete bodies, for information).
    inertia: (n,) kg m^2 about the centre of mass.
    inv_mass, inv_inertia: (n,) 1/kg, 1/(kg m^2); 0 for concrete bodies.
    restitution: (n,) e in [0, 1].
    friction: (n,) Coulomb coefficient.
    concrete: (n,) bool, immovable (the seed's IsConcrete).
    enters_at, leaves_at: (n,) s; the body exists while enters_at <= step * dt < leaves_at
        (leaves_at is +inf for a body that never leaves).
    timed: whether any body enters after time 0 or ever leaves (existence can change).
    category, mask, group: (n,) int64, the collision filter (isaac.collision_filter).
    filtered: whether the broad phase must test pairs against a filter: some body's filter is
        not the default, or a joint keeps its bodies from colliding (else it tests none).
    sweeps: (n,) bool, whether the filter lets some other body collide with it
        (`isaac.collision_filter.colliders`); the broad phase leaves the others out of its
        sweep (they make no pair), as it does absent bodies.
    circles: whether any body is a circle (else no circle code runs).
    joints: the scene's joints as arrays (`isaac.engine.joints.Joints`, m rows; m = 0: none,
        and no joint code runs).
    joint_waves: the same joints in the order the position passes visit them
        (`isaac.engine.joints.in_waves`).
    no_collide: (p,) int64 sorted keys a * n + b (a < b) of the pairs joints keep apart.
    """

    names: tuple[str, ...]
    vertices_local: np.ndarray
    normals_local: np.ndarray
    vertex_count: np.ndarray
    radius: np.ndarray
    thickness: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    inv_mass: np.ndarray
    inv_inertia: np.ndarray
    restitution: np.ndarray
    friction: np.ndarray
    concrete: np.ndarray
    enters_at: np.ndarray
    leaves_at: np.ndarray
    timed: bool
    category: np.ndarray
    mask: np.ndarray
    group: np.ndarray
    filtered: bool
    sweeps: np.ndarray
    circles: bool
    joints: Joints
    joint_waves: Joints
    no_collide: np.ndarray

    @property
    def n_bodies(self) -> int:
        return len(self.names)


@dataclass(eq=False)
class State:
    """What the step changes (arrays updated in place by the compiled kernels).

    step: index of this state; time = step * dt.
    position: (n, 2) centre of mass (m, world).
    angle: (n,) rad, counter-clockwise, wrapped to [-pi, pi].
    velocity: (n, 2) m/s, world.
    angular_velocity: (n,) rad/s.
    exists: (n,) bool.
    """

    step: int
    position: np.ndarray
    angle: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    exists: np.ndarray


PI = np.pi
TWO_PI = 2.0 * np.pi  # exactly twice the float pi


def wrap_angle(angle: float) -> float:
    """Wrap an angle (rad) into [-pi, pi] by whole turns of the float 2*pi.

    For |angle| < 4*pi each subtraction is exact (Sterbenz: x - y is exact when y/2 <= x <= 2y),
    so wrapping every step loses no precision and long runs keep their angle (docs/physics.md).
    The compiled kernels use the same rule (integrate.py).
    """
    while angle > PI:
        angle -= TWO_PI
    while angle < -PI:
        angle += TWO_PI
    return angle


def build_model(scene: Scene) -> Model:
    """Mass properties and padded geometry of every body of `scene`, checked first as the
    loader checks a scene file (`isaac.scene.validate.checked`: TypeError or SceneError),
    since a scene built in Python never passed the loader and the kernels trust the model."""
    checked(scene)
    n = len(scene.bodies)
    width = max((len(b.vertices) for b in scene.bodies), default=3)
    width = max(width, 1)  # a scene of circles only
    verts = np.zeros((n, width, 2))
    normals = np.zeros((n, width, 2))
    count = np.zeros(n, dtype=np.int64)
    radius = np.zeros(n)
    thickness = np.zeros(n)
    mass = np.zeros(n)
    inertia = np.zeros(n)
    for i, body in enumerate(scene.bodies):
        if body.circle is not None:
            r = float(body.circle)
            area, second_moment = circle.mass_properties(r)
            verts[i] = 0.0
            normals[i] = (1.0, 0.0)
            count[i] = 1
            radius[i] = r
            thickness[i] = 2.0 * r
            mass[i] = float(area) * body.density
            inertia[i] = float(second_moment) * body.density
            continue
        raw = np.asarray(body.vertices, dtype=np.float64)
        area, centroid, second_moment = polygon.mass_properties(raw)
        local = raw - centroid
        k = local.shape[0]
        verts[i, :k] = local
        verts[i, k:] = local[k - 1]
        edge = np.roll(local, -1, axis=0) - local
        length = np.sqrt(edge[:, 0] ** 2 + edge[:, 1] ** 2)
        # outward normal of a counter-clockwise edge (dx, dy) is (dy, -dx) / |edge|
        normals[i, :k, 0] = edge[:, 1] / length
        normals[i, :k, 1] = -edge[:, 0] / length
        normals[i, k:] = normals[i, k - 1]
        count[i] = k
        radius[i] = np.sqrt(np.max(local[:, 0] ** 2 + local[:, 1] ** 2))
        # depth of every vertex behind every edge: -n_k . (v_j - v_k), shape (edges, vertices)
        behind = -(
            normals[i, :k, None, 0] * (local[None, :, 0] - local[:, None, 0])
            + normals[i, :k, None, 1] * (local[None, :, 1] - local[:, None, 1])
        )
        thickness[i] = behind.max(axis=1).min()
        mass[i] = area * body.density
        inertia[i] = second_moment * body.density
    concrete = np.array([b.concrete for b in scene.bodies], dtype=bool)
    inv_mass = np.where(concrete, 0.0, 1.0 / mass)
    inv_inertia = np.where(concrete, 0.0, 1.0 / inertia)
    enters_at = np.array([b.enters_at for b in scene.bodies], dtype=np.float64)
    leaves_at = np.array(
        [np.inf if b.leaves_at is None else b.leaves_at for b in scene.bodies], dtype=np.float64
    )
    joints, no_collide = joint_table(scene.joints, n)
    category = np.array([b.category for b in scene.bodies], dtype=np.int64)
    mask = np.array([b.mask for b in scene.bodies], dtype=np.int64)
    group = np.array([b.group for b in scene.bodies], dtype=np.int64)
    filtered = any(b.filtered for b in scene.bodies) or len(no_collide) > 0
    return Model(
        names=tuple(b.name for b in scene.bodies),
        vertices_local=verts,
        normals_local=normals,
        vertex_count=count,
        radius=radius,
        thickness=thickness,
        mass=mass,
        inertia=inertia,
        inv_mass=inv_mass,
        inv_inertia=inv_inertia,
        restitution=np.array([b.restitution for b in scene.bodies], dtype=np.float64),
        friction=np.array([b.friction for b in scene.bodies], dtype=np.float64),
        concrete=concrete,
        enters_at=enters_at,
        leaves_at=leaves_at,
        timed=bool(np.any(enters_at > 0.0) or np.any(np.isfinite(leaves_at))),
        category=category,
        mask=mask,
        group=group,
        filtered=filtered,
        sweeps=colliders(category, mask, group) if filtered else np.ones(n, dtype=bool),
        circles=any(b.circle is not None for b in scene.bodies),
        joints=joints,
        joint_waves=in_waves(joints, n),
        no_collide=no_collide,
    )


def initial_state(scene: Scene, model: Model) -> State:
    """The state at step 0 (time 0), as the scene gives it."""
    n = len(scene.bodies)
    position = np.array([b.position for b in scene.bodies], dtype=np.float64).reshape(n, 2)
    angle = np.array([wrap_angle(b.angle) for b in scene.bodies], dtype=np.float64)
    velocity = np.array([b.velocity for b in scene.bodies], dtype=np.float64).reshape(n, 2)
    angular_velocity = np.array([b.angular_velocity for b in scene.bodies], dtype=np.float64)
    # a concrete body never moves, whatever velocity the scene gave it
    velocity[model.concrete] = 0.0
    angular_velocity[model.concrete] = 0.0
    exists = (model.enters_at <= 0.0) & (0.0 < model.leaves_at)
    return State(0, position, angle, velocity, angular_velocity, exists)
