"""The validated scene: `Scene` and its bodies' `BodySpec`s, plain frozen data."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

from isaac.scene.limits import FILTER_BITS
from isaac.scene.settings import WorldSettings

DEFAULT_CATEGORY = 1
DEFAULT_MASK = 2**FILTER_BITS - 1  # every category


@dataclass(frozen=True)
class BodySpec:
    """One body as the scene gives it (generators already expanded).

    name: unique name.
    vertices: polygon vertices (m) exactly as given (box / regular shapes already turned into
        vertices), counter-clockwise, 3..50 of them, convex. Not yet re-centred: the world builder
        re-centres them on their centroid (the seed's LocalSpaceList is relative to the centre of
        mass), so the same BodySpec always gives the same bits. Empty for a circle.
    circle: the radius (m) of a circle centred on `position`, or None for a polygon.
    position: world position of the centre of mass (m).
    angle: rad, counter-clockwise.
    velocity: m/s, world frame.
    angular_velocity: rad/s, counter-clockwise.
    density: kg/m^2 (mass = area * density).
    restitution: e in [0, 1].
    friction: Coulomb coefficient >= 0 (used only when the world's friction is on).
    concrete: immovable (infinite mass and inertia), the seed's IsConcrete.
    enters_at: time (s) from which the body exists (the seed's Exist).
    leaves_at: time (s) at which the body stops existing, or None.
    category: collision filter, the bits (32) that say what the body is.
    mask: collision filter, the categories it collides with. Two bodies collide when each one's
        mask has a bit of the other's category (Box2D's rule) ...
    group: ... unless they share a non-zero group: a positive group always collides, a negative
        one never (also Box2D's rule, which overrides the bits).
    """

    name: str
    vertices: tuple[tuple[float, float], ...]
    position: tuple[float, float] = (0.0, 0.0)
    angle: float = 0.0
    velocity: tuple[float, float] = (0.0, 0.0)
    angular_velocity: float = 0.0
    density: float = 1.0
    restitution: float = 0.0
    friction: float = 0.5
    concrete: bool = False
    enters_at: float = 0.0
    leaves_at: float | None = None
    circle: float | None = None
    category: int = DEFAULT_CATEGORY
    mask: int = DEFAULT_MASK
    group: int = 0

    @property
    def filtered(self) -> bool:
        """Whether the body's collision filter is not the default (collide with everything)."""
        return (self.category, self.mask, self.group) != (DEFAULT_CATEGORY, DEFAULT_MASK, 0)


JOINT_KINDS = ("revolute", "distance", "weld", "prismatic")


@dataclass(frozen=True)
class JointSpec:
    """One joint as the engine takes it: every value resolved to the bodies' frames at step 0.

    A body's frame has its origin at the body's centre of mass (its `position`) and turns with
    its angle (counter-clockwise); world-frame anchors and axes of the scene file are turned
    into it with the body's pose at step 0 (isaac.trig, so the bits are the same everywhere).

    name: unique among the joints.
    kind: one of JOINT_KINDS.
    a, b: indices into Scene.bodies, a != b, not both concrete (a joint to a concrete body
        pins to the world).
    local_a, local_b: the anchor on each body (m, that body's frame).
    axis: prismatic only: the slide axis, a unit vector in a's frame; (1, 0) otherwise.
    reference_angle: angle of b less angle of a (rad) at which the joint is at rest: revolute
        limits, the weld and the prismatic's locked rotation measure from it.
    length: distance only: the rest length (m) between the anchors.
    min_length, max_length: distance only: limits on the length (m), or None.
    stiffness: distance: a spring of this frequency (Hz) at `length`; weld: an angular spring
        (Box2D 2.3's soft weld); None for rigid.
    damping_ratio: of the spring (0 undamped, 1 critical).
    lower, upper: revolute: angle limits (rad, about reference_angle); prismatic: translation
        limits along the axis (m, about the anchors' start); None for no limits.
    motor_speed: revolute (rad/s, counter-clockwise) or prismatic (m/s along the axis) motor
        target speed, or None for no motor.
    max_motor: the motor's largest torque (N m) or force (N).
    collide_connected: whether the two bodies still collide with each other.
    """

    name: str
    kind: str
    a: int
    b: int
    local_a: tuple[float, float]
    local_b: tuple[float, float]
    axis: tuple[float, float] = (1.0, 0.0)
    reference_angle: float = 0.0
    length: float = 0.0
    min_length: float | None = None
    max_length: float | None = None
    stiffness: float | None = None
    damping_ratio: float = 0.0
    lower: float | None = None
    upper: float | None = None
    motor_speed: float | None = None
    max_motor: float = 0.0
    collide_connected: bool = False


class SceneMarks(NamedTuple):
    """Where a scene's YAML text said what it says (1-based lines), for warnings.

    bodies: (line, key path) of each body of `bodies:`, the scene's first bodies in order.
    generators: (first body, end, line, key path) of each generator's bodies[first:end].
    friction: (line, key path) of every `friction:` a body or a generator gives.
    """

    bodies: tuple[tuple[int, str], ...]
    generators: tuple[tuple[int, int, int, str], ...]
    friction: tuple[tuple[int, str], ...]


@dataclass(frozen=True)
class Scene:
    """A validated scene: world settings and bodies, every generator expanded.

    name: the scene's name (from the file, or its stem).
    source: where it came from (path or "<text>"), for messages.
    analytic: optional analytic reference the scene declares (used by `isaac tradeoff`), or None.
    joints: the joints (JointSpec), in the order the scene gives them.
    marks: where the YAML gave each body (SceneMarks), or None (a scene built in Python or read
        from a log's text); never compared, so it does not change what a scene is.
    as_written: (key path, text) of each time the scene gives as a fraction (`world.dt`,
        `bodies[3].enters_at`: `1/120`); `scene_to_yaml` writes them so, and the log's scene
        text keeps them as the author wrote them. Never compared: the values are the floats.
    """

    name: str
    world: WorldSettings
    bodies: tuple[BodySpec, ...]
    source: str = "<scene>"
    analytic: dict | None = None
    joints: tuple[JointSpec, ...] = ()
    marks: SceneMarks | None = field(default=None, compare=False, repr=False)
    as_written: tuple[tuple[str, str], ...] = field(default=(), compare=False, repr=False)
