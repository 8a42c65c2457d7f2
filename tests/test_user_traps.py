"""Traps a new user fell into: wording that says what to write, and an API that shows itself."""

from __future__ import annotations

import pytest

import isaac
from isaac.errors import SceneError
from isaac.scene import load_scene_text


def _refusal(text: str) -> str:
    with pytest.raises(SceneError) as info:
        load_scene_text(text)
    return str(info.value)


def test_a_box_of_one_number_asks_for_exactly_two_named_numbers():
    message = _refusal("bodies:\n  - {name: a, shape: {box: [1]}}\n")
    assert message.endswith("bodies[0].shape.box: expected exactly 2 numbers [w, h], got 1")
    message = _refusal("bodies:\n  - {name: a, shape: {box: [1, 1]}, position: [1, 2, 3]}\n")
    assert "bodies[0].position: expected exactly 2 numbers [x, y], got 3" in message


@pytest.mark.parametrize(
    ("written", "meant"), [("True", "true"), ("FALSE", "false"), ("yes", "true"), ("off", "false")]
)
def test_a_python_or_yaml11_boolean_gets_a_did_you_mean(written, meant):
    message = _refusal(f"bodies:\n  - {{name: a, shape: {{box: [1, 1]}}, concrete: {written}}}\n")
    assert f"expected true or false, got the string {written!r} (did you mean {meant}?)" in message


def test_a_non_convex_vertex_is_named_by_index_from_0_and_its_coordinates():
    polygon = "[[0, 0], [2, 0], [1, 0.2], [1, 2]]"
    message = _refusal(f"bodies:\n  - {{name: a, shape: {{polygon: {polygon}}}}}\n")
    assert "turns inwards at vertex 2, [1.0, 0.2]; vertices count from 0" in message


def test_dir_lists_the_public_api():
    names = dir(isaac)
    assert names == sorted(isaac.__all__)
    for name in ("Simulation", "load_scene", "StepRecord", "StepBatch", "SceneError"):
        assert name in names and getattr(isaac, name) is not None


def test_a_body_view_shows_its_name_and_state():
    scene = load_scene_text(
        "bodies:\n  - {name: ground, shape: {box: [4, 1]}, concrete: true}\n"
        "  - {name: crate, shape: {box: [1, 1]}, position: [0, 3], velocity: [1.5, 0]}\n"
    )
    sim = isaac.Simulation(scene, compile_ahead=False)
    text = repr(sim.body("crate"))
    assert text.startswith("<BodyView 'crate' (index 1, 1 kg) at step 0:")
    assert "position (0, 3) m" in text and "velocity (1.5, 0) m/s" in text
    assert "concrete" in repr(sim.body("ground"))


def test_run_is_a_lazy_generator_and_advance_is_eager():
    import inspect

    sim = isaac.Simulation(load_scene_text("bodies:\n  - {name: a, shape: {box: [1, 1]}}\n"))
    steps = sim.run(10)
    assert inspect.isgenerator(steps) and sim.step_index == 0  # nothing computed yet
    assert next(steps).step == 1
    assert sim.step_index == 10  # one batch of up to 64 steps: run ahead of the records taken
    sim.advance(3)
    assert sim.step_index == 13  # taken before advance returned


def test_the_sweep_api_is_isaac_sweep_run():
    import inspect

    from isaac.app import sweep

    assert isaac.sweep is sweep and "sweep" in dir(isaac)
    assert list(inspect.signature(isaac.sweep.run).parameters)[:2] == ["sweep_path", "out"]
