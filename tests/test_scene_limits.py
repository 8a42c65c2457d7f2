"""Scene limits: what a scene may hold is what its log can carry back, and no input, however big
or strange, costs more than a few seconds and a few hundred MB before its one-line refusal."""

import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import pytest

from isaac.errors import SceneError
from isaac.scene import generators, load_scene, load_scene_text, scene_to_yaml
from isaac.scene.limits import (
    MAX_BODY_NODES,
    MAX_LIST_ITEMS,
    MAX_NAME_LENGTH,
    MAX_PILE_COUNT,
    MAX_QUOTED,
    MAX_SECTION_NODES,
)
from isaac.scene.reader import Reader, compose
from isaac.scene.warnings import HELD_MASS_RATIO, scene_warnings

ROOT = Path(__file__).resolve().parent.parent
BOX = "shape: {box: [1.0, 1.0]}"
ONE_BODY = f"bodies:\n  - {{{BOX}}}\n"


def _round_trip(scene):
    again = load_scene_text(scene_to_yaml(scene), source=scene.source)
    assert again == scene
    return again


# --- an expanded scene the log loader would refuse is refused at the key that made it -------

# (id, scene text, line, key path, fragment): each of these passed `isaac check` and ran, and
# its log's scene was then refused by `isaac replay`.
UNCARRIABLE = [
    ("box_over_max_extent", "bodies:\n  - shape: {box: [800000, 800000]}\n", 2,
     "bodies[0].shape.box", "extent 1131370.8498984762 m is outside"),
    ("box_sliver", "bodies:\n  - shape: {box: [1e-6, 1e6]}\n", 2,
     "bodies[0].shape.box", "duplicates"),
    ("regular_over_max_extent", "bodies:\n  - shape: {regular: {sides: 5, radius: 7e5}}\n", 2,
     "bodies[0].shape.regular", "extent"),
    ("pile_container_width", "generators:\n  - pile: {count: 3, container: {width: 1e6}}\n", 2,
     "generators[0].pile.container.width", "'pile/floor' it makes: the polygon's extent"),
    ("pile_container_far", "generators:\n  - pile:\n      count: 3\n"
     "      container: {position: [1e9, 0]}\n", 4,
     "generators[0].pile.container.position", "'pile/right' it makes: position"),
    ("pile_container_height", "generators:\n  - pile: {count: 3, container: {height: 1e9}}\n",
     2, "generators[0].pile.container.height", "out of range"),
    ("pile_walls_grow_too_tall", "generators:\n  - pile:\n      count: 500\n"
     "      radius: [1000, 1000]\n      container: {width: 2200}\n", 3,
     "generators[0].pile.count", "'pile/left' it makes: the polygon's extent"),
    ("pyramid_box", "generators:\n  - pyramid: {rows: 2, box: [1e6, 1e6]}\n", 2,
     "generators[0].pyramid.box", "'pyramid/ground' it makes: the polygon's extent"),
    ("pyramid_box_no_ground", "generators:\n  - pyramid: {rows: 2, box: [1e6, 1e6], "
     "ground: false}\n", 2, "generators[0].pyramid.box", "'pyramid/1/1' it makes"),
    ("pyramid_ground", "generators:\n  - pyramid: {rows: 300, box: [5000, 1]}\n", 2,
     "generators[0].pyramid.box", "'pyramid/ground' it makes"),
    ("pyramid_far", "generators:\n  - pyramid:\n      rows: 3\n      box: [1, 1]\n"
     "      base: [0, 999999999]\n", 5, "generators[0].pyramid.base", "'pyramid/2/1' it makes"),
    ("pyramid_name_200", "generators:\n  - pyramid: {rows: 2, box: [1, 1], name: "
     + "p" * 200 + "}\n", 2, "generators[0].pyramid.name", "use at most 193"),
    ("pile_name_for_five_digit_counts", "generators:\n  - pile: {count: 10000, name: "
     + "p" * 195 + "}\n", 2, "generators[0].pile.name", "use at most 194"),
]  # fmt: skip


@pytest.mark.parametrize(
    "text, line, key, fragment", [c[1:] for c in UNCARRIABLE], ids=[c[0] for c in UNCARRIABLE]
)
def test_a_scene_its_log_could_not_carry_is_refused_at_the_key_that_made_it(
    text, line, key, fragment
):
    with pytest.raises(SceneError) as info:
        load_scene_text(text, source="s.yaml")
    error = info.value
    assert (error.line, error.path) == (line, key), str(error)
    assert fragment in error.what
    assert "\n" not in str(error)


@pytest.mark.parametrize(
    "text",
    [
        "bodies:\n  - shape: {box: [700000, 700000]}\n",  # extent 989,949 m
        "bodies:\n  - shape: {box: [1e-6, 1e-6]}\n    density: 1e9\n",
        "bodies:\n  - shape: {regular: {sides: 50, radius: 3.5e5}}\n    position: [1e9, -1e9]\n",
        "generators:\n  - pile: {count: 3, container: {position: [999999000, -999999000]}}\n",
        "generators:\n  - pile: {count: 99, name: " + "q" * 194 + "}\n",
        "generators:\n  - pyramid: {rows: 9, box: [1, 1], name: " + "q" * 193 + "}\n",
        "generators:\n  - pile: {count: 3, container: {width: 999998, thickness: 0.5}}\n",
    ],
    ids=["box", "tiny_dense", "regular_far", "pile_far", "pile_name", "pyramid_name", "wide"],
)
def test_a_scene_at_the_limits_loads_and_its_log_scene_loads_back_bit_for_bit(text):
    scene = load_scene_text(text)
    assert max(len(b.name) for b in scene.bodies) <= MAX_NAME_LENGTH
    again = _round_trip(scene)
    assert scene_to_yaml(again) == scene_to_yaml(scene)


def test_a_scene_at_the_limits_runs_records_and_replays_identical(tmp_path):
    from isaac.engine.simulation import Simulation
    from recorder import Recorder
    from replay.compare import replay_log

    longest = "n" * (MAX_NAME_LENGTH - len("/ground"))
    scene = load_scene_text(
        "world: {dt: 0.01, gravity: [0, -9.81]}\n"
        "bodies:\n"
        "  - {name: far, shape: {box: [700000, 1]}, position: [999000000, -1e9], concrete: true}\n"
        "  - {name: tiny, shape: {box: [1e-6, 1e-6]}, density: 1e9, position: [0, 50]}\n"
        f"generators:\n  - pyramid: {{rows: 2, box: [1, 1], name: {longest}}}\n",
        source="limits.yaml",
    )
    sim = Simulation(scene)
    path = tmp_path / "limits.mcap"
    recorder = Recorder(sim, mcap_path=str(path), offload="none")
    recorder.write(sim.record())
    for _ in range(5):
        recorder.write(sim.step())
    recorder.close()
    report = replay_log(str(path))
    assert report.verdict == "identical", report.verdict
    assert report.steps_compared >= 5


# --- density and mass -----------------------------------------------------------------------


@pytest.mark.parametrize(
    "text, key",
    [
        ("bodies:\n  - shape: {box: [1, 1]}\n    density: 5e-324\n", "bodies[0].density"),
        (
            "bodies:\n  - shape: {box: [1e-6, 1e-6]}\n    density: 1e-300\n    concrete: true\n",
            "bodies[0].density",
        ),
        ("bodies:\n  - shape: {regular: {sides: 3, radius: 1e-6}}\n", None),
        ("generators:\n  - pile: {count: 2, density: 1e-310}\n", "generators[0].pile.density"),
    ],
    ids=["subnormal_density", "tiny_concrete", "tiny_inertia_at_unit_density", "pile"],
)
def test_a_mass_or_inertia_that_is_not_a_normal_float_is_refused_naming_the_values(text, key):
    if key is None:  # a 1e-6 m triangle at density 1 is fine: 1e-13 kg, 1e-25 kg m^2
        scene = load_scene_text(text)
        _round_trip(scene)
        return
    with pytest.raises(SceneError) as info:
        load_scene_text(text)
    assert info.value.path == key
    assert "kg" in info.value.what and "density" in info.value.what
    assert "must be finite normal numbers" in info.value.what


# --- warnings: mass ratios beyond what a preset holds ----------------------------------------


def _two_boxes(preset: str, heavy_density: float) -> str:
    return (
        f"world: {{fidelity: {preset}}}\nbodies:\n"
        "  - {name: ground, shape: {box: [10, 1]}, position: [0, -0.5], concrete: true}\n"
        "  - {name: light, shape: {box: [1, 1]}, position: [0, 0.5]}\n"
        "  - {name: heavy, shape: {box: [1, 1]}, position: [0, 1.5], "
        f"density: {heavy_density}}}\n"
    )


def test_a_mass_ratio_of_1e9_is_warned_about_naming_both_bodies():
    (message,) = scene_warnings(load_scene_text(_two_boxes("accurate", 1e9)))
    assert "'heavy'" in message and "'light'" in message
    assert "1e+09:1" in message and "accurate" in message and "\n" not in message


@pytest.mark.parametrize("preset", sorted(HELD_MASS_RATIO))
def test_a_mass_ratio_a_preset_holds_gives_no_warning_and_one_beyond_it_does(preset):
    held = HELD_MASS_RATIO[preset]
    assert scene_warnings(load_scene_text(_two_boxes(preset, held))) == []
    assert len(scene_warnings(load_scene_text(_two_boxes(preset, held * 2)))) == 1


def test_concrete_bodies_and_equal_masses_give_no_warning():
    scene = load_scene("scenes/pyramid.yaml")
    assert scene_warnings(scene) == []
    assert scene_warnings(load_scene("scenes/mass_ratio.yaml")) == []  # 1000:1, accurate


# --- docs and code agree --------------------------------------------------------------------


def test_container_height_null_means_just_tall_enough_as_the_docs_say():
    text = "generators:\n  - pile: {count: 7, container: {width: 3}}\n"
    left_out = load_scene_text(text)
    given_null = load_scene_text(text.replace("width: 3", "width: 3, height: null"))
    assert given_null == left_out


def test_the_pile_count_limit_is_the_documented_one():
    doc = (ROOT / "docs" / "scene-format.md").read_text()
    assert f"| `count` | integer | 1 .. {MAX_PILE_COUNT:,} |" in doc
    r = Reader("s.yaml")

    def read(count: int):
        root = compose(f"pile: {{count: {count}}}\n", "s.yaml")
        return generators.read_pile(r, r.mapping(root, "", None)["pile"][1], "pile")

    assert read(MAX_PILE_COUNT)[1] == MAX_PILE_COUNT + 3  # the bodies it makes: exactly MAX_BODIES
    with pytest.raises(SceneError, match=f"must be 1..{MAX_PILE_COUNT}"):
        read(MAX_PILE_COUNT + 1)


# --- error lines quote a bounded part of the input ------------------------------------------

HUGE = "x" * 1_000_000


@pytest.mark.parametrize(
    "text",
    [
        f"bodies:\n  - {BOX}\n    density: {HUGE}\n",  # describe(): a string for a number
        f"bodies:\n  - {BOX}\n    density: 1{'0' * 1_000_000}.5\n",  # out of range
        f"world: {{integrator: {HUGE}}}\n{ONE_BODY}",  # choice()
        f"bodies:\n  - {{name: {HUGE}, {BOX}}}\n",  # name()
        f"bodies:\n  - {{{BOX}, {'k' * 1000}: 1}}\n",  # unknown key (libyaml keys: <= 1024)
        f"name: {HUGE}\n{ONE_BODY}",
        f"bodies:\n  - {{{BOX}, concrete: {HUGE}}}\n",
    ],
    ids=["number", "range", "choice", "name", "key", "scene_name", "boolean"],
)
def test_an_error_line_quotes_at_most_a_bounded_part_of_a_huge_value(text):
    with pytest.raises(SceneError) as info:
        load_scene_text(text)
    message = str(info.value)
    assert len(message) < 4 * MAX_QUOTED + 200, message[:400]
    assert "characters)" in message  # it says how long the value was


# --- files that are not files ---------------------------------------------------------------


def _check(path, *, limit_memory: bool = False) -> tuple[subprocess.CompletedProcess, float]:
    def cap():  # runs in the child: 1 GiB of address space
        resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))

    started = time.perf_counter()
    result = subprocess.run(
        [sys.executable, "-m", "isaac", "check", str(path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        preexec_fn=cap if limit_memory else None,
    )
    return result, time.perf_counter() - started


def _one_line_refusal(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 2, (result.returncode, result.stderr[-2000:])
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, lines[:5]
    return lines[0]


def test_isaac_check_refuses_a_fifo_without_waiting_for_a_writer(tmp_path):
    fifo = tmp_path / "scene.yaml"
    os.mkfifo(fifo)
    result, seconds = _check(fifo)  # before: blocked in open() until the 60 s timeout
    assert "is a FIFO" in _one_line_refusal(result)
    assert seconds < 20


@pytest.mark.parametrize("path, what", [("/dev/null", "a device"), (".", "a directory")])
def test_a_device_or_a_directory_is_refused_before_it_is_opened(path, what):
    with pytest.raises(SceneError, match=f"is {what}, not a scene file"):
        load_scene(path)


# --- hostile input: bounded time and memory -------------------------------------------------


def _hostile(tmp_path: Path, kind: str) -> Path:
    path = tmp_path / f"{kind}.yaml"
    body = f"bodies:\n  - {{{BOX}}}\n"
    if kind == "ten_million_numbers":  # 30 MB: a 10^7-number list
        text = "bodies:\n  - shape: {polygon: [" + ", ".join(["0"] * 10_000_000) + "]}\n"
    elif kind == "ten_million_bodies":
        text = "bodies: [" + ", ".join(["0"] * 10_000_000) + "]\n"
    elif kind == "wide_mapping":  # 10 MB: 300,000 keys of short lists
        text = (
            body
            + "analytic:\n"
            + "".join(f"  k{i}: [1, 2, 3, 4, 5, 6, 7, 8]\n" for i in range(300_000))
        )
    elif kind == "deep_lists":  # 10 MB of lists nested 15 deep, each legal
        item = "[" * 14 + "1" + "]" * 14
        text = (
            body
            + "analytic:\n"
            + "".join(f"  k{i}: [{', '.join([item] * 30)}]\n" for i in range(11_000))
        )
    elif kind == "fat_bodies":  # 10 MB: every body carries a big unknown key
        junk = "[" + ", ".join(["[1, 2]"] * 1000) + "]"
        text = "bodies:\n" + "".join(f"  - {{{BOX}, junk: {junk}}}\n" for i in range(1_400))
    elif kind == "many_generators":
        text = "generators:\n" + "  - pile: {count: 1}\n" * 500_000
    else:
        raise AssertionError(kind)
    path.write_text(text)
    return path


def test_isaac_check_runs_under_the_memory_cap_the_hostile_cases_use(tmp_path):
    # the cap is meaningful only if a small scene passes under it (numba and numpy included)
    path = tmp_path / "small.yaml"
    path.write_text(ONE_BODY)
    result, _ = _check(path, limit_memory=True)
    assert result.returncode == 0, result.stderr[-2000:]


@pytest.mark.parametrize(
    "kind, fragment",
    [
        ("ten_million_numbers", f"more than {MAX_BODY_NODES} YAML nodes"),
        ("ten_million_bodies", f"more than {MAX_LIST_ITEMS} items"),
        ("wide_mapping", f"`analytic:` holds more than {MAX_SECTION_NODES} YAML nodes"),
        ("deep_lists", f"`analytic:` holds more than {MAX_SECTION_NODES} YAML nodes"),
        ("fat_bodies", f"more than {MAX_BODY_NODES} YAML nodes"),
        ("many_generators", f"more than {MAX_SECTION_NODES} YAML nodes"),
    ],
)
def test_hostile_scenes_are_refused_in_seconds_under_1_gib(tmp_path, kind, fragment):
    # before: the 30 MB list took 108 s and 3 GB; 7-14 MB scenes 29-36 s and 0.6-1.3 GB
    path = _hostile(tmp_path, kind)
    result, seconds = _check(path, limit_memory=True)
    assert fragment in _one_line_refusal(result)
    assert seconds < 20


def test_a_log_scene_of_many_bodies_loads_back_in_linear_time():
    # the text scene_to_yaml writes for a pile (540 bytes a body) took 87 s for 100,000 bodies
    # (0.87 ms a body, 17 s for these 20,000); now about 40 us a body
    scene = load_scene_text(
        "generators:\n  - pile: {count: 19997, seed: 5, container: {width: 150}}\n"
    )
    text = scene_to_yaml(scene)
    started = time.perf_counter()
    again = load_scene_text(text, source=scene.source)
    seconds = time.perf_counter() - started
    assert again == scene
    assert seconds < 5, f"{seconds:.1f} s for {len(scene.bodies)} bodies"
