"""Reading back, fast, the exact text `scene_to_yaml` writes: the scene a log stores.

The YAML reader builds a node tree of the whole document (about 2 us and 160 bytes a node, 50
nodes a body of `scene_to_yaml`'s text) and reads each node in Python: a 100,000-body log's
scene took 87 s and 2 GB. Here the writer's lines are matched by regular expressions, a body
(12 lines) per match, and the bodies built directly; the name, world and `analytic` lines
(a few dozen) still go through the YAML reader, and every body through the same checks the
loader runs on an expanded scene (isaac.scene.checks.first_problem).

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
from isaac.scene.limits import MAX_BODIES, MAX_VERTICES, MAX_YAML_BYTES
from isaac.scene.reader import Reader, compose, fraction, shown
from isaac.scene.spec import BodySpec, Scene

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
_ESCAPE = re.compile(r'\\(["\\])')
_TAIL = re.compile(r"(?:analytic: \{[^\n]*\}\n)?\Z")


def read(text: str, source: str, default_name: str, read_head, body_alone) -> Scene | None:
    """The Scene of `text` if it is in `scene_to_yaml`'s form, else None.

    read_head(reader, root, default_name) -> (mapping, name, world, analytic) and
    body_alone(reader, text, line, index) -> SceneError | None are the YAML reader's
    (isaac.scene.loader): the first reads the head lines; the second reads one body's lines
    (starting at `line`, as body `index`) and returns the error it finds, for the message about a
    body that fails its checks. Raises SceneError for a text in this form that the YAML reader
    refuses.
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
    r = Reader(source)
    if _TAIL.match(text, pos) is None:
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
    # the head and the tail, at their own lines, read as YAML (bodies left out)
    tail_line = first_line + _BODY_LINES * len(bodies)
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
    return Scene(
        name=name,
        world=world,
        bodies=tuple(bodies),
        source=source,
        analytic=analytic,
        as_written=tuple(r.as_written + fractions),
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
