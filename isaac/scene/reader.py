"""Reading YAML with line marks: a composer that refuses what a scene may not hold, scalars read
by our own rules, and `Reader`, typed access whose every failure names file, line and key path.

We never let PyYAML construct Python objects, nor even build its node tree: we take the parser's
events (libyaml's when available) and compose our own small nodes (value, line, style), refusing
anchors, aliases and explicit tags and stopping at the node, list and nesting limits of
isaac.scene.limits, so a hostile document is refused before it costs much time or memory. Then
we read every scalar ourselves. That is how we get line numbers in every message, refuse
duplicate keys (PyYAML keeps the last one silently), read `1e3` as a number (YAML 1.1 reads it
as a string) and keep `off`/`no`/`yes` as strings (YAML 1.1 reads them as booleans; only
`true`/`false` are booleans here).

Every value or key a message quotes is cut to MAX_QUOTED characters (`shown`), so a 1 MB value
gives a short line.
"""

from __future__ import annotations

import difflib
import math
import re
from fractions import Fraction

import yaml

from isaac.errors import SceneError
from isaac.scene.limits import (
    MAX_BODY_NODES,
    MAX_LIST_ITEMS,
    MAX_NAME_LENGTH,
    MAX_NESTING,
    MAX_QUOTED,
    MAX_SECTION_NODES,
    MAX_VERTICES,
    MAX_YAML_NODES,
)

_INT_RE = re.compile(r"[-+]?[0-9]+\Z")
_HEX_RE = re.compile(r"0[xX][0-9a-fA-F]{1,16}\Z")
_FLOAT_RE = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?\Z")
_NONFINITE_RE = re.compile(r"[-+]?\.?(?:nan|inf|infinity)\Z", re.IGNORECASE)
_NULLS = ("null", "~", "")
# a time written as a fraction of whole numbers: `dt: 1/120`
_FRACTION_RE = re.compile(r"[-+]?[0-9]+/[0-9]+\Z")
_BOOLEAN_SPELLINGS = {
    **dict.fromkeys(("true", "yes", "on", "y"), "true"),
    **dict.fromkeys(("false", "no", "off", "n"), "false"),
}


# --- nodes ----------------------------------------------------------------------------------


class ScalarNode:
    """A scalar as written: `value` the text, `line` 1-based, `style` None or "" when plain,
    else the quote or block indicator."""

    __slots__ = ("value", "line", "style")

    def __init__(self, value: str, line: int, style) -> None:
        self.value = value
        self.line = line
        self.style = style


class SequenceNode:
    """A list: `value` the item nodes in order, `line` 1-based."""

    __slots__ = ("value", "line")

    def __init__(self, line: int) -> None:
        self.value: list = []
        self.line = line


class MappingNode:
    """A mapping: `value` the (key node, value node) pairs in document order, `line` 1-based."""

    __slots__ = ("value", "line")

    def __init__(self, line: int) -> None:
        self.value: list = []  # while composing: key, value, key, value, ...
        self.line = line


class _NoAliasLoader(yaml.SafeLoader):
    """PyYAML's pure-Python reader, scanner and parser; only its events are used."""


if getattr(yaml, "__with_libyaml__", False):
    _LOADER = yaml._yaml.CParser  # libyaml: the same events, about 4x faster
else:  # pragma: no cover - libyaml ships with PyYAML's wheels
    _LOADER = _NoAliasLoader


class Refused(Exception):
    def __init__(self, what: str, line: int | None) -> None:
        self.what = what
        self.line = line


def _compose(parser, document: str = "a scene"):
    """The root node of the one document `parser` yields (None for an empty stream); `document`
    names it in a refusal of anchors, aliases and tags ("a sweep file").

    Bounds, each refused as soon as it is passed: MAX_YAML_NODES nodes in all, of which at most
    MAX_SECTION_NODES under any top-level key but `bodies` (or in all, if the root is not a
    mapping) and MAX_BODY_NODES in any one item of `bodies`; MAX_LIST_ITEMS items in a list;
    MAX_NESTING open lists and mappings.
    """
    get = parser.get_event
    get()  # StreamStartEvent
    event = get()
    if isinstance(event, yaml.StreamEndEvent):
        return None
    scalar_event = yaml.ScalarEvent
    sequence_start = yaml.SequenceStartEvent
    mapping_start = yaml.MappingStartEvent
    mapping_end = yaml.MappingEndEvent
    ends = (yaml.SequenceEndEvent, mapping_end)
    open_nodes: list = []  # the sequences and mappings being composed, outermost first
    count = 0
    section, section_count, section_limit = "", 0, MAX_SECTION_NODES
    in_bodies, item_count, item_line = False, 0, 0
    root = None
    while root is None:
        event = get()
        kind = type(event)
        if kind in ends:
            node = open_nodes.pop()
            if kind is mapping_end:
                flat = node.value
                node.value = list(zip(flat[0::2], flat[1::2]))
            if not open_nodes:
                root = node
            continue
        if kind is yaml.AliasEvent:
            raise Refused(f"YAML aliases (*name) are not allowed in {document}", _line(event))
        if event.anchor is not None:
            raise Refused(f"YAML anchors (&name) are not allowed in {document}", _line(event))
        if event.tag not in (None, "!"):
            raise Refused(
                f"YAML tags ({shown(event.tag)}) are not allowed in {document}", _line(event)
            )
        line = event.start_mark.line + 1
        count += 1
        if count > MAX_YAML_NODES:
            raise Refused(
                f"the document has more than {MAX_YAML_NODES} YAML nodes (values, lists and "
                "mappings); write bigger scenes with generators, or as scene_to_yaml writes them",
                line,
            )
        depth = len(open_nodes)
        if depth == 1 and type(open_nodes[0]) is MappingNode:
            keys = open_nodes[0].value
            if len(keys) % 2:  # the value of a top-level key: a new section
                key = keys[-1]
                section = key.value if type(key) is ScalarNode else "?"
                in_bodies = section == "bodies"
                section_count = 0
                section_limit = MAX_YAML_NODES if in_bodies else MAX_SECTION_NODES
            else:  # a top-level key
                in_bodies, section = False, ""
        elif depth >= 2 and in_bodies:
            if depth == 2:
                item_count, item_line = 0, line
            item_count += 1
            if item_count > MAX_BODY_NODES:
                raise Refused(
                    f"this body has more than {MAX_BODY_NODES} YAML nodes (one of "
                    f"{MAX_VERTICES} vertices with every key has {MAX_VERTICES * 3 + 31})",
                    item_line,
                )
        section_count += 1
        if section_count > section_limit:
            where = f"`{shown(section)[1:-1]}:`" if section else "the document"
            raise Refused(f"{where} holds more than {section_limit} YAML nodes", line)
        if kind is scalar_event:
            node = ScalarNode(event.value, line, event.style)
        elif kind is sequence_start:
            node = SequenceNode(line)
        elif kind is mapping_start:
            node = MappingNode(line)
        else:  # pragma: no cover - the parser yields nothing else inside a document
            raise AssertionError(f"unexpected YAML event {event}")
        if depth:
            parent = open_nodes[-1]
            items = parent.value
            items.append(node)
            if len(items) > MAX_LIST_ITEMS and type(parent) is SequenceNode:
                raise Refused(
                    f"the list that starts here has more than {MAX_LIST_ITEMS} items",
                    parent.line,
                )
        elif kind is scalar_event:
            root = node
        if kind is not scalar_event:
            open_nodes.append(node)
            if depth >= MAX_NESTING:
                raise Refused("the document is nested too deeply", line)
    get()  # DocumentEndEvent
    event = get()
    if not isinstance(event, yaml.StreamEndEvent):
        raise Refused(
            "YAML syntax error: expected a single document in the stream, but found another "
            "document",
            _line(event),
        )
    return root


def _line(event) -> int | None:
    return None if event.start_mark is None else event.start_mark.line + 1


def shown(text: str) -> str:
    """`text` quoted for a message, cut to MAX_QUOTED characters (then its length is said)."""
    if len(text) <= MAX_QUOTED:
        return repr(text)
    return f"{text[:MAX_QUOTED]!r}... ({len(text)} characters)"


def _cut(text: str) -> str:
    """`text` (a number as written) for a message, unquoted, cut like `shown`."""
    if len(text) <= MAX_QUOTED:
        return text
    return f"{text[:MAX_QUOTED]}... ({len(text)} characters)"


def line_of(node) -> int:
    return node.line


def join_path(path: str, key: str) -> str:
    if len(key) > MAX_QUOTED or not key.isprintable():  # keep the message one short line
        key = shown(key)
    return f"{path}.{key}" if path else key


def describe(node) -> str:
    if isinstance(node, MappingNode):
        return "a mapping"
    if isinstance(node, SequenceNode):
        return "a list"
    value = scalar(node)
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f"the string {shown(node.value)}{_quoted_hint(node)}"
    return f"the number {_cut(node.value)}"


def plain_typed_text(node) -> bool:
    """Whether `node` is a plain scalar that `scalar` keeps as text but a typed reader takes as
    a number: a fraction (`1/120`, Reader.time) or a `0x...` (Reader.bits). Such text must be
    written back unquoted: quoted, it is a string (isaac.app.sweep.keys writes runs' scenes)."""
    text = node.value
    return not node.style and bool(_FRACTION_RE.match(text) or _HEX_RE.match(text))


def _quoted_hint(node) -> str:
    """For a quoted scalar that would be a number, a boolean, null, a `0x...` or a fraction
    unquoted: a note saying that quotes make it a string (the one rule: a quoted value is a
    string, wherever it is)."""
    if not node.style or node.style not in ("'", '"'):
        return ""
    text = node.value
    plain = scalar(ScalarNode(text, node.line, None))
    if isinstance(plain, str) and not (_HEX_RE.match(text) or _FRACTION_RE.match(text)):
        return ""
    return " (quoted, so a string: write it without quotes)"


def scalar(node):
    """Python value of a scalar node: None, bool, int, float (may be non-finite) or str."""
    text = node.value
    if node.style:  # quoted or block scalar: always a string (plain is None, or "" from libyaml)
        return text
    if text in _NULLS:
        return None
    if text == "true":
        return True
    if text == "false":
        return False
    if _INT_RE.match(text):
        if len(text) > 30:  # far out of every range, and int() refuses huge digit strings
            return math.copysign(math.inf, -1.0 if text.startswith("-") else 1.0)
        return int(text)
    if _FLOAT_RE.match(text):
        return float(text)
    if _NONFINITE_RE.match(text):
        return float(
            text.replace(".nan", "nan")
            .replace(".NaN", "nan")
            .replace(".NAN", "nan")
            .replace(".inf", "inf")
            .replace(".Inf", "inf")
            .replace(".INF", "inf")
        )
    return text


def valid_name(value: str) -> bool:
    """Whether `value` may name a body or a scene: 1 to MAX_NAME_LENGTH printable characters."""
    return 0 < len(value) <= MAX_NAME_LENGTH and value.isprintable()


def _suggestion(text: str, options) -> str | None:
    if len(text) > 4 * MAX_QUOTED:  # difflib is quadratic: a 1 MB key is no typo
        return None
    close = difflib.get_close_matches(text, list(options), n=1, cutoff=0.6)
    return close[0] if close else None


def suggestion(text: str, options) -> str | None:
    """The option of `options` closest to the misspelt `text` (difflib, cutoff 0.6), or None."""
    return _suggestion(text, options)


def fraction(text: str) -> float:
    """The float nearest the fraction `text` ("1/120", whole numbers either side), correctly
    rounded (`fractions.Fraction`), so `1/120` is the float Python's 1 / 120 gives. ValueError
    with a one-line reason for anything else or a zero denominator. `isaac tradeoff --grid dt=`
    and the scene's times read fractions through this one function."""
    text = text.strip()
    if not _FRACTION_RE.match(text):
        raise ValueError(f"cannot read {_cut(text)} as a fraction of whole numbers")
    try:
        return float(Fraction(text))
    except ZeroDivisionError:
        raise ValueError(f"the fraction {_cut(text)} divides by zero") from None


class Reader:
    """Typed access to a composed node tree; every failure is a SceneError with line and path.

    as_written: (key path, text) of every time read as a fraction, in reading order, so the
    scene's text can be written back as the author wrote it (Scene.as_written)."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.as_written: list[tuple[str, str]] = []

    def fail(self, what: str, node=None, path: str = "") -> SceneError:
        return SceneError(
            what, source=self.source, line=None if node is None else line_of(node), path=path
        )

    def given(self, m: dict, key: str, path: str, wanted: str):
        """The value node of `key` in mapping `m` (`mapping`'s result at `path`), None when it is
        left out; a null there is refused, since only leaves_at and container.height may be
        null (docs/scene-format.md, YAML rules): `joints: null` is not "no joints"."""
        if key not in m:
            return None
        node = m[key][1]
        if isinstance(node, ScalarNode) and scalar(node) is None:
            raise self.fail(
                f"expected {wanted}, got null (only leaves_at and container.height may be null: "
                f"leave `{key}:` out instead)",
                node,
                join_path(path, key),
            )
        return node

    def require(self, m: dict, keys, node, path: str) -> None:
        """Refuse mapping `m` (`node`, read at `path`) if it lacks any of `keys`."""
        for key in keys:
            if key not in m:
                raise self.fail(f"missing key {key!r}", node, path)

    def claim_name(self, seen: dict, what: str, name: str, node, path: str) -> None:
        """Record `what` (body, joint) name `name`, given at `node` (`path`), in `seen` (name ->
        (key path, line)); refuse it if `seen` holds it already, naming where it was first."""
        if name in seen:
            first_path, first_line = seen[name]
            raise self.fail(
                f"duplicate {what} name {shown(name)} (already used by {first_path} at "
                f"line {first_line})",
                node,
                path,
            )
        seen[name] = (path, line_of(node))

    def item_alone(self, key: str, text: str, line: int):
        """The node of list item `text` (`  - ...` lines starting at `line`) under `key:`,
        composed at its own lines, so its messages name the lines of the whole text."""
        root = compose("\n" * (line - 2) + f"{key}:\n" + text, self.source)
        return self.sequence(self.mapping(root, "", (key,))[key][1], key, min_len=1)[0]

    # containers
    def mapping(self, node, path: str, allowed) -> dict:
        """{key: (key node, value node)} in document order; refuses duplicates and unknown keys."""
        if not isinstance(node, MappingNode):
            raise self.fail(
                f"expected a mapping (key: value ...), got {describe(node)}", node, path
            )
        out: dict = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, ScalarNode):
                raise self.fail("keys must be plain names", key_node, path)
            key = key_node.value
            if key in out:
                raise self.fail(
                    f"duplicate key {shown(key)} (first given at line {line_of(out[key][0])})",
                    key_node,
                    join_path(path, key),
                )
            if allowed is not None and key not in allowed:
                close = _suggestion(key, allowed)
                hint = (
                    f" (did you mean {close!r}?)"
                    if close
                    else f" (valid keys: {', '.join(allowed)})"
                )
                raise self.fail(f"unknown key {shown(key)}{hint}", key_node, join_path(path, key))
            out[key] = (key_node, value_node)
        return out

    def sequence(
        self, node, path: str, *, min_len: int = 0, max_len: int | None = None, what: str = "items"
    ) -> list:
        if not isinstance(node, SequenceNode):
            raise self.fail(f"expected a list, got {describe(node)}", node, path)
        n = len(node.value)
        if n < min_len:
            raise self.fail(f"expected at least {min_len} {what}, got {n}", node, path)
        if max_len is not None and n > max_len:
            raise self.fail(f"expected at most {max_len} {what}, got {n}", node, path)
        return node.value

    # scalars
    def number(self, node, path: str, lo: float, hi: float, *, lo_open: bool = False) -> float:
        value = scalar(node) if isinstance(node, ScalarNode) else node
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(f"expected a number, got {describe(node)}", node, path)
        if isinstance(value, float) and math.isnan(value):
            raise self.fail("NaN is not allowed (numbers must be finite)", node, path)
        if isinstance(value, float) and math.isinf(value) and _NONFINITE_RE.match(node.value):
            raise self.fail("infinity is not allowed (numbers must be finite)", node, path)
        value = float(value) if math.isfinite(value) else value
        if not (value > lo if lo_open else value >= lo) or not value <= hi:
            low = f"> {lo!r}" if lo_open else f">= {lo!r}"
            raise self.fail(
                f"{_cut(node.value)} is out of range (must be {low} and <= {hi!r})", node, path
            )
        return value

    def time(self, node, path: str, lo: float, hi: float, *, lo_open: bool = False) -> float:
        """A time (s): a number as `number` reads it, or a fraction written `N/D` (`1/120`),
        which is kept in `as_written`. Plain only: '1/120' quoted is a string, as '0.01' is."""
        value = scalar(node) if isinstance(node, ScalarNode) and not node.style else None
        if not (isinstance(value, str) and "/" in value):
            return self.number(node, path, lo, hi, lo_open=lo_open)
        try:
            seconds = fraction(value)
        except ValueError as exc:
            raise self.fail(
                f"{exc}; give seconds (0.01) or whole numbers either side of one / (1/120)",
                node,
                path,
            ) from None
        if not (seconds > lo if lo_open else seconds >= lo) or not seconds <= hi:
            low = f"> {lo!r}" if lo_open else f">= {lo!r}"
            raise self.fail(
                f"{_cut(value)} = {seconds!r} s is out of range (must be {low} and <= {hi!r})",
                node,
                path,
            )
        self.as_written.append((path, value.strip()))
        return seconds

    def integer(self, node, path: str, lo: int, hi: int) -> int:
        value = scalar(node) if isinstance(node, ScalarNode) else None
        if isinstance(value, float) and math.isinf(value) and _INT_RE.match(node.value):
            raise self.fail(f"{_cut(node.value)} is out of range (must be {lo}..{hi})", node, path)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(f"expected a whole number, got {describe(node)}", node, path)
        if not lo <= value <= hi:
            raise self.fail(f"{value} is out of range (must be {lo}..{hi})", node, path)
        return value

    def bits(self, node, path: str, width: int) -> int:
        """A whole number of `width` bits (a collision filter's category or mask): decimal, or
        hexadecimal written `0x...`."""
        value = scalar(node) if isinstance(node, ScalarNode) else None
        if isinstance(value, str) and not node.style and _HEX_RE.match(value):
            value = int(value, 16)  # plain only: '0x2' quoted is a string, as '2' is
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(
                f"expected a whole number of {width} bits (e.g. 6 or 0x0006), got {describe(node)}",
                node,
                path,
            )
        hi = 2**width - 1
        if not 0 <= value <= hi:
            raise self.fail(f"{value} is out of range (must be 0..{hi:#x})", node, path)
        return value

    def boolean(self, node, path: str) -> bool:
        value = scalar(node) if isinstance(node, ScalarNode) else None
        if not isinstance(value, bool):
            # YAML 1.1 and Python spellings that only `true` / `false` mean here
            meant = _BOOLEAN_SPELLINGS.get(str(value).lower()) if isinstance(value, str) else None
            quoted = isinstance(node, ScalarNode) and _quoted_hint(node)
            hint = f" (did you mean {meant}?)" if meant and not quoted else ""
            raise self.fail(f"expected true or false, got {describe(node)}{hint}", node, path)
        return value

    def string(self, node, path: str) -> str:
        value = scalar(node) if isinstance(node, ScalarNode) else None
        if not isinstance(value, str):
            raise self.fail(f"expected a string, got {describe(node)}", node, path)
        return value

    def name(self, node, path: str) -> str:
        value = scalar(node) if isinstance(node, ScalarNode) else None
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = node.value  # `name: 7` is the name "7"
        else:
            value = self.string(node, path)
        if not valid_name(value):
            raise self.fail(
                f"a name must be 1 to {MAX_NAME_LENGTH} printable characters, got {shown(value)}",
                node,
                path,
            )
        return value

    def choice(self, node, path: str, options) -> str:
        value = scalar(node) if isinstance(node, ScalarNode) else None
        if not isinstance(value, str) or value not in options:
            text = node.value if isinstance(node, ScalarNode) else None
            close = None if text is None else _suggestion(text, options)
            hint = f"; did you mean {close!r}?" if close else ""
            given = describe(node) if text is None else shown(text)
            raise self.fail(f"{given} is not one of {', '.join(options)}{hint}", node, path)
        return value

    def pair(
        self, node, path: str, lo: float, hi: float, *, lo_open: bool = False, names: str = "x, y"
    ) -> tuple[float, float]:
        """Two numbers; `names` says in a refusal what they are (e.g. "w, h" for a box)."""
        if isinstance(node, SequenceNode) and len(node.value) != 2:
            raise self.fail(
                f"expected exactly 2 numbers [{names}], got {len(node.value)}", node, path
            )
        items = self.sequence(node, path, min_len=2, max_len=2, what="numbers")
        return (
            self.number(items[0], f"{path}[0]", lo, hi, lo_open=lo_open),
            self.number(items[1], f"{path}[1]", lo, hi, lo_open=lo_open),
        )

    def plain(self, node, path: str, depth: int = 0):
        """Free-form data (the `analytic` block): mappings, lists, finite numbers, booleans and
        strings."""
        if depth > 16:
            raise self.fail("nested too deeply", node, path)
        if isinstance(node, MappingNode):
            return {
                key: self.plain(v, join_path(path, key), depth + 1)
                for key, (_, v) in self.mapping(node, path, None).items()
            }
        if isinstance(node, SequenceNode):
            return [self.plain(v, f"{path}[{i}]", depth + 1) for i, v in enumerate(node.value)]
        value = scalar(node)
        if isinstance(value, float) and not math.isfinite(value):
            raise self.fail("numbers must be finite", node, path)
        if value is None:
            raise self.fail(
                "null is not allowed here (only leaves_at and container.height may be null; "
                "this free-form data holds mappings, lists, numbers, booleans and strings)",
                node,
                path,
            )
        return value


def optional(reader_fn, m: dict, key: str, path: str, default, *args, **kwargs):
    if key not in m:
        return default
    return reader_fn(m[key][1], join_path(path, key), *args, **kwargs)


def key_at(m: dict, node, path: str, *keys: str):
    """(value node, key path) of the first of `keys` that mapping `m` (`node`, read at `path`)
    gives, else (`node`, `path`): where a message about what those keys say points."""
    for key in keys:
        if key in m:
            return m[key][1], join_path(path, key)
    return node, path


def scalar_or_none(node):
    return scalar(node) if isinstance(node, ScalarNode) else node


def compose(text: str, source: str, *, document: str = "a scene"):
    """The node tree of YAML `text` (with line marks), or SceneError naming the line; `document`
    says what the text is in the refusal of anchors, aliases and tags ("a sweep file")."""
    parser = _LOADER(text)
    try:
        return _compose(parser, document)
    except Refused as exc:
        raise SceneError(exc.what, source=source, line=exc.line) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        what = " ".join(str(exc.problem or exc.context or "invalid YAML").split())
        line = None if mark is None else mark.line + 1
        if "nesting depth" in what:
            # libyaml (and PyYAML >= 6.0.3) bound the depth themselves, some way past ours
            raise SceneError(
                "the document is nested too deeply", source=source, line=line
            ) from None
        raise SceneError(f"YAML syntax error: {_cut(what)}", source=source, line=line) from None
    except yaml.reader.ReaderError as exc:
        line = text[: exc.position].count("\n") + 1
        raise SceneError(
            f"character #x{exc.character:04x} is not allowed in YAML", source=source, line=line
        ) from None
    except yaml.YAMLError as exc:
        raise SceneError(f"YAML error: {_cut(' '.join(str(exc).split()))}", source=source) from None
    finally:
        parser.dispose()
