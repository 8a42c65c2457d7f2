"""Scene loading, preset resolution, generators and the exact YAML round trip."""

import dataclasses
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from isaac.scene import (
    PRESETS,
    BodySpec,
    Scene,
    WorldSettings,
    load_scene,
    load_scene_text,
    scene_to_yaml,
)
from isaac.scene.polygon import mass_properties

# the shipped scenes; a sweep file (`*.sweep.yaml`, isaac sweep) beside them is not a scene
SCENES = sorted(
    p
    for p in (Path(__file__).resolve().parent.parent / "scenes").glob("*.yaml")
    if not p.name.endswith(".sweep.yaml")
)
BOX = "shape: {box: [1.0, 1.0]}"


def _bits(value):
    """Every float of a (nested) value as its 64 bits, so -0.0 != 0.0 and 1 ULP counts."""
    if isinstance(value, float):
        return struct.pack("<d", value)
    if isinstance(value, (tuple, list)):
        return tuple(_bits(v) for v in value)
    if isinstance(value, dict):
        return tuple((k, _bits(v)) for k, v in value.items())
    if dataclasses.is_dataclass(value):
        # fields left out of comparison (Scene.marks: where the YAML said it) are not the scene
        fields = [f for f in dataclasses.fields(value) if f.compare]
        return tuple((f.name, _bits(getattr(value, f.name))) for f in fields)
    return value


def _assert_round_trips(scene: Scene) -> str:
    text = scene_to_yaml(scene)
    again = load_scene_text(text, source=scene.source)
    assert again == scene
    assert _bits(again) == _bits(scene)
    assert scene_to_yaml(again) == text
    return text


def test_shipped_scenes_exist():
    names = {p.stem for p in SCENES}
    assert {"head_on", "bounce", "off_centre", "pyramid", "pile", "spawn", "default"} <= names


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_every_shipped_scene_round_trips_bit_for_bit(path):
    scene = load_scene(path)
    assert scene.name == path.stem
    text = _assert_round_trips(scene)
    assert "generators" not in text and "box:" not in text  # fully expanded


def test_awkward_floats_round_trip_bit_for_bit():
    body = BodySpec(
        name='odd "name" \\ é',
        vertices=((0.1, -0.0), (1.0 / 3.0, 5e-324), (2.0 / 3.0, 0.7000000000000001)),
        position=(-0.0, 1e-300),
        angle=math.pi,
        velocity=(1e5 / 3.0, -2.5e-7),
        angular_velocity=-0.0,
        density=7.0 / 9.0,
        restitution=0.1 + 0.2,
        friction=1e-12,
        enters_at=1.0 / 7.0,
        leaves_at=2.0 / 7.0,
    )
    world = WorldSettings(gravity=(-0.0, -9.80665), dt=1.0 / 240.0, slop=0.1 + 0.2 - 0.3)
    scene = Scene(
        name="odd",
        world=world,
        bodies=(body,),
        source="<text>",
        analytic={
            "kind": "bounce",
            "height": 1.0 / 3.0,
            "n": 3,
            "on": True,
            "series": [0.1, 2],
            "nested": {"x": -0.0},
        },
    )
    _assert_round_trips(scene)


def test_without_world_the_default_preset_applies():
    scene = load_scene_text(f"bodies:\n  - {{{BOX}}}\n")
    assert load_scene_text(f"world: {{}}\nbodies:\n  - {{{BOX}}}\n") == scene
    assert scene.world == WorldSettings()
    assert scene.world.fidelity == "balanced"
    assert all(getattr(scene.world, k) == v for k, v in PRESETS["balanced"].items())


def test_preset_is_applied_then_explicit_keys_override_it():
    scene = load_scene_text(
        f"world: {{fidelity: seed, iterations: 5, ccd: speculative}}\nbodies:\n  - {{{BOX}}}\n"
    )
    expected = dict(PRESETS["seed"], iterations=5, ccd="speculative")
    assert {k: getattr(scene.world, k) for k in expected} == expected
    assert scene.world.fidelity == "seed"


def test_yaml_1_1_words_stay_strings_and_exponent_numbers_are_floats():
    scene = load_scene_text(
        "world:\n  ccd: off\n  position_correction: none\n  dt: 1e-3\n  gravity: [0, -9.81E0]\n"
        f"bodies:\n  - {{{BOX}}}\n"
    )
    assert scene.world.ccd == "off"
    assert scene.world.position_correction == "none"
    assert scene.world.dt == 0.001
    assert scene.world.gravity == (0.0, -9.81)
    assert isinstance(scene.world.gravity[0], float)


def test_body_defaults_match_the_contract():
    body = load_scene_text(f"bodies:\n  - {{{BOX}}}\n").bodies[0]
    assert body == BodySpec(name="body/1", vertices=body.vertices)
    assert body.vertices == ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5))


def test_clockwise_polygon_far_from_origin_is_stored_ccw_with_its_own_coordinates():
    scene = load_scene_text(
        "bodies:\n  - shape: {polygon: [[100, 50], [100, 51], [102, 51], [102, 50]]}\n"
    )
    assert scene.bodies[0].vertices == ((102.0, 50.0), (102.0, 51.0), (100.0, 51.0), (100.0, 50.0))


def test_regular_shape_expands_to_its_vertices():
    scene = load_scene_text("bodies:\n  - shape: {regular: {sides: 4, radius: 2.0}}\n")
    vertices = np.array(scene.bodies[0].vertices)
    assert np.allclose(vertices, [[2, 0], [0, 2], [-2, 0], [0, -2]], atol=1e-15)


def test_name_defaults_to_the_file_stem(tmp_path):
    path = tmp_path / "my_scene.yaml"
    path.write_text(f"bodies:\n  - {{{BOX}}}\n")
    assert load_scene(path).name == "my_scene"
    assert load_scene(path).source == str(path)


def test_bodies_come_first_then_generators_in_order():
    scene = load_scene_text(
        "generators:\n  - pyramid: {rows: 2, box: [1, 1], ground: false}\n"
        "  - pile: {count: 2, name: p}\n"
        f"bodies:\n  - {{name: solo, {BOX}}}\n"
    )
    assert [b.name for b in scene.bodies] == [
        "solo",
        "pyramid/1/1",
        "pyramid/1/2",
        "pyramid/2/1",
        "p/floor",
        "p/left",
        "p/right",
        "p/1",
        "p/2",
    ]


def test_pyramid_boxes_sit_in_rows_centred_on_the_base():
    rows, w, h, gap, base = 4, 1.0, 0.5, 0.1, (2.0, 1.0)
    scene = load_scene_text(
        f"generators:\n  - pyramid: {{rows: {rows}, box: [{w}, {h}], base: [2.0, 1.0], "
        f"spacing: {gap}, density: 3.0}}\n"
    )
    ground, boxes = scene.bodies[0], {b.name: b for b in scene.bodies[1:]}
    assert len(boxes) == rows * (rows + 1) // 2
    assert ground.concrete and ground.name == "pyramid/ground"
    # the ground's top surface passes through the base point
    assert ground.position[1] + max(y for _, y in ground.vertices) == pytest.approx(base[1])
    for row in range(1, rows + 1):
        count = rows - row + 1
        xs = [boxes[f"pyramid/{row}/{c}"].position[0] for c in range(1, count + 1)]
        ys = [boxes[f"pyramid/{row}/{c}"].position[1] for c in range(1, count + 1)]
        assert ys == pytest.approx([base[1] + (row - 0.5) * h] * count)
        assert np.mean(xs) == pytest.approx(base[0])
        assert np.diff(xs) == pytest.approx([w + gap] * (count - 1))
    assert all(b.density == 3.0 and not b.concrete for b in boxes.values())


def _world_vertices(body: BodySpec) -> np.ndarray:
    # the engine's convention: local vertices re-centred on the centroid, then rotated (CCW)
    local = np.array(body.vertices) - mass_properties(body.vertices)[1]
    c, s = math.cos(body.angle), math.sin(body.angle)
    return np.column_stack(
        [
            body.position[0] + c * local[:, 0] - s * local[:, 1],
            body.position[1] + s * local[:, 0] + c * local[:, 1],
        ]
    )


def test_pile_bodies_start_inside_the_container_and_apart():
    width, r_max = 6.0, 0.5
    scene = load_scene_text(
        "generators:\n  - pile: {count: 120, seed: 3, radius: [0.2, 0.5], sides: [3, 8],\n"
        "              container: {width: 6.0, thickness: 0.4, position: [1.0, -2.0]}}\n"
    )
    floor, left, right, *bodies = scene.bodies
    assert [floor.name, left.name, right.name] == ["pile/floor", "pile/left", "pile/right"]
    assert floor.concrete and left.concrete and right.concrete
    wall_top = left.position[1] + max(y for _, y in left.vertices)
    for body in bodies:
        world = _world_vertices(body)
        assert np.all(world[:, 0] > 1.0 - width / 2) and np.all(world[:, 0] < 1.0 + width / 2)
        assert np.all(world[:, 1] > -2.0) and np.all(world[:, 1] < wall_top)
        # the generator draws vertices on a circle around the local origin
        radius = np.hypot(*(np.array(body.vertices).T))
        assert np.all(radius <= r_max + 1e-12) and np.all(radius >= 0.2 - 1e-12)
    # the local origin lands on the cell's centre; circles of radius <= r_max around centres at
    # least 2 * r_max apart cannot overlap
    cell_centres = np.array(
        [_world_vertices(b)[0] - _rotate(np.array(b.vertices[0]), b.angle) for b in bodies]
    )
    gaps = np.hypot(*(cell_centres[:, None, :] - cell_centres[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(gaps, np.inf)
    assert gaps.min() >= 2 * r_max


def _rotate(v: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def test_pile_polygons_respect_sides_and_radius_ranges():
    scene = load_scene_text(
        "generators:\n  - pile: {count: 300, sides: [4, 6], "
        "radius: [0.3, 0.4], container: {width: 20}}\n"
    )
    bodies = scene.bodies[3:]
    sides = {len(b.vertices) for b in bodies}
    assert sides == {4, 5, 6}
    for b in bodies:
        r = np.hypot(*np.array(b.vertices).T)
        assert np.ptp(r) < 1e-12 and 0.3 <= r[0] <= 0.4


def test_pile_is_reproducible_from_its_seed_and_changes_with_it():
    text = "generators:\n  - pile: {{count: 50, seed: {}}}\n"
    assert load_scene_text(text.format(5)) == load_scene_text(text.format(5))
    assert load_scene_text(text.format(5)).bodies[3:] != load_scene_text(text.format(6)).bodies[3:]


def test_pile_walls_default_to_just_tall_enough_for_the_grid():
    # 100 bodies of radius <= 0.5 in 5 m: cells of 1.05 m, 4 per row, 25 rows
    scene = load_scene_text("generators:\n  - pile: {count: 100, container: {width: 5.0}}\n")
    left = scene.bodies[1]
    assert max(y for _, y in left.vertices) * 2 == pytest.approx(25 * 1.05)


@pytest.mark.parametrize("count", [2000, 10000])
def test_big_piles_are_a_few_lines_of_yaml(count):
    scene = load_scene_text(
        f"generators:\n  - pile: {{count: {count}, seed: 1, container: {{width: 100}}}}\n"
    )
    assert len(scene.bodies) == count + 3
    assert len({b.name for b in scene.bodies}) == count + 3


@pytest.mark.slow
def test_a_10000_body_pile_round_trips_bit_for_bit():
    scene = load_scene_text("generators:\n  - pile: {count: 10000, container: {width: 100}}\n")
    _assert_round_trips(scene)


def test_analytic_block_is_kept_as_plain_data():
    scene = load_scene_text(
        f"bodies:\n  - {{{BOX}}}\nanalytic: {{kind: bounce, heights: [1.0, 0.64], n: 2}}\n"
    )
    assert scene.analytic == {"kind": "bounce", "heights": [1.0, 0.64], "n": 2}


def test_every_world_setting_and_body_key_is_documented():
    doc = (Path(__file__).resolve().parent.parent / "docs" / "scene-format.md").read_text()
    world_fields = [f.name for f in dataclasses.fields(WorldSettings)]
    # a body's vertices and circle radius are its `shape:`, documented under Shapes
    shapes = ("vertices", "circle")
    body_keys = [f.name for f in dataclasses.fields(BodySpec) if f.name not in shapes]
    missing = [k for k in world_fields + body_keys + ["shape"] if f"| `{k}` |" not in doc]
    assert missing == []
    assert "* `{circle: {radius: R}}`" in doc
    assert all(set(p) <= set(world_fields) for p in PRESETS.values())


def test_every_world_setting_can_be_set_explicitly():
    # the writer emits every field; reading it back must accept each one, even new ones
    world = load_scene_text(f"world: {{fidelity: fast}}\nbodies:\n  - {{{BOX}}}\n").world
    text = scene_to_yaml(Scene(name="w", world=world, bodies=(), source="<text>"))
    body = f"bodies:\n  - {{{BOX}}}\n"
    assert load_scene_text(text.replace("bodies:\n", body)).world == world


def test_a_number_written_as_a_name_is_that_text():
    scene = load_scene_text(f"bodies:\n  - {{name: 7, {BOX}}}\n  - {{name: nan, {BOX}}}\n")
    assert [b.name for b in scene.bodies] == ["7", "nan"]
    _assert_round_trips(scene)


def test_pure_python_yaml_parser_gives_the_same_scene(monkeypatch):
    # libyaml is optional in PyYAML: the fallback parser must read scenes identically
    from isaac.scene import reader as scene_module

    path = SCENES[0].parent / "default.yaml"
    fast = load_scene(path)
    monkeypatch.setattr(scene_module, "_LOADER", scene_module._NoAliasLoader)
    slow = load_scene(path)
    assert _bits(slow) == _bits(fast)
    with pytest.raises(scene_module.SceneError, match="aliases|anchors"):
        load_scene_text("a: &x 1\nb: *x\n")
