"""Bad scene input: every class is a one-line SceneError naming the file, the line and the key.

Each case is checked twice: through `load_scene` (the error's fields) and through the command
line `isaac check` (exit status 2, one line on stderr, no traceback).
"""

import subprocess
import sys
import time
from pathlib import Path

import pytest

from isaac.errors import SceneError
from isaac.scene import load_scene, load_scene_text
from isaac.scene import loader as scene_module

ROOT = Path(__file__).resolve().parent.parent
BOX = "shape: {box: [1.0, 1.0]}"
ONE_BODY = f"bodies:\n  - {{{BOX}}}\n"

BILLION_LAUGHS = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 9)}]\n" for i in range(8)
)

# (id, file content, line, key path, fragment of the message). line None: no line applies.
CASES = [
    (
        "yaml_syntax",
        "world:\n  dt: 0.01\n  gravity: [0, -9.81\nbodies: []\n",
        4,
        "",
        "YAML syntax error",
    ),
    ("tab_indentation", "world:\n\tdt: 0.01\n", 2, "", "YAML syntax error"),
    ("two_documents", ONE_BODY + "---\n" + ONE_BODY, 3, "", "YAML syntax error"),
    ("not_a_mapping", "- 1\n- 2\n", 1, "", "expected a mapping"),
    ("empty_file", "", 1, "", "empty"),
    ("only_comments", "# nothing here\n", 1, "", "empty"),
    ("no_bodies", "world: {dt: 0.01}\nbodies: []\n", 1, "", "no bodies"),
    ("alias", f"bodies:\n  - &b {{{BOX}}}\n  - *b\n", 2, "", "anchors"),
    ("billion_laughs", BILLION_LAUGHS, 1, "", "anchors"),
    ("explicit_tag", "name: !!python/object/apply:os.system [echo hi]\n" + ONE_BODY, 1, "", "tags"),
    (
        "duplicate_key",
        "world:\n  dt: 0.01\n  dt: 0.02\n" + ONE_BODY,
        3,
        "world.dt",
        "duplicate key 'dt' (first given at line 2)",
    ),
    ("unknown_top_key", "wrold: {dt: 0.01}\n" + ONE_BODY, 1, "wrold", "did you mean 'world'"),
    (
        "unknown_body_key",
        f"bodies:\n  - {BOX}\n    dencity: 2.0\n",
        3,
        "bodies[0].dencity",
        "did you mean 'density'",
    ),
    (
        "string_for_number",
        "world:\n  dt: fast\n" + ONE_BODY,
        2,
        "world.dt",
        "expected a number, got the string 'fast'",
    ),
    ("quoted_number", "world:\n  dt: '0.01'\n" + ONE_BODY, 2, "world.dt", "expected a number"),
    (
        "list_for_number",
        f"bodies:\n  - {BOX}\n    angle: [1, 2]\n",
        3,
        "bodies[0].angle",
        "got a list",
    ),
    (
        "float_for_integer",
        "world:\n  steps: 10.5\n" + ONE_BODY,
        2,
        "world.steps",
        "expected a whole number",
    ),
    (
        "yaml11_boolean_word",
        "world:\n  friction: off\n" + ONE_BODY,
        2,
        "world.friction",
        "expected true or false, got the string 'off'",
    ),
    (
        "yes_is_not_true",
        f"bodies:\n  - {BOX}\n    concrete: yes\n",
        3,
        "bodies[0].concrete",
        "expected true or false",
    ),
    (
        "bad_choice",
        "world:\n  integrator: semi-implicit\n" + ONE_BODY,
        2,
        "world.integrator",
        "did you mean 'semi_implicit'",
    ),
    (
        "bad_preset",
        "world:\n  fidelity: ultra\n" + ONE_BODY,
        2,
        "world.fidelity",
        "not one of seed, fast, balanced, accurate",
    ),
    ("nan", "world:\n  dt: .nan\n" + ONE_BODY, 2, "world.dt", "NaN"),
    ("infinity", "world:\n  gravity: [0.0, -.inf]\n" + ONE_BODY, 2, "world.gravity[1]", "infinity"),
    (
        "overflowing_number",
        f"bodies:\n  - {BOX}\n    density: 1e999\n",
        3,
        "bodies[0].density",
        "out of range",
    ),
    ("zero_dt", "world:\n  dt: 0\n" + ONE_BODY, 2, "world.dt", "out of range"),
    (
        "restitution_above_one",
        f"bodies:\n  - {BOX}\n    restitution: 1.5\n",
        3,
        "bodies[0].restitution",
        "out of range",
    ),
    (
        "negative_density",
        f"bodies:\n  - {BOX}\n    density: -1\n",
        3,
        "bodies[0].density",
        "out of range",
    ),
    (
        "huge_integer",
        "world:\n  steps: 99999999999999999999999999999999999999\n" + ONE_BODY,
        2,
        "world.steps",
        "out of range",
    ),
    (
        "leaves_before_entering",
        f"bodies:\n  - {BOX}\n    enters_at: 2.0\n    leaves_at: 1.0\n",
        4,
        "bodies[0].leaves_at",
        "later than enters_at",
    ),
    (
        "duplicate_body_name",
        f"bodies:\n  - {{name: a, {BOX}}}\n  - {{name: a, {BOX}}}\n",
        3,
        "bodies[1].name",
        "duplicate body name 'a' (already used by bodies[0].name at line 2)",
    ),
    (
        "name_clash_with_generator",
        f"bodies:\n  - {{name: pile/1, {BOX}}}\ngenerators:\n  - pile: {{count: 3}}\n",
        4,
        "generators[0]",
        "duplicate body name 'pile/1'",
    ),
    (
        "two_shapes",
        "bodies:\n  - shape: {box: [1, 1], regular: {sides: 5, radius: 1}}\n",
        2,
        "bodies[0].shape",
        "exactly one of box, polygon, regular",
    ),
    ("missing_shape", "bodies:\n  - name: a\n", 2, "bodies[0]", "missing key 'shape'"),
    (
        "too_many_vertices",
        "bodies:\n  - shape:\n      polygon: [" + ", ".join(["[0, 0]"] * 51) + "]\n",
        3,
        "bodies[0].shape.polygon",
        "at most 50 vertices",
    ),
    (
        "too_few_vertices",
        "bodies:\n  - shape: {polygon: [[0, 0], [1, 0]]}\n",
        2,
        "bodies[0].shape.polygon",
        "at least 3 vertices",
    ),
    (
        "non_convex",
        "bodies:\n  - shape:\n      polygon: [[0, 0], [2, 0], [1, 0.5], [2, 2], [0, 2]]\n",
        3,
        "bodies[0].shape.polygon",
        "not convex",
    ),
    (
        "bow_tie",
        "bodies:\n  - shape:\n      polygon: [[0, 0], [2, 1], [2, 0], [0, 1.5]]\n",
        3,
        "bodies[0].shape.polygon",
        "self-intersecting",
    ),
    (
        "duplicate_vertex",
        "bodies:\n  - shape:\n      polygon: [[0, 0], [1, 0], [1, 0], [0, 1]]\n",
        3,
        "bodies[0].shape.polygon",
        "duplicates",
    ),
    (
        "zero_area",
        "bodies:\n  - shape:\n      polygon: [[0, 0], [1, 1], [2, 2]]\n",
        3,
        "bodies[0].shape.polygon",
        "collinear",
    ),
    (
        "zero_size_box",
        "bodies:\n  - shape: {box: [0, 1]}\n",
        2,
        "bodies[0].shape.box[0]",
        "out of range",
    ),
    (
        "unknown_generator",
        "generators:\n  - pyramids: {rows: 3, box: [1, 1]}\n",
        2,
        "generators[0].pyramids",
        "did you mean 'pyramid'",
    ),
    (
        "generator_count_too_big",
        "generators:\n  - pile:\n      count: 100001\n",
        3,
        "generators[0].pile.count",
        "out of range",
    ),
    (
        "generators_exceed_max_bodies",
        "generators:\n  - pyramid: {rows: 446, box: [1, 1]}\n  - pile:\n      count: 400\n",
        4,
        "generators[1].pile",
        "exceed 100000 bodies",
    ),
    (
        "container_too_low",
        "generators:\n  - pile:\n      count: 100\n      container: {width: 5.0, height: 3.0}\n",
        4,
        "generators[0].pile.container.height",
        "too low for 100 bodies",
    ),
    (
        "container_too_narrow",
        "generators:\n  - pile:\n      count: 10\n      radius: [0.5, 2]\n"
        "      container: {width: 3.0}\n",
        5,
        "generators[0].pile.container.width",
        "narrower than one body cell",
    ),
    ("non_printable_character", 'name: "a\x01b"\n' + ONE_BODY, 1, "", "not allowed"),
]


def _write(tmp_path: Path, content) -> Path:
    path = tmp_path / "bad.yaml"
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8")
    return path


@pytest.mark.parametrize(
    "content, line, key, fragment", [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_bad_scene_raises_scene_error_with_line_and_key(tmp_path, content, line, key, fragment):
    path = _write(tmp_path, content)
    started = time.perf_counter()
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert time.perf_counter() - started < 5.0  # never a hang
    error = info.value
    assert error.source == str(path)
    assert error.line == line
    assert error.path == key
    assert fragment in error.what
    assert "\n" not in str(error)
    expected_start = f"{path}:{line}:" if line is not None else f"{path}:"
    assert str(error).startswith(expected_start + (f" {key}:" if key else ""))


def test_non_utf8_bytes_name_their_line(tmp_path):
    path = _write(tmp_path, b"name: ok\nbodies:\n  - {name: \xff\xfe, shape: {box: [1, 1]}}\n")
    with pytest.raises(SceneError, match="not UTF-8") as info:
        load_scene(path)
    assert info.value.line == 3


def test_missing_file_is_a_scene_error(tmp_path):
    with pytest.raises(SceneError, match="no such file"):
        load_scene(tmp_path / "nope.yaml")


def test_directory_is_a_scene_error(tmp_path):
    with pytest.raises(SceneError, match="directory"):
        load_scene(tmp_path)


def test_unreadable_path_is_a_scene_error(tmp_path):
    # a path through a regular file cannot be opened, whoever runs the test (even root)
    blocker = _write(tmp_path, ONE_BODY)
    with pytest.raises(SceneError, match="cannot read the file"):
        load_scene(blocker / "scene.yaml")


def test_deep_nesting_is_refused_without_a_traceback():
    with pytest.raises(SceneError, match="nested too deeply"):
        load_scene_text("a: " + "[" * 100_000 + "]" * 100_000 + "\n")


def test_more_bodies_than_max_bodies_is_refused(monkeypatch):
    monkeypatch.setattr(scene_module, "MAX_BODIES", 3)
    text = "bodies:\n" + "".join(f"  - {{name: b{i}, {BOX}}}\n" for i in range(4))
    with pytest.raises(SceneError, match="at most 3 bodies") as info:
        load_scene_text(text)
    assert info.value.path == "bodies" and info.value.line == 2


def _cli_check(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "isaac", "check", str(path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.parametrize(
    "content, line, key, fragment", [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_isaac_check_prints_one_line_and_exits_2(tmp_path, content, line, key, fragment):
    path = _write(tmp_path, content)
    result = _cli_check(path)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1
    assert f"{path}:{line}:" in lines[0]
    if key:
        assert f" {key}: " in lines[0]
    assert fragment in lines[0]


@pytest.mark.parametrize(
    "content", [None, b"bodies:\n  - name: \xff\n"], ids=["missing_file", "non_utf8"]
)
def test_isaac_check_reports_unreadable_input_in_one_line(tmp_path, content):
    path = tmp_path / "missing.yaml" if content is None else _write(tmp_path, content)
    result = _cli_check(path)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert str(path) in result.stderr


def test_isaac_check_accepts_a_good_scene():
    result = _cli_check(ROOT / "scenes" / "head_on.yaml")
    assert result.returncode == 0, result.stderr
