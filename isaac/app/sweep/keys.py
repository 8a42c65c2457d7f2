"""Key paths (``bodies.box.restitution``) applied to a scene's YAML node tree, and the edited tree
written back as YAML text that the scene loader checks as it checks any scene.

Why the node tree and not a loaded `Scene`: a swept value must pass the scene's own validation,
with the scene's own messages (range, shape, overlap, a generator's options), so a run's scene is
the base scene's YAML with the swept values put in, read by `isaac.scene.load_scene_text` like
any other. The tree is composed once (isaac.scene.reader: line marks, our scalar rules); each run
only swaps a few nodes (`Slot`), and `emit` writes the tree as flow YAML in which every node of
the base scene stays on its own line, so an error the loader finds in a part of the scene the
sweep did not touch names the scene file's real line. A sweep's check does not write that text
for every run: `Sweep.load_run` puts the run's values into the tree itself, each on the line
`emit_lines` says the text gives it, and has the loader read the tree (the same Scene); a run
refused that way is read again from `emit`'s text, whose message it gets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from isaac.scene.reader import (
    MappingNode,
    Reader,
    ScalarNode,
    SequenceNode,
    join_path,
    plain_typed_text,
    scalar,
)

# components of a list by name: [x, y] pairs (position, velocity, gravity, base, ...)
_COMPONENTS = {"x": 0, "y": 1}
# list-valued keys whose default the loaded scene holds, so one component may be swept even when
# the scene does not write the list: {container: (key, where the loaded Scene keeps it)}
_BODY_PAIRS = ("position", "velocity")
_WORLD_PAIRS = ("gravity",)


class KeyError_(Exception):
    """A key path that does not name a place in the scene: `what` says why (one line)."""

    def __init__(self, what: str) -> None:
        super().__init__(what)
        self.what = what


@dataclass(frozen=True)
class Slot:
    """Where a swept value goes in the base scene's node tree.

    container: the MappingNode or SequenceNode that holds the value; key: the mapping key (str)
    or list index (int); scene_path: the key path the scene loader names that place by
    (``bodies[1].velocity[0]``), to tell whether a refusal is about this value.
    """

    container: object
    key: str | int
    scene_path: str

    def covers(self, path: str) -> bool:
        """Whether the loader's key path `path` is this value, inside it, or the list holding
        it (a refusal of the pair [x, y] when one component was swept)."""
        mine = self.scene_path
        if path == mine or path.startswith(mine + ".") or path.startswith(mine + "["):
            return True
        return mine.startswith(path + "[")

    def overlaps(self, other: Slot) -> bool:
        a, b = self.scene_path, other.scene_path
        return a == b or any(x.startswith(y + s) for x, y in ((a, b), (b, a)) for s in ".[")


def _get(mapping: MappingNode, key: str):
    for k, v in mapping.value:
        if k.value == key:
            return v
    return None


def _insert(mapping: MappingNode, key: str, node) -> None:
    mapping.value.append((ScalarNode(key, 0, None), node))


def _number_node(value: float) -> ScalarNode:
    return ScalarNode(repr(float(value)), 0, None)


def _component(segment: str) -> int | None:
    if segment in _COMPONENTS:
        return _COMPONENTS[segment]
    if segment.isdigit() and len(segment) < 7:
        return int(segment)
    return None


def resolve(key: str, root, scene) -> Slot:
    """The Slot of key path `key` in the scene tree `root` (composed from the text `scene` was
    loaded from). Raises KeyError_ when the path names no place in the scene.

    Paths: ``world.KEY``; ``bodies.NAME.KEY`` (NAME a body of the scene's `bodies:` list, by its
    name, the longest that matches when names hold dots); ``generators.INDEX.KIND.OPTION``; then
    ``.KEY`` into mappings and ``.INDEX`` (or ``.x`` / ``.y``) into lists. May add to the tree,
    once, what the scene leaves to defaults and means the same written out: an empty ``world:``
    mapping, and a body's position or velocity or the world's gravity as the loaded scene has it,
    so that one component of it can be swept.
    """
    if not isinstance(root, MappingNode):
        raise KeyError_("the scene is not a mapping")
    head, _, rest = key.partition(".")
    if head == "world":
        world = _get(root, "world")
        if world is None or (isinstance(world, ScalarNode) and scalar(world) is None):
            world = MappingNode(0)
            root.value = [(k, v) for k, v in root.value if k.value != "world"]
            _insert(root, "world", world)
        defaults = {k: getattr(scene.world, k) for k in _WORLD_PAIRS}
        return _walk(key, world, rest, "world", defaults)
    if head == "bodies":
        return _body_slot(key, root, rest, scene)
    if head == "generators":
        return _generator_slot(key, root, rest)
    raise KeyError_(
        f"a key path starts with world, bodies or generators, not {head!r} "
        "(e.g. bodies.NAME.restitution, world.dt, generators.0.pile.seed)"
    )


def _body_slot(key: str, root, rest: str, scene) -> Slot:
    items = _get(root, "bodies")
    explicit = items.value if isinstance(items, SequenceNode) else []
    names = [b.name for b in scene.bodies[: len(explicit)]]
    best = None
    for i, name in enumerate(names):
        if (rest == name or rest.startswith(name + ".")) and (
            best is None or len(name) > len(names[best])
        ):
            best = i
    if best is None:
        wanted = rest
        made = [b.name for b in scene.bodies[len(explicit) :]]
        for name in sorted(made, key=len, reverse=True):
            if rest == name or rest.startswith(name + "."):
                raise KeyError_(
                    f"body {name!r} is made by a generator: sweep the generator's options "
                    "instead (generators.INDEX.KIND.OPTION)"
                )
        import difflib

        close = difflib.get_close_matches(wanted.split(".")[0], names, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        listed = ", ".join(repr(n) for n in names[:8]) + (", ..." if len(names) > 8 else "")
        raise KeyError_(
            f"the scene has no body named {wanted.split('.')[0]!r}{hint}; its bodies: "
            f"{listed or 'none under bodies:'}"
        )
    name = names[best]
    after = rest[len(name) + 1 :]
    if not after:
        raise KeyError_(f"say which key of body {name!r} (e.g. bodies.{name}.restitution)")
    body = scene.bodies[best]
    defaults = {k: getattr(body, k) for k in _BODY_PAIRS}
    item = explicit[best]
    if not isinstance(item, MappingNode):
        raise KeyError_(f"body {name!r} is not a mapping in the scene")
    return _walk(key, item, after, f"bodies[{best}]", defaults)


def _generator_slot(key: str, root, rest: str) -> Slot:
    items = _get(root, "generators")
    gens = items.value if isinstance(items, SequenceNode) else []
    index_text, _, rest = rest.partition(".")
    if not index_text.isdigit() or len(index_text) > 6:
        raise KeyError_(f"generators.INDEX: expected a generator index, got {index_text!r}")
    index = int(index_text)
    if index >= len(gens):
        raise KeyError_(f"the scene has {len(gens)} generators (indices from 0), not {index + 1}")
    item = gens[index]
    if not isinstance(item, MappingNode) or len(item.value) != 1:
        raise KeyError_(f"generators[{index}] is not a generator mapping in the scene")
    ((kind_node, options),) = item.value
    kind, _, rest = rest.partition(".")
    if kind != kind_node.value:
        raise KeyError_(
            f"generators[{index}] is a {kind_node.value!r} generator, not {kind!r} "
            f"(generators.{index}.{kind_node.value}.OPTION)"
        )
    if not rest:
        raise KeyError_(f"say which option (e.g. generators.{index}.{kind}.seed)")
    if not isinstance(options, MappingNode):
        raise KeyError_(f"generators[{index}].{kind} is not a mapping in the scene")
    return _walk(key, options, rest, f"generators[{index}].{kind_node.value}", {})


def _walk(key: str, node, rest: str, scene_path: str, defaults: dict) -> Slot:
    """Follow the segments of `rest` from `node` (a mapping at `scene_path`)."""
    if not rest:
        raise KeyError_("the key path stops at a mapping: say which key in it")
    segments = rest.split(".")
    for j, seg in enumerate(segments):
        last = j == len(segments) - 1
        if isinstance(node, MappingNode):
            if not seg:
                raise KeyError_("empty segment in the key path (two dots, or a dot at the end)")
            path = join_path(scene_path, seg)
            if last:
                return Slot(node, seg, path)
            value = _get(node, seg)
            if value is None:
                if j == 0 and seg in defaults and _component(segments[1]) is not None:
                    value = SequenceNode(0)
                    value.value = [_number_node(v) for v in defaults[seg]]
                    _insert(node, seg, value)
                else:
                    raise KeyError_(
                        f"{seg!r} is not given in the scene at {scene_path}: write it in the "
                        f"scene to sweep a part of it, or sweep {seg!r} whole"
                    )
            node, scene_path = value, path
        elif isinstance(node, SequenceNode):
            index = _component(seg)
            if index is None:
                raise KeyError_(
                    f"{scene_path} is a list: expected an index (0, 1, ... or x, y), got {seg!r}"
                )
            if index >= len(node.value):
                raise KeyError_(
                    f"{scene_path} has {len(node.value)} items in the scene, no index {index}"
                )
            path = f"{scene_path}[{index}]"
            if last:
                return Slot(node, index, path)
            node, scene_path = node.value[index], path
        else:
            raise KeyError_(f"{scene_path} is a single value in the scene, it has no {seg!r}")
    raise AssertionError("unreachable")


# --- writing the edited tree ----------------------------------------------------------------


def _quoted(text: str) -> str:
    """`text` as a YAML double-quoted scalar (only printable characters written raw)."""
    out = ['"']
    for ch in text:
        if ch == '"' or ch == "\\":
            out.append("\\" + ch)
        elif ch.isprintable():
            out.append(ch)
        else:
            code = ord(ch)
            out.append(f"\\u{code:04x}" if code < 0x10000 else f"\\U{code:08x}")
    out.append('"')
    return "".join(out)


class _Emitter:
    def __init__(self, values: dict) -> None:
        self.values = values  # {(id(container), key): node}
        self.parts: list[str] = []
        self.line = 1
        self.value_lines: dict = {}  # {(id(container), key): the line its value is written on}

    def goto(self, line: int) -> None:
        # determinism and messages: each base node starts on its own line of the scene file;
        # continuation lines of a flow collection are indented by one space
        if line > self.line:
            self.parts.append("\n " * (line - self.line))
            self.line = line

    def node(self, node, own: bool) -> None:
        """Write `node`; `own`: it belongs to the base scene (keep its line)."""
        if own and node.line:
            self.goto(node.line)
        if isinstance(node, MappingNode):
            self.parts.append("{")
            first = True
            seen = set()
            for k, v in node.value:
                if not first:
                    self.parts.append(", ")
                first = False
                if own and k.line:
                    self.goto(k.line)
                self.parts.append(_quoted(k.value) + ": ")
                seen.add(k.value)
                swapped = self.values.get((id(node), k.value))
                if swapped is not None:
                    self.value_lines[id(node), k.value] = self.line
                self.node(v if swapped is None else swapped, own and swapped is None)
            for (container, key), v in self.values.items():
                if container == id(node) and isinstance(key, str) and key not in seen:
                    if not first:
                        self.parts.append(", ")
                    first = False
                    self.parts.append(_quoted(key) + ": ")
                    self.value_lines[container, key] = self.line
                    self.node(v, False)
            self.parts.append("}")
        elif isinstance(node, SequenceNode):
            self.parts.append("[")
            for i, v in enumerate(node.value):
                if i:
                    self.parts.append(", ")
                swapped = self.values.get((id(node), i))
                if swapped is not None:
                    self.value_lines[id(node), i] = self.line
                self.node(v if swapped is None else swapped, own and swapped is None)
            self.parts.append("]")
        else:
            value = scalar(node)
            if isinstance(value, str) and not plain_typed_text(node):
                self.parts.append(_quoted(node.value))
            elif value is None:
                self.parts.append("null")
            else:
                self.parts.append(node.value)


def emit(root, values: dict) -> str:
    """YAML text of the tree `root` with `values` ({(id(container), key): node}) put in place.

    Every node of the base tree starts on the line it had in the scene file; strings are
    double-quoted, numbers and booleans written as they were, so the loader reads each value
    exactly as it read the scene.
    """
    e = _Emitter(values)
    e.node(root, True)
    e.parts.append("\n")
    return "".join(e.parts)


def emit_lines(root, values: dict) -> tuple[str, dict]:
    """`emit`'s text and {(id(container), key): line}: the line of that text on which each value
    of `values` is written. A swapped value is written on the line the emitter is on (never on
    one of its own), so its line depends on the base tree and the places swapped, not on the
    values: what the scene loader reads as the value's line from the text."""
    e = _Emitter(values)
    e.node(root, True)
    e.parts.append("\n")
    return "".join(e.parts), e.value_lines


def value_node(value) -> ScalarNode:
    """A scalar node for a drawn value (float, int, bool or str)."""
    if isinstance(value, bool):
        return ScalarNode("true" if value else "false", 0, None)
    if isinstance(value, int):
        return ScalarNode(str(value), 0, None)
    if isinstance(value, float):
        if not math.isfinite(value):
            return ScalarNode(
                ".nan" if math.isnan(value) else (".inf" if value > 0 else "-.inf"), 0, None
            )
        return _number_node(value)
    return ScalarNode(str(value), 0, '"')


def plain_value(reader: Reader, node, path: str):
    """The Python value of a sweep value node, for the results table (lists as lists)."""
    return reader.plain(node, path)
