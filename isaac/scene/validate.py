"""The loader's checks, run on a `Scene` however it was made (built in Python, changed with
`dataclasses.replace`): what the engine builds its model from (`isaac.engine.world.build_model`).

A scene built in Python never passed the YAML loader, and the compiled kernels trust their
input: a NaN position, a zero mass or a joint naming a body past the end would reach them. So
`check_scene` runs the loader's own value checks (`isaac.scene.checks`: `world_problem`,
`first_problem`, `first_joint_problem`) after making sure every field holds the kind of value
those checks read (a `BodySpec` with a string for its density is refused here, not turned
into numpy's error). docs/physics.md, "The Python API's guards".

A scene passes once: `checked` remembers every scene that passed (and the loader's, via
`remember`, which ran the same checks as it read them), so that a scene of 100,000 bodies is
not checked again by each simulation built from it. Only a scene of tuples is remembered (a
frozen Scene holding lists could change after its check).
"""

from __future__ import annotations

import dataclasses
import numbers
import weakref

from isaac.errors import SceneError
from isaac.scene import checks
from isaac.scene.limits import MAX_BODIES, MAX_NAME_LENGTH, MAX_VERTICES
from isaac.scene.reader import shown, valid_name
from isaac.scene.spec import BodySpec, JointSpec, Scene

# what each field of a BodySpec holds: "number", "pair" (two numbers), "vertices" (pairs),
# "name", "bool", "whole" (an int); "number?" is a number or None
_BODY_KINDS = {
    "name": "name",
    "vertices": "vertices",
    "position": "pair",
    "angle": "number",
    "velocity": "pair",
    "angular_velocity": "number",
    "density": "number",
    "restitution": "number",
    "friction": "number",
    "concrete": "bool",
    "enters_at": "number",
    "leaves_at": "number?",
    "circle": "number?",
    "category": "whole",
    "mask": "whole",
    "group": "whole",
}
_JOINT_KINDS = {
    "name": "name",
    "kind": "name",
    "a": "whole",
    "b": "whole",
    "local_a": "pair",
    "local_b": "pair",
    "axis": "pair",
    "reference_angle": "number",
    "length": "number",
    "min_length": "number?",
    "max_length": "number?",
    "stiffness": "number?",
    "damping_ratio": "number",
    "lower": "number?",
    "upper": "number?",
    "motor_speed": "number?",
    "max_motor": "number",
    "collide_connected": "bool",
}
assert set(_BODY_KINDS) == {f.name for f in dataclasses.fields(BodySpec)}
assert set(_JOINT_KINDS) == {f.name for f in dataclasses.fields(JointSpec)}

_WANTED = {
    "name": "a string",
    "number": "a number (int or float)",
    "number?": "a number (int or float) or None",
    "pair": "a tuple of two numbers",
    "vertices": f"a tuple of at most {MAX_VERTICES} (x, y) tuples of numbers",
    "bool": "True or False",
    "whole": "an int",
}


def _number(x) -> bool:
    # what the checks' ranges and the scene writer take: Python ints and floats, not bool
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _pair(p) -> bool:
    return isinstance(p, tuple) and len(p) == 2 and _number(p[0]) and _number(p[1])


def _holds(kind: str, value) -> bool:
    """Whether `value` is the kind of value `kind` names (the ranges are the checks')."""
    if kind == "number":
        return _number(value)
    if kind == "number?":
        return value is None or _number(value)
    if kind == "pair":
        return _pair(value)
    if kind == "name":
        return isinstance(value, str)
    if kind == "bool":
        return isinstance(value, bool)
    if kind == "whole":
        return isinstance(value, numbers.Integral) and not isinstance(value, bool)
    # vertices: a vertex count past the largest is said by the checks, with the count
    return isinstance(value, tuple) and (len(value) > MAX_VERTICES or all(_pair(v) for v in value))


def _kind_problem(spec, kinds: dict) -> tuple[str, str] | None:
    for field, kind in kinds.items():
        value = getattr(spec, field)
        if not _holds(kind, value):
            return field, f"{field} must be {_WANTED[kind]}, got {_shown(value)}"
    return None


def _shown(value) -> str:
    if isinstance(value, str):
        return shown(value)
    if hasattr(value, "shape") and hasattr(value, "dtype"):  # a numpy array: no repr of it
        return f"a {type(value).__name__} of shape {value.shape}"
    text = repr(value)
    return text if len(text) <= 80 else f"{text[:80]}... ({type(value).__name__})"


# id(scene) -> a weak reference to it, for every scene known to pass (see the module's doc)
_PASSED: dict[int, weakref.ref] = {}


def remember(scene: Scene) -> Scene:
    """Note that `scene` passes `check_scene` (the loader calls it on what it made, having run
    the same checks); returns `scene`. A scene holding lists is not noted."""
    if not (
        type(scene.bodies) is tuple
        and type(scene.joints) is tuple
        and type(scene.world.gravity) is tuple
    ):
        return scene
    key = id(scene)
    _PASSED[key] = weakref.ref(scene, lambda _, key=key: _PASSED.pop(key, None))
    return scene


def checked(scene: Scene) -> Scene:
    """`scene` after `check_scene`, unless it is known to pass already (`remember`)."""
    known = _PASSED.get(id(scene))
    if known is None or known() is not scene:
        check_scene(scene)
        remember(scene)
    return scene


def _items(value, what: str, spec_type, source: str) -> tuple:
    if not isinstance(value, (tuple, list)):
        raise SceneError(
            f"must be a tuple of {spec_type.__name__}s, got {type(value).__name__}",
            source=source,
            path=what,
        )
    for i, item in enumerate(value):
        if not isinstance(item, spec_type):
            raise SceneError(
                f"must be an isaac.scene.{spec_type.__name__}, got {type(item).__name__}",
                source=source,
                path=f"{what}[{i}]",
            )
    return tuple(value)


def check_scene(scene: Scene) -> None:
    """Refuse `scene` unless the loader would have made it: TypeError when it is not a
    `Scene`, else a SceneError (one line) at the first thing wrong, naming its key path, the
    body or joint and the field, e.g. ``<scene>: bodies[2].density: body 'box': density nan
    is out of range ...``.

    Checked: the scene's name; every world setting (`checks.world_problem`); 1 to MAX_BODIES
    `BodySpec`s, each field holding a value of its kind (numbers are Python ints or floats;
    pairs and vertices tuples), then `checks.first_problem` (shapes, ranges, mass and
    inertia); unique body names; `JointSpec`s of their kinds, `checks.joint_solver_problem`
    and `checks.first_joint_problem` (body indices, ranges, unique names).
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"a simulation runs an isaac.scene.Scene, got {type(scene).__name__}")
    source = scene.source if isinstance(scene.source, str) else "<scene>"
    if not isinstance(scene.name, str) or not valid_name(scene.name):
        raise SceneError(
            f"the scene's name {_shown(scene.name)} is not 1 to {MAX_NAME_LENGTH} printable "
            "characters",
            source=source,
            path="name",
        )
    if scene.analytic is not None and not isinstance(scene.analytic, dict):
        raise SceneError(
            f"must be a dict or None, got {type(scene.analytic).__name__}",
            source=source,
            path="analytic",
        )
    why = checks.world_problem(scene.world)
    if why is not None:
        field, what = why
        path = "world" if field == "world" else f"world.{field}"
        raise SceneError(what, source=source, path=path)
    bodies = _items(scene.bodies, "bodies", BodySpec, source)
    if not bodies:
        raise SceneError("the scene has no bodies", source=source, path="bodies")
    if len(bodies) > MAX_BODIES:
        raise SceneError(
            f"the scene has {len(bodies)} bodies, more than {MAX_BODIES}",
            source=source,
            path="bodies",
        )
    for i, body in enumerate(bodies):
        why = _kind_problem(body, _BODY_KINDS)
        if why is not None:
            raise _body_error(source, i, body, *why)
    problem = checks.first_problem(bodies)
    if problem is not None:
        i, field, what = problem
        raise _body_error(source, i, bodies[i], field, what)
    first: dict[str, int] = {}
    for i, body in enumerate(bodies):
        j = first.setdefault(body.name, i)
        if j != i:
            raise _body_error(
                source, i, body, "name", f"duplicate body name (already used by bodies[{j}])"
            )
    joints = _items(scene.joints, "joints", JointSpec, source)
    for i, joint in enumerate(joints):
        why = _kind_problem(joint, _JOINT_KINDS)
        if why is not None:
            raise _joint_error(source, i, joint, *why)
    refusal = checks.joint_solver_problem(scene.world.solver, joints)
    if refusal is not None:
        raise SceneError(refusal, source=source, path="joints")
    problem = checks.first_joint_problem(bodies, joints)
    if problem is not None:
        i, field, what = problem
        raise _joint_error(source, i, joints[i] if i < len(joints) else None, field, what)


def _body_error(source: str, i: int, body: BodySpec, field: str, what: str) -> SceneError:
    name = shown(body.name) if isinstance(body.name, str) else "(unnamed)"
    return SceneError(f"body {name}: {what}", source=source, path=f"bodies[{i}].{field}")


def _joint_error(source: str, i: int, joint, field: str, what: str) -> SceneError:
    name = shown(joint.name) if joint is not None and isinstance(joint.name, str) else ""
    said = f"joint {name}: " if name else ""
    return SceneError(f"{said}{what}", source=source, path=f"joints[{i}].{field}")
