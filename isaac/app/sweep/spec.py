"""The sweep file (docs/sweep-format.md) read into a `Sweep`: the base scene, the swept keys and
their values, and every run's scene text, each checked by the scene loader before anything runs.

Errors follow the scene file's rules: one line ``FILE:LINE: KEY.PATH: what is wrong``, exit 2.
"""

from __future__ import annotations

import hashlib
import math
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from isaac.app.sweep import keys
from isaac.app.sweep.metrics import METRICS
from isaac.errors import SceneError
from isaac.scene import load_scene_text
from isaac.scene.limits import MAX_SCENE_BYTES, MAX_STEPS, MAX_YAML_BYTES
from isaac.scene.loader import read_scene_tree
from isaac.scene.reader import (
    MappingNode,
    Reader,
    ScalarNode,
    SequenceNode,
    compose,
    join_path,
    shown,
)

MAX_RUNS = 1_000_000
MAX_SWEEP_BYTES = 16 * 1024 * 1024
RECORD_MODES = ("none", "mcap", "mcap+rrd")
DISTRIBUTIONS = ("uniform", "loguniform", "normal", "integers", "choice")
_TOP_KEYS = ("scene", "runs", "steps", "record", "metrics")


class SweepError(SceneError):
    """A sweep file is invalid: ``FILE:LINE: KEY.PATH: what is wrong`` (exit status 2)."""


@dataclass
class Axis:
    """One swept key: `key` as written, `slot` in the base scene, `line` of the key in the sweep
    file, and either `values` (grid: value nodes) or `dist` (random: name, parameters)."""

    key: str
    slot: keys.Slot
    line: int
    values: list = field(default_factory=list)  # grid: [(node, plain value, line)]
    dist: tuple | None = None  # random: (name, params, node line)


@dataclass
class Sweep:
    """A read sweep file; `run_scene_text(i)` and `params(i)` give run i (0 <= i < n_runs)."""

    path: str
    text: str
    scene_path: str
    scene_text: str
    scene_name: str
    root: object  # the base scene's node tree (keys.emit writes each run's text from it)
    scene: object  # the base scene as loaded (isaac.scene.Scene): its warnings, its bodies
    grid: list[Axis]
    random: list[Axis]
    n_random: int  # samples per grid point (1 without `random:`)
    seed: int
    steps: int | None
    record: str
    metrics: tuple[str, ...]
    final_bodies: tuple[str, ...]
    runs_line: int
    n_runs: int = 0
    # the line of each axis's value in a run's text (keys.emit_lines), or False where runs are
    # read from their text (`load_run`); worked out on first use
    value_lines: list | bool | None = field(default=None, repr=False, compare=False)

    @property
    def axes(self) -> list[Axis]:
        return self.grid + self.random

    def _choice(self, index: int) -> tuple[list, int]:
        """(grid value index per grid axis, random sample number) of run `index`: grid points
        in the order of itertools.product (the last key varies fastest), each with the
        samples 0 .. n - 1."""
        point, sample = divmod(index, self.n_random)
        picks = []
        for axis in reversed(self.grid):
            point, k = divmod(point, len(axis.values))
            picks.append(k)
        return picks[::-1], sample

    def draws(self, index: int) -> list[tuple[Axis, object, object]]:
        """[(axis, value node to put in the scene, plain value for the table)] of run `index`."""
        picks, sample = self._choice(index)
        out = []
        for axis, k in zip(self.grid, picks):
            node, plain, _ = axis.values[k]
            out.append((axis, node, plain))
        for axis in self.random:
            node, plain = draw(axis, self.seed, sample)
            out.append((axis, node, plain))
        return out

    def params(self, index: int) -> dict:
        return {axis.key: plain for axis, _, plain in self.draws(index)}

    def run_scene_text(self, index: int) -> str:
        return keys.emit(self.root, _swapped(self.draws(index)))

    def load_run(self, index: int, draws=None):
        """Run `index`'s Scene (`draws`: its `draws(index)`, when known), or the SceneError of
        the scene loader: the same Scene, and the same verdict, as `load_scene_text` of
        `run_scene_text(index)`, without writing and composing that text. The run's values
        are put into the base scene's node tree, each on the line the text would have it on,
        the tree is read by the loader (isaac.scene.loader.read_scene_tree) and the base tree
        is put back. A run the tree's reading refuses is read again from its text, whose
        verdict (and message) it then is; so is a run with a list or mapping as a value (a
        grid value that is a list), where the text's node limits could differ."""
        draws = self.draws(index) if draws is None else draws
        lines = self._value_lines()
        if lines and all(type(node) is ScalarNode for _, node, _ in draws):
            with _TREE_LOCK:
                undo = []
                try:
                    for (axis, node, _), line in zip(draws, lines):
                        undo.append(_put(axis.slot, ScalarNode(node.value, line, node.style)))
                    return read_scene_tree(self.root, self.scene_path, default_name=self.scene_name)
                except SceneError:
                    pass  # read from the text below: its verdict and message
                finally:
                    for put_back in reversed(undo):
                        put_back()
        return load_scene_text(
            keys.emit(self.root, _swapped(draws)),
            source=self.scene_path,
            default_name=self.scene_name,
        )

    def _value_lines(self):
        """`value_lines`, worked out once: False when a run's text could be refused for its
        size or shape where its tree is not (the text near MAX_YAML_BYTES, or run 0's text
        refused by the YAML composer, whose node counts every run of scalar values shares)."""
        if self.value_lines is None:
            draws = self.draws(0)
            text, where = keys.emit_lines(self.root, _swapped(draws))
            room = sum(len(a.key) + 64 + _longest_value(a) for a in self.axes)
            try:
                compose(text, self.scene_path)
                ok = len(text) + room < min(MAX_YAML_BYTES, MAX_SCENE_BYTES)
            except SceneError:
                ok = False
            keyed = [(id(a.slot.container), a.slot.key) for a, _, _ in draws]
            self.value_lines = [where[k] for k in keyed] if ok else False
        return self.value_lines


def _swapped(draws) -> dict:
    """{(id(container), key): value node} of a run's `draws`, in the axes' order: what
    `keys.emit` puts in place of the base scene's nodes."""
    return {(id(a.slot.container), a.slot.key): node for a, node, _ in draws}


_TREE_LOCK = threading.Lock()  # `Sweep.load_run` edits the base tree while it reads it


def _put(slot: keys.Slot, node):
    """Put `node` at `slot` of the base tree (as `keys.emit` writes it: in place of the value
    the scene gives, else as a key added at the end of its mapping); returns the undo."""
    c, key = slot.container, slot.key
    if isinstance(c, SequenceNode):
        old = c.value[key]
        c.value[key] = node

        def undo_item():
            c.value[key] = old

        return undo_item
    for j, (k, v) in enumerate(c.value):
        if k.value == key:
            c.value[j] = (k, node)

            def undo_value(j=j, pair=(k, v)):
                c.value[j] = pair

            return undo_value
    c.value.append((ScalarNode(key, node.line, '"'), node))

    def undo_key():
        c.value.pop()

    return undo_key


def _longest_value(axis: Axis) -> int:
    """Characters the longest value of `axis` may take in a run's text (a bound)."""
    nodes = [n for n, _, _ in axis.values]
    if axis.dist is not None and axis.dist[0] == "choice":
        nodes = [n for n, _ in axis.dist[1]]
    return max([32] + [2 * len(getattr(n, "value", "")) + 8 for n in nodes])


def stream(seed: int, sample: int, key: str) -> np.random.Generator:
    """The random stream of `key` in sample `sample`: numpy's PCG64 seeded by
    SeedSequence([seed, sample, w0, w1, w2, w3]), w the first four little-endian 32-bit words of
    sha256(key). It depends on nothing else: not on the worker, the order of the runs, nor the
    other keys of the sweep."""
    words = np.frombuffer(hashlib.sha256(key.encode("utf-8")).digest()[:16], dtype="<u4")
    entropy = [int(seed), int(sample), *(int(w) for w in words)]
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(entropy)))


def draw(axis: Axis, seed: int, sample: int):
    """(node, plain value) of `axis`'s distribution for sample `sample`."""
    name, params, _ = axis.dist
    rng = stream(seed, sample, axis.key)
    if name == "uniform":
        value = float(rng.uniform(params[0], params[1]))
    elif name == "loguniform":
        value = math.exp(float(rng.uniform(math.log(params[0]), math.log(params[1]))))
    elif name == "normal":
        value = float(rng.normal(params[0], params[1]))
    elif name == "integers":
        value = int(rng.integers(params[0], params[1], endpoint=True))
    else:  # choice: [(node, plain)]
        node, plain = params[int(rng.integers(0, len(params)))]
        return node, plain
    return keys.value_node(value), value


# --- reading --------------------------------------------------------------------------------


def read_bytes(path: str, what: str, source: str, line: int | None = None, key: str = "") -> str:
    p = Path(path)
    try:
        if not p.is_file():
            raise SweepError(
                f"{'no such file' if not p.exists() else 'not a regular file'}: {path}"
                if key
                else ("no such file" if not p.exists() else "not a regular file"),
                source=source,
                line=line,
                path=key,
            )
        data = p.read_bytes()
    except OSError as exc:
        raise SweepError(
            f"cannot read {what}: {exc.strerror or exc}", source=source, line=line, path=key
        ) from None
    if len(data) > MAX_SWEEP_BYTES and what == "the sweep file":
        raise SweepError(f"the file is larger than {MAX_SWEEP_BYTES} bytes", source=source)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SweepError(
            f"not UTF-8 text (byte offset {exc.start})", source=source, line=line, path=key
        ) from None


def load_sweep(path) -> Sweep:
    """Read the sweep file at `path`, its scene, and check every run's scene (SweepError, or
    the scene's SceneError for a scene that is invalid as it stands)."""
    source = str(path)
    text = read_bytes(source, "the sweep file", source)
    # the scene's YAML rules, anchors and aliases refused too: a sweep file is small, and a
    # refusal naming it says which of the two files to change
    root = compose(text, source, document="a sweep file")
    r = Reader(source)
    if root is None:
        raise SweepError(
            "the sweep file is empty (expected scene: and runs:)", source=source, line=1
        )
    m = r.mapping(root, "", _TOP_KEYS)
    for key in ("scene", "runs"):
        if key not in m:
            raise r.fail(f"missing key {key!r}", root, "")
    scene_node = m["scene"][1]
    scene_rel = r.string(scene_node, "scene")
    scene_path = os.path.join(os.path.dirname(source), scene_rel)
    scene_text = read_bytes(scene_path, "the scene", source, scene_node.line, "scene")
    stem = Path(scene_path).stem
    base = load_scene_text(scene_text, source=scene_path, default_name=stem)
    scene_root = compose(scene_text, scene_path)

    steps = None
    if "steps" in m:
        steps = r.integer(m["steps"][1], "steps", 1, MAX_STEPS)
    record = "mcap"
    if "record" in m:
        record = r.choice(m["record"][1], "record", RECORD_MODES)
    metrics, final_bodies = _read_metrics(r, m, base)

    runs_node = m["runs"][1]
    runs = r.mapping(runs_node, "runs", ("grid", "random"))
    if not runs:
        raise r.fail("give grid:, random: or both", runs_node, "runs")
    grid: list[Axis] = []
    random: list[Axis] = []
    n_random, seed = 1, 0
    if "grid" in runs:
        grid = _read_grid(r, runs["grid"][1], scene_root, base)
    if "random" in runs:
        random, n_random, seed = _read_random(r, runs["random"][1], scene_root, base)
    axes = grid + random
    for i, a in enumerate(axes):
        for b in axes[:i]:
            if a.slot.overlaps(b.slot):
                raise r.fail(
                    f"overlaps {b.key!r} (line {b.line}): each place in the scene is swept by "
                    "one key",
                    _line_node(a.line),
                    _sweep_path(a, grid),
                )
    n_runs = n_random
    for axis in grid:
        n_runs *= len(axis.values)
        if n_runs > MAX_RUNS:
            raise r.fail(f"the sweep has more than {MAX_RUNS} runs", runs_node, "runs")
    sweep = Sweep(
        path=source,
        text=text,
        scene_path=scene_path,
        scene_text=scene_text,
        scene_name=base.name,
        root=scene_root,
        scene=base,
        grid=grid,
        random=random,
        n_random=n_random,
        seed=seed,
        steps=steps,
        record=record,
        metrics=metrics,
        final_bodies=final_bodies,
        runs_line=runs_node.line,
        n_runs=n_runs,
    )
    return sweep


def _line_node(line: int) -> ScalarNode:
    return ScalarNode("", line, None)


def _sweep_path(axis: Axis, grid: list[Axis]) -> str:
    section = "runs.grid" if any(a is axis for a in grid) else "runs.random"
    return f"{section}.{axis.key}"


def _read_metrics(r: Reader, m: dict, scene) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(metric names, bodies whose final state gets columns)."""
    moving = [b.name for b in scene.bodies if not b.concrete]
    default_bodies = tuple(moving) if len(moving) <= 8 else ()
    if "metrics" not in m:
        return tuple(METRICS), default_bodies
    node = m["metrics"][1]
    items = r.sequence(node, "metrics", min_len=1, what="metrics")
    names: list[str] = []
    bodies = default_bodies
    for i, item in enumerate(items):
        path = f"metrics[{i}]"
        if isinstance(item, MappingNode):
            mm = r.mapping(item, path, ("final_state",))
            if len(mm) != 1:
                raise r.fail("expected final_state: [BODY, ...]", item, path)
            bnode = mm["final_state"][1]
            bpath = join_path(path, "final_state")
            listed = r.sequence(bnode, bpath, min_len=1, what="body names")
            known = {b.name for b in scene.bodies}
            chosen = []
            for j, b in enumerate(listed):
                name = r.name(b, f"{bpath}[{j}]")
                if name not in known:
                    raise r.fail(f"the scene has no body named {shown(name)}", b, f"{bpath}[{j}]")
                chosen.append(name)
            bodies = tuple(chosen)
            name = "final_state"
        else:
            name = r.choice(item, path, tuple(METRICS))
        if name in names:
            raise r.fail(f"{name} is listed twice", item, path)
        names.append(name)
    return tuple(names), bodies if "final_state" in names else ()


def _key(r: Reader, key_node, section: str) -> str:
    key = key_node.value
    if not key or len(key) > 1000 or not key.isprintable():
        raise r.fail("expected a key path such as bodies.NAME.restitution", key_node, section)
    return key


def _slot(r: Reader, key: str, key_node, path: str, scene_root, base) -> keys.Slot:
    try:
        return keys.resolve(key, scene_root, base)
    except keys.KeyError_ as exc:
        raise r.fail(exc.what, key_node, path) from None


def _read_grid(r: Reader, node, scene_root, base) -> list[Axis]:
    m = r.mapping(node, "runs.grid", None)
    if not m:
        raise r.fail("expected at least one key path with its list of values", node, "runs.grid")
    axes = []
    for _key_text, (key_node, values_node) in m.items():
        key = _key(r, key_node, "runs.grid")
        path = f"runs.grid.{key}"
        slot = _slot(r, key, key_node, path, scene_root, base)
        items = r.sequence(values_node, path, min_len=1, what="values")
        values = [(v, r.plain(v, f"{path}[{i}]"), v.line) for i, v in enumerate(items)]
        axes.append(Axis(key=key, slot=slot, line=key_node.line, values=values))
    return axes


def _read_random(r: Reader, node, scene_root, base) -> tuple[list[Axis], int, int]:
    m = r.mapping(node, "runs.random", None)
    for need in ("n", "seed"):
        if need not in m:
            raise r.fail(f"missing key {need!r}", node, "runs.random")
    n = r.integer(m["n"][1], "runs.random.n", 1, MAX_RUNS)
    seed = r.integer(m["seed"][1], "runs.random.seed", 0, 2**63 - 1)
    axes = []
    for key_text, (key_node, dist_node) in m.items():
        if key_text in ("n", "seed"):
            continue
        key = _key(r, key_node, "runs.random")
        path = f"runs.random.{key}"
        slot = _slot(r, key, key_node, path, scene_root, base)
        dist = _read_dist(r, dist_node, path)
        axes.append(Axis(key=key, slot=slot, line=key_node.line, dist=dist))
    if not axes:
        raise r.fail("expected at least one key path with its distribution", node, "runs.random")
    return axes, n, seed


def _read_dist(r: Reader, node, path: str) -> tuple:
    d = r.mapping(node, path, DISTRIBUTIONS)
    if len(d) != 1:
        raise r.fail(
            f"expected one distribution: {{{' | '.join(DISTRIBUTIONS)}: [...]}}", node, path
        )
    name, (_, pnode) = next(iter(d.items()))
    dpath = join_path(path, name)
    if name == "choice":
        items = r.sequence(pnode, dpath, min_len=1, what="values")
        return name, [(v, r.plain(v, f"{dpath}[{i}]")) for i, v in enumerate(items)], node.line
    if name == "integers":
        items = r.sequence(pnode, dpath, min_len=2, max_len=2, what="numbers [low, high]")
        lo = r.integer(items[0], f"{dpath}[0]", -(2**62), 2**62)
        hi = r.integer(items[1], f"{dpath}[1]", -(2**62), 2**62)
        if lo > hi:
            raise r.fail(f"low {lo} is greater than high {hi}", pnode, dpath)
        return name, (lo, hi), node.line
    names = "mean, std" if name == "normal" else "low, high"
    a, b = r.pair(pnode, dpath, -1e300, 1e300, names=names)
    if name == "normal":
        if not b > 0.0:
            raise r.fail(f"std must be > 0, got {b!r}", pnode, dpath)
    elif not a < b:
        raise r.fail(f"low {a!r} must be less than high {b!r}", pnode, dpath)
    if name == "loguniform" and not a > 0.0:
        raise r.fail(f"loguniform needs low > 0, got {a!r}", pnode, dpath)
    return name, (a, b), node.line


# --- every run's scene, checked -------------------------------------------------------------


def load_runs(sweep: Sweep, indices, keep: bool = True, budget: float | None = None) -> dict:
    """Load the scenes of runs `indices` (in order) with the scene loader, up to the first one it
    refuses (or, with `budget`, until that many seconds have passed: the runs loaded are then a
    first part of `indices`). {"indices": the runs loaded, "scenes": their Scenes (None unless
    `keep`), "params": their table values, "refused": the index of the first run refused (else
    None), "worlds": {world settings repr: first run index with them}}. Plain data: a Dask
    worker returns it, and `refusal` names the refused run's key from it."""
    scenes: list | None = [] if keep else None
    done, params, worlds = [], [], {}
    refused = None
    until = None if budget is None else time.perf_counter() + budget
    for index in indices:
        if until is not None and time.perf_counter() > until:
            break
        draws = sweep.draws(index)
        try:
            scene = sweep.load_run(index, draws)
        except SceneError:
            refused = index
            break
        worlds.setdefault(repr(scene.world), index)
        done.append(index)
        params.append({axis.key: plain for axis, _, plain in draws})
        if scenes is not None:
            scenes.append(scene)
    return {
        "indices": done,
        "scenes": scenes,
        "params": params,
        "refused": refused,
        "worlds": worlds,
    }


def refusal(sweep: Sweep, index: int) -> SweepError:
    """The SweepError for run `index`, whose scene the loader refuses (loaded again here, so
    the message is the loader's own wherever the refusal was first found)."""
    try:
        load_scene_text(
            sweep.run_scene_text(index), source=sweep.scene_path, default_name=sweep.scene_name
        )
    except SceneError as exc:
        return _run_refusal(sweep, index, exc)
    return SweepError(
        f"run {index}: a worker's scene loader refuses this run's scene, which this process's "
        "accepts: do the workers run the same version of ISAAC?",
        source=sweep.path,
        line=sweep.runs_line,
        path="runs",
    )


def check_runs(sweep: Sweep, indices=None) -> dict:
    """Load the scenes of runs `indices` (default every run) with the scene loader; SweepError
    naming the run and the key for the first run whose scene is refused. Returns {world
    settings repr: run index} of the distinct world settings (for compiling their kernels
    before the fan-out)."""
    loaded = load_runs(sweep, range(sweep.n_runs) if indices is None else indices, keep=False)
    if loaded["refused"] is not None:
        raise refusal(sweep, loaded["refused"])
    return loaded["worlds"]


def _run_refusal(sweep: Sweep, index: int, exc: SceneError) -> SweepError:
    draws = sweep.draws(index)
    for axis, node, plain in draws:
        if exc.path and exc.path == axis.slot.scene_path and exc.what.startswith("unknown key"):
            # the key path names no place a scene has (a misspelt field): not the value's fault
            return SweepError(
                f"no such key in a scene: {exc.what} (scene {exc.path})",
                source=sweep.path,
                line=axis.line,
                path=_sweep_path(axis, sweep.grid),
            )
        if exc.path and axis.slot.covers(exc.path):
            if axis.dist is not None:
                line, kind = axis.dist[2], f"drawn value {_shown_value(plain)}"
            else:
                line = next(ln for n, _, ln in axis.values if n is node)
                kind = f"value {_shown_value(plain)}"
            return SweepError(
                f"run {index}: {kind} makes the scene invalid: {exc.what} (scene {exc.path})",
                source=sweep.path,
                line=line,
                path=_sweep_path(axis, sweep.grid),
            )
    values = ", ".join(f"{a.key}={_shown_value(p)}" for a, _, p in draws)
    return SweepError(
        f"run {index} ({values}) makes the scene invalid: {exc}",
        source=sweep.path,
        line=sweep.runs_line,
        path="runs",
    )


def _shown_value(value) -> str:
    text = repr(value) if not isinstance(value, str) else shown(value)
    return text if len(text) <= 60 else text[:60] + "..."
