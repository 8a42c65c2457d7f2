"""Reading back, fast, the exact text `scene_to_yaml` writes: the scene a log stores.

The YAML reader builds a node tree of the whole document (50 nodes a body of `scene_to_yaml`'s
text) and reads each node in Python: a 100,000-body log's scene takes over a minute and
gigabytes that way. Here the writer's lines are matched by regular expressions, a body
(12 lines) per match, and the bodies built directly; the name, world and `analytic` lines
(a few dozen) still go through the YAML reader, and every body through the same checks the
loader runs on an expanded scene (isaac.scene.checks.first_problem).

The `joints:` section that may follow the bodies is matched the same way, a joint per match
(its kind's lines only), and each joint checked (isaac.scene.checks.joint_problem); one that
matches but does not fit is read alone by the YAML reader, for its message.

The result is the Scene the YAML reader gives for the same text, or None when the text is not
the writer's form line for line (then the YAML reader reads it). A body that matches but does
not pass the checks is read again, alone, by the YAML reader, so its message is the one the
YAML reader gives, with its line. A body with a collision filter (three more lines) is not in
this form: such scenes go through the YAML reader. The accepted form is strict: each line
exactly as the writer writes it, numbers as `repr(float)` writes them (a "." or an exponent)
or, for a time the author wrote as a fraction, as written (`1/120`), names without escapes
other than \\" and \\\\.
"""

from __future__ import annotations

import re

from isaac.errors import SceneError
from isaac.scene import checks
from isaac.scene.limits import MAX_BODIES, MAX_JOINTS, MAX_VERTICES, MAX_YAML_BYTES
from isaac.scene.reader import Reader, compose, fraction, shown
from isaac.scene.spec import BodySpec, JointSpec, Scene

_F = r"-?[0-9]+(?:\.[0-9]+(?:e[-+][0-9]+)?|e[-+][0-9]+)"  # repr(float) of a finite float
_PAIR = rf"\[{_F}, {_F}\]"
_TIME = rf"{_F}|[0-9]+/[0-9]+"  # a time as repr writes it, or as the author wrote a fraction
_QUOTED = r'"(?:[^"\\\n]|\\[^\n])*"'  # one line; the YAML reader decodes it (head only)
_NAME = r'"((?:[^"\\\n]|\\["\\])*)"'

# `name:`, `world:` and one line per world setting, each value a whole flow scalar or a pair on
# its line, so nothing in the head can reach past `bodies:`.
_HEAD = re.compile(
    rf"name: {_QUOTED}\nworld:\n(?:  [a-z_]+: (?:{_QUOTED}|[-+./0-9a-z_]+|{_PAIR})\n)*bodies:\n"
)
_POLYGON = rf"polygon: \[({_PAIR}(?:, {_PAIR}){{2,{MAX_VERTICES - 1}}})\]"
_CIRCLE = rf"circle: \{{radius: ({_F})\}}"
_BODY = re.compile(
    rf"""  - name: {_NAME}
    shape: \{{(?:{_POLYGON}|{_CIRCLE})\}}
    position: \[({_F}), ({_F})\]
    angle: ({_F})
    velocity: \[({_F}), ({_F})\]
    angular_velocity: ({_F})
    density: ({_F})
    restitution: ({_F})
    friction: ({_F})
    concrete: (true|false)
    enters_at: ({_TIME})
    leaves_at: ({_TIME}|null)
"""
)
_BODY_LINES = 12
# a joint as `scene_to_yaml` writes it: the lines its kind does not use are left out (which lines
# fit which kind is checked after the match, in `_joint`)
_JOINT = re.compile(
    rf"""  - name: {_NAME}
    type: (revolute|distance|weld|prismatic)
    bodies: \[{_NAME}, {_NAME}\]
    frame: body
    anchor_a: \[({_F}), ({_F})\]
    anchor_b: \[({_F}), ({_F})\]
(?:    axis: \[({_F}), ({_F})\]
)?    reference_angle: ({_F})
(?:    length: ({_F})
)?(?:    min_length: ({_F})
)?(?:    max_length: ({_F})
)?(?:    stiffness: ({_F})
    damping_ratio: ({_F})
)?(?:    limits: \[({_F}), ({_F})\]
)?(?:    motor: \{{speed: ({_F}), max_(torque|force): ({_F})\}}
)?    collide_connected: (true|false)
"""
)
_ESCAPE = re.compile(r'\\(["\\])')
_TAIL = re.compile(r"(?:analytic: \{[^\n]*\}\n)?\Z")


def read(
    text: str, source: str, default_name: str, read_head, body_alone, joint_alone=None
) -> Scene | None:
    """The Scene of `text` if it is in `scene_to_yaml`'s form, else None.

    read_head(reader, root, default_name) -> (mapping, name, world, analytic),
    body_alone(reader, text, line, index) -> SceneError | None and
    joint_alone(reader, text, line, index, bodies, index_of) -> JointSpec are the YAML reader's
    (isaac.scene.loader.read_head, isaac.scene.bodies.body_alone and
    isaac.scene.joints.joint_alone): the first reads the head lines; the second reads one body's
    lines (starting at `line`, as body `index`) and returns the error it finds, for the message
    about a body that fails its checks; the third reads one joint's lines as joints[index]
    (`index_of`: the bodies' indices by name) and raises the error it finds. A joint whose lines
    match but do not fit its kind or fail the checks is read by `joint_alone`, so the message (or
    the joint) is the YAML reader's. Without `joint_alone` a text with joints is left to the YAML
    reader. Raises SceneError for a text in this form that the YAML reader refuses.
    """
    head = _HEAD.match(text)
    if head is None:
        return None
    pos = head.end()
    first_line = text.count("\n", 0, pos) + 1  # the line of the first body's `- name:`
    bodies: list[BodySpec] = []
    starts: list[int] = []
    fractions: list[tuple[str, str]] = []  # (key path, text) of the bodies' times as fractions
    match = _BODY.match
    while (found := match(text, pos)) is not None:
        if len(bodies) == MAX_BODIES:
            raise SceneError(
                f"expected at most {MAX_BODIES} bodies, got more",
                source=source,
                line=first_line,
                path="bodies",
            )
        starts.append(pos)
        try:
            bodies.append(_body(found, len(bodies), fractions))
        except ValueError:
            return None  # a fraction that divides by zero: the YAML reader says so, at its line
        pos = found.end()
    # the joints, after the bodies: matched here, built once the bodies are known good
    joint_matches: list[tuple[re.Match, int]] = []  # (match, line of its `- name:`)
    joints_line = first_line + _BODY_LINES * len(bodies)  # the `joints:` line, if any
    tail_line = joints_line
    bad_joint = None  # (start, line) of a joint that does not match, in a text too long for YAML
    if text.startswith("joints:\n", pos):
        if joint_alone is None:
            return None
        pos += len("joints:\n")
        tail_line += 1
        match = _JOINT.match
        while (found := match(text, pos)) is not None:
            if len(joint_matches) == MAX_JOINTS:
                raise SceneError(
                    f"expected at most {MAX_JOINTS} joints, got more",
                    source=source,
                    line=joints_line,
                    path="joints",
                )
            joint_matches.append((found, tail_line))
            tail_line += found.group().count("\n")
            pos = found.end()
        if not joint_matches:
            return None
        if _TAIL.match(text, pos) is None and len(text) > MAX_YAML_BYTES:
            if text.startswith("  - ", pos):
                bad_joint = (pos, tail_line)
            else:
                return None
    r = Reader(source)
    # (a joint that does not match is said once the bodies are read: its message needs them)
    if bad_joint is None and _TAIL.match(text, pos) is None:
        if len(text) > MAX_YAML_BYTES and text.startswith("  - ", pos):
            # too long for the YAML reader: say what is wrong with the body that does not match
            end = text.find("\n  - ", pos + 1)
            end = len(text) if end < 0 else end + 1
            line = first_line + _BODY_LINES * len(bodies)
            error = body_alone(r, text[pos:end], line, len(bodies))
            if error is not None:
                raise error
        return None
    if not bodies:
        return None
    # the head and the tail, at their own lines, read as YAML (bodies and joints left out)
    if bad_joint is not None:
        pos = len(text)  # the head alone: the joints' tail is not read
    rest = text[: head.end() - len("bodies:\n")]
    rest += "\n" * (tail_line - rest.count("\n") - 1) + text[pos:]
    _, name, world, analytic = read_head(r, compose(rest, source), default_name)

    seen: dict[str, int] = {}
    duplicate = None
    for i, body in enumerate(bodies):
        if body.name in seen:
            duplicate = i
            break
        seen[body.name] = i
    problem = checks.first_problem(bodies)
    if problem is not None and (duplicate is None or problem.index < duplicate):
        i = problem.index
        end = starts[i + 1] if i + 1 < len(starts) else pos
        error = body_alone(r, text[starts[i] : end], first_line + _BODY_LINES * i, i)
        if error is not None:
            raise error
        return None  # the YAML reader accepts what the checks refuse: let it read the text
    if duplicate is not None:
        i, first = duplicate, seen[bodies[duplicate].name]
        raise SceneError(
            f"duplicate body name {shown(bodies[i].name)} (already used by bodies[{first}].name "
            f"at line {first_line + _BODY_LINES * first})",
            source=source,
            line=first_line + _BODY_LINES * i,
            path=f"bodies[{i}].name",
        )
    joints = ()
    if joint_matches:
        problem = checks.joint_solver_problem(world.solver, joint_matches)
        if problem is not None:
            raise SceneError(problem, source=source, line=joints_line, path="joints")
        joints = _joints(r, joint_matches, bodies, joint_alone)
        if bad_joint is not None:
            start, line = bad_joint
            end = text.find("\n  - ", start + 1)
            end = len(text) if end < 0 else end + 1
            joint_alone(r, text[start:end], line, len(joints), bodies, _index_of(bodies))
            return None  # a joint the YAML reader accepts but not in this form
    return Scene(
        name=name,
        world=world,
        bodies=tuple(bodies),
        source=source,
        analytic=analytic,
        joints=joints,
        as_written=tuple(r.as_written + fractions),
    )


def _index_of(bodies) -> dict[str, int]:
    return {body.name: i for i, body in enumerate(bodies)}


def _joints(r: Reader, found, bodies, joint_alone) -> tuple[JointSpec, ...]:
    """The JointSpecs of the matched joints `found` ((match, line) each), in order; a joint not
    in the strict form or failing the checks is read by `joint_alone` (which raises its error).
    Names unique, as the YAML reader requires (same message)."""
    index_of = _index_of(bodies)
    joints: list[JointSpec] = []
    seen: dict[str, int] = {}
    for k, (match, line) in enumerate(found):
        joint = _joint(match, index_of)
        if joint is None or checks.joint_problem(bodies, joint) is not None:
            joint = joint_alone(r, match.group(), line, k, bodies, index_of)
        if joint.name in seen:
            raise SceneError(
                f"duplicate joint name {shown(joint.name)} (already used by "
                f"joints[{seen[joint.name]}].name at line {found[seen[joint.name]][1]})",
                source=r.source,
                line=line,
                path=f"joints[{k}].name",
            )
        seen[joint.name] = k
        joints.append(joint)
    return tuple(joints)


# the optional lines of a joint each kind may have (the others it must not)
_KIND_LINES = {
    "revolute": ("limits", "motor"),
    "distance": ("length", "min_length", "max_length", "stiffness"),
    "weld": ("stiffness",),
    "prismatic": ("axis", "limits", "motor"),
}


def _joint(found: re.Match, index_of: dict) -> JointSpec | None:
    """The JointSpec of a matched joint, or None when its lines do not fit its kind (or name an
    unknown body, or give an axis not already unit): then the YAML reader reads it."""
    (name, kind, name_a, name_b, ax, ay, bx, by, axis_x, axis_y, reference, length, low,
     high, stiffness, damping, lower, upper, speed, most, max_motor,
     collide) = found.groups()  # fmt: skip
    given = {
        "axis": axis_x,
        "length": length,
        "min_length": low,
        "max_length": high,
        "stiffness": stiffness,
        "limits": lower,
        "motor": speed,
    }
    allowed = _KIND_LINES[kind]
    if any(value is not None and key not in allowed for key, value in given.items()):
        return None
    if kind == "distance" and length is None:
        return None  # the default length is the YAML reader's to compute
    if speed is not None and most != ("torque" if kind == "revolute" else "force"):
        return None
    if kind == "prismatic" and axis_x is None:
        return None
    names = [_ESCAPE.sub(r"\1", n) if "\\" in n else n for n in (name, name_a, name_b)]
    a, b = index_of.get(names[1]), index_of.get(names[2])
    if a is None or b is None:
        return None
    values = {}
    if axis_x is not None:
        axis = (float(axis_x), float(axis_y))
        if checks.unit_axis(axis) != axis:
            return None
        values["axis"] = axis
    if length is not None:
        values["length"] = float(length)
    if low is not None:
        values["min_length"] = float(low)
    if high is not None:
        values["max_length"] = float(high)
    if stiffness is not None:
        values["stiffness"] = float(stiffness)
        values["damping_ratio"] = float(damping)
    if lower is not None:
        values["lower"], values["upper"] = float(lower), float(upper)
    if speed is not None:
        values["motor_speed"], values["max_motor"] = float(speed), float(max_motor)
    return JointSpec(
        name=names[0],
        kind=kind,
        a=a,
        b=b,
        local_a=(float(ax), float(ay)),
        local_b=(float(bx), float(by)),
        reference_angle=float(reference),
        collide_connected=collide == "true",
        **values,
    )


def _time(text: str, path: str, fractions: list) -> float:
    if "/" in text:
        fractions.append((path, text))
        return fraction(text)
    return float(text)


def _body(found: re.Match, index: int, fractions: list) -> BodySpec:
    (name, vertices, radius, px, py, angle, vx, vy, spin, density, restitution, friction,
     concrete, enters_at, leaves_at) = found.groups()  # fmt: skip
    if "\\" in name:
        name = _ESCAPE.sub(r"\1", name)
    if vertices is None:
        shape = ()
    else:
        # the match has checked every number and bracket: splitting is enough
        numbers = map(float, vertices.replace("[", "").replace("]", "").split(", "))
        shape = tuple(zip(numbers, numbers))
    return BodySpec(
        name=name,
        vertices=shape,
        circle=None if radius is None else float(radius),
        position=(float(px), float(py)),
        angle=float(angle),
        velocity=(float(vx), float(vy)),
        angular_velocity=float(spin),
        density=float(density),
        restitution=float(restitution),
        friction=float(friction),
        concrete=concrete == "true",
        enters_at=_time(enters_at, f"bodies[{index}].enters_at", fractions),
        leaves_at=(
            None
            if leaves_at == "null"
            else _time(leaves_at, f"bodies[{index}].leaves_at", fractions)
        ),
    )
