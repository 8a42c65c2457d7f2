"""A sweep reads each run's scene by putting the run's values into the base scene's node tree
(`Sweep.load_run`), not by writing the run's YAML text and composing it again: the same Scene,
the same refusals and the same messages as `load_scene_text(sweep.run_scene_text(i))`, for
every kind of key path."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from isaac.app.sweep import keys, load_sweep
from isaac.errors import SceneError
from isaac.scene import load_scene_text, scene_to_yaml

SCENE = """\
name: tree
world:
  dt: 0.01
  steps: 50
  friction: true
bodies:
  - name: ground
    shape: {box: [20.0, 1.0]}
    position: [0.0, -0.5]
    concrete: true
  - name: box
    shape: {box: [1.0, 1.0]}
    position: [0.0, 2.0]
    restitution: 0.5
    friction: 0.4
  - name: wheel
    shape: {regular: {sides: 8, radius: 0.5}}
    position: [3.0, 2.0]
generators:
  - pile:
      count: 5
      seed: 3
      container: {width: 4.0, thickness: 0.5, position: [0.0, 6.0]}
"""


def _grid(*keys: str) -> str:
    return "grid:\n" + "".join(f"    {k}\n" for k in keys)


def _random(seed: int, *keys: str) -> str:
    return f"random:\n    n: 8\n    seed: {seed}\n" + "".join(f"    {k}\n" for k in keys)


# (what, the runs: section): every kind of key path, values given and left out by the scene
KINDS = [
    ("world setting given", _grid("world.dt: [0.01, 0.005, 1/120]")),
    ("world choice left out", _grid("world.restitution_rule: [min, max, mean]")),
    ("world pair component left out", _grid("world.gravity.y: [-9.81, -1.0, 0.0]")),
    ("world fidelity", _grid("world.fidelity: [fast, balanced, accurate]")),
    ("body key given", _random(1, "bodies.box.restitution: {uniform: [0.0, 1.0]}")),
    ("body key left out", _random(2, "bodies.wheel.friction: {uniform: [0.0, 1.0]}")),
    ("body pair component given", _random(3, "bodies.box.position.x: {normal: [0.0, 1.0]}")),
    ("body pair component left out", _random(4, "bodies.wheel.velocity.y: {uniform: [-2.0, 2.0]}")),
    (
        "shape option",
        _grid(
            "bodies.box.shape.box.0: [0.5, 1.0, 2.0]", "bodies.wheel.shape.regular.sides: [3, 12]"
        ),
    ),
    (
        "boolean and time",
        _grid("bodies.box.concrete: [true, false]", "bodies.wheel.enters_at: [0.0, 1/4]"),
    ),
    ("generator option", _random(5, "generators.0.pile.seed: {integers: [0, 1000000]}")),
    (
        "generator nested option",
        _grid("generators.0.pile.container.width: [3.0, 5.0]", "generators.0.pile.count: [1, 7]"),
    ),
    ("choice of names", _random(6, "world.friction_rule: {choice: [sqrt, min, product]}")),
    ("a list value (read from the text)", _grid("bodies.box.velocity: [[1.0, 0.0], [0.0, -2.0]]")),
    # refused: out of range (given, left out), the checks of a body and of a generator's
    (
        "out of range",
        _grid("bodies.box.restitution: [0.5, 1.5]", "bodies.wheel.friction: [0.3, -1.0]"),
    ),
    ("a body's mass refused", _grid("bodies.wheel.density: [1.0, 1e-320]")),
    ("a generator's bodies refused", _grid("generators.0.pile.density: [1.0, 1e-320]")),
    ("not a number", _grid("bodies.box.angle: [0.1, spin]")),
]


def _sweep(tmp_path: Path, runs: str):
    (tmp_path / "tree.yaml").write_text(SCENE)
    path = tmp_path / "s.sweep.yaml"
    path.write_text(f"scene: tree.yaml\nruns:\n  {textwrap.indent(runs, '  ').strip()}\n")
    return load_sweep(path)


def _from_text(sweep, index: int):
    text = sweep.run_scene_text(index)
    return load_scene_text(text, source=sweep.scene_path, default_name=sweep.scene_name)


@pytest.mark.parametrize("what, runs", KINDS, ids=[k[0] for k in KINDS])
def test_a_runs_scene_read_from_the_tree_is_the_one_read_from_its_text(tmp_path, what, runs):
    sweep = _sweep(tmp_path, runs)
    base_text = keys.emit(sweep.root, {})
    refused = 0
    for i in range(sweep.n_runs):
        try:
            want = _from_text(sweep, i)
        except SceneError as exc:
            with pytest.raises(SceneError) as got:
                sweep.load_run(i)
            assert str(got.value) == str(exc)  # the same line: FILE:LINE: KEY.PATH: what
            assert (got.value.line, got.value.path) == (exc.line, exc.path)
            refused += 1
            continue
        got = sweep.load_run(i)
        assert got == want
        assert got.marks == want.marks  # the lines of the run's values too
        assert got.as_written == want.as_written  # times written as fractions
        assert scene_to_yaml(got) == scene_to_yaml(want)  # the log's scene, byte for byte
    assert keys.emit(sweep.root, {}) == base_text  # the base tree is as it was
    assert (refused > 0) == what.startswith(("out of", "a body's", "a generator's", "not a"))


def test_scalar_values_are_read_from_the_tree_and_list_values_from_the_text(tmp_path):
    assert isinstance(_sweep(tmp_path, KINDS[1][1])._value_lines(), list)
    assert isinstance(_sweep(tmp_path, KINDS[10][1])._value_lines(), list)
    # a list value may add YAML nodes the text's limits count: such runs are read from text
    sweep = _sweep(tmp_path, KINDS[13][1])
    assert all(type(node).__name__ != "ScalarNode" for _, node, _ in sweep.draws(0))


def test_a_run_the_tree_refuses_gets_the_texts_message_with_its_line(tmp_path):
    sweep = _sweep(tmp_path, "grid:\n    bodies.wheel.friction: [-1.0]\n")
    with pytest.raises(SceneError) as got:
        sweep.load_run(0)
    with pytest.raises(SceneError) as want:
        _from_text(sweep, 0)
    assert str(got.value) == str(want.value)
    assert "bodies[2].friction" in str(got.value) and "out of range" in str(got.value)
