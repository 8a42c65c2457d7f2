"""Scenes: the YAML contract (docs/scene-format.md) turned into a validated, immutable `Scene`.

A scene says everything a run needs. It is validated once, here; the engine trusts a `Scene`.
Loading: YAML text -> node tree with line marks (isaac.scene.reader) -> the scene's name,
`world:` (isaac.scene.settings), `bodies:` (isaac.scene.bodies), `generators:`
(isaac.scene.generators) and `joints:` (isaac.scene.joints), each checked -> Scene.
"""

from __future__ import annotations

import contextlib
import gc
import os
import stat
from pathlib import Path

from isaac.errors import SceneError
from isaac.scene import bodies, checks, fast_reader, generators, joints, validate
from isaac.scene.limits import MAX_BODIES, MAX_SCENE_BYTES, MAX_YAML_BYTES
from isaac.scene.reader import (
    MappingNode,
    Reader,
    compose,
    describe,
    join_path,
    key_at,
    line_of,
    optional,
)
from isaac.scene.settings import read_world
from isaac.scene.spec import BodySpec, Scene, SceneMarks

_SCENE_KEYS = ("name", "world", "bodies", "generators", "joints", "analytic")


def load_scene(path) -> Scene:
    """Read, check and expand the scene file at `path` (YAML, UTF-8; docs/scene-format.md).

    The scene's name defaults to the file's stem. Raises SceneError (one line:
    ``FILE:LINE: KEY.PATH: what is wrong``) for anything unreadable or invalid, including a
    path that is not a regular file (a FIFO, a device, a directory), which is refused before it
    is opened: reading a FIFO would wait for a writer forever.
    """
    source = str(path)
    p = Path(path)
    try:
        _refuse_unless_file(os.stat(p).st_mode, source)
        # O_NONBLOCK: should the path have become a FIFO since the stat, opening it does not
        # wait for a writer, and fstat below refuses it.
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with open(fd, "rb") as f:
            _refuse_unless_file(os.fstat(f.fileno()).st_mode, source)
            data = f.read(MAX_SCENE_BYTES + 1)
    except SceneError:
        raise
    except FileNotFoundError:
        raise SceneError("no such file", source=source) from None
    except OSError as exc:
        raise SceneError(f"cannot read the file: {exc.strerror or exc}", source=source) from None
    if len(data) > MAX_SCENE_BYTES:
        raise SceneError(f"the file is larger than {MAX_SCENE_BYTES} bytes", source=source)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise SceneError(
            f"not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start})",
            source=source,
            line=line,
        ) from None
    del data
    return load_scene_text(text, source=source, default_name=p.stem)


_NOT_FILES = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISCHR, "a device"),
    (stat.S_ISBLK, "a device"),
)


def _refuse_unless_file(mode: int, source: str) -> None:
    """SceneError unless `mode` (an st_mode) is a regular file's, saying what it is instead."""
    if not stat.S_ISREG(mode):
        kind = next((kind for test, kind in _NOT_FILES if test(mode)), "not a regular file")
        raise SceneError(f"is {kind}, not a scene file", source=source)


def load_scene_text(text: str, source: str = "<text>", *, default_name: str | None = None) -> Scene:
    """Check and expand scene YAML `text`; `source` names it in messages and in `Scene.source`.

    The name defaults to `default_name`, else "scene". Raises SceneError like `load_scene`.
    Text in the exact form `scene_to_yaml` writes (a log's scene) is read line by line without a
    YAML node tree (isaac.scene.fast_reader), to the same Scene; any other text goes through
    the YAML reader, bounded by MAX_YAML_BYTES and the node limits of isaac.scene.limits.
    """
    if len(text) > MAX_SCENE_BYTES:
        raise SceneError(f"the text is longer than {MAX_SCENE_BYTES} characters", source=source)
    with _reading(source):
        scene = fast_reader.read(
            text, source, default_name or "scene", read_head, bodies.body_alone, joints.joint_alone
        )
        if scene is not None:
            return validate.remember(scene)
        if len(text) > MAX_YAML_BYTES:
            raise SceneError(
                f"the text is longer than {MAX_YAML_BYTES} characters (the limit for YAML not "
                "written by scene_to_yaml)",
                source=source,
            )
        root = compose(text, source)
        if root is None:
            raise SceneError(
                "the scene is empty (expected a mapping with `bodies:` or `generators:`)",
                source=source,
                line=1,
            )
        return read_scene_tree(root, source, default_name=default_name)


def read_scene_tree(root, source: str = "<text>", *, default_name: str | None = None) -> Scene:
    """Check and expand the scene node tree `root`, as `load_scene_text` does the tree it
    composes from YAML text (isaac.scene.reader.compose); `source` names it in messages and
    in `Scene.source`. For a caller that holds a composed tree and changes a few of its nodes
    between reads (isaac.app.sweep: one scene, many runs), so as not to write and compose the
    whole text again each time. Raises SceneError like `load_scene_text`; its lines are the
    nodes' own."""
    with _reading(source):
        return validate.remember(_read_scene(Reader(source), root, default_name or "scene"))


@contextlib.contextmanager
def _reading(source: str):
    """Pause the cyclic garbage collector while a scene is read, and say a RecursionError as
    the document being nested too deeply. The node tree and the readers' objects hold no
    cycles, yet their many small objects make the collector run over and over while they
    grow: pausing it halves the load time of a large scene."""
    collecting = gc.isenabled()
    gc.disable()
    try:
        yield
    except RecursionError:
        raise SceneError("the document is nested too deeply", source=source) from None
    finally:
        if collecting:
            gc.enable()


def read_head(r: Reader, root, default_name: str):
    """(mapping, name, world, analytic) of the scene mapping `root`."""
    m = r.mapping(root, "", _SCENE_KEYS)
    name = optional(r.name, m, "name", "", default_name)
    world = read_world(r, r.given(m, "world", "", "a mapping of world settings"))
    analytic = None
    node = r.given(m, "analytic", "", "a mapping")
    if node is not None:
        if not isinstance(node, MappingNode):
            raise r.fail(f"expected a mapping, got {describe(node)}", node, "analytic")
        analytic = r.plain(node, "analytic")
    return m, name, world, analytic


def _read_scene(r: Reader, root, default_name: str) -> Scene:
    m, name, world, analytic = read_head(r, root, default_name)
    specs: list[BodySpec] = []
    origin: dict[str, tuple[str, int]] = {}  # name -> (key path, line) where it was made
    explicit = []  # (item node, key path) of each body of `bodies:`
    made = []  # (first body, end, kind, options node, key path, name prefix) of each generator
    friction_given = []  # (line, key path) of each `friction:` given, for the warnings

    node = r.given(m, "bodies", "", "a list of bodies")
    if node is not None:
        items = r.sequence(node, "bodies", max_len=MAX_BODIES, what="bodies")
        for i, item in enumerate(items):
            path = f"bodies[{i}]"
            spec = bodies.read_body(r, item, path, i)
            given = r.mapping(item, path, None)
            r.claim_name(origin, "body", spec.name, *key_at(given, item, path, "name"))
            specs.append(spec)
            explicit.append((item, path))
            if "friction" in given:
                friction_given.append((line_of(given["friction"][1]), join_path(path, "friction")))
    node = r.given(m, "generators", "", "a list of generators")
    if node is not None:
        items = r.sequence(node, "generators")
        for i, item in enumerate(items):
            path = f"generators[{i}]"
            first = len(specs)
            kind, options_node, gen_path, prefix, made_specs = generators.expand(
                r, item, path, MAX_BODIES - len(specs)
            )
            for spec in made_specs:
                r.claim_name(origin, "body", spec.name, item, path)
                specs.append(spec)
            made.append((first, len(specs), kind, options_node, gen_path, prefix))
            friction_node = generators.option_node(r, options_node, gen_path, "friction")
            if friction_node is not None:
                friction_given.append((line_of(friction_node), join_path(gen_path, "friction")))
    if not specs:
        raise r.fail("the scene has no bodies (give `bodies:` or `generators:`)", root)
    problem = checks.first_problem(specs)
    if problem is not None:
        i, field, what = problem
        if i < len(explicit):
            raise bodies.refusal(r, field, what, *explicit[i])
        _, _, kind, options_node, path, prefix = next(g for g in made if g[0] <= i < g[1])
        raise generators.refusal(r, field, what, specs[i].name, kind, options_node, path, prefix)
    marks = SceneMarks(
        bodies=tuple((line_of(item), path) for item, path in explicit),
        generators=tuple(
            (first, end, line_of(node), path) for first, end, _, node, path, _ in made
        ),
        friction=tuple(friction_given),
    )
    return Scene(
        name=name,
        world=world,
        bodies=tuple(specs),
        source=r.source,
        analytic=analytic,
        joints=joints.read_joints(r, m, specs, world),
        marks=marks,
        as_written=tuple(r.as_written),
    )
