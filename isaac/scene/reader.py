"""Reading YAML with line marks: a composer that refuses what a scene may not hold, scalars read
by our own rules, and `Reader`, typed access whose every failure names file, line and key path.


We never let PyYAML construct Python objects: we compose the node tree with a SafeLoader that
refuses anchors, aliases and explicit tags, then read every scalar ourselves. That is how we get
line numbers in every message, refuse duplicate keys (PyYAML keeps the last one silently), read
`1e3` as a number (YAML 1.1 reads it as a string) and keep `off`/`no`/`yes` as strings (YAML 1.1
reads them as booleans; only `true`/`false` are booleans here).
"""

from __future__ import annotations

import difflib
import math
import re

import yaml

from isaac.errors import SceneError
from isaac.scene.limits import MAX_NAME_LENGTH

_INT_RE = re.compile(r"[-+]?[0-9]+\Z")
_FLOAT_RE = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?\Z")
_NONFINITE_RE = re.compile(r"[-+]?\.?(?:nan|inf|infinity)\Z", re.IGNORECASE)
_NULLS = ("null", "~", "")


class _RefuseAliases(yaml.composer.Composer):
    """A composer that refuses anchors, aliases and explicit tags.

    Aliases are refused outright rather than bounded: a "billion laughs" document composes in
    milliseconds but walking the result took 16.7 s and 1.6 GiB when measured.
    """

    def compose_node(self, parent, index):
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            raise Refused("YAML aliases (*name) are not allowed in a scene", event.start_mark)
        if getattr(event, "anchor", None) is not None:
            raise Refused("YAML anchors (&name) are not allowed in a scene", event.start_mark)
        if getattr(event, "tag", None) not in (None, "!"):
            raise Refused(f"YAML tags ({event.tag}) are not allowed in a scene", event.start_mark)
        return super().compose_node(parent, index)

    def resolve(self, kind, value, implicit):
        # we read scalars ourselves (scalar), so PyYAML's implicit typing is skipped: it is a
        # third of the load time of a large scene.
        if kind is yaml.ScalarNode:
            return "tag:yaml.org,2002:str"
        if kind is yaml.SequenceNode:
            return "tag:yaml.org,2002:seq"
        return "tag:yaml.org,2002:map"


class _NoAliasLoader(_RefuseAliases, yaml.SafeLoader):
    """Pure-Python scanner and parser, our composer."""


if getattr(yaml, "__with_libyaml__", False):

    class _FastNoAliasLoader(
        _RefuseAliases, yaml._yaml.CParser, yaml.constructor.SafeConstructor, yaml.resolver.Resolver
    ):
        """libyaml's scanner and parser (about 4x faster on a large expanded scene), our
        composer: same nodes, same marks, same refusals."""

        def __init__(self, stream) -> None:
            yaml._yaml.CParser.__init__(self, stream)
            _RefuseAliases.__init__(self)
            yaml.constructor.SafeConstructor.__init__(self)
            yaml.resolver.Resolver.__init__(self)

    _LOADER = _FastNoAliasLoader
else:
    _LOADER = _NoAliasLoader


class Refused(Exception):
    def __init__(self, what: str, mark) -> None:
        self.what = what
        self.mark = mark


def line_of(node) -> int:
    return node.start_mark.line + 1


def join_path(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def describe(node) -> str:
    if isinstance(node, yaml.MappingNode):
        return "a mapping"
    if isinstance(node, yaml.SequenceNode):
        return "a list"
    value = scalar(node)
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f"the string {node.value!r}"
    return f"the number {node.value}"


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
    if _FLOAT_RE.match(text) or _NONFINITE_RE.match(text):
        return float(
            text.replace(".nan", "nan")
            .replace(".NaN", "nan")
            .replace(".NAN", "nan")
            .replace(".inf", "inf")
            .replace(".Inf", "inf")
            .replace(".INF", "inf")
        )
    return text


class Reader:
    """Typed access to a composed node tree; every failure is a SceneError with line and path."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, what: str, node=None, path: str = "") -> SceneError:
        return SceneError(
            what, source=self.source, line=None if node is None else line_of(node), path=path
        )

    # containers
    def mapping(self, node, path: str, allowed) -> dict:
        """{key: (key node, value node)} in document order; refuses duplicates and unknown keys."""
        if not isinstance(node, yaml.MappingNode):
            raise self.fail(
                f"expected a mapping (key: value ...), got {describe(node)}", node, path
            )
        out: dict = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                raise self.fail("keys must be plain names", key_node, path)
            key = key_node.value
            if key in out:
                raise self.fail(
                    f"duplicate key {key!r} (first given at line {line_of(out[key][0])})",
                    key_node,
                    join_path(path, key),
                )
            if allowed is not None and key not in allowed:
                close = difflib.get_close_matches(key, list(allowed), n=1, cutoff=0.6)
                hint = (
                    f" (did you mean {close[0]!r}?)"
                    if close
                    else f" (valid keys: {', '.join(allowed)})"
                )
                raise self.fail(f"unknown key {key!r}{hint}", key_node, join_path(path, key))
            out[key] = (key_node, value_node)
        return out

    def sequence(
        self, node, path: str, *, min_len: int = 0, max_len: int | None = None, what: str = "items"
    ) -> list:
        if not isinstance(node, yaml.SequenceNode):
            raise self.fail(f"expected a list, got {describe(node)}", node, path)
        n = len(node.value)
        if n < min_len:
            raise self.fail(f"expected at least {min_len} {what}, got {n}", node, path)
        if max_len is not None and n > max_len:
            raise self.fail(f"expected at most {max_len} {what}, got {n}", node, path)
        return node.value

    # scalars
    def number(self, node, path: str, lo: float, hi: float, *, lo_open: bool = False) -> float:
        value = scalar(node) if isinstance(node, yaml.ScalarNode) else node
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
                f"{node.value} is out of range (must be {low} and <= {hi!r})", node, path
            )
        return value

    def integer(self, node, path: str, lo: int, hi: int) -> int:
        value = scalar(node) if isinstance(node, yaml.ScalarNode) else None
        if isinstance(value, float) and math.isinf(value) and _INT_RE.match(node.value):
            raise self.fail(f"{node.value} is out of range (must be {lo}..{hi})", node, path)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(f"expected a whole number, got {describe(node)}", node, path)
        if not lo <= value <= hi:
            raise self.fail(f"{value} is out of range (must be {lo}..{hi})", node, path)
        return value

    def boolean(self, node, path: str) -> bool:
        value = scalar(node) if isinstance(node, yaml.ScalarNode) else None
        if not isinstance(value, bool):
            raise self.fail(f"expected true or false, got {describe(node)}", node, path)
        return value

    def string(self, node, path: str) -> str:
        value = scalar(node) if isinstance(node, yaml.ScalarNode) else None
        if not isinstance(value, str):
            raise self.fail(f"expected a string, got {describe(node)}", node, path)
        return value

    def name(self, node, path: str) -> str:
        value = scalar(node) if isinstance(node, yaml.ScalarNode) else None
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = node.value  # `name: 7` is the name "7"
        else:
            value = self.string(node, path)
        if not value or len(value) > MAX_NAME_LENGTH or not value.isprintable():
            raise self.fail(
                f"a name must be 1 to {MAX_NAME_LENGTH} printable characters, got {value[:40]!r}",
                node,
                path,
            )
        return value

    def choice(self, node, path: str, options) -> str:
        value = scalar(node) if isinstance(node, yaml.ScalarNode) else None
        if not isinstance(value, str) or value not in options:
            shown = node.value if isinstance(node, yaml.ScalarNode) else describe(node)
            close = difflib.get_close_matches(str(shown), list(options), n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise self.fail(f"{shown!r} is not one of {', '.join(options)}{hint}", node, path)
        return value

    def pair(
        self, node, path: str, lo: float, hi: float, *, lo_open: bool = False
    ) -> tuple[float, float]:
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
        if isinstance(node, yaml.MappingNode):
            return {
                key: self.plain(v, join_path(path, key), depth + 1)
                for key, (_, v) in self.mapping(node, path, None).items()
            }
        if isinstance(node, yaml.SequenceNode):
            return [self.plain(v, f"{path}[{i}]", depth + 1) for i, v in enumerate(node.value)]
        value = scalar(node)
        if isinstance(value, float) and not math.isfinite(value):
            raise self.fail("numbers must be finite", node, path)
        return value


def optional(reader_fn, m: dict, key: str, path: str, default, *args, **kwargs):
    if key not in m:
        return default
    return reader_fn(m[key][1], join_path(path, key), *args, **kwargs)


def scalar_or_none(node):
    return scalar(node) if isinstance(node, yaml.ScalarNode) else node


def compose(text: str, source: str):
    """The node tree of YAML `text` (with line marks), or SceneError naming the line."""
    try:
        return yaml.compose(text, Loader=_LOADER)
    except Refused as exc:
        raise SceneError(exc.what, source=source, line=exc.mark.line + 1) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        what = " ".join(str(exc.problem or exc.context or "invalid YAML").split())
        line = None if mark is None else mark.line + 1
        if "nesting depth" in what:
            # PyYAML >= 6.0.3 bounds the depth itself; older ones end in RecursionError below:
            # the same message either way
            raise SceneError(
                "the document is nested too deeply", source=source, line=line
            ) from None
        raise SceneError(f"YAML syntax error: {what}", source=source, line=line) from None
    except yaml.reader.ReaderError as exc:
        line = text[: exc.position].count("\n") + 1
        raise SceneError(
            f"character #x{exc.character:04x} is not allowed in YAML", source=source, line=line
        ) from None
    except yaml.YAMLError as exc:
        raise SceneError(f"YAML error: {' '.join(str(exc).split())}", source=source) from None
    except RecursionError:
        raise SceneError("the document is nested too deeply", source=source) from None
